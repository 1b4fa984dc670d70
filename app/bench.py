"""`headway bench`: per-stage median and p99 milliseconds per frame, measured on rendered frames.

Frames are rendered first (not timed), then fed through ``process()`` - the per-frame code of the
real-time loop. Frames with a full detection and tracking-only frames are reported apart, because
the thesis pipeline's cost depends on which kind a frame is.
"""
from __future__ import annotations

import json
import os
import platform
from typing import Optional

import numpy as np

from app import config as configuration
from app.core import Pipeline


def _stats(values: list[float]) -> dict:
    a = np.asarray(values, dtype=float)
    return {"n": int(a.size), "median_ms": float(np.median(a)), "p99_ms": float(np.percentile(a, 99)),
            "mean_ms": float(a.mean())}


def run_bench(scenario: str = "dense_traffic", preset: Optional[str] = None, width: int = 640, height: int = 480,
              repeats: int = 3, config_path: Optional[str] = None) -> dict:
    from app.sim import load_scenario, render

    sc = load_scenario(scenario)
    frames = [(f.image, f.t_s) for f in render(sc, camera_overrides={"width": width, "height": height,
                                                                       "cx": width / 2, "cy": height / 2})]
    cfg = configuration.load(config_path)
    cfg["camera"].update(width=width, height=height, cx=width / 2, cy=height / 2)
    if preset:
        cfg["pipeline"]["preset"] = preset
    per_kind: dict[str, dict[str, list[float]]] = {"all": {}, "full_detection": {}, "tracking_only": {}}
    for _ in range(repeats):
        with Pipeline(configuration.core_sections(cfg)) as p:
            for img, t in frames:
                r = p.process(img, t)
                kind = "full_detection" if r.full_detection else "tracking_only"
                for bucket in ("all", kind):
                    for name, ms in list(r.stages.items()) + [("total", r.total_ms)]:
                        per_kind[bucket].setdefault(name, []).append(ms)
    return {
        "scenario": scenario, "preset": cfg["pipeline"]["preset"], "frame_size": f"{width}x{height}",
        "frames": len(frames) * repeats, "machine": f"{platform.processor() or platform.machine()}, "
                                                     f"{os.cpu_count()} cores, one core used by the pipeline",
        "stages": {bucket: {name: _stats(v) for name, v in stages.items()} for bucket, stages in per_kind.items()
                   if stages},
    }


def format_table(report: dict) -> str:
    lines = [f"headway bench: preset {report['preset']}, {report['frame_size']}, scenario {report['scenario']}, "
             f"{report['frames']} frames ({report['machine']})", "",
             "| frames | stage | n | median ms | p99 ms |", "| --- | --- | ---: | ---: | ---: |"]
    for bucket, stages in report["stages"].items():
        for name, s in stages.items():
            lines.append(f"| {bucket} | {name} | {s['n']} | {s['median_ms']:.3f} | {s['p99_ms']:.3f} |")
    return "\n".join(lines)


def main(args) -> int:
    report = run_bench(args.scenario, args.preset, args.width, args.height, args.repeats, args.config)
    print(json.dumps(report, indent=2) if args.json else format_table(report))
    return 0
