"""`headway bench`: per-stage median and p99 milliseconds per frame, measured on rendered frames.

Frames are rendered first (not timed), then fed through ``process()`` - the per-frame code of the
real-time loop - twice: as fast as possible (the work per frame), and at the camera's frame rate (``--fps``,
the configuration's ``source.fps`` unless given), as a camera delivers them: the latency a frame sees from its
arrival to its result, with the detection on its worker thread using the time between frames (phd.detect_lag).
Frames whose tracker took a full detection and tracking-only frames are reported apart, because the cost
depends on which kind a frame is.

`headway bench --images DIR`: what `headway detect` spends on each image, part by part (run_image_bench).
"""
from __future__ import annotations

import contextlib
import json
import os
import platform
import threading
import time
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from app import config as configuration
from app.bench import particles
from app.can import CanSession
from app.core import EndOfStream, Pipeline, monotonic_s
from app.detect_images import (detector_config, image_entry, image_pipeline, operating_point, read_usable,
                                scaled_camera_note)
from app.recording import natural_key
from app.sim import load_scenario, render
from app.supervisor.stack import Stack


def _stats(values: list[float]) -> dict:
    a = np.asarray(values, dtype=float)
    return {"n": int(a.size), "median_ms": float(np.median(a)), "p99_ms": float(np.percentile(a, 99)),
            "mean_ms": float(a.mean())}


def _feed(cfg: dict, frames: list, repeats: int, fps: Optional[float]) -> tuple[dict, list[float]]:
    """Every frame through a new pipeline per repeat: back to back (fps None), or each at its slot of a camera
    running at fps (a frame late for its slot is fed at once). Returns the stage times by kind of frame, and for
    each frame whose tracker took a full detection the detection's age then (ms from the arrival of the frame it
    was found on to the result that took it)."""
    from app.core import monotonic_s

    per_kind: dict[str, dict[str, list[float]]] = {"all": {}, "full_detection": {}, "tracking_only": {}}
    ages_ms: list[float] = []
    for _ in range(repeats):
        arrived: dict[int, float] = {}
        with Pipeline(configuration.core_sections(cfg)) as p:
            t_start = monotonic_s()
            for i, (img, t) in enumerate(frames):
                if fps:
                    time.sleep(max(0.0, t_start + i / fps - monotonic_s()))
                arrived[i] = monotonic_s()
                r = p.process(img, t)
                kind = "full_detection" if r.full_detection else "tracking_only"
                for bucket in ("all", kind):
                    for name, ms in list(r.stages.items()) + [("total", r.total_ms)]:
                        per_kind[bucket].setdefault(name, []).append(ms)
                if r.full_detection and r.detections_frame in arrived:
                    ages_ms.append(1000.0 * (r.t_done_s - arrived[r.detections_frame]))
    return per_kind, ages_ms


def run_bench(scenario: str = "dense_traffic", preset: Optional[str] = None, width: int = 640, height: int = 480,
              repeats: int = 3, config_path: Optional[str] = None, fps: Optional[float] = None) -> dict:
    """The as-fast-as-possible figures ("stages"), and with fps > 0 (None: the configuration's source.fps) the
    figures at that camera rate ("at_camera_rate": stages, the detection's age at fusion and how many detections
    a second the tracker took)."""
    sc = load_scenario(scenario)
    frames = [(f.image, f.t_s) for f in render(sc, camera_overrides={"width": width, "height": height,
                                                                       "cx": width / 2, "cy": height / 2})]
    cfg = configuration.load(config_path, {"pipeline": {"preset": preset}} if preset else None)
    cfg["camera"].update(width=width, height=height, cx=width / 2, cy=height / 2)
    if fps is None:
        fps = float(cfg["source"]["fps"])
    if fps < 0:
        raise BenchError(f"--fps {fps}: a camera rate is positive (frames/s), or 0 for back to back only")
    report = {
        "scenario": scenario, "preset": cfg["pipeline"]["preset"], "frame_size": f"{width}x{height}",
        "frames": len(frames) * repeats, "machine": f"{platform.processor() or platform.machine()}, "
                                                     f"{os.cpu_count()} cores",
    }
    per_kind, _ = _feed(cfg, frames, repeats, None)
    report["stages"] = {bucket: {name: _stats(v) for name, v in stages.items()} for bucket, stages in per_kind.items()
                        if stages}
    if fps:
        paced, ages_ms = _feed(cfg, frames, repeats, fps)
        n_full = len(paced["full_detection"].get("total", []))
        report["at_camera_rate"] = {
            "fps": fps,
            "stages": {bucket: {name: _stats(v) for name, v in stages.items()} for bucket, stages in paced.items()
                       if stages},
            "detection_age": _stats(ages_ms) if ages_ms else None,
            "detections_per_s": n_full / (len(frames) * repeats / fps),
        }
    return report


