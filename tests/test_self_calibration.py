"""Self-calibration from the lanes: from a camera configured 2 deg off in pitch and yaw and 15 % off in
height, the estimates converge within 10 s of driving to 0.2 deg and 3 %, range is then within 5 %
median to 60 m; switched off, the configured camera is used unchanged; the estimate reaches the tracks file.
From scratch (self_calibration.from_scratch) on the real lane clips: a camera given only its intrinsics and height
finds pitch and yaw within a clip's 20 frames, and the lanes reach the TuSimple bar as with the pitch given."""
from __future__ import annotations

import json

import pytest

from app.eval.self_calibration import synthetic


@pytest.mark.parametrize("sign", [1, -1])
def test_converges_from_a_wrong_camera_within_10_s(sign):
    r = synthetic("calibration_drive", {"pitch_deg": 2.0 * sign, "yaw_deg": 2.0 * sign, "height_rel": 0.15 * sign})
    assert r["converged_s"] is not None and r["converged_s"] <= 10.0, r
    err = r["max_abs_err_after_convergence"]
    assert err["pitch_deg"] <= 0.2 and err["yaw_deg"] <= 0.2 and err["height_rel"] <= 0.03, r
    assert r["range_n_after"] > 100 and r["range_median_rel_error_after"] <= 0.05, r


@pytest.mark.parametrize("sign", [1, -1])
def test_the_default_trackers_range_follows_the_estimated_height(sign):
    """The phd tracker ranges its vehicles itself (its UKF): it takes the estimated camera as the geometry stage does."""
    r = synthetic("calibration_drive", {"pitch_deg": 2.0 * sign, "yaw_deg": 2.0 * sign, "height_rel": 0.15 * sign},
                  preset="default")
    assert r["converged_s"] is not None and r["converged_s"] <= 10.0, r
    assert r["range_n_after"] > 100 and r["range_median_rel_error_after"] <= 0.05, r


def test_switched_off_keeps_the_configured_camera():
    r = synthetic("calibration_drive", enabled=False)
    assert r["converged_s"] is None
    assert r["final"]["pitch_err_deg"] == pytest.approx(2.0, abs=1e-3)
    assert r["final"]["height_err_rel"] == pytest.approx(0.15, abs=1e-3)
    assert r["range_median_rel_error_first_s"] > 0.10  # what a 15 % height error does to range


def test_estimate_and_uncertainty_in_the_tracks_file(tmp_path):
    from app.replay import replay_scenario

    # plain drawn vehicles, as measured (docs/sim.md, "Real-looking vehicles"): with the real look the estimate takes
    # 90 updates on steady_following, against 136
    replay_scenario("steady_following", tracks_path=str(tmp_path / "t.jsonl"), progress=False, vehicle_look="plain")
    recs = [json.loads(x) for x in (tmp_path / "t.jsonl").read_text().splitlines()]
    first, last = recs[0]["calibration"], recs[-1]["calibration"]
    assert {"pitch_deg", "yaw_deg", "height_m", "pitch_sigma_deg", "yaw_sigma_deg", "height_sigma_m"} <= set(last)
    # the camera of the scenario is exact: the estimate stays on it while its uncertainty shrinks
    assert last["pitch_sigma_deg"] < 0.5 * first["pitch_sigma_deg"] and last["updates"] > 100
    assert abs(last["pitch_deg"] - 1.0) < 0.2 and abs(last["height_m"] - 1.3) < 0.04


def test_status_shows_the_estimate_with_its_uncertainty():
    import time

    from app.supervisor.status_file import format_status

    cal = {"pitch_deg": 1.04, "yaw_deg": -0.1, "height_m": 1.31, "pitch_sigma_deg": 0.03, "yaw_sigma_deg": 0.03,
           "height_sigma_m": 0.006, "updates": 812, "active": True}
    text = format_status({"state": "ok", "written_unix_s": time.time(), "calibration": cal}, "/run/x")
    assert "calibration: pitch 1.04 +- 0.03 deg, yaw -0.10 +- 0.03 deg, height 1.310 +- 0.006 m (812 frames" in text
    off = format_status({"state": "ok", "written_unix_s": time.time(), "calibration": dict(cal, active=False)}, "/x")
    assert "calibration: off (configured pitch 1.04 deg" in off


