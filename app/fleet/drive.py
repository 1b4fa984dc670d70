"""One drive of the fleet, run inside a worker process: `app.replay.replay` (core, supervisor, CAN
encoding) with the drive's effective configuration, then its outputs written into ``OUT/drives/NAME/``:

- ``tracks.jsonl``  the tracks file (README), ``can.log`` every CAN frame Headway sent (candump -L);
- ``summary.json``  frames, skipped frames, vehicles confirmed, FCW events, CAN counts;
- ``metrics.json``  where the drive has truth: detection, MOT and range metrics (and a scenario's FCW timing);
- ``config.yaml``   the effective configuration (`headway replay SOURCE --config` it gives the same outputs);
- ``key``           inputs + configuration + code version (app/fleet/manifest.py); written last;
- ``run.json``      wall time, worker, per-frame time: the one file that differs between runs.

Everything but run.json depends only on the inputs, so 1 or N workers give byte-identical files. A drive
is written into a partial folder named after its host and process and renamed into place when complete:
a worker that dies leaves no half-written drive, and re-running a drive (a rescheduled task) is harmless.
"""
from __future__ import annotations

import json
import os
import shutil
import socket
import statistics
import time
import traceback
from pathlib import Path
from typing import Optional

import yaml

from app.contracts.fcw_level import FcwLevel
from app.eval.fcw_scenarios import NO_WARNING, REQUIRED_TTC_S, true_ttc
from app.eval.track_score import TrackScorer
from app.fleet.manifest import Drive, code_version
from app.replay import replay

def drive_dir(out: str | Path, name: str) -> Path:
    return Path(out) / "drives" / name


def partial_prefix(name: str) -> str:
    """Partial folders are ``.NAME.partial-HOST-PID``: the process writing it is in its name."""
    return f".{name}.partial-"


def is_done(out: str | Path, name: str, key: str) -> bool:
    p = drive_dir(out, name) / "key"
    return p.is_file() and p.read_text().strip() == key


def _dump(path: Path, obj) -> None:
    path.write_text(json.dumps(obj, indent=1, sort_keys=True) + "\n")


def one_line(exc: BaseException) -> str:
    msg = " ".join(str(exc).split()) or "(no message)"
    return f"{type(exc).__name__}: {msg}"


def run_drive(drive: Drive, out: str, key: str, client_code: str) -> dict:
    """Replay one drive; returns its result row ({"name", "status": "ok" | "failed", ...}). Never raises
    for a bad drive: the error is its row's one line."""
    started = time.perf_counter()
    row = {"name": drive.name, "source": drive.source, "key": key, "worker": f"{socket.gethostname()}:{os.getpid()}"}
    if is_done(out, drive.name, key):          # a rescheduled task whose first run finished after all
        return load_row(out, drive.name) | {"status": "ok"}
    if code_version() != client_code:
        return row | {"status": "failed", "error": f"this worker runs Headway code {code_version()}, the client "
                                                   f"{client_code}: install the same version on every worker"}
    final = drive_dir(out, drive.name)
    partial = final.parent / f"{partial_prefix(drive.name)}{socket.gethostname()}-{os.getpid()}"
    shutil.rmtree(partial, ignore_errors=True)
    partial.mkdir(parents=True)
    try:
        summary, metrics, frame_ms = _replay_into(drive, partial)
        _dump(partial / "summary.json", summary)
        if metrics is not None:
            _dump(partial / "metrics.json", metrics)
        _dump(partial / "run.json", {"seconds": round(time.perf_counter() - started, 3), "worker": row["worker"],
                                      "frame_ms_median": frame_ms})
        (partial / "key").write_text(key + "\n")
        _publish(partial, final, key)
    except Exception as exc:   # any failure of this drive is its report line; the others go on
        shutil.rmtree(partial, ignore_errors=True)
        if not isinstance(exc, (OSError, ValueError, RuntimeError)):
            traceback.print_exc()   # an unexpected error: the worker's log has the trace
        return row | {"status": "failed", "error": one_line(exc), "seconds": round(time.perf_counter() - started, 3)}
    return load_row(out, drive.name) | {"status": "ok"}


def _publish(partial: Path, final: Path, key: str) -> None:
    """Rename the complete partial folder into place (an older run's folder is moved aside first)."""
    if final.exists():
        if is_done(final.parent.parent, final.name, key):   # another run of the same drive got there first
            shutil.rmtree(partial, ignore_errors=True)
            return
        old = partial.with_name(partial.name.replace(".partial-", ".old-"))
        os.replace(final, old)
        shutil.rmtree(old, ignore_errors=True)
    os.replace(partial, final)