IMAGE_SUFFIXES = (".jpg", ".jpeg", ".png", ".bmp")


class BenchError(ValueError):
    pass


def image_paths(sources: Sequence[str], limit: Optional[int] = None) -> list[str]:
    """Image files: each source a file, or a folder whose images (by suffix) are taken in name order; the first
    `limit` of all."""
    paths: list[str] = []
    for src in sources:
        p = Path(src)
        if p.is_dir():
            found = sorted((str(f) for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES),
                           key=lambda f: natural_key(Path(f).name))
            if not found:
                raise BenchError(f"--images {src}: the folder holds no image ({', '.join(IMAGE_SUFFIXES)}); "
                                 f"give a folder of images or image files")
            paths += found
        elif p.is_file():
            paths.append(str(p))
        else:
            raise BenchError(f"--images {src}: no such file or folder")
    return paths[:limit] if limit else paths


def run_image_bench(sources: Sequence[str], preset: Optional[str] = None, config_path: Optional[str] = None,
                    limit: Optional[int] = 100, repeats: int = 1) -> dict:
    """`headway detect`'s work on each image, timed part by part: "read" (the file read, checked whole, decoded
    and its size checked: detect_images.read_usable), the core's stages of the
    preset's detection stage (lanes; for the cascade, "cascade" = the scan, grouping and suppression and
    "verifier" = its network's looks; "verify" = the shadow hypotheses and their vertical edges), "core" (the
    core's whole stage) and "total" (read, the stage and the output entry: what one more image costs
    `headway detect`, its start-up not counted). Each image size's pipeline detects its first image once untimed
    first (loading the cascade and the verifier)."""
    paths = image_paths(sources, limit)
    base = detector_config(config_path, preset)
    min_score = operating_point(base)
    pipes: dict[tuple[int, int], Pipeline] = {}
    times: dict[str, list[float]] = {}
    skipped: list[str] = []
    notes: list[str] = []
    try:
        for rep in range(repeats):
            for path in paths:
                t0 = time.perf_counter()
                gray, why = read_usable(path)
                t_read = time.perf_counter()
                if why:
                    if rep == 0:
                        skipped.append(f"{path}: {why}")
                    continue
                size = (gray.shape[1], gray.shape[0])
                if size not in pipes:  # a new size: its pipeline, warmed up (the models loaded) untimed
                    pipes[size] = image_pipeline(base, *size)
                    note = scaled_camera_note(base, size, config_path is not None)
                    if note:
                        notes.append(note)
                    pipes[size].detect(gray)
                    t0 = time.perf_counter()
                    gray, _ = read_usable(path)
                    t_read = time.perf_counter()
                r = pipes[size].detect(gray)
                image_entry(path, r.rows(), min_score)
                t1 = time.perf_counter()
                for name, ms in [("read", 1000.0 * (t_read - t0)), *r.stages.items(), ("core", r.total_ms),
                                 ("total", 1000.0 * (t1 - t0))]:
                    times.setdefault(name, []).append(ms)
    finally:
        for p in pipes.values():
            p.close()
    if "total" not in times:
        raise BenchError("--images: none of the images can be used: " + "; ".join(skipped[:5]))
    return {"preset": base["pipeline"]["preset"], "images": len(times["total"]), "skipped": skipped, "notes": notes,
            "frame_sizes": sorted(f"{w}x{h}" for w, h in pipes),
            "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} cores",
            "stages": {"image": {name: _stats(v) for name, v in times.items()}}}


