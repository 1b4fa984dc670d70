"""Cost of the phd preset's tracker (features, LK, GM-PHD, UKF: the "track" stage, the detector's stages
excluded) per 640x480 frame, against the number of vehicles it holds and the features per vehicle.

The frames are the synthetic scenarios with the most traffic, and ten cars side by side (8 vehicles held at
once); each frame's time is a sample for the number of vehicles (tracks, confirmed or not) the tracker then
held: wall time ("track") and the thread's CPU time ("track_cpu"), which a loaded machine does not inflate.
The features per vehicle are set by phd_features.max_per_vehicle (corners looked for per box) and
gmphd.max_components (the cap). Pinned to one core, as `headway bench`.

    python -m app.bench.phd [--features 12,24,40] [--json]
"""
from __future__ import annotations

import argparse
import json
import os
import tempfile
from pathlib import Path
from typing import Optional

import numpy as np

from app.core import Pipeline
from app.sim import load_scenario, render
from app.sim.frames import scenario_camera

SCENARIOS = ("dense_traffic", "adjacent_passing", "steady_following", "lane_change", "cut_in", "many_vehicles")

# No shipped scenario keeps 8 vehicles in the tracker at once (dense_traffic: 7 at most): ten cars at the
# ego's speed on a five-lane road, two per lane, 12-50 m ahead, all in view for 4 s.
MANY_VEHICLES = """
name: many_vehicles
description: Ten cars at the ego's speed on five lanes, 12-50 m ahead (the phd tracker's cost at 8+ vehicles).
duration_s: 4.0
fps: 30
seed: 77
road: {lanes: 5}
ego: {speed_kmh: 60}
vehicles:
  - {id: 1, kind: car, lane: -2, z_m: 16, speed_kmh: 60}
  - {id: 2, kind: car, lane: -2, z_m: 40, speed_kmh: 60}
  - {id: 3, kind: car, lane: -1, z_m: 12, speed_kmh: 60}
  - {id: 4, kind: van, lane: -1, z_m: 32, speed_kmh: 60}
  - {id: 5, kind: car, lane: 0, z_m: 20, speed_kmh: 60}
  - {id: 6, kind: car, lane: 0, z_m: 50, speed_kmh: 60}
  - {id: 7, kind: car, lane: 1, z_m: 14, speed_kmh: 60}
  - {id: 8, kind: van, lane: 1, z_m: 34, speed_kmh: 60}
  - {id: 9, kind: car, lane: 2, z_m: 18, speed_kmh: 60}
  - {id: 10, kind: car, lane: 2, z_m: 44, speed_kmh: 60}
"""


def _scenario(name: str):
    if name != "many_vehicles":
        return load_scenario(name)
    with tempfile.TemporaryDirectory() as d:
        path = Path(d) / "many_vehicles.yaml"
        path.write_text(MANY_VEHICLES)
        return load_scenario(path)


def phd_cost(features: int, cap: int, scenarios=SCENARIOS, max_n: int = 9) -> dict:
    """{N: {"n": frames, "median_ms", "p99_ms" (wall), "cpu_median_ms", "cpu_p99_ms" (the thread's CPU time)}}."""
    by_n: dict[int, list[tuple[float, float]]] = {}
    for name in scenarios:
        sc = _scenario(name)
        cfg = {"pipeline": {"preset": "thesis", "tracker": "phd"}, "camera": scenario_camera(sc).to_dict(),
               "phd_features": {"max_per_vehicle": features}, "gmphd": {"max_components": cap}}
        with Pipeline(cfg) as p:
            for f in render(sc):
                p.set_ego_motion(f.ego_speed_mps, 0.0)
                r = p.process(f.image, f.t_s)
                by_n.setdefault(len(r.tracks), []).append(
                    (r.stages.get("track", float("nan")), r.stages.get("track_cpu", float("nan"))))
    out = {}
    for n, v in sorted(by_n.items()):
        if n > max_n:
            continue
        wall, cpu = np.array(v).T
        out[n] = {"n": len(v), "median_ms": float(np.median(wall)), "p99_ms": float(np.percentile(wall, 99)),
                  "cpu_median_ms": float(np.median(cpu)), "cpu_p99_ms": float(np.percentile(cpu, 99))}
    return out


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
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"load average {load:.1f} on {os.cpu_count()} cores")
    print("| features per vehicle (search = cap) | N vehicles | frames | CPU median ms | CPU p99 ms | "
          "wall median ms | wall p99 ms |")
    print("| ---: | ---: | ---: | ---: | ---: | ---: | ---: |")
    for k, costs in report.items():
        for n, c in costs.items():
            print(f"| {k} | {n} | {c['n']} | {c['cpu_median_ms']:.3f} | {c['cpu_p99_ms']:.3f} | {c['median_ms']:.3f} | "
                  f"{c['p99_ms']:.3f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
