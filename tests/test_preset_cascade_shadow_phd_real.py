"""Issue 12's real-video bar held by the preset `cascade_shadow_phd` (cascade + shadow merged, phd): every one of
the seven vehicles visible throughout the real sequences tracked on >= 80 % of its frames, and no warning nor
pre-warning on any of the six recordings (../shared/data; skipped when absent). Measured: 42/50, 47/50, 85/88,
97/100, 94/100, 35/38, 35/38 frames and 0 / 0 everywhere (docs/RESULTS.md, "Preset `cascade_shadow_phd`")."""
from __future__ import annotations

from app.eval import real_video_fcw, road_motion
from tests.conftest import DATA, data_path

PRESET = "cascade_shadow_phd"


def test_no_warning_nor_pre_warning_on_any_recording():
    data_path("udacity", "clips")
    data_path("tme", "tme08")
    rows = real_video_fcw.evaluate(str(DATA), PRESET)
    assert len(rows) == 6 and sum(r["frames"] for r in rows) >= 550, rows
    assert [(r["clip"], r["warnings"], r["prewarnings"]) for r in rows if r["warnings"] or r["prewarnings"]] == [], rows


def test_the_seven_vehicles_visible_throughout_are_tracked_on_80_percent_of_their_frames():
    data_path("udacity", "clips")
    data_path("tme", "tme08")
    report = road_motion.evaluate(str(DATA), PRESET)
    tracked = {(seq, name): (v["iou0.3"]["tracked_frames"], v["frames"])
               for seq, r in report.items() if seq != "skipped"
               for name, v in r.get("visible_throughout", {}).items()}
    assert len(tracked) == 7, tracked
    assert [k for k, (n, total) in tracked.items() if n < 0.8 * total] == [], tracked
