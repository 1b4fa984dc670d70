"""Haar-like features over integral images, evaluated exactly as OpenCV 4's HaarEvaluator does.

A feature is up to three rectangles (x, y, w, h) inside the W x H window, each with a weight; its
response on a window is

    f = (w0 * S(r0) + w1 * S(r1) [+ w2 * S(r2)]) * n,    n = 1 / sqrt(A * sum(I^2) - sum(I)^2)

where S(r) is the pixel sum of rectangle r (four lookups in the integral image) and the sums for the
variance normalisation n run over the window shrunk by one pixel on every side (A = (W-2)(H-2) pixels:
OpenCV's `normrect`). OpenCV computes f in single precision in this order and rejects every window whose
A * n >= 0.1, i.e. whose grey-level standard deviation is 10 or less; both are reproduced here so that
the trainer's decisions are the ones `cv2.CascadeClassifier` makes on the same pixels.

The feature set is traincascade's (mode ALL, upright): edge features x2/y2, line features x3/y3 and
x4/y4, the four-rectangle x2_y2 and the centre-surround x3_y3; the first rectangle always spans the
whole feature with weight -1, the others carry the weight that balances its area.
"""
from __future__ import annotations

import numpy as np
from scipy import sparse

# (name, rectangles as (x, y, w, h, weight) in units of the cell (dx, dy), whole extent in cells)
_SHAPES = (
    ("x2", ((0, 0, 2, 1, -1.0), (1, 0, 1, 1, 2.0)), (2, 1)),
    ("y2", ((0, 0, 1, 2, -1.0), (0, 1, 1, 1, 2.0)), (1, 2)),
    ("x3", ((0, 0, 3, 1, -1.0), (1, 0, 1, 1, 3.0)), (3, 1)),
    ("y3", ((0, 0, 1, 3, -1.0), (0, 1, 1, 1, 3.0)), (1, 3)),
    ("x4", ((0, 0, 4, 1, -1.0), (1, 0, 2, 1, 2.0)), (4, 1)),
    ("y4", ((0, 0, 1, 4, -1.0), (0, 1, 1, 2, 2.0)), (1, 4)),
    ("x2_y2", ((0, 0, 2, 2, -1.0), (0, 0, 1, 1, 2.0), (1, 1, 1, 1, 2.0)), (2, 2)),
    ("x3_y3", ((0, 0, 3, 3, -1.0), (1, 1, 1, 1, 9.0)), (3, 3)),
)


class FeatureSet:
    """Every upright Haar feature of a `width` x `height` window.

    rects: (F, 3, 4) int32 x, y, w, h (unused third rectangle: zeros); weights: (F, 3) float32."""

    def __init__(self, width: int, height: int):
        self.width, self.height = width, height
        rects, weights = [], []
        for _, shape, (cx, cy) in _SHAPES:
            for dy in range(1, height // cy + 1):
                for dx in range(1, width // cx + 1):
                    for y in range(0, height - cy * dy + 1):
                        for x in range(0, width - cx * dx + 1):
                            r = [(x + a * dx, y + b * dy, c * dx, d * dy) for a, b, c, d, _ in shape]
                            wt = [s[4] for s in shape]
                            while len(r) < 3:
                                r.append((0, 0, 0, 0))
                                wt.append(0.0)
                            rects.append(r)
                            weights.append(wt)
        self.rects = np.asarray(rects, np.int32)
        self.weights = np.asarray(weights, np.float32)

    def __len__(self) -> int:
        return len(self.rects)

    def corner_index(self, idx: np.ndarray) -> np.ndarray:
        """(len(idx), 3, 4) flat indices into a (H+1) x (W+1) integral image: S = I[a] - I[b] - I[c] + I[d]
        with a = bottom-right, b = top-right, c = bottom-left, d = top-left."""
        r = self.rects[idx]
        x, y, w, h = r[..., 0], r[..., 1], r[..., 2], r[..., 3]
        s = self.width + 1
        return np.stack([(y + h) * s + x + w, y * s + x + w, (y + h) * s + x, y * s + x], axis=-1)


def integrals(patches: np.ndarray) -> np.ndarray:
    """(N, H, W) uint8 windows -> (N, (H+1)*(W+1)) int64 integral images, zero first row and column."""
    n, h, w = patches.shape
    ii = np.zeros((n, h + 1, w + 1), np.int64)
    ii[:, 1:, 1:] = patches.astype(np.int64).cumsum(1).cumsum(2)
    return ii.reshape(n, -1)


def variance_norm(patches: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """OpenCV's per-window normalisation factor n (float32) and whether OpenCV scans the window at all
    (n defined and A * n < 0.1, A the area of the window less its one-pixel border)."""
    inner = patches[:, 1:-1, 1:-1].astype(np.int64)
    area = float(inner.shape[1] * inner.shape[2])
    s = inner.sum((1, 2)).astype(np.float64)
    sq = (inner * inner).sum((1, 2)).astype(np.float64)
    nf = area * sq - s * s
    ok = nf > 0
    n = np.ones(len(patches), np.float32)
    n[ok] = (1.0 / np.sqrt(nf[ok])).astype(np.float32)
    valid = ok & (area * n.astype(np.float64) < 1e-1)
    return n, valid


def responses(fs: FeatureSet, idx: np.ndarray, ii: np.ndarray, norm: np.ndarray) -> np.ndarray:
    """(len(idx), N) float32 responses of features `idx` on windows with integrals `ii` and factors
    `norm`, computed in OpenCV's order and precision. The rectangle sums are exact integers, found for
    all windows at once as one sparse product (corner coefficients +1 -1 -1 +1) per rectangle."""
    corners = fs.corner_index(idx)                          # (f, 3, 4)
    wts = fs.weights[idx]                                   # (f, 3)
    iit = np.ascontiguousarray(ii.T, dtype=np.float64)      # (P, N)
    cols = np.repeat(np.arange(len(idx)), 4)
    coef = np.tile([1.0, -1.0, -1.0, 1.0], len(idx))
    acc = None
    for k in range(3):
        m = sparse.csr_matrix((coef, (cols, corners[:, k, :].ravel())), shape=(len(idx), iit.shape[0]))
        rs = (m @ iit).astype(np.float32)                   # (f, N) rectangle sums
        term = wts[:, k, None] * rs
        if k < 2:
            acc = term if acc is None else acc + term
        else:  # OpenCV adds the third rectangle only when its weight is not zero
            has3 = wts[:, 2] != 0
            acc[has3] = acc[has3] + term[has3]
    return acc * norm[None, :]
