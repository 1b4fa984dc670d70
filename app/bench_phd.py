"""Cost of the phd preset's tracker (features, LK, GM-PHD, UKF: the "track" stage, the detector's stages
excluded) per 640x480 frame, against the number of vehicles it holds and the features per vehicle.

The frames are the synthetic scenarios with the most traffic; each frame's "track" time is a sample for
the number of vehicles (tracks, confirmed or not) the tracker then held. The features per vehicle are
set by phd_features.max_per_vehicle (corners looked for per box) and gmphd.max_components (the cap).
Pinned to one core, as `headway bench`.

    python -m app.bench_phd [--features 12,24,40] [--json]
"""
from __future__ import annotations

import argparse
import json
import os
from typing import Optional

import numpy as np

from app.core import Pipeline

SCENARIOS = ("dense_traffic", "adjacent_passing", "steady_following", "lane_change", "cut_in")


def phd_cost(features: int, cap: int, scenarios=SCENARIOS, max_n: int = 8) -> dict:
    """{N: {"n": frames, "median_ms", "p99_ms", "features": mean stable features per vehicle}}."""
    from app.sim import load_scenario, render
    from app.sim.frames import scenario_camera

    by_n: dict[int, list[float]] = {}
    for name in scenarios:
        sc = load_scenario(name)
        cfg = {"pipeline": {"preset": "phd"}, "camera": scenario_camera(sc).to_dict(),
               "phd_features": {"max_per_vehicle": features}, "gmphd": {"max_components": cap}}
        with Pipeline(cfg) as p:
            for f in render(sc):
                p.set_ego_motion(f.ego_speed_mps, 0.0)
                r = p.process(f.image, f.t_s)
                by_n.setdefault(len(r.tracks), []).append(r.stages.get("track", float("nan")))
    return {n: {"n": len(v), "median_ms": float(np.median(v)), "p99_ms": float(np.percentile(v, 99))}
            for n, v in sorted(by_n.items()) if n <= max_n}


def main(argv: Optional[list[str]] = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--features", default="12,24,40", help="corners per box searched (cap = the same number)")
    p.add_argument("--json", action="store_true")
    a = p.parse_args(argv)
    if hasattr(os, "sched_setaffinity"):
        os.sched_setaffinity(0, {sorted(os.sched_getaffinity(0))[0]})
    report = {k: phd_cost(k, k) for k in (int(x) for x in a.features.split(","))}
    if a.json:
        print(json.dumps(report, indent=1))
        return 0
    print("| features per vehicle (search = cap) | N vehicles | frames | track median ms | p99 ms |")
    print("| ---: | ---: | ---: | ---: | ---: |")
    for k, costs in report.items():
        for n, c in costs.items():
            print(f"| {k} | {n} | {c['n']} | {c['median_ms']:.3f} | {c['p99_ms']:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