def _replay_into(drive: Drive, folder: Path) -> tuple[dict, Optional[dict], Optional[float]]:
    """(summary, metrics or None, median ms per frame) of the drive replayed into `folder`."""
    cfg_path = folder / "config.yaml"
    cfg_path.write_text(yaml.safe_dump(drive.config, sort_keys=True))
    scorer, truth_ttc, boxes = None, [], None
    if drive.truth is not None:
        scorer = TrackScorer()
        if drive.truth != "scenario":
            boxes = read_boxes(drive.truth)

    def on_result(r, decision, truth):
        if scorer is None:
            return
        confirmed = [t for t in r.tracks if t.confirmed]
        if truth is not None:     # a scenario's own truth
            scorer.update(r.frame, truth, confirmed, (r.width, r.height))
            truth_ttc.append((r.t_s, true_ttc(truth)))
        else:
            index = round(r.t_s * drive.fps)
            if index in boxes:    # frames without truth are not scored
                scorer.update(index, boxes[index], confirmed, (r.width, r.height))

    s = replay(drive.source, config_path=str(cfg_path), fps=drive.fps, tracks_path=str(folder / "tracks.jsonl"),
               can_in=drive.can_in, can_out=str(folder / "can.log"), on_result=on_result, progress=False)
    can = {k: v for k, v in s.can.items() if k != "output_log"}
    summary = {"name": drive.name, "kind": drive.kind, "source": drive.source, "frames": s.frames,
               "skipped": s.skipped, "vehicles_confirmed": len(s.confirmed_ids),
               "fcw_events": [{"t": round(t, 6), "level": level, "ttc_used_s": None if ttc is None else round(ttc, 4)}
                              for t, level, ttc in s.warnings],
               "can": can}
    metrics = None
    if scorer is not None:
        metrics = scorer.metrics()
        if drive.truth == "scenario":
            metrics["fcw"] = _fcw_timing(drive.source, s.warnings, truth_ttc)
    return summary, metrics, round(statistics.median(s.total_ms), 3) if s.total_ms else None


def _fcw_timing(scenario: str, warnings: list, truth_ttc: list) -> dict:
    """A scenario's first warning against the NCAP requirement (app/eval/fcw_scenarios.py)."""
    name = Path(scenario).stem
    first = next(((t, ttc) for t, level, ttc in warnings if level == FcwLevel.WARNING.label), None)
    out = {"first_warning_t_s": None if first is None else round(first[0], 6), "true_ttc_s": None,
           "required_ttc_s": REQUIRED_TTC_S.get(name), "pass": None}
    if first is not None and truth_ttc:
        nearest = min(truth_ttc, key=lambda x: abs(x[0] - first[0]))[1]
        out["true_ttc_s"] = None if nearest is None else round(nearest, 4)
    if name in REQUIRED_TTC_S:
        out["pass"] = out["true_ttc_s"] is not None and out["true_ttc_s"] >= REQUIRED_TTC_S[name]
    elif name in NO_WARNING:
        out["pass"] = first is None
    return out


def read_boxes(path: str) -> dict[int, list[dict]]:
    """A truth file: one JSON object per annotated frame, ``{"frame": N, "vehicles": [{"id", "box":
    [l,t,r,b]}]}`` (`headway sim`'s truth.jsonl is one)."""
    out: dict[int, list[dict]] = {}
    with open(path, encoding="utf-8") as f:
        for n, line in enumerate(f, 1):
            if not line.strip():
                continue
            try:
                rec = json.loads(line)
                vehicles = [{**v, "id": v["id"], "box": v.get("box_clipped") or v["box"]} for v in rec["vehicles"]]
                out[int(rec["frame"])] = vehicles
            except (ValueError, KeyError, TypeError) as exc:
                raise ValueError(f"{path}:{n}: expected {{\"frame\": N, \"vehicles\": [{{\"id\", \"box\"}}]}} "
                                 f"({one_line(exc)})") from None
    return out


def load_row(out: str | Path, name: str) -> dict:
    """A finished drive's report row, read back from its folder (this run's or an earlier one's)."""
    d = drive_dir(out, name)
    summary = json.loads((d / "summary.json").read_text())
    run = json.loads((d / "run.json").read_text())
    metrics = json.loads((d / "metrics.json").read_text()) if (d / "metrics.json").exists() else None
    return {"name": name, "source": summary["source"], "key": (d / "key").read_text().strip(),
            "frames": summary["frames"], "seconds": run["seconds"], "worker": run["worker"],
            "vehicles_confirmed": summary["vehicles_confirmed"],
            "warnings": sum(1 for e in summary["fcw_events"] if e["level"] == FcwLevel.WARNING.label),
            "prewarnings": sum(1 for e in summary["fcw_events"] if e["level"] == FcwLevel.PREWARNING.label),
            "can_frames": summary["can"].get("frames_sent", 0), "metrics": metrics}
