"""A soak run of the service on a real clip: `python -m app.bench.soak CLIP --minutes 15 --out soak.json`.

The service (`headway service`, a subprocess, exactly as systemd starts it) reads the clip's frames
through its FIFO source at the clip's own frame rate, looping, for the given time, with CAN on the
virtual bus and its output log on. Every ``--every-s`` the soak samples the service's resident memory
(VmRSS from /proc) and the processing latency and state from its status file. At the end it stops the
service with SIGTERM and checks that the CAN output log parses whole. The figures go to docs/RELIABILITY.md.
"""
from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import can

from app.output_files import write_whole
from app.recording import open_recording

REPO = Path(__file__).resolve().parents[2]  # the checkout: app/bench/soak.py


def rss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    return 0


def _feed(fifo: Path, frames: list[bytes], fps: float, stop: threading.Event, fed: list) -> None:
    """Writes the frames into the FIFO at ``fps``, looping; ``fed[0]``: frames written whole so far, and
    ``fed[1]``: how many were written later than their slot by more than a frame period (the service did not
    keep up with the camera rate)."""
    while not fifo.exists() and not stop.is_set():
        time.sleep(0.01)
    fd = os.open(fifo, os.O_WRONLY)
    period, next_t, i = 1.0 / fps, time.monotonic(), 0
    try:
        while not stop.is_set():
            try:
                os.write(fd, frames[i % len(frames)])
            except BrokenPipeError:
                return
            i += 1
            fed[0] = i
            if time.monotonic() - next_t > period:
                fed[1] += 1
            next_t += period
            time.sleep(max(0.0, next_t - time.monotonic()))
    finally:
        os.close(fd)


def soak(clip: str, minutes: float, every_s: float, workdir: Path, fps: float | None = None,
         sections: dict | None = None) -> dict:
    """`sections`: further configuration sections ({section: {key: value}}), e.g. {"phd": {"detect_lag": 0}}."""
    rec = open_recording(clip)
    fps = fps or rec.fps
    frames = [g.tobytes() for g in rec.read_all()]
    w, h = rec.size
    cfg = workdir / "config.yaml"
    cfg.write_text(f"camera: {{width: {w}, height: {h}, fx: {0.9 * w:.1f}, fy: {0.9 * w:.1f}, cx: {w / 2}, "
                   f"cy: {h / 2}}}\n"
                   f"source: {{kind: fifo, path: {workdir / 'frames.fifo'}}}\n"
                   f"can: {{interface: virtual, channel: soak-{os.getpid()}, output_log: {workdir / 'out.log'}}}\n"
                   f"service: {{status_file: {workdir / 'status.json'}}}\n" +
                   "".join(f"{name}: {json.dumps(values)}\n" for name, values in (sections or {}).items()))
    p = subprocess.Popen([sys.executable, "-m", "app.cli", "service", "--config", str(cfg)], cwd=REPO,
                         stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    stop = threading.Event()
    fed = [0, 0]
    feeder = threading.Thread(target=_feed, args=(workdir / "frames.fifo", frames, fps, stop, fed), daemon=True)
    feeder.start()
    samples = []
    t_start = time.monotonic()
    try:
        while time.monotonic() - t_start < minutes * 60:
            time.sleep(every_s)
            if p.poll() is not None:
                break
            try:
                st = json.loads((workdir / "status.json").read_text())
            except (OSError, ValueError):
                st = {}
            samples.append({"t_s": round(time.monotonic() - t_start, 1), "rss_kb": rss_kb(p.pid),
                            "state": st.get("state"), "fps": st.get("fps"),
                            "latency_median_ms": st.get("latency_median_ms"),
                            "latency_p99_ms": st.get("latency_p99_ms")})
    finally:
        stop.set()          # the last frames are processed before the stop: every frame fed is accounted for
        feeder.join(timeout=5)
        time.sleep(2.0)
        p.send_signal(signal.SIGTERM)
        rc = p.wait(timeout=30)
        err = p.stderr.read()
    if not (workdir / "out.log").exists():
        last = err.strip().splitlines()[-1:] or ["nothing on stderr"]
        raise RuntimeError(f"the service ended before it sent a CAN frame (exit {rc}): {last[0]}")
    try:
        final = json.loads((workdir / "status.json").read_text())
    except (OSError, ValueError):
        final = {}
    lines = (workdir / "out.log").read_text().splitlines()
    parsed = sum(1 for _ in can.LogReader(str(workdir / "out.log")))
    after = [s for s in samples if s["t_s"] >= 60.0] or samples  # after a minute of warm-up
    med = [s["latency_median_ms"] for s in samples if s["latency_median_ms"] is not None]
    p99 = [s["latency_p99_ms"] for s in samples if s["latency_p99_ms"] is not None]
    return {"clip": clip, "sections": sections or {}, "frames_in_clip": len(frames), "size": f"{w}x{h}", "fps": fps,
            "minutes": minutes,
            "frames_fed": fed[0], "frames_fed_late": fed[1], "frames_captured": final.get("frames_captured"),
            "frames_processed": final.get("frames"), "queue_drops": final.get("queue_drops"),
            "state_after_stop": final.get("state"),
            "exit_code": rc, "traceback": "Traceback" in err,
            "rss_kb_at_1min": after[0]["rss_kb"], "rss_kb_end": samples[-1]["rss_kb"],
            "rss_kb_max": max(s["rss_kb"] for s in samples),
            "latency_median_ms_median": statistics.median(med) if med else None,
            "latency_p99_ms_max": max(p99) if p99 else None,
            "states": sorted({str(s["state"]) for s in samples}),
            "can_log_lines": len(lines), "can_log_parsed": parsed, "samples": samples}


def main(argv=None) -> int:
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    a.add_argument("clip")
    a.add_argument("--minutes", type=float, default=15.0)
    a.add_argument("--every-s", type=float, default=10.0)
    a.add_argument("--fps", type=float, help="frames/s written into the FIFO (default: the clip's own)")
    a.add_argument("--out", default="soak.json")
    a.add_argument("--sections", type=json.loads, default=None,
                   help='further configuration sections as JSON, e.g. \'{"phd": {"detect_lag": 0}}\'')
    args = a.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="headway-soak-") as tmp:
        rep = soak(args.clip, args.minutes, args.every_s, Path(tmp), args.fps, args.sections)
    write_whole(args.out, json.dumps(rep, indent=1))
    print(json.dumps({k: v for k, v in rep.items() if k != "samples"}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
