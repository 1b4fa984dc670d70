"""The status file: the service's latest health, for `headway status` at a shell.

Written atomically (temporary file + rename) so a reader never sees half a file. Every write carries the
writer's process id and the kernel's boot id, and a clean stop writes the state ``stopped``: a reader
can then tell a running service from one that stopped (``stopped``) or died without a word
(``unknown``: the process is gone, the file was written in another boot, its time stamp is stale, in the
future or not a number, or any field is malformed). ``assess`` decides, and never raises.
"""
from __future__ import annotations

import json
import math
import os
import time
from pathlib import Path
from typing import Any, Callable, Optional

from app.safe_yaml import short
from app.contracts.faults import STATES

DEFAULT_PATH = "/run/headway/status.json"
# s; a status older than this is stale (the service rewrites it at service.status_rate_hz, 2 Hz by default,
# so 5 s is ten missed writes): its state is unknown.
STALE_AFTER_S = 5.0
# s; a time stamp further ahead of this host's clock than this was not written by a service on this clock
# (the clock went back, or the file came from elsewhere): its state is unknown. Above the few ms between
# the writer's clock read and the reader's.
FUTURE_TOLERANCE_S = 1.0
STOPPED = "stopped"   # written once by a clean stop; no other process writes it
UNKNOWN = "unknown"
BOOT_ID_PATH = "/proc/sys/kernel/random/boot_id"


def boot_id() -> str:
    """The kernel's id of this boot (a process id is only meaningful within one boot); "" if unreadable."""
    try:
        return Path(BOOT_ID_PATH).read_text().strip()
    except OSError:
        return ""


def write_status(path: str, status: dict) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    stamp = {"written_unix_s": round(time.time(), 3), "pid": os.getpid(), "boot_id": boot_id()}
    tmp.write_text(json.dumps({**status, **stamp}, indent=1))
    os.replace(tmp, p)


class StatusFileError(ValueError):
    """A status file that is there but cannot be read as the service's status."""


def _number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def _count(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= 0


def _optional_number(v: Any) -> bool:
    return v is None or (_number(v) and v >= 0)


def _str_list(v: Any) -> bool:
    return isinstance(v, list) and all(isinstance(x, str) for x in v)


def _counts(v: Any) -> bool:
    """{"name": count or {"name": count ...}}: the can_input and decode-error tallies."""
    return isinstance(v, dict) and all(isinstance(k, str) and (_count(x) or _counts(x)) for k, x in v.items())


_CALIBRATION_NUMBERS = ("pitch_deg", "yaw_deg", "height_m")
_CALIBRATION_SIGMAS = ("pitch_sigma_deg", "yaw_sigma_deg", "height_sigma_m")


def _calibration(c: Any) -> bool:
    if c is None:
        return True
    if not isinstance(c, dict) or not isinstance(c.get("active", False), bool):
        return False
    needed = _CALIBRATION_NUMBERS + ((_CALIBRATION_SIGMAS + ("updates",)) if c.get("active") else ())
    return (all(_number(c.get(k)) for k in needed) and (not c.get("active") or _count(c["updates"]))
            and isinstance(c.get("state", ""), (str, type(None))))


# Every field the service writes, with the test its value passes; a field that fails it makes the status
# unknown (a file that is not what the service wrote says nothing about the service).
FIELDS: dict[str, tuple[bool, Callable[[Any], bool]]] = {   # name: (required, valid)
    "state": (True, lambda v: v in STATES or v == STOPPED),
    "written_unix_s": (True, _number),
    "pid": (True, lambda v: _count(v) and v > 0),
    "boot_id": (True, lambda v: isinstance(v, str)),
    "faults": (False, _str_list),
    "bits": (False, _count),
    "fps": (False, _optional_number),
    "latency_median_ms": (False, _optional_number),
    "latency_p99_ms": (False, _optional_number),
    "frames": (False, _count),
    "queue_drops": (False, _count),
    "frames_captured": (False, _count),
    "camera": (False, lambda v: isinstance(v, str)),
    "source_state": (False, lambda v: isinstance(v, str)),
    "can_input": (False, _counts),
    "decode_errors": (False, _counts),
    "calibration": (False, _calibration),
    "fcw": (False, lambda v: v is None or isinstance(v, str)),
}


def malformed_field(status: dict) -> Optional[str]:
    """The first field that is missing or not what the service writes, as "name: why"; None if all are."""
    for name, (required, valid) in FIELDS.items():
        if name not in status:
            if required:
                return f"{name}: missing"
            continue
        if not valid(status[name]):
            return f"{name}: {short(status[name])} is not a valid value"
    return None


def read_status(path: str) -> Optional[dict]:
    """The status written by the service; None if there is no file; StatusFileError if it is malformed."""
    try:
        text = Path(path).read_text(errors="replace")
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:   # ValueError: a path with a NUL byte
        raise StatusFileError(f"{short(path)}: cannot be read ({getattr(exc, 'strerror', None) or exc})") from None
    try:
        status = json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise StatusFileError(f"{short(path)}: not a status file (not JSON: {short(str(exc))})") from None
    if not isinstance(status, dict):
        raise StatusFileError(f"{short(path)}: not a status file (not a JSON object)")
    bad = malformed_field(status)
    if bad:
        raise StatusFileError(f"{short(path)}: not a status file ({bad})")
    return status


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True   # another user's process (the service runs as its own user); OverflowError: not a pid
    return True


def assess(status: dict, now: Optional[float] = None, stale_after_s: float = STALE_AFTER_S) -> tuple[str, str]:
    """(state, why): the written state when the file is fresh and its writer alive; ``stopped`` after a clean
    stop; else ``unknown`` with the reason. ``status`` has passed read_status's checks."""
    now = time.time() if now is None else now
    said = status["state"]
    if said == STOPPED:
        return STOPPED, "the service stopped cleanly"
    age = now - status["written_unix_s"]
    if age < -FUTURE_TOLERANCE_S:
        return UNKNOWN, (f"status is stamped {-age:.0f} s in the future: the clock went back or the file is not "
                         f"this host's; its last report said {said}")
    if status["boot_id"] != boot_id():
        return UNKNOWN, f"status was written before this host last booted; its last report said {said}"
    if not _alive(status["pid"]):
        return UNKNOWN, f"the service (pid {status['pid']}) is gone without stopping; its last report said {said}"
    if age > stale_after_s:
        return UNKNOWN, f"status is {age:.0f} s old: the service is not updating it; its last report said {said}"
    return said, ""


def format_status(status: Optional[dict], path: str, stale_after_s: float = STALE_AFTER_S) -> str:
    if status is None:
        return f"headway: no status at {path} (is the service running? systemctl status headway)"
    state, why = assess(status, stale_after_s=stale_after_s) if "pid" in status else (status.get("state", "?"), "")
    lines = [f"state: {state}" + (f"  ({why})" if why and state == UNKNOWN else "")]
    faults = status.get("faults") or []
    lines.append("faults: " + (", ".join(str(f) for f in faults) if faults else "none"))
    for key in ("fps", "latency_median_ms", "latency_p99_ms", "frames", "queue_drops", "camera", "can",
                "ego_speed", "mcu", "fcw", "lead_id", "can_input", "decode_errors"):
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
