"""Cost of the parallax preset's joint particle filter against the number of tracked vehicles N.

The filter's cost grows with N (the state stacks every vehicle: O(n_s N (M + 1)) per frame, M the
measurements), so it is measured at N = 1..8 on frames made for it: the synthetic empty road with 1..8 dark
vehicle-sized patches held still in the image (a car keeping the ego's speed is one: its rear stays put
while the road flows under it), which the aligned difference measures in every frame. After a warm-up
in which the filter confirms them one by one, each frame's "particles" stage time is a sample for the
number of vehicles the filter then holds.
"""
from __future__ import annotations

import dataclasses
from typing import Optional

import numpy as np

from app.core import Pipeline
from app.sim import load_scenario, render

# Patch boxes (l, t, r, b) at 640x480 in two rows, ~14 m and ~9 m ahead, each wider than the detector's
# shortest vehicle at its row, far enough apart not to be joined, all well inside the road area (patches near
# the image sides were confirmed late and lost again, so N = 6-8 were rarely reached). Ordered so that the
# first n alternate between the rows.
_FAR = [(150, 272, 200, 290), (240, 272, 290, 290), (330, 272, 380, 290), (420, 272, 470, 290)]
_NEAR = [(110, 326, 170, 348), (220, 326, 280, 348), (350, 326, 410, 348), (460, 326, 520, 348)]
PATCHES = [_FAR[1], _NEAR[2], _FAR[2], _NEAR[1], _FAR[0], _NEAR[3], _FAR[3], _NEAR[0]]


def particle_cost(max_n: int = 8, seconds: float = 12.0, warmup: int = 40, config: Optional[dict] = None) -> dict:
    """{N: {"n": frames, "median_ms", "p99_ms"}}: the particles stage time of the frames in which the filter
    held N confirmed vehicles, over runs with 1..max_n patches on `seconds` of empty road."""
    sc = dataclasses.replace(load_scenario("empty_road"), duration_s=seconds)
    base = [(f.image, f.t_s, f.ego_speed_mps) for f in render(sc)]
    by_n: dict[int, list[float]] = {}
    for n in range(1, min(max_n, len(PATCHES)) + 1):
        cfg = {"pipeline": {"preset": "parallax"}}
        cfg.update(config or {})
        with Pipeline(cfg) as p:
            for k, (img, t, v) in enumerate(base):
                img = img.copy()
                for (l, tp, r, b) in PATCHES[:n]:
                    img[tp:b, l:r] = 35
                p.set_ego_motion(v, 0.0)
                res = p.process(img, t)
                if k >= warmup:
                    n_conf = sum(1 for tr in res.tracks if tr.confirmed)
                    by_n.setdefault(n_conf, []).append(res.stages.get("particles", float("nan")))
    return {n: {"n": len(v), "median_ms": float(np.median(v)), "p99_ms": float(np.percentile(v, 99))}
            for n, v in sorted(by_n.items()) if 1 <= n <= max_n}


def format_table(costs: dict) -> str:
    lines = ["| N vehicles in the filter | frames | particles median ms | p99 ms |", "| ---: | ---: | ---: | ---: |"]
    for n, c in costs.items():
        lines.append(f"| {n} | {c['n']} | {c['median_ms']:.3f} | {c['p99_ms']:.3f} |")
    return "\n".join(lines)
