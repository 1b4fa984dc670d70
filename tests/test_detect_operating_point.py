"""`headway detect` (issue 12 point 4): single images go through the fused detector (the trained cascade and the
shadows, merged), and only detections at the detector's operating point are written. The operating point was
chosen on held-out training images (app/detect_images.py OPERATING_POINT, docs/cascade.md "The operating point of
`headway detect`"); here the shipped models are measured at it on the validation split (0001-0600) by the
project's one scoring code (IoU >= 0.5, boxes >= 40 px)."""
from __future__ import annotations

import json

import pytest

from app.detect_images import DEFAULT_DETECTOR, OPERATING_POINT
from tests.conftest import data_path
from tests.test_cli import headway

# Measured on the 600 validation images with the shipped models (docs/cascade.md); floors that catch a regression
# of the models or of the operating point. Session 13 (windows reaching past the image's border, the verifier trained
# on their groups, 8 epochs each seeing 0.3 of the plain others): fused at 0.79 recall 0.806, precision 0.880
# (cascade at 0.77: 0.810, 0.888).
FUSED_AT_OPERATING_POINT = {"recall": 0.78, "precision": 0.85}


def test_detect_writes_only_detections_at_the_operating_point(tmp_path):
    """By default the fused detector writes only boxes scoring at least its operating point; --min-score 0 writes
    every detection (a superset: the same boxes and more), --detector thesis its own."""
    images = [str(p) for p in sorted(data_path("tusimple", "supp", "images").glob("*.jpg"))[:4]]
    assert DEFAULT_DETECTOR == "fused"
    runs = {}
    for name, extra in (("default", []), ("all", ["--min-score", "0"]), ("thesis", ["--detector", "thesis"])):
        out = tmp_path / f"{name}.json"
        r = headway("detect", *images, "--out", str(out), *extra)
        assert r.returncode == 0, r.stderr
        runs[name] = json.loads(out.read_text())
    kept = [b for e in runs["default"] for b in e["bbox"]]
    every = [b for e in runs["all"] for b in e["bbox"]]
    assert kept and all(b["score"] >= OPERATING_POINT["fused"] for b in kept)
    assert len(every) > 2 * len(kept)
    assert all(b in every for b in kept)
    assert [b for b in every if b["score"] >= OPERATING_POINT["fused"]] == kept
    assert [e["file_name"] for e in runs["thesis"]] == [e["file_name"] for e in runs["default"]]


def test_detector_thesis_is_the_thesis_detector_alone_whatever_the_configuration_composes(tmp_path):
    """`--detector thesis` is shadows + vertical edges alone. Since fused became the default preset, the core's
    "detect" stage under the default configuration ran the cascade beside the shadows, and `--detector thesis`
    wrote their merge (other scores, cascade boxes). Now it writes what the thesis preset finds, under the default
    configuration and under one that composes the cascade and the shadows explicitly."""
    images = [str(p) for p in sorted(data_path("tusimple", "supp", "images").glob("*.jpg"))[:3]]
    configs = {"thesis": "pipeline: {preset: thesis}\n", "composed": "pipeline: {detectors: [cascade, shadow]}\n"}
    runs = {}
    for name in ("default", *configs):
        extra = []
        if name in configs:
            (tmp_path / f"{name}.yaml").write_text(configs[name])
            extra = ["--config", str(tmp_path / f"{name}.yaml")]
        out = tmp_path / f"{name}.json"
        r = headway("detect", *images, "--out", str(out), "--detector", "thesis", *extra)
        assert r.returncode == 0, r.stderr
        runs[name] = json.loads(out.read_text())
    assert any(e["bbox"] for e in runs["thesis"])
    assert runs["default"] == runs["thesis"] == runs["composed"]


@pytest.mark.parametrize("value", ["1.5", "-0.1", "nan"])
def test_a_min_score_outside_0_1_is_one_clear_line(tmp_path, value):
    r = headway("detect", str(tmp_path / "any.jpg"), "--out", str(tmp_path / "o.json"), "--min-score", value)
    assert r.returncode != 0 and "Traceback" not in r.stderr
    assert f"--min-score {value}" in r.stderr and "[0, 1]" in r.stderr


@pytest.fixture(scope="module")
def fused_scores():
    from app.eval.tusimple_boxes import evaluate

    r = evaluate(str(data_path("tusimple", "supp")), preset="fused")
    print("TuSimple supp, fused:", json.dumps(r["operating_point"]), json.dumps(r["best_at_precision_0.85"]))
    return r


def test_fused_at_its_operating_point_keeps_what_the_docs_say(fused_scores):
    """What `headway detect` writes, measured on the validation split: the operating point chosen on other images
    holds its precision here, at the recall the docs give."""
    op = fused_scores["operating_point"]
    assert op["threshold"] == OPERATING_POINT["fused"]
    assert op["recall"] >= FUSED_AT_OPERATING_POINT["recall"] and op["precision"] >= FUSED_AT_OPERATING_POINT["precision"]


def test_fused_meets_the_issue_bar(fused_scores):
    """Issue 12's bar for `headway detect`: recall >= 0.80 at precision >= 0.85 (boxes >= 40 px), on the curve and at
    the operating point it writes by (chosen on held-out training images). Session 13's verifier: 0.819 at 0.855 on
    the evaluation's curve, 0.806 at 0.880 at the operating point 0.79 (session 12's: 0.812 at 0.867, 0.806 at 0.881)."""
    op = fused_scores["operating_point"]
    assert op["recall"] >= 0.80 and op["precision"] >= 0.85, op
    best = fused_scores["best_at_precision_0.85"]
    assert best is not None and best["recall"] >= 0.80
