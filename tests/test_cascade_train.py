"""The cascade trainer (app/train/cascade): a tiny cascade trained in seconds on tiny synthetic data
loads in OpenCV's CascadeClassifier, and OpenCV accepts exactly the windows the trainer's own
evaluator accepts (scanned as OpenCV scans: every second pixel, skipping the window after one that
the first stage rejects), with the same last-stage sums (the trainer reproduces OpenCV's variance
normalisation and single-precision arithmetic)."""
from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from app.train.cascade import FeatureSet, TrainParams, train
from app.train.cascade.haar import integrals, responses, variance_norm

W, H = 12, 8


def _scene(rng, size=(160, 120)):
    """Textured background with 1-3 'vehicles': a body, a dark band at the bottom, two bright lights."""
    img = rng.normal(120, 25, (size[1], size[0])).clip(0, 255)
    img = cv2.GaussianBlur(img, (0, 0), 1.5)
    boxes = []
    for _ in range(rng.integers(1, 4)):
        h = int(rng.integers(12, 36))
        w = int(1.5 * h)
        x, y = int(rng.integers(0, size[0] - w)), int(rng.integers(0, size[1] - h))
        img[y:y + h, x:x + w] = 170
        img[y + int(0.75 * h):y + h, x:x + w] = 30
        img[y + h // 3:y + h // 2, x + w // 8:x + w // 4] = 250
        img[y + h // 3:y + h // 2, x + 3 * w // 4:x + 7 * w // 8] = 250
        boxes.append({"left": x, "top": y, "right": x + w, "bottom": y + h})
    return img.astype(np.uint8), boxes


def _dataset(folder, n, seed):
    rng = np.random.default_rng(seed)
    (folder / "images").mkdir(parents=True)
    ann = []
    for i in range(n):
        img, boxes = _scene(rng)
        cv2.imwrite(str(folder / "images" / f"{i:04d}.png"), img)
        ann.append({"file_name": f"images/{i:04d}.png", "bbox": boxes})
    (folder / "annotation.json").write_text(json.dumps(ann))
    return folder


def _tiny(tmp_path_factory, booster: str, width: int = W, height: int = H):
    folder = _dataset(tmp_path_factory.mktemp("tiny") / "data", 40, 1)
    out = tmp_path_factory.mktemp("model") / f"tiny-{booster}-{width}x{height}.xml"
    p = TrainParams(width=width, height=height, stages=3, num_pos=200, num_neg=200, features=400, min_box_height=10,
                    max_weak=20, seed=0, booster=booster)
    lines = []
    cascade = train([str(folder)], str(out), p, log=lines.append)
    return cascade, out, lines


@pytest.fixture(scope="module")
def tiny_cascade(tmp_path_factory):
    return _tiny(tmp_path_factory, "gentle")


@pytest.fixture(scope="module")
def tiny_discrete(tmp_path_factory):
    return _tiny(tmp_path_factory, "discrete")


@pytest.fixture(scope="module")
def tiny_square(tmp_path_factory):
    return _tiny(tmp_path_factory, "gentle", 10, 10)


def test_tiny_cascade_trains_with_a_log_line_per_stage(tiny_cascade):
    cascade, out, lines = tiny_cascade
    assert len(cascade.stages) >= 2
    stage_lines = [ln for ln in lines if ln.startswith("stage")]
    assert len(stage_lines) == len(cascade.stages)
    for ln in stage_lines:
        assert "stumps" in ln and "hit rate" in ln and "false alarm" in ln and "negatives" in ln


def test_opencv_accepts_exactly_the_windows_the_trainer_accepts(tiny_cascade):
    _check_opencv_agrees(*tiny_cascade[:2])


def test_a_discrete_adaboost_cascade_loads_in_opencv_and_agrees_with_the_trainer(tiny_discrete):
    """`--boost discrete` (paper 004's booster): leaves +-alpha, written as boostType DAB; OpenCV runs it exactly
    as the trainer's evaluator does."""
    cascade, out, _ = tiny_discrete
    assert "<boostType>DAB</boostType>" in out.read_text() and len(cascade.stages) >= 2
    for st in cascade.stages:
        assert all(a == pytest.approx(-b) and a != 0 for a, b in zip(st.left, st.right))
    _check_opencv_agrees(cascade, out)


def test_discrete_stump_has_the_least_weighted_error_and_alpha_from_it():
    """One round of Discrete AdaBoost on random responses: the stump is the split and polarity of least weighted
    error over every feature (checked by brute force), and its leaves are +-ln((1 - e) / e) / 2."""
    from app.train.cascade.boost import train_stage

    rng = np.random.default_rng(5)
    y = np.r_[np.ones(30), -np.ones(50)]
    values = (rng.normal(0, 1, (6, 80)) + np.outer(rng.normal(0, 0.8, 6), y)).astype(np.float32)
    w = np.where(y > 0, 0.5 / 30, 0.5 / 50)
    best = 1.0
    for f in range(6):
        xs = np.unique(values[f])
        for t in (xs[1:] + xs[:-1]) / 2:
            e = w[(values[f] < t) & (y < 0)].sum() + w[(values[f] >= t) & (y > 0)].sum()
            best = min(best, e, 1 - e)
    st, _, _ = train_stage(values, np.arange(6), y, 0.9, 0.0, 1, booster="discrete")
    f, t = st.features[0], st.thresholds[0]
    left = values[f] < t
    e = w[left & (y < 0)].sum() + w[~left & (y > 0)].sum()
    assert min(e, 1 - e) == pytest.approx(best, abs=1e-9)
    alpha = 0.5 * np.log((1 - best) / best)
    assert abs(st.left[0]) == pytest.approx(alpha, rel=1e-5) and st.right[0] == pytest.approx(-st.left[0])
    assert (st.left[0] > 0) == (e < 0.5)  # the side where the vehicles are gets +alpha
    with pytest.raises(ValueError, match="booster"):
        train_stage(values, np.arange(6), y, 0.9, 0.0, 1, booster="real")


def _check_opencv_agrees(cascade, out):
    cc = cv2.CascadeClassifier(str(out))
    assert not cc.empty() and tuple(cc.getOriginalWindowSize()) == (W, H)
    fs = FeatureSet(W, H)
    rng = np.random.default_rng(7)
    n_acc = n_rej = 0
    for _ in range(3):
        img, _ = _scene(rng)
        # one scale (window = the model's), every second pixel as OpenCV scans at scale 1
        rects, _, weights = cc.detectMultiScale3(img, scaleFactor=1.5, minNeighbors=0, minSize=(W, H),
                                                 maxSize=(W, H), outputRejectLevels=True)
        ocv = {(int(x), int(y)): float(w) for (x, y, _, _), w in zip(np.asarray(rects).reshape(-1, 4),
                                                                       np.ravel(weights))}
        grid = [(x, y) for y in range(0, img.shape[0] - H + 1, 2) for x in range(0, img.shape[1] - W + 1, 2)]
        patches = np.array([img[y:y + H, x:x + W] for x, y in grid])
        passed, depth, score = cascade.evaluate(fs, patches)
        _, scanned = variance_norm(patches)
        # OpenCV's scan skips the next window of a row after one its first stage rejects
        verdict = dict(zip(grid, zip(passed, depth == 0, scanned, score)))
        ours, pos = {}, []
        for y in range(0, img.shape[0] - H + 1, 2):
            x = 0
            while x <= img.shape[1] - W:
                ok, first_rejects, contrast, s = verdict[(x, y)]
                pos.append((x, y))
                if ok:
                    ours[(x, y)] = s
                x += 4 if (first_rejects and contrast) else 2
        assert set(ours) == set(ocv)
        for p in ours:
            assert ours[p] == pytest.approx(ocv[p], abs=1e-5)
        n_acc += len(ours)
        n_rej += len(pos) - len(ours)
    assert n_acc > 0 and n_rej > 0  # both decisions were compared


def test_feature_responses_match_direct_pixel_sums():
    fs = FeatureSet(W, H)
    x = np.random.default_rng(3).integers(0, 256, (50, H, W)).astype(np.uint8)
    norm, _ = variance_norm(x)
    idx = np.arange(0, len(fs), 97)
    vals = responses(fs, idx, integrals(x), norm)
    for row, f in zip(vals, idx):
        sums = [x[:, r[1]:r[1] + r[3], r[0]:r[0] + r[2]].reshape(len(x), -1).sum(1) for r in fs.rects[f]]
        w = fs.weights[f]
        ref = np.float32(w[0]) * sums[0].astype(np.float32) + np.float32(w[1]) * sums[1].astype(np.float32)
        if w[2] != 0:
            ref = ref + np.float32(w[2]) * sums[2].astype(np.float32)
        assert np.array_equal(row, ref * norm)


def test_cli_names_a_folder_without_annotations(tmp_path):
    r = subprocess.run([sys.executable, "-m", "app.cli", "train", "cascade", "--data", str(tmp_path),
                        "--out", str(tmp_path / "m.xml")], capture_output=True, text=True)
    assert r.returncode == 1
    assert "annotation.json" in r.stderr and "Traceback" not in r.stderr


def test_training_resumes_from_a_written_cascade(tiny_cascade, tmp_path):
    """`--resume`: the XML the trainer wrote reads back into the same stages (features, thresholds,
    leaves), and a resumed run keeps them and adds stages after them."""
    from app.train.cascade.model import Cascade

    cascade, out, _ = tiny_cascade
    fs = FeatureSet(W, H)
    back = Cascade.from_xml(fs, str(out))
    assert back.stages == cascade.stages
    first = tmp_path / "first.xml"
    Cascade(W, H, stages=cascade.stages[:1]).save(fs, str(first))
    folder = _dataset(tmp_path / "data", 40, 1)
    p = TrainParams(width=W, height=H, stages=2, num_pos=200, num_neg=200, features=400, min_box_height=10,
                    max_weak=20, seed=0, resume=str(first))
    lines = []
    resumed = train([str(folder)], str(tmp_path / "more.xml"), p, log=lines.append)
    assert resumed.stages[0] == cascade.stages[0] and len(resumed.stages) == 2
    assert [ln[:8] for ln in lines if ln.startswith("stage")] == ["stage  1"]
    with pytest.raises(ValueError, match="window"):
        Cascade.from_xml(FeatureSet(W + 2, H), str(out))


def test_positives_of_one_view_only(tmp_path):
    """--min-aspect / --max-aspect keep only the boxes of one shape (a cascade per view, docs/decisions.md): the
    synthetic vehicles are 1.5 times as wide as high."""
    from app.train.cascade.samples import load_folders, positives

    items = load_folders([str(_dataset(tmp_path / "data", 6, 2))])
    every = positives(items, W, H, 10, 3.0)
    assert len(every) > 0
    assert len(positives(items, W, H, 10, 3.0, min_aspect=1.4)) == len(every)
    assert len(positives(items, W, H, 10, 3.0, min_aspect=1.6)) == 0
    assert len(positives(items, W, H, 10, 1.4)) == 0
    r = subprocess.run([sys.executable, "-m", "app.cli", "train", "cascade", "--data", str(tmp_path / "data"),
                        "--out", str(tmp_path / "m.xml"), "--min-aspect", "2", "--max-aspect", "1"],
                       capture_output=True, text=True)
    assert r.returncode == 1 and "--min-aspect 2 --max-aspect 1" in r.stderr and "Traceback" not in r.stderr


def test_a_square_window_cascade_runs_in_the_core_at_its_own_size(tiny_square):
    """Any window the trainer takes (`--window 24x24`, docs/decisions.md "Cascade window size"): the core's cascade
    (the detection stage with pipeline.detectors [cascade]) reads the window from the XML, so a square model gives
    square boxes whose smallest height is the model's own, and the core's scanner finds exactly the windows OpenCV's
    finds (every raw group kept, on rendered road frames where the tiny model fires often)."""
    from app import config as configuration
    from app.core import Pipeline
    from app.sim import load_scenario, render
    from app.sim.frames import scenario_camera
    from tests.conftest import cascade_alone

    _, out, _ = tiny_square
    assert tuple(cv2.CascadeClassifier(str(out)).getOriginalWindowSize()) == (10, 10)
    sc = load_scenario("dense_traffic")
    frames = [f.image for f in list(render(sc, frames=range(3)))]
    found = {}
    for opencv in (True, False):
        cfg = configuration.load(None, cascade_alone(cascade={"model": str(out), "verifier": "off", "nms_iou": 1.0,
                                                              "min_neighbors": 1, "opencv_scan": opencv}))
        cfg["camera"].update(scenario_camera(sc).to_dict())
        with Pipeline(configuration.core_sections(cfg)) as pipe:
            found[opencv] = [pipe.detect(g).rows() for g in frames]
    assert found[False] == found[True]
    boxes = np.array([b[:4] for f in found[False] for b in f])
    assert len(boxes) > 20
    w, h = boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]
    inside = (boxes[:, 0] > 0) & (boxes[:, 2] < frames[0].shape[1])   # a box the border cuts (border_frac) is narrower
    assert inside.sum() > 20
    assert np.abs(w - h)[inside].max() < 1e-3       # the model's aspect, not the shipped 30x20's 1.5
    # The smallest size scanned is the model's own: a group's box is the mean of the windows in it, so the smallest
    # box lies between 10 px and the next scale (1.12 x 10); CI saw 10.6, a 10 and an 11.2 window grouped.
    assert 10 - 1e-3 <= h.min() < 10 * configuration.load(None)["cascade"]["scale_factor"]


def test_scan_band_negatives_come_only_from_the_rows_the_detector_scans(tmp_path):
    """`--scan-band`: random and mined negatives lie inside the flat-road band of each window size (bottom
    between horizon + h * cam_h / 4.5 and horizon + h * cam_h / 1.0, widened by a quarter window), never in
    the rows above or below it. The scene is dark noise outside the widest band and bright noise inside."""
    from app.train.cascade.samples import Miner, ScanBand, load_folders, random_negatives

    band = ScanBand(horizon_row=60, camera_height_m=1.5)
    top, bottom = band.rows(H)
    assert (top, bottom) == pytest.approx((60 + H * 1.5 / 4.5 - H - 0.25 * H, 60 + H * 1.5 + 0.25 * H))
    rng = np.random.default_rng(3)
    # the union of the bands of every window size scanned (H .. 2H here): rows 45 .. 88
    lo, hi = int(band.rows(2 * H)[0]), int(np.ceil(band.rows(2 * H)[1]))
    (tmp_path / "images").mkdir()
    img = rng.integers(0, 60, (140, 200)).astype(np.uint8)
    img[lo:hi] = rng.integers(190, 256, (hi - lo, 200))
    cv2.imwrite(str(tmp_path / "images" / "0.png"), img)
    (tmp_path / "annotation.json").write_text(json.dumps([{"file_name": "images/0.png", "bbox": []}]))
    items = load_folders([str(tmp_path)])
    inside = random_negatives(items, 200, W, H, rng, max_scale=2.0, band=band)
    assert len(inside) == 200 and inside.min() >= 150  # bilinear sampling may blend the band's edge row
    anywhere = random_negatives(items, 200, W, H, rng, max_scale=2.0)
    assert (anywhere.reshape(200, -1).max(1) < 100).sum() > 50  # without the band, most rows are dark
    # a one-stump cascade that accepts every window: the miner's crops stay inside the band too
    from app.train.cascade.model import Cascade, Stage

    fs = FeatureSet(W, H)
    accept_all = Cascade(W, H, stages=[Stage(features=[0], thresholds=[0.0], left=[1.0], right=[1.0],
                                             threshold=-1.0)])
    xml = tmp_path / "all.xml"
    accept_all.save(fs, str(xml))
    mined, scanned, seen = Miner(items, W, H, rng, max_scale=2.0, band=band).mine(str(xml), 100, 1.0, 200)
    assert len(mined) == 100 and scanned > 0 and mined.min() >= 150


def test_mined_negatives_do_not_depend_on_the_order_opencv_returns_windows(tiny_cascade, tmp_path, monkeypatch):
    """OpenCV's detector threads append windows in the order they finish, so the same scan returns them in another
    order from run to run on a multi-core machine. The miner must pick the same negatives whatever that order:
    training is deterministic by seed."""
    from app.train.cascade import samples

    _, xml, _ = tiny_cascade
    items = samples.load_folders([str(_dataset(tmp_path / "data", 12, 5))])

    def mine():
        return samples.Miner(items, W, H, np.random.default_rng(4)).mine(str(xml), 150, 0.05, 60)

    plain = mine()
    real = cv2.CascadeClassifier

    class Shuffled:
        def __init__(self, path):
            self.cc, self.rng = real(path), np.random.default_rng(9)

        def empty(self):
            return self.cc.empty()

        def detectMultiScale(self, *a, **k):
            r = np.asarray(self.cc.detectMultiScale(*a, **k))
            return r[self.rng.permutation(len(r))] if len(r) else r

    monkeypatch.setattr(samples.cv2, "CascadeClassifier", Shuffled)
    shuffled = mine()
    assert len(plain[0]) > 50 and plain[1:] == shuffled[1:]
    assert np.array_equal(plain[0], shuffled[0])


@pytest.mark.parametrize("band", ["344", "344,abc", "344,-1.8", "344,1.8,4.5,1.0"])
def test_cli_names_a_bad_scan_band(tmp_path, band):
    folder = _dataset(tmp_path / "data", 2, 1)
    r = subprocess.run([sys.executable, "-m", "app.cli", "train", "cascade", "--data", str(folder),
                        "--out", str(tmp_path / "m.xml"), "--scan-band", band], capture_output=True, text=True)
    assert r.returncode == 1 and f"--scan-band {band!r}" in r.stderr and "ROW,HEIGHT_M" in r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "m.xml").exists()
