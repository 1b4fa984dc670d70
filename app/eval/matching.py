"""Box matching shared by every evaluation: IoU and one-to-one assignment at an IoU threshold."""
from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.optimize import linear_sum_assignment

Box = Sequence[float]  # left, top, right, bottom


def _intersections(a: Sequence[Box], b: Sequence[Box]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pairwise intersection areas of a's and b's boxes, with each side's own areas (broadcast)."""
    A = np.asarray(a, float)[:, None, :]
    B = np.asarray(b, float)[None, :, :]
    iw = np.clip(np.minimum(A[..., 2], B[..., 2]) - np.maximum(A[..., 0], B[..., 0]), 0, None)
    ih = np.clip(np.minimum(A[..., 3], B[..., 3]) - np.maximum(A[..., 1], B[..., 1]), 0, None)
    area_a = (A[..., 2] - A[..., 0]) * (A[..., 3] - A[..., 1])
    area_b = (B[..., 2] - B[..., 0]) * (B[..., 3] - B[..., 1])
    return iw * ih, area_a, area_b


def iou_matrix(a: Sequence[Box], b: Sequence[Box]) -> np.ndarray:
    if not len(a) or not len(b):
        return np.zeros((len(a), len(b)))
    inter, area_a, area_b = _intersections(a, b)
    return inter / np.maximum(area_a + area_b - inter, 1e-9)


def inside_matrix(a: Sequence[Box], b: Sequence[Box]) -> np.ndarray:
    """The fraction of each of a's boxes that lies inside each of b's (intersection over a's area): KITTI's
    overlap for a box on a don't-care region."""
    if not len(a) or not len(b):
        return np.zeros((len(a), len(b)))
    inter, area_a, _ = _intersections(a, b)
    return inter / np.maximum(area_a, 1e-9)


def match(a: Sequence[Box], b: Sequence[Box], min_iou: float = 0.5) -> list[tuple[int, int, float]]:
    """One-to-one pairs (i in a, j in b, iou) maximising total IoU, each pair with IoU >= min_iou."""
    m = iou_matrix(a, b)
    if m.size == 0:
        return []
    rows, cols = linear_sum_assignment(-m)
    return [(int(i), int(j), float(m[i, j])) for i, j in zip(rows, cols) if m[i, j] >= min_iou]
