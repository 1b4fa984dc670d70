"""Training windows: positives cut from annotated images, negatives from the regions that hold no
vehicle, and hard negatives mined as the false alarms of the cascade trained so far.

Data folders hold `annotation.json` in the TuSimple velocity format ([{"file_name": "images/0601.jpg",
"bbox": [{"top", "left", "bottom", "right"}, ...]}, ...]) with every vehicle boxed, so any window whose
IoU with every box is below `NEG_IOU` is a true negative. Windows are sampled from the image by bilinear
interpolation at the window's scale, as OpenCV's detector samples its image pyramid.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .haar import variance_norm

NEG_IOU = 0.3  # a window is a negative when its IoU with every annotated box is below this


@dataclass
class Annotated:
    path: str
    boxes: np.ndarray  # (n, 4) float left, top, right, bottom


@dataclass(frozen=True)
class ScanBand:
    """The rows a detector scans for each window size on a flat road, as Headway's `cascade` stage does:
    a window of height h (px) has its bottom between `horizon_row + h * camera_height_m / max_vehicle_m`
    and `horizon_row + h * camera_height_m / min_vehicle_m`. Negatives taken only there are the windows the
    detector will meet (road, vehicles' surroundings, barriers) rather than sky and trees, which it never
    scans. `margin` widens the band by that fraction of h each way (the horizon moves with the lanes)."""
    horizon_row: float
    camera_height_m: float
    min_vehicle_m: float = 1.0
    max_vehicle_m: float = 4.5
    margin: float = 0.25

    def rows(self, h: float) -> tuple[float, float]:
        """Top and bottom image rows (original pixels) of the windows of height `h`."""
        top = self.horizon_row + h * self.camera_height_m / self.max_vehicle_m - h
        bottom = self.horizon_row + h * self.camera_height_m / self.min_vehicle_m
        return top - self.margin * h, bottom + self.margin * h


def load_folders(folders: list[str]) -> list[Annotated]:
    out = []
    for d in folders:
        ann = Path(d) / "annotation.json"
        if not ann.is_file():
            raise FileNotFoundError(f"{d}: no annotation.json (expected the TuSimple velocity format, e.g. the "
                                    "OUTDIR of ../shared/tools/tusimple-train)")
        for e in json.loads(ann.read_text()):
            b = np.array([[x["left"], x["top"], x["right"], x["bottom"]] for x in e["bbox"]], float).reshape(-1, 4)
            out.append(Annotated(str(Path(d) / e["file_name"]), b))
    if not out:
        raise ValueError(f"{folders}: no annotated images")
    return out


def read_gray(path: str) -> np.ndarray:
    img = cv2.imread(path, cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise FileNotFoundError(f"{path}: cannot be read as an image")
    return img


def iou(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(n, m) IoU of boxes a (n, 4) and b (m, 4), each left, top, right, bottom."""
    if not len(a) or not len(b):
        return np.zeros((len(a), len(b)))
    lt = np.maximum(a[:, None, :2], b[None, :, :2])
    rb = np.minimum(a[:, None, 2:], b[None, :, 2:])
    inter = np.clip(rb - lt, 0, None).prod(-1)
    area = lambda x: (x[:, 2] - x[:, 0]) * (x[:, 3] - x[:, 1])  # noqa: E731
    return inter / (area(a)[:, None] + area(b)[None, :] - inter)


def sample_window(gray: np.ndarray, box, width: int, height: int) -> np.ndarray:
    """The window `box` (left, top, right, bottom) resampled to width x height, pixel centres mapped as
    cv2.resize maps them: x = left + (u + 0.5) * s - 0.5."""
    l, t, r, b = box
    sx, sy = (r - l) / width, (b - t) / height
    m = np.array([[sx, 0, l + 0.5 * sx - 0.5], [0, sy, t + 0.5 * sy - 0.5]])
    return cv2.warpAffine(gray, m, (width, height), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)


def window_around(box, width: int, height: int) -> tuple:
    """The window of the cascade's aspect with the box's height, centred on the box."""
    l, t, r, b = box
    w = (b - t) * width / height
    c = (l + r) / 2
    return (c - w / 2, t, c + w / 2, b)


def positives(items: list[Annotated], width: int, height: int, min_height: float, max_aspect: float,
              flip: bool = True, progress=None, min_aspect: float = 0.0) -> np.ndarray:
    """Every box at least `min_height` px high with `min_aspect` <= width/height <= `max_aspect` and its window
    inside the image, as a window (and its mirror image)."""
    out = []
    for it in items:
        keep = [b for b in it.boxes if b[3] - b[1] >= min_height
                and min_aspect * (b[3] - b[1]) <= (b[2] - b[0]) <= max_aspect * (b[3] - b[1])]
        if keep:
            g = read_gray(it.path)
            for b in keep:
                wb = window_around(b, width, height)
                if wb[0] < 0 or wb[1] < 0 or wb[2] > g.shape[1] or wb[3] > g.shape[0]:
                    continue
                p = sample_window(g, wb, width, height)
                out.append(p)
                if flip:
                    out.append(p[:, ::-1])
        if progress:
            progress(1)
    return np.ascontiguousarray(np.array(out, np.uint8).reshape(-1, height, width))


def random_negatives(items: list[Annotated], n: int, width: int, height: int, rng: np.random.Generator,
                     max_scale: float = 12.0, band: ScanBand | None = None) -> np.ndarray:
    """`n` windows at random places and scales (window height H to H * max_scale) overlapping no box,
    among those OpenCV scans (contrast above its threshold); inside `band`'s rows when given."""
    out = []
    while len(out) < n:
        if len(out) >= 64:
            out = list(np.array(out)[variance_norm(np.array(out))[1]])
            if len(out) >= n:
                break
        it = items[rng.integers(len(items))]
        g = read_gray(it.path)
        for _ in range(32):
            s = np.exp(rng.uniform(0, np.log(max_scale)))
            w, h = width * s, height * s
            if w >= g.shape[1] or h >= g.shape[0]:
                continue
            y_lo, y_hi = 0.0, g.shape[0] - h
            if band is not None:
                top, bottom = band.rows(h)
                y_lo, y_hi = max(y_lo, top), min(y_hi, bottom - h)
                if y_hi <= y_lo:
                    continue
            x, y = rng.uniform(0, g.shape[1] - w), rng.uniform(y_lo, y_hi)
            box = np.array([[x, y, x + w, y + h]])
            if len(it.boxes) and iou(box, it.boxes).max() >= NEG_IOU:
                continue
            out.append(sample_window(g, box[0], width, height))
    return np.array(out[:n], np.uint8)


class Miner:
    """Hard negatives: windows the current cascade accepts (cv2.CascadeClassifier on its XML) in the
    training images, overlapping no box. Walks the images in a seeded order, carrying on where the
    previous stage stopped (cycling), at most `per_image` windows per visit. Each visit scans one random
    scale (window height H to H * `max_scale`, log-uniform): the image is resized to it and a random part
    of it, big enough for about 2 * per_image false alarms at the cascade's current false-alarm rate, is
    scanned at that scale, so that the windows taken are exactly the pixels OpenCV classified. With a
    `band`, the part scanned lies inside the band's rows for that scale."""

    def __init__(self, items: list[Annotated], width: int, height: int, rng: np.random.Generator,
                 per_image: int = 8, max_scale: float = 12.0, band: ScanBand | None = None):
        self.items, self.width, self.height, self.band = items, width, height, band
        self.order = rng.permutation(len(items))
        self.rng, self.per_image, self.max_scale = rng, per_image, max_scale
        self.next = 0

    def mine(self, xml_path: str, n: int, false_alarm: float, max_visits: int,
             progress=None) -> tuple[np.ndarray, int, int]:
        """Up to `n` windows; also the windows scanned and the false alarms seen among them."""
        cc = cv2.CascadeClassifier(xml_path)
        if cc.empty():
            raise RuntimeError(f"{xml_path}: OpenCV cannot load the cascade being trained")
        W, H = self.width, self.height
        want = 2.0 * self.per_image / max(false_alarm, 1e-9)   # windows to scan per visit
        out, scanned, seen, visits = [], 0, 0, 0
        while len(out) < n and visits < max_visits:
            it = self.items[self.order[self.next % len(self.items)]]
            self.next += 1
            visits += 1
            g = read_gray(it.path)
            f = float(np.exp(self.rng.uniform(0, np.log(self.max_scale))))
            sw, sh = round(g.shape[1] / f), round(g.shape[0] / f)
            if sw <= W + 2 or sh <= H + 2:
                continue
            # the rows that may be scanned at this scale (all, or the band's), in the resized image
            r0, r1 = 0, sh
            if self.band is not None:
                top, bottom = self.band.rows(H * f)
                r0, r1 = max(0, int(np.floor(top / f))), min(sh, int(np.ceil(bottom / f)))
                if r1 - r0 <= H + 2:
                    continue
            small = cv2.resize(g, (sw, sh), interpolation=cv2.INTER_LINEAR)
            # a crop of about `want` windows (step 2) with the image's aspect, at least one window
            cw = int(min(sw, max(W + 2, np.sqrt(4 * want * sw / sh) + W)))
            ch = int(min(r1 - r0, max(H + 2, np.sqrt(4 * want * sh / sw) + H)))
            x0, y0 = int(self.rng.integers(0, sw - cw + 1)), int(self.rng.integers(r0, r1 - ch + 1))
            crop = np.ascontiguousarray(small[y0:y0 + ch, x0:x0 + cw])
            scanned += ((cw - W) // 2 + 1) * ((ch - H) // 2 + 1)
            rects = cc.detectMultiScale(crop, scaleFactor=1.5, minNeighbors=0, minSize=(W, H), maxSize=(W, H))
            if not len(rects):
                continue
            # OpenCV's threads append windows in the order they finish: sorted, the seed alone picks the negatives
            r = np.asarray(rects, int)
            r = r[np.lexsort((r[:, 0], r[:, 1]))]
            boxes = np.c_[r[:, 0] + x0, r[:, 1] + y0, r[:, 0] + x0 + W, r[:, 1] + y0 + H].astype(float) * f
            keep = np.ones(len(r), bool) if not len(it.boxes) else iou(boxes, it.boxes).max(1) < NEG_IOU
            r = r[keep]
            seen += len(r)
            for k in self.rng.permutation(len(r))[: min(self.per_image, n - len(out))]:
                x, y = r[k, 0], r[k, 1]
                out.append(crop[y:y + H, x:x + W])
            if progress:
                progress(len(out), n)
        return np.array(out, np.uint8).reshape(-1, H, W), scanned, seen
