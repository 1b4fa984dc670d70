"""Fuzzing `config check` against the service: every mutated configuration either fails the check with
exit 2 and one line of at most 200 characters naming the key (or, for text that is not YAML, the line), or
starts the service, which then runs 50 frames. None is accepted by the check and then refused by the service.

The CI set is CASES configurations with a fixed seed; the measurement in docs/RELIABILITY.md runs more:

    .venv/bin/python -m tests.test_config_service_fuzz --cases 10000 --seed 40
"""
from __future__ import annotations

import argparse
import contextlib
import io
import random
import re
import sys
import tempfile
import threading
import time
from pathlib import Path

import yaml

from app import cli
from app import config as configuration
from tests.test_config_fuzz import mutate

CASES = 200
SEED = 40
FRAMES = 50            # frames the service must process for a configuration the check accepted
SERVICE_TIMEOUT_S = 60.0
MAX_LINE = 200
# never mutated: the source stays the test's video (a camera absent here would only be waited for), and the
# stall that exists to test the watchdog is no configuration a car runs
FIXED = {"source.kind", "pipeline.debug_stall_after_s"}
_KEY = re.compile(r"(?<![\w./-])([A-Za-z_]\w*)\.([A-Za-z_]\w*)")


def values(spec: dict, tmp: Path) -> tuple[list, list]:
    """(likely valid, likely not) values for a key: its default and the edges of its range, and the mistakes
    people and tools make."""
    if spec["type"] in ("int", "float"):
        lo, hi = spec.get("min"), spec.get("max")
        good = [spec["default"]] + ([] if lo is None else
                                    [lo, hi, (lo + hi) / 2 if spec["type"] == "float" else (lo + hi) // 2])
        bad = ["12:30:00", "yes", ".nan", "1e999", "'3'", "[1, 2]", "{}", "~"] + ([] if lo is None else [lo - 1, hi + 1])
        return good + ["0x10"], bad
    if spec["type"] == "bool":
        return ["true", "false", "True"], ["yes", "no", "on", "1", "~"]
    if "choices" in spec:
        return [c or "''" for c in spec["choices"].split("|")], ["nope", "[shadow, shadow]", "[]"]
    good = ["''", str(tmp / "f.jsonl"), str(tmp / "out" / "f.log"), "relative.jsonl", "plain text"]
    bad = ["/nonexistent/dir/f.jsonl", '"/tmp/a\\0b.jsonl"', "/tmp/" + "A" * 300, "/tmp/" + "B" * 5000, str(tmp),
           str(tmp / "video.avi"), str(tmp / "existing.txt"), "/dev/null", "'" + "x" * 5000 + "'", "12:30:00", "off"]
    return good, bad


def base_config(tmp: Path, channel: str) -> dict:
    return {"camera": {"width": 320, "height": 240, "fx": 350.0, "fy": 350.0, "cx": 160.0, "cy": 120.0},
            "source": {"kind": "video", "path": str(tmp / "video.avi")},
            "can": {"interface": "virtual", "channel": channel},
            "service": {"status_file": str(tmp / "status.json")}}


def make_inputs(tmp: Path) -> None:
    import cv2
    import numpy as np

    w = cv2.VideoWriter(str(tmp / "video.avi"), cv2.VideoWriter_fourcc(*"MJPG"), 20.0, (320, 240))
    for i in range(FRAMES * 4):   # more than the service runs: it is stopped, not ended
        img = np.full((240, 320, 3), 60, np.uint8)
        cv2.rectangle(img, (40 + i % 200, 150), (90 + i % 200, 190), (20, 20, 20), -1)
        w.write(img)
    w.release()
    (tmp / "existing.txt").write_text("an input\n")


def case_text(rng: random.Random, tmp: Path, schema: dict, channel: str) -> str:
    cfg = base_config(tmp, channel)
    text = yaml.safe_dump(cfg, sort_keys=False)
    keys = [(s, k) for s in schema for k in schema[s] if f"{s}.{k}" not in FIXED]
    lines = []
    for sec, key in rng.sample(keys, rng.randint(1, 3)):
        good, bad = values(schema[sec][key], tmp)
        lines.append(f"{sec}:\n  {key}: {rng.choice(good if rng.random() < 0.6 else bad)}\n")
    # the mutated keys in sections of their own after the base (a section twice is its own error: kept rare)
    extra = "".join(lines)
    merged = yaml.safe_load(text)
    if rng.random() < 0.8:
        for block in lines:
            sec, rest = block.split(":\n", 1)
            if sec in merged:
                text = text.replace(f"{sec}:\n", f"{sec}:\n{rest}", 1)
            else:
                text += block
        return text
    if rng.random() < 0.5:
        return text + extra
    return mutate(rng, text.splitlines())


def check(path: Path) -> tuple[int, str]:
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        rc = cli.main(["config", "check", str(path), "--skip-absent-devices"])
    return rc, err.getvalue()


def run_service(path: Path) -> tuple[int, str]:
    """(frames processed, what went wrong or ""): the service (its start check, then its run) on this file,
    stopped once it processed FRAMES frames."""
    from app.config_check import problems
    from app.supervisor.service import Service

    cfg = configuration.load(path)
    found = problems(cfg, open_bus=False, open_source=False)   # the service's own start check
    if found:
        return 0, f"the service's start check refused it: {found[0]}"
    svc = Service(cfg)
    outcome: list = []

    def body():
        try:
            outcome.append(svc.run())
        except BaseException as exc:   # noqa: BLE001 - reported as the failure
            outcome.append(f"{type(exc).__name__}: {exc}")

    t = threading.Thread(target=body, daemon=True)
    t.start()
    # a file cut short leaves the default camera source: on this machine without one the service starts and
    # waits for it (source.wait_for_device), which is what it must do; it is given a second to fail instead
    camera = cfg["source"]["kind"] in ("v4l2", "firewire")
    end = time.monotonic() + (1.0 if camera else SERVICE_TIMEOUT_S)
    while (camera or svc.health.frames < FRAMES) and t.is_alive() and time.monotonic() < end:
        time.sleep(0.01)
    frames = FRAMES if camera and t.is_alive() else svc.health.frames
    svc.stop.set()
    t.join(30)
    if t.is_alive():
        return frames, "did not stop within 30 s"
    if outcome != [0]:
        return frames, f"exited {outcome}"
    return frames, "" if frames >= FRAMES else f"ran {frames} frames in {SERVICE_TIMEOUT_S:.0f} s"


def names_key_or_line(line: str, schema: dict) -> bool:
    for m in _KEY.finditer(line):
        if m.group(1) in schema and m.group(2) in schema[m.group(1)]:
            return True
    return bool(re.search(r"lines? \d+", line)) or any(f" {s}:" in line or f" {s}." in line for s in schema)


def fuzz(cases: int, seed: int, tmp: Path, progress=None) -> dict:
    import logging

    logging.disable(logging.CRITICAL)   # the service's journal lines: not what is measured
    make_inputs(tmp)
    rng = random.Random(seed)
    schema = configuration.schema()
    counts = {"refused": 0, "accepted": 0, "failures": []}
    for case in range(cases):
        path = tmp / f"case{case % 2}.yaml"
        path.write_text(case_text(rng, tmp, schema, f"fuzz-{seed}-{case}"), errors="surrogateescape")
        rc, err = check(path)
        lines = err.strip("\n").split("\n") if err.strip() else []
        if rc == 2:
            counts["refused"] += 1
            if len(lines) != 1 or len(lines[0]) > MAX_LINE or not names_key_or_line(lines[0], schema):
                counts["failures"].append((case, "check's error", err[:400], path.read_text(errors="replace")[:400]))
        elif rc == 0:
            counts["accepted"] += 1
            frames, why = run_service(path)
            if why:
                counts["failures"].append((case, why, "", path.read_text(errors="replace")[:400]))
        else:
            counts["failures"].append((case, f"check exit {rc}", err[:400], path.read_text(errors="replace")[:400]))
        for f in (tmp / "f.jsonl", tmp / "relative.jsonl", tmp / "out"):
            if f.is_file():
                f.unlink()
        if progress:
            progress(case, counts)
    logging.disable(logging.NOTSET)
    return counts


def test_fuzzed_configurations_fail_the_check_in_one_line_or_run_the_service(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    counts = fuzz(CASES, SEED, tmp_path)
    assert not counts["failures"], counts["failures"][:3]
    # both outcomes are exercised
    assert counts["accepted"] >= CASES // 10 and counts["refused"] >= CASES // 4, counts


def main(argv=None) -> int:
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    a.add_argument("--cases", type=int, default=10_000)
    a.add_argument("--seed", type=int, default=SEED)
    args = a.parse_args(argv)
    t0 = time.monotonic()

    shown = [0]

    def progress(case, counts):
        for failure in counts["failures"][shown[0]:]:   # each failure as it comes: a long run may be cut short
            print(f"FAILURE {failure}", file=sys.stderr, flush=True)
        shown[0] = len(counts["failures"])
        if (case + 1) % 250 == 0:
            print(f"{case + 1} cases, {counts['accepted']} accepted and run, {counts['refused']} refused, "
                  f"{len(counts['failures'])} failures, {time.monotonic() - t0:.0f} s", file=sys.stderr, flush=True)

    with tempfile.TemporaryDirectory(prefix="headway-fuzz-") as tmp:
        import os

        os.chdir(tmp)
        counts = fuzz(args.cases, args.seed, Path(tmp), progress)
    print(f"{args.cases} configurations, seed {args.seed}: {counts['accepted']} accepted by config check and "
          f"each ran {FRAMES} frames in the service, {counts['refused']} refused (exit 2, one line <= {MAX_LINE} "
          f"characters naming the key or line), {len(counts['failures'])} failures; {time.monotonic() - t0:.0f} s")
    for f in counts["failures"][:20]:
        print(f)
    return 1 if counts["failures"] else 0


if __name__ == "__main__":
    sys.exit(main())