def test_yaw_from_the_road_planes_motion():
    """Parallax preset, the yaw 2 deg off and the lanes' angles made nearly uninformative (10 deg a frame):
    the lateral part of the car's travel in the fitted road motion alone brings the yaw in."""
    from app.eval.self_calibration import synthetic_runs

    runs = [{"offsets": {"pitch_deg": 0.0, "yaw_deg": 2.0, "height_rel": 0.0},
             "self_calibration": {"angle_noise_deg": 10.0, "road_motion": on, "motion_yaw_noise_deg": 0.3}}
            for on in (True, False)]
    # measured on the plain drawn vehicles (docs/sim.md, "Real-looking vehicles"); with the real look it converges
    # after 2.9 s
    with_motion, without = synthetic_runs("steady_following", runs, preset="parallax", vehicle_look="plain")
    assert with_motion["converged_s"] is not None and with_motion["converged_s"] <= 2.0, with_motion
    assert abs(with_motion["final"]["yaw_err_deg"]) <= 0.05, with_motion
    assert without["converged_s"] is None or without["converged_s"] > 4.0, without


def _states(scenario: str, seconds: float, pitch_off_deg: float = 0.0, **self_calibration) -> list[str]:
    """The estimator's state in every frame of the first `seconds` of a scenario, thesis preset, CAN speed."""
    return [c["state"] for c in _calibrations(scenario, seconds, pitch_off_deg, **self_calibration)]


def _calibrations(scenario: str, seconds: float, pitch_off_deg: float = 0.0, **self_calibration) -> list[dict]:
    """The estimate in every frame of the first `seconds` of a scenario, thesis preset, CAN speed."""
    import dataclasses
    import itertools

    from app import config as configuration
    from app.core import Pipeline
    from app.sim import load_scenario, render
    from app.sim.frames import scenario_camera

    sc = load_scenario(scenario)
    cfg = configuration.load(None)
    cfg["camera"].update(dataclasses.asdict(scenario_camera(sc)))
    cfg["camera"]["pitch_deg"] += pitch_off_deg
    cfg["self_calibration"].update(self_calibration)
    states = []
    with Pipeline(configuration.core_sections(cfg)) as pipe:
        for f in itertools.islice(render(sc), int(seconds * sc.fps)):
            pipe.set_ego_motion(f.ego_speed_mps, f.yaw_rate_rps)
            states.append(pipe.process(f.image, f.t_s).calibration)
    return states


def test_the_state_says_learning_converged_at_a_limit_or_off():
    exact = _states("steady_following", 3.0)
    # one frame's lanes: 0.5 deg, 6 %; converged at 0.1 deg and 1 % (about 40 frames of lanes)
    assert exact[0] == "learning" and exact[-1] == "converged"
    first = exact.index("converged")
    assert 10 <= first <= 60 and set(exact[first:]) == {"converged"}, exact
    # the mounting 2 deg off and the estimate allowed 0.5 deg: held at the bound, and the state says so
    assert _states("steady_following", 2.0, pitch_off_deg=2.0, max_pitch_dev_deg=0.5)[-1] == "at_limit"
    # from scratch, the camera pitched 1 deg down and the search range ending at 0.5 deg: likewise
    assert _states("steady_following", 2.0, from_scratch=True, pitch_max_deg=0.5)[-1] == "at_limit"
    assert set(_states("steady_following", 0.5, enabled=False)) == {"off"}


def test_from_scratch_a_camera_configured_4_deg_off_converges_and_the_guard_is_centred_on_its_converged_value():
    """self_calibration.from_scratch: the configured pitch is a starting value only. 4 deg off (beyond the +-3 deg the
    estimate may otherwise move from it: held at that limit) the estimate finds the camera's; once converged, the
    guard is around the converged value (with max_pitch_dev_deg 0 the estimate stays where it converged, 1 deg, and
    says at_limit)."""
    trusted = _calibrations("steady_following", 3.0, pitch_off_deg=4.0)
    assert trusted[-1]["state"] == "at_limit" and abs(trusted[-1]["pitch_deg"] - 2.0) < 0.01, trusted[-1]
    free = _calibrations("steady_following", 3.0, pitch_off_deg=4.0, from_scratch=True)
    assert free[-1]["state"] == "converged" and abs(free[-1]["pitch_deg"] - 1.0) < 0.2, free[-1]
    held = _calibrations("steady_following", 3.0, pitch_off_deg=4.0, from_scratch=True, max_pitch_dev_deg=0.0)
    assert held[-1]["state"] == "at_limit" and abs(held[-1]["pitch_deg"] - 1.0) < 0.2, held[-1]


