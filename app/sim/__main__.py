"""Developer entry point: ``python -m app.sim list | render NAME OUT [--video] | time NAME``.

The product CLI (``headway``) wraps the same public functions; this one exists so the
simulator can be used and timed on its own.
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time

import cv2
import numpy as np

from . import ScenarioError, list_scenarios, load_scenario, render, write_scenario
from .scenario import VEHICLE_LOOKS


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m app.sim", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="names of the shipped scenarios")
    p_render = sub.add_parser("render", help="write frames (or a video), truth.jsonl and the CAN log")
    p_render.add_argument("scenario", help="shipped name or path to a YAML file")
    p_render.add_argument("out_dir")
    p_render.add_argument("--video", action="store_true", help="write video.mp4 instead of PNG frames")
    p_time = sub.add_parser("time", help="render time per frame (image + truth, no file output)")
    p_time.add_argument("scenario", nargs="*", help="default: every shipped scenario")
    p_time.add_argument("--threads", type=int, default=None, help="OpenCV threads (default: OpenCV's choice)")
    for p in (p_render, p_time):
        p.add_argument("--vehicle-look", choices=VEHICLE_LOOKS, default=None,
                       help="draw the vehicles this way instead of the scenario's own vehicle_look (docs/sim.md)")
    args = parser.parse_args(argv)

    def scenario(name):
        loaded = load_scenario(name)
        return loaded if args.vehicle_look is None else dataclasses.replace(loaded, vehicle_look=args.vehicle_look)

    try:
        if args.command == "list":
            print("\n".join(list_scenarios()))
        elif args.command == "render":
            summary = write_scenario(scenario(args.scenario), args.out_dir, video=args.video,
                                     progress=lambda i, n: print(f"\r{i}/{n}", end="", file=sys.stderr))
            print(file=sys.stderr)
            print(f"{summary['n_frames']} frames -> {summary['out_dir']}")
        else:
            if args.threads is not None:
                cv2.setNumThreads(args.threads)
            for name in args.scenario or list_scenarios():
                loaded = scenario(name)
                # Per frame: wall time and this process's CPU time; medians ignore the frames where a
                # busy machine preempted us (cache misses caused by neighbours still count).
                wall_ms, cpu_ms = [], []
                wall, cpu = time.perf_counter(), time.process_time()
                for _ in render(loaded):
                    wall_ms.append(1e3 * (time.perf_counter() - wall))
                    cpu_ms.append(1e3 * (time.process_time() - cpu))
                    wall, cpu = time.perf_counter(), time.process_time()
                print(f"{name:24s} {len(cpu_ms):4d} frames  median per frame: {np.median(wall_ms):6.2f} ms wall, "
                      f"{np.median(cpu_ms):6.2f} ms CPU")
    except ScenarioError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
