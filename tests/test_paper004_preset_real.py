"""The `paper004` preset (the trained cascade's detections -> phd) on a real motorway sequence (../shared/data;
skipped when absent): a box the cascade's learned verifier doubts may follow a vehicle but not start one
(`phd.birth_min_appearance`), so the two cars ahead are tracked throughout and few other tracks are born."""
from __future__ import annotations

import pytest

from app.eval import road_motion
from tests.conftest import data_path, tme08_sequence


@pytest.fixture(scope="module")
def tme08():
    return tme08_sequence("paper004")


def test_the_two_cars_ahead_are_tracked_and_few_other_tracks_born(tme08):
    """tme08 (50 frames): measured with the default birth_min_appearance 0.9: both cars ahead tracked on 47 of
    50 frames at IoU >= 0.3, one fragment, no id switch; 6 confirmed ids in all. With every cascade box allowed to
    start a vehicle (0): the same 47 / 47 frames, but 31 ids (docs/RESULTS.md)."""
    frames, fps, values = tme08
    cfg = road_motion.core_config(values)
    cars = road_motion.visible_throughout("tme08")
    res = road_motion.identity(frames, cfg, fps, cars)
    for car in cars:
        r = res[car["name"]]["iou0.3"]
        assert r["tracked_frames"] >= 42 and r["id_switches"] <= 1, (car["name"], r)
    assert road_motion.track_continuity(frames, cfg, fps)["ids"] <= 10


def test_every_cascade_box_may_start_a_vehicle_when_asked(tme08):
    """birth_min_appearance 0 (every box starts a vehicle) gives far more confirmed tracks on the same
    sequence: the key is what holds them down (measured 31 against 6)."""
    frames, fps, values = tme08
    cfg = road_motion.core_config({**values, "phd": {"birth_min_appearance": 0.0}})
    assert road_motion.track_continuity(frames, cfg, fps)["ids"] >= 20


def _tme08_through_the_stack(tmp_path, values: dict) -> tuple[list, float]:
    """tme08 replayed through the whole stack (pipeline, supervisor, FCW) as the real-video false-warning check
    runs it (ego speed 27 m/s from a CAN log): the FCW events and the lead's smallest TTC."""
    import json

    import yaml

    from app.eval import real_video_fcw
    from app.replay import replay_recording
    from app.sim.can_log import write_ego_speed_log
    from app.sim.world import Motion1D

    folder = data_path("tme", "tme08")
    frames, fps = road_motion.read_tme(folder)
    cam = road_motion.fit_horizon(road_motion.tme_camera(data_path("tme", "calibration.ini")), frames)
    cfg = real_video_fcw.recording_config(cam, "paper004")
    for section, keys in values.items():
        cfg.setdefault(section, {}).update(keys)
    (tmp_path / "c.yaml").write_text(yaml.safe_dump(cfg))
    write_ego_speed_log(tmp_path / "speed.log", Motion1D(0.0, real_video_fcw.EGO_SPEED_MPS, []), 60.0)
    s = replay_recording(str(folder), str(tmp_path / "c.yaml"), fps=fps, can_in=str(tmp_path / "speed.log"),
                         tracks_path=str(tmp_path / "tracks.jsonl"), progress=False)
    ttcs = [t["ttc_s"] for r in map(json.loads, (tmp_path / "tracks.jsonl").read_text().splitlines())
            for t in r["tracks"] if t["id"] == r["lead_id"] and t["ttc_s"] is not None]
    return s.warnings, min(ttcs, default=float("inf"))


def test_no_pre_warning_on_tme08_from_pitch_or_the_feature_clouds_background(tmp_path):
    """The car ahead at ~48 m keeps its distance. Before: a 9 px pitch swing (the lanes' horizon followed 2 px of
    it) and a feature cloud whose road and background points grew faster than the car gave the UKF -13 m/s and a
    pre-warning at TTC 3.67 s. With the horizon following the far scene (phd_pitch) and the expansion's spread
    not averaged over points that share one bias (phd.expansion_independent_points): no event; the lead's smallest
    TTC 5.43 s (measured; 4.10 s with the expansion change alone), asserted half a second over the 4.0 s
    pre-warning threshold."""
    events, min_ttc = _tme08_through_the_stack(tmp_path, {})
    assert events == [] and min_ttc >= 4.5, (events, min_ttc)


def test_the_pre_warning_returns_without_either_correction(tmp_path):
    """Both corrections off (the horizon from the lanes alone, the expansion's spread over every point): the
    pre-warning of before (TTC 3.67 s at 0.95 s) comes back, so the test above measures them. Measured as before,
    with the scan inside the image (cascade.border_frac 0; TTC 3.49 s at 0.95 s): the windows reaching past the
    border (0.5, session 12) change the feature clouds enough that the uncorrected run stays quiet too (4.79 s)."""
    events, min_ttc = _tme08_through_the_stack(
        tmp_path, {"phd_pitch": {"enabled": False}, "phd": {"expansion_independent_points": 1000},
                   "cascade": {"border_frac": 0.0}})
    assert any(level == "prewarning" for _, level, _ in events) and min_ttc < 4.0, (events, min_ttc)
