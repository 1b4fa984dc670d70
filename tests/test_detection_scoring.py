"""Scoring of single-image detections by box-height band, the score curve, and the CNN reference that
gives the TuSimple bar its meaning."""
from __future__ import annotations

import pytest

from app.eval.tusimple_boxes import band_counts, operating_curve, recall_at_precision
from tests.conftest import REPO, data_path


def _entry(*boxes):
    return {"bbox": [{"left": l, "top": t, "right": r, "bottom": b} for l, t, r, b in boxes]}


ENTRIES = [_entry((100, 100, 160, 150), (400, 300, 520, 400)),   # 50 px and 100 px high
           _entry((10, 10, 30, 25))]                               # 15 px high


def test_bands_count_matches_misses_and_false_positives():
    det = [[(102, 101, 161, 152), (600, 300, 700, 400)],  # the 50 px car found, one 100 px false box
           [(10, 10, 30, 25)]]                            # the small one found exactly
    c = band_counts(ENTRIES, det)
    assert c["40-80"] == {"tp": 1, "fp": 0, "fn": 0, "gt": 1, "recall": 1.0, "precision": 1.0}
    assert c[">=80"]["tp"] == 0 and c[">=80"]["fn"] == 1 and c[">=80"]["fp"] == 1
    assert c[">=40"]["recall"] == 0.5 and c[">=40"]["precision"] == 0.5
    assert c["0-20"]["recall"] == 1.0
    assert c["overall"]["gt"] == 3 and c["overall"]["tp"] == 2


def test_a_box_below_iou_half_is_not_a_match():
    shifted = [[(130, 100, 190, 150)], []]  # IoU 1/3 with the 50 px car
    c = band_counts(ENTRIES, shifted)
    assert c["40-80"]["tp"] == 0 and c["40-80"]["fp"] == 1


def test_score_curve_trades_recall_for_precision():
    scored = [[(102, 101, 161, 152, 0.9), (600, 300, 700, 400, 0.4), (400, 300, 520, 400, 0.3)], []]
    curve = operating_curve(ENTRIES, scored, [0.0, 0.35, 0.5])
    assert [round(c["recall"], 2) for c in curve] == [1.0, 0.5, 0.5]
    assert [round(c["precision"], 2) for c in curve] == [0.67, 0.5, 1.0]
    assert recall_at_precision(curve, 0.8)["threshold"] == 0.5
    assert recall_at_precision(curve, 0.6)["threshold"] == 0.0
    assert recall_at_precision([{"threshold": 0, "recall": 0.0, "precision": None}], 0.8) is None


def test_cnn_reference_reaches_the_bar_on_the_first_images():
    """The decoding of the reference CNN is right when it finds the annotated cars: on the first 40
    images it must clear the issue's bar (it measures 0.77 at 0.91 on all 600)."""
    model = REPO.parent / "shared" / "baselines" / "cnn" / "nanodet_m_416.onnx"
    if not model.exists():
        pytest.skip(f"reference CNN not found at {model} (../shared/baselines is absent on this machine)")
    from app.eval.cnn_reference import evaluate

    r = evaluate(str(data_path("tusimple", "supp")), str(model), limit=40)
    b = r["bands"][">=40"]
    assert b["gt"] > 50
    assert b["recall"] >= 0.70 and b["precision"] >= 0.80, b


def test_cnn_reference_names_a_missing_model(tmp_path, capsys):
    from app.eval.cnn_reference import main

    assert main(["--model", str(tmp_path / "none.onnx"), "--supp", str(tmp_path)]) == 2
    assert "none.onnx: NanoDet-m ONNX model not found" in capsys.readouterr().err
