"""Cost of the parallax preset's joint particle filter against the number of tracked vehicles N.

The filter's cost grows with N (the state stacks every vehicle: O(n_s N (M + 1)) per frame, M the
measurements), so it is measured at N = 1..8 on frames made for it: the synthetic empty road with 1..8 dark
vehicle-sized patches held still in the image (a car keeping the ego's speed is one: its rear stays put
while the road flows under it), which the aligned difference measures in every frame. After a warm-up
in which the filter confirms them one by one, each frame's "particles" stage time is a sample for the
number of vehicles the filter then holds.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from app.core import Pipeline

# Patch boxes (l, t, r, b) at 640x480 in two rows, ~14 m and ~7 m ahead, each wider than the detector's
# shortest vehicle at its row, far enough apart not to be joined, the far ones not over the near ones.
PATCHES = [(232, 272, 288, 290), (62, 336, 122, 360), (514, 336, 574, 360), (334, 272, 390, 290),
           (176, 336, 236, 360), (400, 336, 460, 360), (130, 272, 186, 290), (436, 272, 492, 290)]


def particle_cost(max_n: int = 8, frames: int = 140, warmup: int = 80, config: Optional[dict] = None) -> dict:
    """{N: {"n": frames, "median_ms", "p99_ms"}}: the particles stage time of the frames in which the filter
    held N confirmed vehicles, over runs with 1..max_n patches."""
    from app.sim import load_scenario, render

    base = [(f.image, f.t_s, f.ego_speed_mps) for f in render(load_scenario("empty_road"), frames=range(frames))]
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
