"""The convolutional verifier (app/train/verifier_cnn.py, verifier_onnx.py; the core's
csrc/detect/vehicle_verifier_cnn.cpp): fitted by the project's own code, deterministic by seed, written
as ONNX that cv::dnn runs, and the core gives each cascade detection the probability the trainer's own
forward pass computes for the same crop."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from app import config as configuration
from app.core import Pipeline
from app.train import verifier_onnx as vo
from tests.conftest import data_path

SHIPPED_CNN = configuration.SHIPPED_VERIFIER   # the default verifier (app/models/vehicle_verifier.onnx)


def _dnn_probability(path, z, extra):
    net = cv2.dnn.readNetFromONNX(str(path))
    net.setInput(z, "crop")
    net.setInput(extra.astype(np.float32), "extra")
    return net.forward().ravel()


def _bars(rng, n):
    """Crops with noise; 'vehicles' carry a dark horizontal bar low in the crop (a shadow under a car)."""
    y = np.where(rng.random(n) < 0.3, 1, -1).astype(np.int8)
    crops = rng.normal(128, 30, (n, vo.CROP_H, vo.CROP_W)).clip(0, 255).astype(np.uint8)
    crops[y > 0, 22:27, 8:40] = 20
    extra = rng.normal(0, 1, (n, 2)).astype(np.float32)
    return crops, extra, y


def test_cnn_learns_is_deterministic_and_its_onnx_runs_in_cv2_dnn(tmp_path):
    pytest.importorskip("jax", reason="the CNN trainer needs the train extra: pip install '.[train]'")
    from app.train.verifier_cnn import fit, passed_at, predict

    rng = np.random.default_rng(0)
    crops, extra, y = _bars(rng, 1536)
    tc, te, ty = _bars(rng, 512)
    p = fit(crops, extra, y, channels=(4, 8, 8), hidden=8, epochs=3, seed=0)
    pt = predict(p, tc, te)
    assert passed_at(pt, ty, (0.95,))[0] <= 0.05   # 95 % of vehicles kept, at most 5 % of the others
    again = fit(crops, extra, y, channels=(4, 8, 8), hidden=8, epochs=3, seed=0)
    assert all(np.array_equal(p[k], again[k]) for k in p)
    vo.save_onnx(p, str(tmp_path / "v.onnx"))
    z = vo.standardise(tc[:40])
    assert np.abs(_dnn_probability(tmp_path / "v.onnx", z, te[:40]) - pt[:40]).max() < 1e-4
    back = vo.load_onnx(str(tmp_path / "v.onnx"))   # standardisation folded into the dense layer
    assert np.abs(vo.forward(back, z, te[:40]) - pt[:40]).max() < 1e-4


def test_crop_keeps_the_box_and_replicates_the_border():
    gray = np.zeros((100, 200), np.uint8)
    gray[40:60, 50:110] = 200                      # a 60 x 20 bright box
    c = vo.crop_boxes(gray, [(50, 40, 110, 60), (-10, -5, 20, 15)])
    # the box's margin (0.1 of its size each side) is dark, its inside bright
    assert c[0, vo.CROP_H // 2, vo.CROP_W // 2] == 200
    assert c[0, 0, 0] == 0 and c[0, -1, -1] == 0
    assert c.shape == (2, vo.CROP_H, vo.CROP_W)
    z = vo.standardise(c)
    assert abs(float(z[0].mean())) < 1e-4


def test_core_and_cv2_dnn_give_the_trainers_probability():
    """The core's CNN verifier (cv::dnn of Debian's OpenCV) and cv2.dnn give each cascade detection of a
    validation image the probability the trainer's numpy forward pass computes on the same crop."""
    from app.eval.tusimple_boxes import tusimple_config
    from app.train.verifier import geometry_features

    supp = data_path("tusimple", "supp")
    entry = json.loads((supp / "annotation.json").read_text())[0]
    gray = cv2.imread(str(supp / entry["file_name"]), cv2.IMREAD_GRAYSCALE)
    cfg = tusimple_config(configuration.load(None, {"cascade": {"verifier": str(SHIPPED_CNN), "nms_iou": 1.0}}))
    off = tusimple_config(configuration.load(None, {"cascade": {"verifier": "off", "nms_iou": 1.0}}))
    with Pipeline(configuration.core_sections(cfg)) as pipe, Pipeline(configuration.core_sections(off)) as plain:
        r = pipe.run_stage("cascade", gray)
        # the same groups without the verifier: confidence n / (n + neighbors_half) gives their window counts
        half = off["cascade"]["neighbors_half"]
        n = [round(half * t.confidence / (1 - t.confidence)) for t in plain.run_stage("cascade", gray).tracks]
    assert len(r.tracks) >= 10 and len(n) == len(r.tracks)
    boxes = [t.box for t in r.tracks]
    z = vo.standardise(vo.crop_boxes(gray, boxes))
    extra = geometry_features(boxes, n, r.horizon_row, cfg["camera"]["height_m"])
    p = vo.forward(vo.load_onnx(str(SHIPPED_CNN)), z, extra)
    assert np.abs(p - np.array([t.confidence for t in r.tracks])).max() < 1e-3
    assert np.abs(p - _dnn_probability(SHIPPED_CNN, z, extra)).max() < 1e-3
    assert p.min() < 0.5 < p.max()   # it tells the boxes apart


def test_a_file_that_is_not_a_verifier_network_is_a_clear_error(tmp_path):
    bad = tmp_path / "v.onnx"
    bad.write_bytes(b"not a network")
    cfg = configuration.load(None, {"cascade": {"verifier": str(bad)}})
    with Pipeline(configuration.core_sections(cfg)) as pipe:   # the cascade stage loads on first use
        with pytest.raises(ValueError, match="cascade.verifier.*headway train verifier"):
            pipe.run_stage("cascade", np.zeros((480, 640), np.uint8))


def test_training_without_the_train_extra_names_it(monkeypatch):
    from app.train import verifier_cnn

    monkeypatch.setitem(__import__("sys").modules, "jax", None)
    with pytest.raises(SystemExit, match=r"pip install '\.\[train\]'"):
        verifier_cnn.require_train_extra()
