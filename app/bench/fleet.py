"""The fleet's benchmark: drives per minute with 1 and 2 workers, and the overhead per drive against
`headway replay` alone (docs/PERFORMANCE.md, "Fleet replay").

    .venv/bin/python -m app.bench.fleet [--scenarios a,b,...] [--data ../shared/data]

Drives: shipped scenarios (rendered as they replay) and, when ../shared/data has them, TME tme08 and
Udacity's test video. Each drive is first replayed alone, one after the other: in this process
(`app.replay.replay`, what a worker runs) and as `headway replay` commands (a new process each, as a
user would run them). Then the same drives as a fleet with 1 and with 2 workers, fresh output each time
(cluster start included in the wall time).
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from app.fleet.run import run_fleet
from app.replay import replay

DEFAULT_SCENARIOS = "steady_following,cut_in,stopped_lead_72kmh,adjacent_passing,empty_road,lane_change"


def _drives(scenarios: list[str], data: Path) -> list[dict]:
    entries = [{"source": s} for s in scenarios]
    if (data / "tme" / "tme08").exists():
        entries.append({"source": str((data / "tme" / "tme08").resolve()), "fps": 20})
    if (data / "udacity" / "test_video.mp4").exists():
        entries.append({"source": str((data / "udacity" / "test_video.mp4").resolve())})
    return entries


def run(scenarios: list[str], data: Path, tmp: Path) -> dict:
    entries = _drives(scenarios, data)
    manifest = tmp / "bench.yaml"
    manifest.write_text(yaml.safe_dump({"drives": entries}))
    alone, cli = {}, {}
    for e in entries:
        t0 = time.perf_counter()
        s = replay(e["source"], fps=e.get("fps"), tracks_path=str(tmp / "t.jsonl"), can_out=str(tmp / "c.log"),
                   progress=False)
        alone[e["source"]] = (time.perf_counter() - t0, s.frames)
        cmd = [str(Path(sys.executable).parent / "headway"), "replay", e["source"], "--tracks", str(tmp / "t.jsonl"),
               "--can-out", str(tmp / "c.log")] + (["--fps", str(e["fps"])] if e.get("fps") else [])
        t0 = time.perf_counter()
        subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        cli[e["source"]] = time.perf_counter() - t0
    n = len(entries)
    out = {"drives": n, "frames": sum(f for _, f in alone.values()),
           "replay_alone_s": round(sum(t for t, _ in alone.values()), 2),
           "headway_replay_commands_s": round(sum(cli.values()), 2), "fleet": {}}
    for workers in (1, 2):
        t0 = time.perf_counter()
        rep = run_fleet(str(manifest), str(tmp / f"out{workers}"), workers=workers, progress=False)
        wall = time.perf_counter() - t0
        assert not rep["failed"], rep["failed"]
        out["fleet"][workers] = {"wall_s": round(wall, 2), "drives_per_minute": round(60 * n / wall, 1),
                                 "drive_task_s": round(rep["totals"]["seconds"], 2)}
    f1 = out["fleet"][1]
    out["overhead_per_drive_s"] = {
        "fleet_1_worker_vs_replay_in_process": round((f1["wall_s"] - out["replay_alone_s"]) / n, 3),
        "fleet_1_worker_vs_headway_replay_commands": round((f1["wall_s"] - out["headway_replay_commands_s"]) / n, 3),
        "drive_task_vs_replay_in_process": round((f1["drive_task_s"] - out["replay_alone_s"]) / n, 3)}
    out["drives_per_minute_replay_alone"] = round(60 * n / out["replay_alone_s"], 1)
    out["machine"] = f"{os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f} at the end"
    return out


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m app.bench.fleet", description=__doc__.split("\n\n")[0])
    p.add_argument("--scenarios", default=DEFAULT_SCENARIOS, help="comma-separated shipped scenarios")
    p.add_argument("--data", default="../shared/data", help="real data folder (tme08, Udacity test video)")
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="headway-fleet-bench-") as tmp:
        print(json.dumps(run(a.scenarios.split(","), Path(a.data), Path(tmp)), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