def format_image_table(report: dict) -> str:
    lines = [f"headway bench --images: `headway detect --preset {report['preset']}`, per image, "
             f"{report['images']} images of {', '.join(report['frame_sizes'])} ({report['machine']})", "",
             "| part | n | median ms | p99 ms |", "| --- | ---: | ---: | ---: |"]
    for name, s in report["stages"]["image"].items():
        lines.append(f"| {name} | {s['n']} | {s['median_ms']:.3f} | {s['p99_ms']:.3f} |")
    lines += [f"skipped {line}" for line in report["skipped"]]
    lines += [f"note: {line}" for line in report.get("notes", [])]
    return "\n".join(lines)


def run_latency_bench(scenario: str = "dense_traffic", seconds: float = 10.0, config_path: Optional[str] = None,
                      preset: Optional[str] = None) -> dict:
    """Capture-to-CAN latency through the real-time loop: frames pushed at their frame rate (stamped with
    the monotonic clock at capture, as a camera's are), results popped and handed to the supervisor's
    stack, which encodes and sends the CAN frames on a python-can `virtual` bus. Measured per frame:
    the capture stamp to the moment the CAN frames were handed to the bus, and the supervisor's own CPU
    time per frame (vehicle inputs, FCW, CAN encoding)."""
    sc = load_scenario(scenario)
    images = [f.image for f in render(sc)]
    cfg = configuration.load(config_path, {"pipeline": {"preset": preset}} if preset else None)
    cfg["can"].update(interface="virtual", channel="headway-bench")
    latencies, cpu_ms = [], []
    with Pipeline(configuration.core_sections(cfg)) as pipe, CanSession.for_live(cfg) as can_session:
        sup = Stack(cfg, can_session)
        pipe.start({"kind": "push"})
        stop = threading.Event()

        def camera():
            period = 1.0 / sc.fps
            n = int(seconds * sc.fps)
            t_next = time.monotonic()
            for i in range(n):
                if stop.is_set():
                    return
                pipe.push(images[i % len(images)], monotonic_s())
                t_next += period
                time.sleep(max(0.0, t_next - time.monotonic()))
            pipe.push_end()

        cam = threading.Thread(target=camera, daemon=True)
        cam.start()
        while True:
            try:
                r = pipe.pop(timeout_s=2.0)
            except EndOfStream:
                break
            if r is None:
                break
            c0 = time.process_time()
            sup.step(r, time.time(), pipe)
            cpu_ms.append((time.process_time() - c0) * 1000.0)
            latencies.append((monotonic_s() - r.t_s) * 1000.0)
        stop.set()
        cam.join()
        dropped = pipe.health()["results_dropped"]
    return {"scenario": scenario, "preset": cfg["pipeline"]["preset"], "fps": sc.fps, "frames": len(latencies),
            "dropped": dropped,
            "capture_to_can": _stats(latencies), "supervisor_cpu_per_frame": _stats(cpu_ms)}


def format_latency(report: dict) -> str:
    c, s = report["capture_to_can"], report["supervisor_cpu_per_frame"]
    return (f"capture-to-CAN latency, preset {report['preset']}, over {report['frames']} frames ({report['scenario']}, "
            f"{report['fps']:g} fps pushed through the real-time loop, CAN on a virtual bus, {report['dropped']} "
            f"dropped):\n"
            f"| measure | median ms | p99 ms |\n| --- | ---: | ---: |\n"
            f"| capture to CAN frames handed to the bus | {c['median_ms']:.2f} | {c['p99_ms']:.2f} |\n"
            f"| supervisor CPU per frame (inputs, FCW, CAN encoding) | {s['median_ms']:.2f} | {s['p99_ms']:.2f} |")


def _stage_rows(stages: dict) -> list[str]:
    lines = ["| frames | stage | n | median ms | p99 ms |", "| --- | --- | ---: | ---: | ---: |"]
    for bucket, by_name in stages.items():
        for name, s in by_name.items():
            lines.append(f"| {bucket} | {name} | {s['n']} | {s['median_ms']:.3f} | {s['p99_ms']:.3f} |")
    return lines


