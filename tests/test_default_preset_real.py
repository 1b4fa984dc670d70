"""The default preset on the real recordings (../shared/data; skipped when absent): every one of the seven vehicles
visible throughout the real sequences tracked on >= 90 % of its frames with at most 2 identity switches in all, and
no warning nor pre-warning on any of the six recordings. Measured: 47/50, 47/50, 85/88, 97/100, 97/100, 35/38,
35/38 frames, no switch, and 0 / 0 everywhere (`headway eval --pipeline default --parts road_motion,real_fcw`)."""
from __future__ import annotations

from app.eval import real_video_fcw, road_motion
from tests.conftest import DATA, data_path

PRESET = "default"


def test_no_warning_nor_pre_warning_on_any_recording():
    data_path("udacity", "clips")
    data_path("tme", "tme08")
    rows = real_video_fcw.evaluate(str(DATA), PRESET)
    assert len(rows) == 6 and sum(r["frames"] for r in rows) >= 550, rows
    assert [(r["clip"], r["warnings"], r["prewarnings"]) for r in rows if r["warnings"] or r["prewarnings"]] == [], rows


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


def test_a_box_that_steps_wider_is_not_a_vehicle_closing_in(tmp_path):
    """TME tme08, the car 51 m ahead in the ego lane: its box steps from 66 to 79 px wide in one frame (it takes in
    the flank) while the range closes at 8 m/s. Fitted through, that step read as TTC 1.9 s and warned; a width
    change no vehicle can make in one frame (kinematics.scale_jump_closing_mps) restarts the scale fit instead.
    Since session 9 the box no longer steps there: its shadow, cast past its right side to the lane marking, is cut
    back to the car (shadow.beside_rel); the step, and the warning fitted through it, come back with that cut off
    (measured: TTC 1.92 s at 0.8 s; no warning with the cut on and the jump rule off)."""
    data_path("tme", "tme08")
    fitted_through = tmp_path / "no_jump_rule.yaml"
    fitted_through.write_text("kinematics:\n  scale_jump_closing_mps: 1000\nshadow:\n  beside_rel: 0.0\n")
    before = real_video_fcw.evaluate(str(DATA), PRESET, str(fitted_through), only="tme08")
    after = real_video_fcw.evaluate(str(DATA), PRESET, only="tme08")
    assert [(r["warnings"], r["prewarnings"]) for r in after] == [(0, 0)], after
    assert before[0]["warnings"] >= 1 and min(ttc for _, _, ttc in before[0]["events"]) < 2.5, before
