"""The parallax preset on real motorway frames (../shared/data; skipped when absent): the road homography is
accepted on most frames, and the pipeline runs through a real clip."""
from __future__ import annotations

import numpy as np

from app.core import Pipeline
from app.eval import road_motion
from tests.conftest import data_path


def test_tme_motorway_homography_is_accepted_on_most_frames():
    """tme08 (dashed markings, 20 fps, no CAN speed). Measured: 87 % of 45 windows accepted."""
    frames, _ = road_motion.read_tme(data_path("tme", "tme08"))
    cam = road_motion.fit_horizon(road_motion.tme_camera(data_path("tme", "calibration.ini")), frames)
    cfg = {"camera": cam, "pipeline": {"preset": "parallax"}, "parallax": {"hood_frac": road_motion.HOOD["tme08"]}}
    h = road_motion.homography_windows(frames, cfg, window=6, step=3)
    assert h["pairs"] == 15
    assert h["accepted_rate"] >= 0.7, h
    assert h["aligned_pairs"] == h["pairs"], h  # an alignment on every window


def test_udacity_clip_runs_through_the_parallax_preset():
    """project_video_cut: the first 40 frames through process(); the homography is accepted on at least
    a third of the windows (measured: 76 % over the whole clip) and every result is well formed."""
    frames, fps = road_motion.read_video(data_path("udacity", "clips", "project_video_cut.mp4"), max_frames=40)
    cam = road_motion.fit_horizon(road_motion.udacity_camera(frames[0].shape[1], frames[0].shape[0]), frames)
    cfg = {"camera": cam, "pipeline": {"preset": "parallax"},
           "parallax": {"hood_frac": road_motion.HOOD["project_video_cut.mp4"]}}
    h = road_motion.homography_windows(frames, cfg, window=6, step=2)
    assert h["accepted_rate"] >= 1 / 3, h
    with Pipeline(cfg) as p:
        for k, img in enumerate(frames):
            r = p.process(img, k / fps)
            assert {"features", "homography", "parallax", "particles"} <= set(r.stages)
            for t in r.tracks:
                assert t.id >= 1 and np.isfinite(t.box).all() and t.box[2] > t.box[0] and t.box[3] > t.box[1]
