"""A second learned stage for the cascade: a linear classifier over HOG features of each detection,
trained on the cascade's own detections in the training images (`headway train verifier`).

Candidates are what the core's "cascade" stage reports on the training images (so the verifier sees
the same boxes it will judge): a candidate with IoU >= 0.5 with an annotated box is a vehicle, one
with IoU < 0.3 with every box is not, the rest are left out; the annotated boxes themselves (at the
cascade's aspect) and all positives mirrored are added. Each box is resized to the HOG window
(cv::HOGDescriptor: 48 x 32 px, 16 px blocks, 8 px cells and stride, 9 bins: 540 values) and an
L2-regularised logistic regression is fitted (L-BFGS):
    p(vehicle | x) = 1 / (1 + exp(-(w . x + b))),  minimising  sum_i log(1 + exp(-y_i (w . x_i + b))) + |w|^2 / (2 C)
The model is written with cv2.FileStorage (hog parameters, w, b) and read by the core
(csrc/detect/vehicle_verifier.hpp).
"""
from __future__ import annotations

import sys
import time
from typing import Callable

import cv2
import numpy as np
from scipy.optimize import minimize
from tqdm import tqdm

from app.train.cascade.samples import iou, load_folders, read_gray, window_around

HOG_WIN = (48, 32)


def hog() -> cv2.HOGDescriptor:
    return cv2.HOGDescriptor(HOG_WIN, (16, 16), (8, 8), (8, 8), 9)


def box_features(h: cv2.HOGDescriptor, gray: np.ndarray, boxes) -> np.ndarray:
    """HOG of every box (left, top, right, bottom) resized to the HOG window (clipped to the image)."""
    out = []
    for l, t, r, b in boxes:
        l, t = max(0, int(round(l))), max(0, int(round(t)))
        r, b = min(gray.shape[1], int(round(r))), min(gray.shape[0], int(round(b)))
        crop = cv2.resize(gray[t:b, l:r], HOG_WIN, interpolation=cv2.INTER_AREA)
        out.append(h.compute(crop).ravel())
    return np.array(out, np.float32).reshape(-1, h.getDescriptorSize())


def candidates(folders: list[str], cascade_xml: str, every: int, cfg: dict, progress=None):
    """(features, labels) from the cascade stage's detections on every `every`-th training image, the core
    configured by `cfg` (a validated configuration: its camera must be the images' camera)."""
    from app import config as configuration
    from app.core import Pipeline

    cfg["cascade"]["model"] = cascade_xml
    cfg["cascade"]["verifier"] = "off"
    cfg["cascade"]["min_neighbors"] = 1
    items = load_folders(folders)[::every]
    h = hog()
    xs, ys = [], []
    with Pipeline(configuration.core_sections(cfg)) as pipe:
        for it in items:
            g = read_gray(it.path)
            det = np.array([t.box for t in pipe.run_stage("cascade", g).tracks], float).reshape(-1, 4)
            gt = it.boxes[(it.boxes[:, 3] - it.boxes[:, 1]) >= 20]
            m = iou(det, it.boxes).max(1) if len(it.boxes) else np.zeros(len(det))
            pos = [window_around(b, 3, 2) for b in gt] + list(det[m >= 0.5])
            neg = list(det[m < 0.3])
            fp = box_features(h, g, pos)
            fpm = box_features(h, g[:, ::-1].copy(), [(g.shape[1] - r, t, g.shape[1] - l, b) for l, t, r, b in pos])
            xs += [fp, fpm, box_features(h, g, neg)]
            ys += [np.ones(len(fp) + len(fpm)), -np.ones(len(neg))]
            if progress:
                progress(1)
    return np.concatenate(xs), np.concatenate(ys), len(items)


def fit_logistic(x: np.ndarray, y: np.ndarray, c: float) -> tuple[np.ndarray, float]:
    # class-balanced weights so that the many negatives do not swamp the vehicles
    sw = np.where(y > 0, 0.5 / (y > 0).sum(), 0.5 / (y < 0).sum()) * len(y)
    xd = x.astype(np.float64)

    def f(theta):
        w, b = theta[:-1], theta[-1]
        z = y * (xd @ w + b)
        loss = (sw * np.logaddexp(0, -z)).sum() + (w @ w) / (2 * c)
        g = -sw * y / (1 + np.exp(z))
        return loss, np.r_[xd.T @ g + w / c, g.sum()]

    res = minimize(f, np.zeros(x.shape[1] + 1), jac=True, method="L-BFGS-B", options={"maxiter": 500})
    return res.x[:-1].astype(np.float32), float(res.x[-1])


def train(folders: list[str], cascade_xml: str, out: str, cfg: dict, every: int = 4, c: float = 10.0,
          log: Callable[[str], None] = print) -> None:
    t0 = time.perf_counter()
    n_items = len(load_folders(folders)[::every])
    with tqdm(total=n_items, desc="candidates", unit="img", file=sys.stderr, disable=not sys.stderr.isatty(),
              leave=False) as bar:
        x, y, n = candidates(folders, cascade_xml, every, cfg, progress=bar.update)
    rng = np.random.default_rng(0)
    order = rng.permutation(len(y))
    x, y = x[order], y[order]
    k = len(y) * 4 // 5   # last fifth held out to report the verifier's own accuracy
    w, b = fit_logistic(x[:k], y[:k], c)
    s = x[k:] @ w + b
    acc_pos, acc_neg = float((s[y[k:] > 0] > 0).mean()), float((s[y[k:] < 0] <= 0).mean())
    w, b = fit_logistic(x, y, c)
    fs = cv2.FileStorage(out, cv2.FILE_STORAGE_WRITE)
    fs.write("hog_width", HOG_WIN[0])
    fs.write("hog_height", HOG_WIN[1])
    fs.write("weights", w.reshape(1, -1))
    fs.write("bias", b)
    fs.release()
    log(f"verifier: {n} images (every {every}th), {int((y > 0).sum())} vehicle and {int((y < 0).sum())} other boxes, "
        f"HOG {HOG_WIN[0]}x{HOG_WIN[1]} ({x.shape[1]} values), C={c:g}; held-out fifth: {acc_pos:.3f} of vehicles "
        f"and {acc_neg:.3f} of others right; {(time.perf_counter() - t0) / 60:.1f} min -> {out}")