def format_table(report: dict) -> str:
    lines = [f"headway bench: preset {report['preset']}, {report['frame_size']}, scenario {report['scenario']}, "
             f"{report['frames']} frames ({report['machine']})", "", "Back to back (the work per frame):", "",
             *_stage_rows(report["stages"])]
    paced = report.get("at_camera_rate")
    if paced:
        lines += ["", f"At the camera's rate, {paced['fps']:g} fps (a frame's latency from its arrival to its result; "
                      "bg_*: the detection on its worker thread, not in the frame's latency):", "",
                  *_stage_rows(paced["stages"]), ""]
        age = paced["detection_age"]
        lines.append(f"full detections taken: {paced['detections_per_s']:.2f} per s; their age when taken (arrival "
                     f"of their frame to the result that took them): " +
                     (f"median {age['median_ms']:.1f} ms, p99 {age['p99_ms']:.1f} ms" if age else "none taken"))
    return "\n".join(lines)


@contextlib.contextmanager
def pinned_to_one_core():
    """This process (and the threads OpenCV starts in it) on one core, restored after: the budget is per core,
    and OpenCV would otherwise spread some calls over the others. Yields the core, None where affinity is not
    supported."""
    if not hasattr(os, "sched_setaffinity"):
        yield None
        return
    before = os.sched_getaffinity(0)
    core = max(before)
    os.sched_setaffinity(0, {core})
    try:
        yield core
    finally:
        os.sched_setaffinity(0, before)


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("bench", help="per-stage median and p99 ms per frame")
    s.add_argument("--scenario", default="dense_traffic", help="scenario whose frames are timed")
    s.add_argument("--preset", help="pipeline preset (default: the configuration's); with --images, the preset whose "
                                    "detection stage is timed, as `headway detect --preset`")
    s.add_argument("--width", type=int, default=640)
    s.add_argument("--height", type=int, default=480)
    s.add_argument("--repeats", type=int, default=3, help="passes over the scenario (with --images: over the images)")
    s.add_argument("--fps", type=float, default=None,
                   help="also feed the frames at this camera rate and report each frame's latency and the detection's "
                        "age (default: the configuration's source.fps; 0: back to back only)")
    s.add_argument("--config", help="configuration YAML")
    s.add_argument("--json", action="store_true", help="print JSON instead of a table")
    s.add_argument("--latency", action="store_true",
                   help="measure capture-to-CAN latency and the supervisor's CPU per frame through the live loop")
    s.add_argument("--seconds", type=float, default=10.0, help="length of the --latency run")
    s.add_argument("--images", nargs="+", metavar="PATH",
                   help="time `headway detect` instead, per image and part (reading and decoding, lanes, the cascade's "
                        "scan, its verifier, the shadows), on these image files or folders of images")
    s.add_argument("--limit", type=int, default=100, help="with --images: the first this many images (0 = all)")
    s.set_defaults(run=run)


def run(args) -> int:
    if args.latency:
        report = run_latency_bench(args.scenario, args.seconds, args.config, args.preset)
        print(json.dumps(report, indent=2) if args.json else format_latency(report))
        return 0
    if args.images:
        with pinned_to_one_core() as core:
            report = run_image_bench(args.images, args.preset, args.config, args.limit or None, args.repeats)
        report["machine"] += f", pinned to core {core}" if core is not None else ", not pinned to a core"
        print(json.dumps(report, indent=2) if args.json else format_image_table(report))
        return 0
    with pinned_to_one_core() as core:
        report = run_bench(args.scenario, args.preset, args.width, args.height, args.repeats, args.config, args.fps)
        if report["preset"] == "parallax" and (args.width, args.height) == (640, 480):
            # the joint particle filter's cost against the vehicles it holds
            report["particles_by_vehicles"] = particles.particle_cost()
    report["machine"] += f", pinned to core {core}" if core is not None else ", not pinned to a core"
    print(json.dumps(report, indent=2) if args.json else format_table(report))
    if "particles_by_vehicles" in report and not args.json:
        print("\nparallax: joint particle filter against N (synthetic patches, app/bench/particles.py)\n")
        print(particles.format_table(report["particles_by_vehicles"]))
    return 0