def test_height_from_the_road_planes_motion_needs_no_lane_width():
    """Parallax preset, the camera 2 deg / 2 deg / 15 % off and the lane width assumed 3.75 m on 3.6 m lanes
    (4 % wrong): the lanes alone leave the height 4.1 % off; the CAN speed against the road's image motion
    brings it within 1 % (measured 0.66 %, converged after 5.0 s)."""
    from app.eval.self_calibration import synthetic_runs

    runs = [{"offsets": {"pitch_deg": 2.0, "yaw_deg": -2.0, "height_rel": -0.15}, "road": {"lane_width_m": 3.75},
             "self_calibration": {"motion_height": on}} for on in (True, False)]
    # measured on the plain drawn vehicles (docs/sim.md, "Real-looking vehicles"); with the real look it converges
    # after 2.9 s
    with_motion, without = synthetic_runs("steady_following", runs, preset="parallax", vehicle_look="plain")
    assert with_motion["converged_s"] is not None and with_motion["converged_s"] <= 10.0, with_motion
    assert abs(with_motion["final"]["height_err_rel"]) <= 0.01, with_motion
    assert with_motion["range_median_rel_error_after"] <= 0.05, with_motion
    assert without["converged_s"] is None and abs(without["final"]["height_err_rel"]) >= 0.035, without


def test_pitch_from_the_road_planes_motion_when_switched_on():
    """motion_pitch (off by default): the road plane's tilt in its fitted motion measures the pitch. With the lanes'
    angle made weak (10 deg a frame) and the estimate let to count as converged early (3 deg), from 1 deg off the
    pitch is within 0.2 deg for good after 2.0 s with it, 3.6 s without, and its 1-sigma is 0.02 against 0.59 deg."""
    from app.eval.self_calibration import synthetic_runs

    runs = [{"offsets": {"pitch_deg": 1.0, "yaw_deg": 0.0, "height_rel": 0.0},
             "self_calibration": {"angle_noise_deg": 10.0, "converged_sigma_deg": 3.0, "motion_pitch": on}}
            for on in (True, False)]
    # measured on the plain drawn vehicles (docs/sim.md, "Real-looking vehicles"); with the real look it converges
    # after 2.9 s
    with_motion, without = synthetic_runs("steady_following", runs, preset="parallax", vehicle_look="plain")
    assert with_motion["converged_s"] is not None and with_motion["converged_s"] <= 2.5, with_motion
    assert abs(with_motion["final"]["pitch_err_deg"]) <= 0.1 and with_motion["final"]["pitch_sigma_deg"] <= 0.05
    assert without["converged_s"] is None or without["converged_s"] >= 3.0, without
    assert without["final"]["pitch_sigma_deg"] >= 0.3, without


@pytest.fixture(scope="module")
def clips_from_scratch():
    from app.eval.self_calibration import lane_clips
    from tests.conftest import data_path

    return lane_clips(str(data_path("tusimple", "lane_clips").parent.parent))


# The done-when bar on the 12 clips, last frame: accuracy >= 0.92, FP <= 0.10, FN <= 0.10.
MIN_ACCURACY, MAX_FP, MAX_FN = 0.92, 0.10, 0.10


def test_lane_clips_from_intrinsics_and_height_alone_reach_the_tusimple_bar(clips_from_scratch):
    """Each clip replayed as `headway replay CLIP --fps 20 --config F` with F holding only TuSimple's calibration.txt
    (intrinsics, 1.80 m height) and the hood line: a camera section without pitch_deg is calibrated from scratch;
    the default pitch (1 deg) is 10 deg off the camera's. Measured 0.931 / 0.097 / 0.090 (the same file with
    self_calibration.from_scratch false: 0.512 / 0.667 / 0.729)."""
    m = clips_from_scratch["no_pitch"]
    assert m["clips"] == 12
    assert m["accuracy"] >= MIN_ACCURACY and m["fp"] <= MAX_FP and m["fn"] <= MAX_FN, m


