"""`headway eval --pipeline A,B,...`: every preset evaluated into a folder of its own and set side by side in
OUT/compare.md, each figure the one of that preset's own report; a bad preset name is an error naming it."""
from __future__ import annotations

import json
import re

import pytest

from app.eval import compare
from tests.test_cli import headway


def _row(text: str, label: str) -> list[str]:
    """The cells after the label of the compare.md row that starts with it."""
    line = next(ln for ln in text.splitlines() if ln.startswith(f"| {label} |"))
    return [c.strip() for c in line.strip().strip("|").split("|")][1:]


def test_two_presets_are_set_side_by_side_with_their_own_reports_figures(tmp_path):
    out = tmp_path / "cmp"
    r = headway("eval", "--pipeline", "thesis,default", "--parts", "synthetic", "--scenarios",
                "steady_following,overpass_shadow", "--out", str(out))
    assert r.returncode == 0, r.stderr
    text = (out / "compare.md").read_text()
    assert text == r.stdout.split("\nreport: ")[0]  # what is printed is what is written
    own = {p: json.loads((out / p / "report.json").read_text()) for p in ("thesis", "default")}
    assert all(own[p]["preset"] == p and (out / p / "report.md").exists() for p in own)
    # the synthetic suite: each column is that preset's own overall figures, and each scenario's
    assert _row(text, "all scenarios: MOTA") == [f"{own[p]['synthetic']['overall']['mota']:.3f}" for p in own]
    for name in ("steady_following", "overpass_shadow"):
        assert _row(text, f"{name}: MOTA / IDF1") == [
            f"{own[p]['synthetic']['per_scenario'][name]['mota']:.3f} / "
            f"{own[p]['synthetic']['per_scenario'][name]['idf1']:.3f}" for p in own]
    assert json.loads((out / "compare.json").read_text())["presets"] == ["thesis", "default"]


def test_a_real_data_comparison_shows_the_score_curve_the_warnings_and_the_real_recordings(tmp_path):
    """Built from reports (no run): the TuSimple bands, the score curve at its thresholds, the FCW margins and
    verdicts, the vehicles visible throughout and the real recordings' warnings, one column per preset."""
    def report(preset, recall, vehicles_tracked, warnings):
        return {"preset": preset, "skipped": {},
                "fcw": [{"scenario": "stopped", "required_ttc_s": 2.1, "margin_s": recall - 0.5, "pass": recall > 0.5,
                         "warnings": 1},
                        {"scenario": "passing", "required_ttc_s": None, "margin_s": None, "pass": warnings == 0,
                         "warnings": warnings}],
                "tusimple": {"images": 600,
                             "bands": {">=40": {"recall": recall, "precision": 0.5}},
                             "curve_ge40": [{"threshold": t, "recall": recall - t / 10, "precision": 0.5 + t / 2}
                                            for t in compare.CURVE_THRESHOLDS],
                             "best_at_precision_0.8": None, "best_at_precision_0.85": None,
                             "operating_point": {"threshold": 0.79, "recall": recall - 0.1, "precision": 0.88}},
                "road_motion": {"skipped": {}, "tme08": {"visible_throughout": {
                    "dark car": {"frames": 50, "iou0.3": {"tracked_frames": vehicles_tracked, "id_switches": 1}}}}},
                "real_fcw": [{"clip": "a.mp4", "warnings": warnings, "prewarnings": 0, "vehicles_confirmed": 3}]}
    text = compare.markdown([report("thesis", 0.3, 40, 0), report("default", 0.9, 48, 1)])
    assert _row(text, "boxes >=40 px, every detection kept") == ["0.300 / 0.500", "0.900 / 0.500"]
    assert _row(text, ">= 0.90") == ["0.210 / 0.950", "0.810 / 0.950"]
    assert _row(text, "boxes >= 40 px, best at precision >= 0.8") == ["-", "-"]
    assert _row(text, "boxes >= 40 px, operating point (what `headway detect` writes)") == [
        "0.200 / 0.880 (score >= 0.79)", "0.800 / 0.880 (score >= 0.79)"]
    assert _row(text, "tme08: dark car") == ["40 of 50 (80%), 1", "48 of 50 (96%), 1"]
    assert _row(text, "a.mp4") == ["0 / 0 (3)", "1 / 0 (3)"]
    assert _row(text, "stopped") == ["FAIL -0.20 s", "+0.40 s"]
    assert _row(text, "passing") == ["pass, 0 warnings", "FAIL, 1 warnings"]
    assert not re.search(r"Synthetic suite|Lanes", text)  # parts no report holds are left out


@pytest.mark.parametrize("arg, message", [("thesis,fussed", "unknown preset.*fussed.*choose from"),
                                          ("default,default", "names a preset twice")])
def test_a_bad_preset_list_is_named(tmp_path, arg, message):
    r = headway("eval", "--pipeline", arg, "--parts", "fcw", "--out", str(tmp_path / "x"))
    assert r.returncode != 0
    assert re.search(message, r.stderr), r.stderr
    assert not (tmp_path / "x").exists()  # nothing run


def test_a_preset_without_a_single_image_detector_skips_the_tusimple_images_with_the_reason(tmp_path):
    """The parallax detector compares a frame with the one before: `headway eval` of parallax (alone or beside other
    presets) leaves the single-image TuSimple part out with the reason, and measures the rest."""
    from tests.conftest import data_path

    data_path("tusimple", "supp")
    out = tmp_path / "p"
    r = headway("eval", "--pipeline", "parallax", "--parts", "tusimple,synthetic", "--scenarios", "steady_following",
                "--out", str(out))
    assert r.returncode == 0, r.stderr
    rep = json.loads((out / "report.json").read_text())
    assert "tusimple" not in rep and "two frames" in rep["skipped"]["tusimple"]
    assert rep["synthetic"]["overall"]["mota"] > 0.5
    assert "skipped tusimple" in (out / "report.md").read_text()
