"""The default preset on the real recordings (../shared/data; skipped when absent): every one of the seven vehicles
visible throughout the real sequences tracked on >= 90 % of its frames with at most 2 identity switches in all, and
no warning nor pre-warning on any of the six recordings. Measured: 47/50, 47/50, 85/88, 97/100, 97/100, 35/38,
35/38 frames, no switch, and 0 / 0 everywhere (`headway eval --pipeline default --parts road_motion,real_fcw`).
TuSimple train_clip1's car, 21.31 m ahead and closing at 1.23 m/s by the range sensors on the last frame, is ranged
within 3 % and its range rate within 0.5 m/s (measured 21.8 m, +2.5 %, and -1.43 m/s,
`headway eval --pipeline default --parts range`)."""
from __future__ import annotations

import pytest

from app.eval import range_clip, real_video_fcw, road_motion
from tests.conftest import DATA, data_path

PRESET = "default"


@pytest.fixture(scope="module")
def recordings():
    data_path("udacity", "clips")
    data_path("tme", "tme08")
    return real_video_fcw.evaluate(str(DATA), PRESET)


def test_no_warning_nor_pre_warning_on_any_recording(recordings):
    rows = recordings
    assert len(rows) == 6 and sum(r["frames"] for r in rows) >= 550, rows
    assert [(r["clip"], r["warnings"], r["prewarnings"]) for r in rows if r["warnings"] or r["prewarnings"]] == [], rows


def test_only_the_vehicles_on_the_carriageway_are_confirmed(recordings):
    """project_video_cut.mp4: the white car on the right, alone; test_small2.mp4: the black and the white car ahead.
    Detections the verifier scores under phd.low_score (0.1) pair with no vehicle; when they did, they kept confirmed
    a dark shape at the median barrier's end 46 m ahead, a stretch of empty road 32-39 m ahead and a car across the
    barrier (2 and 4 vehicles confirmed instead of 1 and 2)."""
    confirmed = {r["clip"]: r["vehicles_confirmed"] for r in recordings}
    assert confirmed["project_video_cut.mp4"] == 1 and confirmed["test_small2.mp4"] == 2, recordings


def test_the_seven_vehicles_visible_throughout_are_tracked_on_90_percent_of_their_frames():
    data_path("udacity", "clips")
    data_path("tme", "tme08")
    report = road_motion.evaluate(str(DATA), PRESET)
    seen = {(seq, name): v for seq, r in report.items() if seq != "skipped"
            for name, v in r.get("visible_throughout", {}).items()}
    tracked = {k: (v["iou0.3"]["tracked_frames"], v["frames"]) for k, v in seen.items()}
    assert len(tracked) == 7, tracked
    assert [k for k, (n, total) in tracked.items() if n < 0.9 * total] == [], tracked
    assert sum(v["iou0.3"]["id_switches"] for v in seen.values()) <= 2, seen


def test_the_range_sensors_car_on_train_clip1_is_ranged_within_3_percent_and_its_rate_within_half_a_metre_a_second():
    """The camera's 1.80 m of calibration.txt puts the ego lane 3.9-4.1 m wide; self-calibration's height from the lane
    width (1.62 m at the last frame) is what the tracker ranges with."""
    clip = data_path("tusimple", "train_clip1")
    (car,) = range_clip.evaluate(str(clip), preset=PRESET)["vehicles"]
    assert car["found"] and car["confirmed"], car
    assert abs(car["rel_error"]) <= 0.03, car
    # the rate: its contact row carried by 3-4 features high on the car's corner for frames 30-39 would read -2.3 m/s
    # with their contact measured as sharply as a full cloud's (phd.contact_full_depth)
    assert abs(car["range_rate_mps"] - car["true_range_rate_mps"]) <= 0.5, car
