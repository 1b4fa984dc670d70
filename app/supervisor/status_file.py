"""The status file: the service's latest health, for `headway status` at a shell.

Written atomically (temporary file + rename) so a reader never sees half a file.
"""
from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Optional

DEFAULT_PATH = "/run/headway/status.json"
# s; a status older than this is stale (the service rewrites it at service.status_rate_hz, 2 Hz by default,
# so 5 s is ten missed writes): its state is unknown.
STALE_AFTER_S = 5.0


def write_status(path: str, status: dict) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(json.dumps({**status, "written_unix_s": round(time.time(), 3)}, indent=1))
    os.replace(tmp, p)


class StatusFileError(ValueError):
    """A status file that is there but cannot be read as the service's status."""


def read_status(path: str) -> Optional[dict]:
    """The status written by the service; None if there is no file; StatusFileError if it is malformed."""
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        return None
    except OSError as exc:
        raise StatusFileError(f"{path}: cannot be read ({exc.strerror or exc})") from None
    try:
        status = json.loads(text)
    except ValueError as exc:
        raise StatusFileError(f"{path}: not a status file (not JSON: {exc})") from None
    if not isinstance(status, dict) or not isinstance(status.get("written_unix_s"), (int, float)):
        raise StatusFileError(f"{path}: not a status file (no written_unix_s time stamp)")
    return status


def is_stale(status: dict, stale_after_s: float = STALE_AFTER_S) -> bool:
    """True when the service has not rewritten its status for stale_after_s: its state is unknown."""
    return time.time() - status["written_unix_s"] > stale_after_s


def format_status(status: Optional[dict], path: str, stale_after_s: float = STALE_AFTER_S) -> str:
    if status is None:
        return f"headway: no status at {path} (is the service running? systemctl status headway)"
    age = time.time() - status["written_unix_s"]
    if age > stale_after_s:
        lines = [f"state: unknown  (status is {age:.0f} s old: the service is not updating it; its last report "
                 f"said {status.get('state', '?')})"]
    else:
        lines = [f"state: {status.get('state', '?')}"]
    faults = status.get("faults") or []
    if not isinstance(faults, list):
        faults = [str(faults)]
    lines.append("faults: " + (", ".join(str(f) for f in faults) if faults else "none"))
    for key in ("fps", "latency_median_ms", "latency_p99_ms", "frames", "queue_drops", "camera", "can",
                "ego_speed", "mcu", "fcw", "lead_id", "can_input_drops"):
        if key in status:
            lines.append(f"{key}: {status[key]}")
    if status.get("calibration"):
        lines.append("calibration: " + format_calibration(status["calibration"]))
    return "\n".join(lines)


def format_calibration(c: dict) -> str:
    """The camera as self-calibration has it, with 1-sigma uncertainties."""
    if not c.get("active"):
        return f"off (configured pitch {c['pitch_deg']:.2f} deg, yaw {c['yaw_deg']:.2f} deg, height {c['height_m']:.2f} m)"
    return (f"pitch {c['pitch_deg']:.2f} +- {c['pitch_sigma_deg']:.2f} deg, yaw {c['yaw_deg']:.2f} +- "
            f"{c['yaw_sigma_deg']:.2f} deg, height {c['height_m']:.3f} +- {c['height_sigma_m']:.3f} m "
            f"({c['updates']} frames used" + (f", {c['state']})" if c.get("state") else ")"))
