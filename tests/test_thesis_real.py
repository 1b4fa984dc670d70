"""The `thesis` preset's box tracker on real video (../shared/data; skipped when absent): a vehicle's width and
its bottom's depth below the horizon grow together on a flat road (w = W d / h), so an ROI or template measurement
that breaks their ratio is not taken (`kalman.max_width_depth_change`). On tme08 the ROI search let the two cars'
boxes grow (60 -> 130 px in 8 frames, a side jumping to the next edge) until their detections no longer matched;
on test_small2 a template slid down the image with the road's texture and was warned about."""
from __future__ import annotations

import json

import pytest

from app.eval import road_motion
from tests.conftest import data_path, tme08_sequence

OFF = {"kalman": {"max_width_depth_change": 100.0}}


@pytest.fixture(scope="module")
def tme08():
    return tme08_sequence("thesis")


def _tracked_frames(tme08, extra: dict) -> dict:
    frames, fps, values = tme08
    res = road_motion.identity(frames, road_motion.core_config({**values, **extra}), fps,
                               road_motion.visible_throughout("tme08"))
    return {name: r["iou0.3"]["tracked_frames"] for name, r in res.items()}


def test_the_silver_car_ahead_is_tracked_when_boxes_keep_their_width_per_depth(tme08):
    """tme08 (50 frames), measured: the silver car ahead right on 47 frames (29 without the check). The dark car
    ahead left stayed on 13 (11) with it: its detections were 85-100 px wide against its 54 (the check at 0.15
    kept it on 31 frames but cost the synthetic leads their tight edges; docs/tracking.md), which the
    shadow rule of the next test mends."""
    on, off = _tracked_frames(tme08, {}), _tracked_frames(tme08, OFF)
    assert on["silver car ahead right"] >= 45, on
    assert off["silver car ahead right"] <= 35, f"the check made no difference ({off}): the test no longer tests it"


def test_the_dark_car_whose_shadow_reaches_the_lane_marking_is_tracked(tme08):
    """tme08's dark car ahead left, in a low sun from the left: its shadow runs on past its right side over the
    road up to the next lane marking (85-100 px against the car's 54), and the verification took that marking
    for its right side. With the stretch of shadow that has lit road above it cut off (`shadow.beside_rel`),
    measured: tracked on 48 of its 50 frames (13 without), the silver car on 47 (47)."""
    on, off = _tracked_frames(tme08, {}), _tracked_frames(tme08, {"shadow": {"beside_rel": 0.0}})
    assert on["dark car ahead left"] >= 40, on
    assert on["silver car ahead right"] >= 45, on
    assert off["dark car ahead left"] <= 20, f"the rule made no difference ({off}): the test no longer tests it"


def test_a_template_sliding_down_the_road_is_no_lead(tmp_path):
    """test_small2.mp4 replayed through the whole stack as the real-video false-warning check runs it: no warning.
    Measured: with ROI measurements checked but not the template, a box kept its width while its bottom slid down
    the road (431 -> 522 px in 11 frames, 'closing' at 17 m/s) and was warned about at 2.76 s."""
    import yaml

    from app.eval import real_video_fcw
    from app.replay import replay_recording
    from app.sim.can_log import write_ego_speed_log
    from app.sim.world import Motion1D

    data_path("udacity", "clips", "test_small2.mp4")  # skips when absent
    (source, camera, fps, is_folder), = real_video_fcw.recordings(data_path(), "test_small2.mp4")
    write_ego_speed_log(tmp_path / "ego.log", Motion1D(0.0, real_video_fcw.EGO_SPEED_MPS, []), 60.0)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(real_video_fcw.recording_config(camera, "thesis")))
    s = replay_recording(str(source), str(tmp_path / "c.yaml"), fps=fps if is_folder else None,
                         can_in=str(tmp_path / "ego.log"), progress=False)
    assert s.frames == 100 and not s.warnings, json.dumps(s.warnings)
