"""One cascade stage by Gentle AdaBoost over regression stumps (Friedman, Hastie, Tibshirani 2000), the
booster OpenCV's traincascade used by default, or by Discrete AdaBoost as paper 004 (Viola-Jones) has it.

Each round fits the stump h(x) = (f(x) < t ? a : b) that minimises the weighted squared error
sum_i w_i (y_i - h(x_i))^2, y in {-1, +1}; for a split of the sorted responses into L and R the optimum
is a = sum_L w y / sum_L w, b = sum_R w y / sum_R w and the error falls by (sum_L w y)^2 / sum_L w +
(sum_R w y)^2 / sum_R w, found for every feature and split at once from cumulative sums over the
responses sorted once per stage. Discrete AdaBoost instead takes the split and polarity of least weighted
error e = sum of the weights of the samples on the wrong side; with W_L y = sum_L w y over the left part
and W y the total, e = (sum w)/2 - |W_L y - W y / 2|, so the best split maximises |W_L y - W y / 2|, from the
same cumulative sums; its leaves are +-alpha, alpha = ln((1 - e) / e) / 2, the sign of the side's majority.
Either way the weights then become w_i exp(-y_i h(x_i)), normalised. The stage
threshold T is the largest that keeps `min_hit_rate` of the positives (sum >= T); rounds are added until
the negatives passing fall to `max_false_alarm` or `max_weak` stumps are used.
"""
from __future__ import annotations

from typing import Callable, Optional

import numpy as np

from .model import Stage, stage_passes


BOOSTERS = ("gentle", "discrete")


def _best_stumps(xs: np.ndarray, order: np.ndarray, w: np.ndarray, wy: np.ndarray, discrete: bool = False,
                 chunk: int = 512):
    """Best split of every feature: (gain, position k: left = the k+1 smallest) per feature row. The gain is the
    fall of the weighted squared error (Gentle) or, `discrete`, how far the weighted error lies below half."""
    nf, n = xs.shape
    gains = np.full(nf, -np.inf)
    pos = np.zeros(nf, np.int64)
    tw, twy = w.sum(), wy.sum()
    for a in range(0, nf, chunk):
        o = order[a:a + chunk]
        cw = np.cumsum(w[o], axis=1)[:, :-1]
        cwy = np.cumsum(wy[o], axis=1)[:, :-1]
        rw = tw - cw
        with np.errstate(divide="ignore", invalid="ignore"):
            g = np.abs(cwy - twy / 2) if discrete else cwy * cwy / cw + (twy - cwy) ** 2 / rw
        x = xs[a:a + chunk]
        g[(x[:, 1:] <= x[:, :-1]) | (cw <= 0) | (rw <= 0)] = -np.inf
        k = np.argmax(g, axis=1)
        gains[a:a + chunk] = g[np.arange(len(k)), k]
        pos[a:a + chunk] = k
    return gains, pos


def train_stage(values: np.ndarray, feature_ids: np.ndarray, y: np.ndarray, min_hit_rate: float,
                max_false_alarm: float, max_weak: int,
                on_round: Optional[Callable[[int, float, float], None]] = None,
                booster: str = "gentle") -> tuple[Stage, float, float]:
    """Boost one stage on (F, N) responses of candidate features `feature_ids` for labels `y` (+1/-1), by
    `booster` (BOOSTERS).

    Returns the stage, its hit rate and false-alarm rate on these samples."""
    if booster not in BOOSTERS:
        raise ValueError(f"booster {booster!r}: one of {', '.join(BOOSTERS)}")
    discrete = booster == "discrete"
    order = np.argsort(values, axis=1, kind="stable").astype(np.int32)
    xs = np.take_along_axis(values, order, axis=1)
    pos, neg = y > 0, y < 0
    w = np.where(pos, 0.5 / pos.sum(), 0.5 / neg.sum())
    total = np.zeros(len(y))
    st = Stage()
    hit = fa = 1.0
    for r in range(max_weak):
        gains, k = _best_stumps(xs, order, w, w * y, discrete)
        f = int(np.argmax(gains))
        kk = int(k[f])
        lo, hi = xs[f, kk], xs[f, kk + 1]
        t = np.float32((np.float64(lo) + np.float64(hi)) / 2)
        if not lo < t <= hi:
            t = hi
        left = values[f] < t
        if discrete:
            # weighted error with the left side called a vehicle (the weights sum to 1)
            e = w[left & neg].sum() + w[~left & pos].sum()
            err = min(e, 1.0 - e)  # of the better polarity
            alpha = 0.5 * np.log((1.0 - err) / max(err, 1e-12))
            a = np.float32(alpha if e <= 0.5 else -alpha)  # the side holding the vehicles gets +alpha
            b = -a
        else:
            a = np.float32((w * y)[left].sum() / w[left].sum())
            b = np.float32((w * y)[~left].sum() / w[~left].sum())
        h = np.where(left, a, b).astype(np.float64)
        total += h
        w = w * np.exp(-y * h)
        w /= w.sum()
        st.features.append(int(feature_ids[f]))
        st.thresholds.append(float(t))
        st.left.append(float(a))
        st.right.append(float(b))
        # T halfway between the k-th lowest positive sum and the next lower sum of any sample, so that
        # no sum lies within rounding (or OpenCV's 1e-5 allowance) of it
        kth = np.sort(total[pos])[int(np.floor((1.0 - min_hit_rate) * len(total[pos])))]
        below = total[total < kth]
        thr = np.float32((kth + below.max()) / 2) if len(below) else np.float32(kth - 1.0)
        hit = float(stage_passes(total[pos], thr).mean())
        fa = float(stage_passes(total[neg], thr).mean())
        st.threshold = float(thr)
        if on_round:
            on_round(r + 1, hit, fa)
        if fa <= max_false_alarm:
            break
    return st, hit, fa


