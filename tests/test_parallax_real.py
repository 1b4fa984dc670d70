"""The parallax preset on real motorway frames (../shared/data; skipped when absent): the road homography is
accepted on most frames, and the pipeline runs through a real clip."""
from __future__ import annotations

import numpy as np

from app.core import Pipeline
from app.eval import road_motion
from tests.conftest import data_path


def udacity_parallax(*path: str, max_frames=None):
    """Frames, frame rate and the parallax configuration (camera fitted to the lanes, bonnet) of a Udacity clip."""
    frames, fps = road_motion.read_video(data_path("udacity", *path), max_frames=max_frames)
    cam = road_motion.fit_horizon(road_motion.udacity_camera(frames[0].shape[1], frames[0].shape[0]), frames)
    return frames, fps, {"camera": {**cam, "hood_frac": road_motion.HOOD[path[-1]]}, "pipeline": {"preset": "parallax"}}


def test_tme_motorway_homography_is_accepted_on_most_frames():
    """tme08 (dashed markings, 20 fps, no CAN speed). Measured: 87 % of 45 windows accepted."""
    frames, _ = road_motion.read_tme(data_path("tme", "tme08"))
    cam = road_motion.fit_horizon(road_motion.tme_camera(data_path("tme", "calibration.ini")), frames)
    cfg = {"camera": {**cam, "hood_frac": road_motion.HOOD["tme08"]}, "pipeline": {"preset": "parallax"}}
    h = road_motion.homography_windows(frames, cfg, window=6, step=3)
    assert h["pairs"] == 15
    assert h["accepted_rate"] >= 0.7, h
    assert h["aligned_pairs"] == h["pairs"], h  # an alignment on every window


def test_the_homography_is_judged_alike_whatever_preset_is_evaluated():
    """`headway eval --parts road_motion` judges the road-motion stage for every preset: a configuration naming the
    default preset (whose parts do not need the road's motion) gives the same windows as the parallax preset."""
    frames, _ = road_motion.read_tme(data_path("tme", "tme08"))
    cam = road_motion.fit_horizon(road_motion.tme_camera(data_path("tme", "calibration.ini")), frames)
    base = {"camera": {**cam, "hood_frac": road_motion.HOOD["tme08"]}}
    parallax = road_motion.homography_windows(frames, {**base, "pipeline": {"preset": "parallax"}}, window=6, step=9)
    default = road_motion.homography_windows(frames, {**base, "pipeline": {"preset": "default"}}, window=6, step=9)
    assert parallax["accepted_rate"] > 0.5, parallax
    assert default == parallax


def test_tme_motorway_alignment_leaves_less_than_no_alignment():
    """tme08: with the brightness change between the frames taken out (photometric.hpp), the aligned road
    differs far less than the unaligned one. Measured on these 15 windows: median 2.53 against 5.44 gray
    levels (45 windows: 2.56 against 5.47); with the brightness change left in the aligned residual is 8.02,
    above the unaligned one."""
    frames, _ = road_motion.read_tme(data_path("tme", "tme08"))
    cam = road_motion.fit_horizon(road_motion.tme_camera(data_path("tme", "calibration.ini")), frames)
    cfg = {"camera": {**cam, "hood_frac": road_motion.HOOD["tme08"]}, "pipeline": {"preset": "parallax"}}
    h = road_motion.homography_windows(frames, cfg, window=6, step=3)
    assert h["residual_median"] < 0.65 * h["unwarped_median"], h
    assert h["raw_residual_median"] > h["residual_median"] + 3.0, h  # the brightness change is real and large


def test_udacity_black_car_ahead_is_tracked_continuously():
    """test_video: the black car ahead, visible in all 38 frames (app/eval/data/visible_throughout.json),
    carries one confirmed track from frame 5 on without a break or an id switch. Measured: 33 of 38 frames at
    IoU >= 0.3 (27-31 at 0.5 across the last changes), 1 fragment, 0 id switches. (The white car beside it and
    the vehicles of tme08 and the other clips are not tracked: docs/tracking.md, "Real drives".)"""
    frames, fps, cfg = udacity_parallax("test_video.mp4")
    vehicles = [v for v in road_motion.visible_throughout("test_video.mp4") if v["name"] == "black car ahead"]
    res = road_motion.identity(frames, cfg, fps, vehicles)["black car ahead"]["iou0.3"]
    assert res["tracked_frames"] >= 30, res
    assert res["fragments"] == 1 and res["id_switches"] == 0, res
    assert res["first_tracked"] <= 8, res


def test_udacity_car_in_the_adjacent_lane_is_tracked():
    """test_small2: the black car ahead in the right lane, visible in all 100 frames. The lane model's area
    covered it only partly (its right boundary found near the car) and no region on it was inside by the
    margin: 0 frames tracked. With the road area at least two lanes each side of the ego lane
    (parallax.road_lanes_each_side): measured 80 frames at IoU >= 0.3, from frame 20, in 1 fragment, all on one
    track; the 2 id switches counted are a second, shorter track on the car's shadow 70 px below it (frames 68-80)
    whose IoU with the car briefly equals that of the car's own track (0.46)."""
    frames, fps, cfg = udacity_parallax("clips", "test_small2.mp4")
    vehicles = [v for v in road_motion.visible_throughout("test_small2.mp4") if v["name"] == "black car ahead"]
    res = road_motion.identity(frames, cfg, fps, vehicles)["black car ahead"]["iou0.3"]
    assert res["tracked_frames"] >= 60, res
    assert res["fragments"] <= 2 and res["id_switches"] <= 2, res


def test_tme_running_homography_is_accepted_on_most_frames():
    """tme08 through process(): the running filter accepts a measurement on 98 % of the frame pairs (measured
    48 of 49; the first pair has no estimate yet) and never coasts longer than 3 frames."""
    frames, fps = road_motion.read_tme(data_path("tme", "tme08"))
    cam = road_motion.fit_horizon(road_motion.tme_camera(data_path("tme", "calibration.ini")), frames)
    cfg = {"camera": {**cam, "hood_frac": road_motion.HOOD["tme08"]}, "pipeline": {"preset": "parallax"}}
    rf = road_motion.track_continuity(frames, cfg, fps)["running_filter"]
    assert rf["accepted_rate"] >= 0.9 and rf["longest_coast_frames"] <= 3, rf


def test_udacity_clip_runs_through_the_parallax_preset():
    """project_video_cut: the first 40 frames through process(); the homography is accepted on at least
    a third of the windows (measured: 76 % over the whole clip) and every result is well formed."""
    frames, fps, cfg = udacity_parallax("clips", "project_video_cut.mp4", max_frames=40)
    h = road_motion.homography_windows(frames, cfg, window=6, step=2)
    assert h["accepted_rate"] >= 1 / 3, h
    with Pipeline(cfg) as p:
        for k, img in enumerate(frames):
            r = p.process(img, k / fps)
            assert {"features", "homography", "parallax", "particles"} <= set(r.stages)
            for t in r.tracks:
                assert t.id >= 1 and np.isfinite(t.box).all() and t.box[2] > t.box[0] and t.box[3] > t.box[1]
