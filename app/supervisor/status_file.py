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


def write_status(path: str, status: dict) -> None:
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(json.dumps({**status, "written_unix_s": round(time.time(), 3)}, indent=1))
    os.replace(tmp, p)


def read_status(path: str) -> Optional[dict]:
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None


def format_status(status: Optional[dict], path: str, stale_after_s: float = 5.0) -> str:
    if status is None:
        return f"headway: no status at {path} (is the service running? systemctl status headway)"
    age = time.time() - status.get("written_unix_s", 0)
    lines = [f"state: {status.get('state', '?')}" + (f"  (status is {age:.0f} s old: the service is not "
                                                     f"updating it)" if age > stale_after_s else "")]
    faults = status.get("faults") or []
    lines.append("faults: " + (", ".join(faults) if faults else "none"))
    for key in ("fps", "latency_median_ms", "latency_p99_ms", "frames", "queue_drops", "camera", "can",
                "ego_speed", "mcu", "fcw", "lead_id"):
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
            f"({c['updates']} frames used)")
