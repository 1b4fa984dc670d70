"""The learned first stage (app/train/proposals.py, proposals_onnx.py; the core's detector part "proposals",
csrc/detect/proposals/part.cpp, proposal_net.cpp): the ONNX file cv::dnn runs computes the trainer's network,
the core decodes its peaks as the trainer does, and the whole path (train on a tiny set, export, load in the core,
detect) finds the vehicles of a scene it never saw."""
from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from app import config as configuration
from app.core import CoreError, Pipeline
from app.detect_images import image_pipeline
from app.eval.matching import match
from app.train import proposals_onnx as po
from tests.conftest import data_path

jax = pytest.importorskip("jax", reason="the trainer needs the train extra (pip install '.[train]')")

SIZE = (320, 180)   # px of the scenes
INPUT_WIDTH = 160   # the network's input 160 x 90: the scenes at half size, as 1280x720 images at a quarter
# the detector alone on these scenes: no verifier, the road checks open (the scenes' boxes stand anywhere)
OPEN = {"verifier": "off", "min_vehicle_height_m": 0.1, "max_vehicle_height_m": 20.0, "min_width_ratio": 0.0,
        "max_width_ratio": 100.0, "nms_iou": 1.0, "top_k": 200}


def _scene(rng, n_cars: int):
    """A grey road scene with noise and n dark 'vehicles' (a body, a lighter window band, a black shadow under it);
    the boxes (left, top, right, bottom) as annotations draw them."""
    w, h = SIZE
    img = np.tile(np.linspace(170, 90, h, dtype=np.float32)[:, None], (1, w))
    img += rng.normal(0, 8, img.shape)
    boxes = []
    for _ in range(200):
        if len(boxes) == n_cars:
            break
        bh = rng.uniform(24, 50)
        bw = bh * rng.uniform(1.1, 1.5)
        x0, y0 = rng.uniform(0, w - bw), rng.uniform(0.35 * h, h - bh - 4)
        b = (x0, y0, x0 + bw, y0 + bh)
        if any(min(b[2], c[2]) > max(b[0], c[0]) - 6 and min(b[3], c[3]) > max(b[1], c[1]) - 6 for c in boxes):
            continue
        boxes.append(b)
        x0, y0, x1, y1 = (int(round(v)) for v in b)
        img[y0:y1, x0:x1] = rng.uniform(30, 70)
        img[y0 + (y1 - y0) // 5:y0 + (y1 - y0) // 2, x0 + 2:x1 - 2] += 60
        img[y1 - 2:y1, x0:x1] = 10
    return np.clip(img, 0, 255).astype(np.uint8), boxes


def _folder(tmp_path, n: int, seed: int):
    rng = np.random.default_rng(seed)
    (tmp_path / "images").mkdir()
    entries = []
    for k in range(n):
        img, boxes = _scene(rng, 3)
        name = f"images/{k:04d}.png"
        cv2.imwrite(str(tmp_path / name), img)
        entries.append({"file_name": name, "bbox": [dict(zip(("left", "top", "right", "bottom"), map(float, b)))
                                                    for b in boxes]})
    (tmp_path / "annotation.json").write_text(json.dumps(entries))
    return tmp_path


def _pipeline(model, **keys):
    cfg = configuration.load(None, {"pipeline": {"preset": "none", "detectors": ["proposals"], "tracker": "kalman"},
                                    "proposals": {"model": str(model), "input_width": INPUT_WIDTH, **OPEN, **keys}})
    return image_pipeline(cfg, *SIZE)


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """A network trained on 40 scenes (36 fitted, 4 held out) by the project's trainer, and its log."""
    from app.train import proposals

    folder = _folder(tmp_path_factory.mktemp("scenes"), 40, seed=1)
    out = tmp_path_factory.mktemp("model") / "p.onnx"
    lines = []
    # a smaller network than the shipped one (16 channels, 3 blocks, output stride 4): the same code, trained in well
    # under a minute
    proposals.train([str(folder)], str(out), epochs=15, seed=0, input_width=INPUT_WIDTH, batch=6, lr=1e-2, width=16,
                    blocks=3, blocks8=0, subcells=1, log=lines.append, threads=1)
    return out, lines


@pytest.mark.parametrize("blocks8,subcells,stride", [(po.BLOCKS8, 1, 8), (0, 1, 4), (po.BLOCKS8, 2, 4)])
def test_onnx_computes_the_trainers_network_at_any_size(tmp_path, blocks8, subcells, stride):
    """cv::dnn on the written file gives the JAX forward pass's heat (after the sigmoid) and box maps, at the
    shipped input size and at an odd one (fully convolutional: every stride rounds up), with the stride-8 level,
    without it, and with 2x2 sub-cells a stride-8 cell (laid out on the stride-4 grid by to_grid)."""
    params = po.init_params(3, blocks8=blocks8, subcells=subcells)
    assert po.stride_of(params) == stride
    params["heat_b"] = np.full(subcells ** 2, 0.3, np.float32)   # away from the 0.01 prior, so that the heat varies
    params["heat_w"] *= 30   # and differs between the sub-cells
    path = tmp_path / "n.onnx"
    po.save_onnx(params, str(path))
    rng = np.random.default_rng(0)
    for h, w in ((180, 320), (97, 131)):
        small = rng.integers(0, 256, (h, w), np.uint8)
        heat, box = po.run_onnx(str(path), small)
        logit, ref_box = po.forward_jax(params, po.standardise(small))
        level = stride * subcells
        assert heat.shape == (-(-h // level) * subcells, -(-w // level) * subcells) and box.shape == (4, *heat.shape)
        assert heat.shape[::-1] == po.output_size(w, h, stride, subcells)
        np.testing.assert_allclose(heat, 1 / (1 + np.exp(-np.asarray(logit)[0, 0])), atol=1e-4)
        np.testing.assert_allclose(box, np.asarray(ref_box)[0], atol=1e-4)


def test_training_logs_every_epoch_and_the_core_finds_the_vehicles_of_unseen_scenes(trained):
    """Train, export, load in the core, detect: on 10 scenes the training never saw, the core's detection stage
    (pipeline {detectors: [proposals]}) finds at least 80 % of the vehicles at IoU 0.5 with at most one other box
    an image at heat >= 0.3, and the log reports every epoch."""
    out, lines = trained
    assert sum(line.startswith("epoch ") for line in lines) == 15
    assert "held out" in lines[0]
    rng = np.random.default_rng(99)
    found = total = others = 0
    with _pipeline(out) as pipe:
        for _ in range(10):
            img, boxes = _scene(rng, 3)
            det = [b[:4] for b in pipe.detect(img).rows() if b[4] >= 0.3]
            pairs = match(boxes, det)
            found, total, others = found + len(pairs), total + len(boxes), others + len(det) - len(pairs)
    assert found / total >= 0.8, (found, total)
    assert others <= 10, others


def _core_and_trainer_boxes(model, scene_seed: int, stride: int, top_k: int):
    """The core's boxes (pipeline {detectors: [proposals]}, min_heat 0.05) and proposals_onnx.decode's of the same
    network's maps on one scene, cut to the image and kept where the core's checks would keep them (standing below
    the horizon, at least 2 px each way)."""
    img, _ = _scene(np.random.default_rng(scene_seed), 3)
    small = po.prepare(img, INPUT_WIDTH)
    heat, box = po.run_onnx(str(model), small)
    ref = po.decode(heat, box, SIZE[0] / small.shape[1], SIZE[1] / small.shape[0], 0.05, top_k=top_k, stride=stride)
    ref[:, [0, 2]] = ref[:, [0, 2]].clip(0, SIZE[0])
    ref[:, [1, 3]] = ref[:, [1, 3]].clip(0, SIZE[1])
    with _pipeline(model, min_heat=0.05) as pipe:
        r = pipe.detect(img)
    ref = ref[(ref[:, 3] > r.horizon_row + 1) & (ref[:, 2] - ref[:, 0] >= 2) & (ref[:, 3] - ref[:, 1] >= 2)]
    return r.boxes, ref


@pytest.mark.parametrize("pred,target,expected", [
    ((1, 1, 1, 1), (1, 1, 1, 1), 1.0),          # the same box
    ((1, 1, 1, 1), (1, 1, 3, 1), 0.5),          # 2x2 inside 4x2: IoU 0.5, the hull is the union
    ((1, 1, 1, 1), (0.5, 3, 0.5, 3), -1 / 12),  # a cross: IoU 2/8, hull 12, union 8
])
def test_the_box_loss_compares_the_boxes_by_generalised_iou(pred, target, expected):
    """The box loss's GIoU, at one cell, of the boxes its four distances (l, t, r, b) give about the cell's centre."""
    from app.train.proposals import giou

    cell = lambda d: np.log(np.float32(d)).reshape(1, 4, 1, 1)
    assert float(np.asarray(giou(cell(pred), cell(target))).ravel()[0]) == pytest.approx(expected, abs=1e-6)


def test_the_core_decodes_the_peaks_as_the_trainer(trained):
    """Every hypothesis the core reports is a peak of the network's heat map decoded as proposals_onnx.decode does
    (box within 0.05 px, score = heat), strongest first, when no check but "standing below the horizon" and no
    verifier removes any."""
    out, _ = trained
    boxes, ref = _core_and_trainer_boxes(out, 5, stride=4, top_k=64)
    assert len(boxes) == len(ref) > 0
    np.testing.assert_allclose(boxes[:, :4], ref[:, :4], atol=0.05)
    np.testing.assert_allclose(boxes[:, 4], ref[:, 4], atol=1e-5)


@pytest.mark.parametrize("blocks8,subcells,stride", [(2, 1, 8), (0, 1, 4), (2, 2, 4)])
def test_the_core_reads_the_stride_from_the_network(tmp_path, blocks8, subcells, stride):
    """A network with the stride-8 level, one without it, and one with 2x2 sub-cells a stride-8 cell: the core decodes
    each one's peaks on its own grid, as proposals_onnx.decode does (box within 0.05 px)."""
    params = po.init_params(4, width=16, blocks=1, width8=16, blocks8=blocks8, subcells=subcells)
    params["heat_b"] = np.full(subcells ** 2, 0.3, np.float32)
    params["heat_w"] *= 30
    params["box_w"] *= 20   # boxes of varied sizes
    path = tmp_path / "n.onnx"
    po.save_onnx(params, str(path))
    boxes, ref = _core_and_trainer_boxes(path, 6, stride=stride, top_k=1000)
    assert len(boxes) == len(ref) > 0
    np.testing.assert_allclose(boxes[:, :4], ref[:, :4], atol=0.05)


def test_a_file_that_is_not_a_proposal_network_is_refused_by_name(tmp_path):
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"not a network")
    with pytest.raises(CoreError, match="proposals.model: cv::dnn cannot read"):
        _pipeline(junk)
    with pytest.raises(CoreError, match="proposals.model: .* is not a proposal network .*outputs heat and box"):
        _pipeline(configuration.SHIPPED_VERIFIER)


def test_image_bench_times_the_network_and_its_verifier_apart(tmp_path):
    """`headway bench --images DIR --config C` with C's pipeline {detectors: [proposals]} times the part's two stages,
    "proposals" (the network, its decoding and road checks) and "prop_verifier", inside the core's whole stage."""
    from app.bench.pipeline import run_image_bench

    images = data_path("tusimple", "supp", "images")
    (tmp_path / "p.yaml").write_text("pipeline: {detectors: [proposals], tracker: kalman}\n")
    rep = run_image_bench([str(images)], config_path=str(tmp_path / "p.yaml"), limit=2, repeats=1)
    parts = rep["stages"]["image"]
    assert {"read", "proposals", "prop_verifier", "core", "total"} <= set(parts) and "cascade" not in parts
    mean = {k: s["mean_ms"] for k, s in parts.items()}
    assert mean["core"] >= mean["proposals"] + mean["prop_verifier"] - 1e-3
    assert mean["proposals"] > 0 and mean["prop_verifier"] > 0


def test_the_shipped_network_scores_on_the_validation_split_what_its_card_says():
    """docs/detection.md ("The proposals part"): the shipped network with the CNN verifier, `pipeline: {detectors:
    [proposals]}`, on the 600 validation images (boxes >= 40 px, IoU 0.5) at the operating point chosen on held-out
    training images (score >= 0.21), on the recordings' camera: recall 0.721, precision 0.915; every detection kept:
    recall 0.808."""
    from app.eval.detector_points import composition_config, scored_images, summary
    from app.eval.tusimple_boxes import load_entries

    folder = data_path("tusimple", "supp")
    entries = load_entries(str(folder))
    assert len(entries) == 600
    r = summary(entries, scored_images(str(folder), entries, composition_config(["proposals"])), at=0.21)
    assert r["at"]["recall"] == pytest.approx(0.721, abs=0.01) and r["at"]["precision"] == pytest.approx(0.915, abs=0.01)
    assert r["every_detection"]["recall"] == pytest.approx(0.808, abs=0.01)
