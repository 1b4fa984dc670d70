"""A second learned stage for the cascade: a small neural network (one hidden layer) over HOG features of
each detection, trained on the cascade's own detections in the training images (`headway train verifier`).

Candidates are what the core's detection stage with the cascade alone reports on the training images (so the verifier sees
the same boxes it will judge, the cascade's hard negatives among them): a candidate with IoU >= 0.5 with
an annotated box is a vehicle, one with IoU < 0.3 with every box is not, the rest are left out; the
annotated boxes themselves (at the cascade's aspect) are added, and every sample also mirrored. Each box
is resized to the HOG window (cv::HOGDescriptor: 64 x 40 px, 16 px blocks, 8 px cells and stride, 9
bins: 1008 values), standardised (z = (x - mean) * scale) and judged by
    p(vehicle | x) = sigmoid(w2 . relu(W1^T z + b1) + b2)
fitted by Adam on the class-balanced cross-entropy with L2 weight decay, deterministic by seed. The model
is written with cv2.FileStorage and read by the core (csrc/detect/vehicle_verifier.hpp), which computes
the same expression with cv::Mat products: no new runtime dependency.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from typing import Callable

import cv2
import numpy as np
from tqdm import tqdm

from app import config as configuration
from app.core import Pipeline
from app.output_files import written_whole
from app.train.cascade.samples import iou, load_folders, read_gray

HOG_WIN = (64, 40)   # px: the cascade's aspect 1.5 (1.6 here: HOG needs multiples of 8), a 40 px box at 1:1


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


def geometry_features(boxes, neighbors, horizon_row: float, cam_height_m: float) -> np.ndarray:
    """(n, 2): log(1 + raw windows grouped) and the vehicle height the box implies on a flat road,
    H = h_cam * h / (y_b - y_h) (m, 10 when the bottom is not below the horizon, clipped to 0..10)."""
    b = np.asarray(boxes, float).reshape(-1, 4)
    below = b[:, 3] - horizon_row
    hv = np.where(below > 0, cam_height_m * (b[:, 3] - b[:, 1]) / np.maximum(below, 1e-6), 10.0)
    return np.c_[np.log1p(np.asarray(neighbors, float)), np.clip(hv, 0, 10)].astype(np.float32)


def cascade_detections(folders: list[str], cascade_xml: str, every: int, cfg: dict, progress=None):
    """Per every `every`-th training image, the core's detection stage with the cascade alone (verifier off, groups of one
    window kept), the core configured by `cfg` (a validated configuration: its camera must be the images'
    camera). Yields (image index k, gray image, boxes (n, 4) left, top, right, bottom, raw windows per box,
    label per box: 1 = vehicle (IoU >= 0.5 with an annotated box), -1 = other (IoU < 0.3 with every box),
    0 = left out, the image's horizon row, each box's largest IoU with an annotated box)."""
    cfg["pipeline"].update(detectors=["cascade"], tracker="kalman")
    cfg["cascade"]["model"] = cascade_xml
    cfg["cascade"]["verifier"] = "off"
    cfg["cascade"]["min_neighbors"] = 1
    half = cfg["cascade"]["neighbors_half"]
    with Pipeline(configuration.core_sections(cfg)) as pipe:
        for k, it in enumerate(load_folders(folders)[::every]):
            g = read_gray(it.path)
            found = pipe.detect(g)   # every group
            r, horizon = found.boxes, found.horizon_row
            det = r[:, :4].astype(float)
            conf = r[:, 4].astype(float)
            n = np.rint(half * conf / np.maximum(1 - conf, 1e-6))   # confidence n / (n + half) without verifier
            m = iou(det, it.boxes).max(1) if len(it.boxes) else np.zeros(len(det))
            yield k, g, det, n, np.where(m >= 0.5, 1, np.where(m < 0.3, -1, 0)), horizon, m
            if progress:
                progress(1)


def candidates(folders: list[str], cascade_xml: str, every: int, cfg: dict, progress=None):
    """(features, labels, image index per sample, images used) from the cascade stage's detections on
    every `every`-th training image (`cascade_detections`), every sample also mirrored."""
    cam_h = cfg["camera"]["height_m"]
    h = hog()
    xs, ys, img = [], [], []
    used = 0
    for k, g, det, n, lab, horizon, _ in cascade_detections(folders, cascade_xml, every, cfg, progress):
        used += 1
        gm = g[:, ::-1].copy()
        for label in (1.0, -1.0):
            sel = lab == label
            geo = geometry_features(det[sel], n[sel], horizon, cam_h)
            mirrored = [(g.shape[1] - r_, t, g.shape[1] - l, b) for l, t, r_, b in det[sel]]
            for f in (box_features(h, g, det[sel]), box_features(h, gm, mirrored)):
                f = np.c_[f, geo]
                xs.append(f)
                ys.append(np.full(len(f), label))
                img.append(np.full(len(f), k))
    return np.concatenate(xs), np.concatenate(ys), np.concatenate(img), used


@dataclass
class Mlp:
    mean: np.ndarray    # (d,) feature means
    scale: np.ndarray   # (d,) 1 / feature standard deviations
    w1: np.ndarray      # (d, hidden)
    b1: np.ndarray      # (hidden,)
    w2: np.ndarray      # (hidden,)
    b2: float

    def logit(self, x: np.ndarray) -> np.ndarray:
        z = (x - self.mean) * self.scale
        return np.maximum(z @ self.w1 + self.b1, 0) @ self.w2 + self.b2

    def probability(self, x: np.ndarray) -> np.ndarray:
        return 1 / (1 + np.exp(-self.logit(x)))

    def save(self, path: str) -> None:
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_WRITE)
        fs.write("hog_width", HOG_WIN[0])
        fs.write("hog_height", HOG_WIN[1])
        fs.write("mean", self.mean.reshape(1, -1).astype(np.float32))
        fs.write("scale", self.scale.reshape(1, -1).astype(np.float32))
        fs.write("w1", self.w1.astype(np.float32))
        fs.write("b1", self.b1.reshape(1, -1).astype(np.float32))
        fs.write("w2", self.w2.reshape(-1, 1).astype(np.float32))
        fs.write("b2", float(self.b2))
        fs.release()

    @staticmethod
    def load(path: str) -> "Mlp":
        fs = cv2.FileStorage(path, cv2.FILE_STORAGE_READ)
        if not fs.isOpened() or fs.getNode("w1").empty():
            raise ValueError(f"{path}: not a verifier model written by `headway train verifier`")
        m = lambda k: fs.getNode(k).mat().astype(np.float32)  # noqa: E731
        return Mlp(m("mean").ravel(), m("scale").ravel(), m("w1"), m("b1").ravel(), m("w2").ravel(),
                   fs.getNode("b2").real())


def fit_mlp(x: np.ndarray, y: np.ndarray, hidden: int, epochs: int, decay: float, seed: int,
            batch: int = 256, lr: float = 1e-3) -> Mlp:
    """Adam (beta 0.9, 0.999) on the class-balanced cross-entropy
    L = sum_i s_i log(1 + exp(-y_i f(x_i))) / sum_i s_i + decay (|W1|^2 + |w2|^2) / 2,
    s_i = 1 / (2 n_class(y_i)); the learning rate falls linearly to 0 over the epochs."""
    rng = np.random.default_rng(seed)
    mean = x.mean(0)
    scale = 1 / (x.std(0) + 1e-3)
    z_all = ((x - mean) * scale).astype(np.float32)
    d = x.shape[1]
    params = [rng.normal(0, np.sqrt(2 / d), (d, hidden)).astype(np.float32), np.zeros(hidden, np.float32),
              rng.normal(0, np.sqrt(1 / hidden), hidden).astype(np.float32), np.zeros(1, np.float32)]
    m1 = [np.zeros_like(p) for p in params]
    m2 = [np.zeros_like(p) for p in params]
    sw = np.where(y > 0, 0.5 / (y > 0).sum(), 0.5 / (y < 0).sum()).astype(np.float32) * len(y)
    yf = y.astype(np.float32)
    steps = epochs * ((len(y) + batch - 1) // batch)
    t = 0
    for _ in range(epochs):
        for idx in np.array_split(rng.permutation(len(y)), max(1, len(y) // batch)):
            w1, b1, w2, b2 = params
            z, yy, s = z_all[idx], yf[idx], sw[idx]
            a = z @ w1 + b1
            hdn = np.maximum(a, 0)
            f = hdn @ w2 + b2[0]
            g = -s * yy / (1 + np.exp(np.clip(yy * f, -30, 30))) / len(idx)   # dL/df
            gh = np.outer(g, w2) * (a > 0)
            grads = [z.T @ gh + decay * w1, gh.sum(0), hdn.T @ g + decay * w2, np.array([g.sum()], np.float32)]
            t += 1
            rate = lr * (1 - (t - 1) / steps)
            for p, gr, ma, va in zip(params, grads, m1, m2):
                ma *= 0.9
                ma += 0.1 * gr
                va *= 0.999
                va += 0.001 * gr * gr
                p -= rate * (ma / (1 - 0.9 ** t)) / (np.sqrt(va / (1 - 0.999 ** t)) + 1e-8)
    w1, b1, w2, b2 = params
    return Mlp(mean.astype(np.float32), scale.astype(np.float32), w1, b1, w2, float(b2[0]))


def train(folders: list[str], cascade_xml: str, out: str, cfg: dict, every: int = 4, hidden: int = 64,
          epochs: int = 12, decay: float = 1e-4, seed: int = 0, log: Callable[[str], None] = print) -> Mlp:
    t0 = time.perf_counter()
    n_items = len(load_folders(folders)[::every])
    with tqdm(total=n_items, desc="candidates", unit="img", file=sys.stderr, disable=not sys.stderr.isatty(),
              leave=False) as bar:
        x, y, img, n = candidates(folders, cascade_xml, every, cfg, progress=bar.update)
    held = img % 5 == 4   # every fifth image held out to report the verifier's own accuracy
    m = fit_mlp(x[~held], y[~held], hidden, epochs, decay, seed)
    s = m.logit(x[held])
    acc_pos, acc_neg = float((s[y[held] > 0] > 0).mean()), float((s[y[held] < 0] <= 0).mean())
    m = fit_mlp(x, y, hidden, epochs, decay, seed)
    with written_whole(out) as tmp:   # same suffixes: OpenCV writes .yml.gz as gzipped YAML
        m.save(tmp)
    log(f"verifier: {n} images (every {every}th), {int((y > 0).sum())} vehicle and {int((y < 0).sum())} other "
        f"boxes (mirrors included), HOG {HOG_WIN[0]}x{HOG_WIN[1]} ({x.shape[1]} values), {hidden} hidden units, "
        f"{epochs} epochs, decay {decay:g}, seed {seed}; held-out fifth of the images: {acc_pos:.3f} of vehicles "
        f"and {acc_neg:.3f} of others right at p = 0.5; {(time.perf_counter() - t0) / 60:.1f} min -> {out}")
    return m