def test_lane_clips_lose_nothing_with_the_pitch_given(clips_from_scratch):
    """The same with camera.pitch_deg 10.5 given (the configured mounting is then trusted to +- 3 deg): measured
    0.930 / 0.097 / 0.090 against 0.931 without it, one lane point of 1,152."""
    given, scratch = clips_from_scratch["pitch_given"], clips_from_scratch["no_pitch"]
    assert given["accuracy"] >= MIN_ACCURACY and given["fp"] <= MAX_FP and given["fn"] <= MAX_FN, given
    assert given["accuracy"] >= scratch["accuracy"] - 0.005 and given["fp"] <= scratch["fp"] + 1e-9, (given, scratch)


def test_pitch_from_scratch_settles_within_the_clip(clips_from_scratch):
    """Every clip without the pitch: after its 20 frames the pitch found is in the 10-13 deg a downward-looking
    TuSimple camera has (measured 10.6-12.7 deg) with 1-sigma <= 0.15 deg, within 1.2 deg of the estimate with the
    pitch given (measured <= 1.13 deg), and from frame 11 at the latest it stays within 0.3 deg of its final value
    (measured: from frames 0-8)."""
    clips = clips_from_scratch["clips"]
    assert len(clips) == 12
    for c in clips:
        assert 10.0 <= c["no_pitch"]["pitch_deg"] <= 13.0, c
        assert c["no_pitch"]["pitch_sigma_deg"] <= 0.15, c
        assert abs(c["pitch_diff_deg"]) <= 1.2, c
    assert all(c["pitch_settled_from_frame"] is not None and c["pitch_settled_from_frame"] <= 11 for c in clips), clips


def test_pitch_from_scratch_meets_the_labelled_lanes_vanishing_row(clips_from_scratch):
    """Against independent truth: where frame 20's labelled ego boundaries meet. On the 7 clips whose labelled
    boundaries are straight (that row the same from lines through all their points and through the near ones), the
    pitch found without the pitch given is within 0.3 deg of it on 6 and within 0.5 deg on all (measured 0.03-0.15
    deg on 6, 0.47 deg on 0313-2/20), and on the whole nearer to it than the estimate with the pitch given (measured
    mean absolute error 0.13 against 0.27 deg)."""
    straight = [c for c in clips_from_scratch["clips"] if c["labels_straight"]]
    assert len(straight) == 7, clips_from_scratch["clips"]
    scratch = [abs(c["no_pitch"]["pitch_deg"] - c["labelled_pitch_deg"]) for c in straight]
    given = [abs(c["pitch_given"]["pitch_deg"] - c["labelled_pitch_deg"]) for c in straight]
    assert sum(e <= 0.3 for e in scratch) >= 6 and max(scratch) <= 0.5, straight
    assert sum(scratch) < sum(given), (scratch, given)


def test_yaw_from_scratch_is_measured_within_20_frames(clips_from_scratch):
    """The yaw likewise, where the car keeps its lane: on 10 of the 12 clips its 1-sigma is under 0.3 deg after 20
    frames (the other two: a lane change or the lane's offset jittering faster than max_lateral_rate_mps)."""
    clips = clips_from_scratch["clips"]
    assert sum(c["no_pitch"]["yaw_sigma_deg"] <= 0.3 for c in clips) >= 10, clips


def test_an_empty_pitch_search_range_is_a_clear_error():
    from app.core import ConfigError, Pipeline

    with pytest.raises(ConfigError, match="self_calibration.pitch_min_deg: must be below"):
        Pipeline({"self_calibration": {"pitch_min_deg": 12.0, "pitch_max_deg": 5.0}})


@pytest.mark.parametrize("camera, calibration, from_scratch", [
    ({"fx": 1000.0, "height_m": 1.8}, None, True),               # a camera without its pitch: found from scratch
    ({"fx": 1000.0, "height_m": 1.8, "pitch_deg": 10.5}, None, False),  # the pitch given: trusted to +- 3 deg
    ({"fx": 1000.0, "height_m": 1.8}, {"from_scratch": False}, False),  # the configuration's own choice wins
    (None, None, False),                                           # no camera section: the defaults as they are
])
def test_a_camera_section_without_its_pitch_is_calibrated_from_scratch(tmp_path, camera, calibration, from_scratch):
    import yaml

    from app.config import load

    text = {k: v for k, v in (("camera", camera), ("self_calibration", calibration)) if v is not None}
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(text))
    assert load(path)["self_calibration"]["from_scratch"] is from_scratch
