"""FCW over the synthetic scenarios through the whole stack (core, supervisor, CAN): when the first
warning came, with which TTC, and how much margin that leaves to the US NCAP FCW requirement; whether the warning,
once the true TTC is below that requirement, stays on to the end (the driver has not braked); and the false
warnings where none is expected. The CAN output is decoded with cantools, as the car would."""
from __future__ import annotations

import tempfile
from pathlib import Path
from typing import Optional

import can
import numpy as np

from app.can import headway_database
from app.contracts.fcw_level import FcwLevel
from app.replay import replay_scenario

# scenario -> the true TTC (s) by which a warning must have come (NCAP FCW confirmation test);
# scenarios not listed must give no warning.
REQUIRED_TTC_S = {
    "stopped_lead_50kmh": 2.1,
    "stopped_lead_72kmh": 2.1,
    "stopped_lead_100kmh": 2.1,
    "lead_braking_0p3g": 2.4,
    "slower_lead": 2.0,
}
# Once a warning is due it must stay on down to this true TTC; nearer, no reaction changes the outcome, and the
# vehicle fills the image (a warning ending 0.02-0.15 s before contact is not counted).
LAST_USEFUL_TTC_S = 0.5
# The TTC the FCW used is compared with the true one on the frames whose true TTC lies in this range (s): from the
# pre-warning's 4 s and a second more, down to the last second, where the vehicle fills the image.
TTC_ACCURACY_RANGE_S = (1.0, 5.0)
NO_WARNING = ("steady_following", "adjacent_passing", "cut_out_stopped_car", "overpass_shadow", "dense_traffic",
              "empty_road", "cut_in", "lane_change", "overtaking_from_side")


def true_ttc(truth: list[dict]) -> Optional[float]:
    """TTC to the ego front of the most urgent vehicle in the ego lane (None if nobody is closing)."""
    ttcs = [v["ttc_s"] for v in truth if v["lane"] == 0 and v["ttc_s"] is not None]
    return min(ttcs) if ttcs else None


def _ttc_accuracy(errors: list[float]) -> Optional[dict]:
    """The relative errors of the TTC the FCW used: how many frames had one, their median (its bias: > 0 reads
    late) and the 90th percentile of their size."""
    if not errors:
        return None
    e = np.array(errors)
    return {"frames": len(e), "median": round(float(np.median(e)), 4),
            "p90_abs": round(float(np.percentile(np.abs(e), 90)), 4)}


def _true_ttc_at(truth_ttc: list[tuple[float, Optional[float]]], t: float) -> Optional[float]:
    """The true TTC of the frame nearest to time t."""
    return min(truth_ttc, key=lambda x: abs(x[0] - t))[1]


def warnings_in_can_log(path: str) -> list[tuple[float, int, Optional[float]]]:
    """(t, level, ttc) at every change of HW_FCW's level in a CAN log, decoded with cantools; t is
    relative to the log's first frame (the replay's frame 0)."""
    db = headway_database()
    msg = db.get_message_by_name("HW_FCW")
    frames = list(can.LogReader(path))
    if not frames:
        return []
    t0 = min(m.timestamp for m in frames)
    out, last = [], FcwLevel.NONE
    for m in frames:
        if m.arbitration_id != msg.frame_id:
            continue
        sig = msg.decode(m.data, decode_choices=False)
        level = int(sig["FCW_LEVEL"])
        if level != last:
            out.append((m.timestamp - t0, level, sig.get("TTC_USED_S")))
            last = level
    return out


def evaluate(name: str, config_path: Optional[str] = None, preset: Optional[str] = None,
             vehicle_look: Optional[str] = None) -> dict:
    """`preset`: the pipeline preset to run (None: the configuration's); `vehicle_look`: "real" or "plain" instead of
    the scenario's own (docs/sim.md)."""
    truth_ttc: list[tuple[float, Optional[float]]] = []
    ttc_errors: list[float] = []   # (TTC the FCW used - true TTC) / true TTC, true TTC within TTC_ACCURACY_RANGE_S

    def on_result(r, decision, truth):
        ttc = true_ttc(truth)
        truth_ttc.append((r.t_s, ttc))
        lo, hi = TTC_ACCURACY_RANGE_S
        if ttc is not None and lo <= ttc <= hi and decision.ttc_used_s is not None:
            ttc_errors.append(decision.ttc_used_s / ttc - 1.0)

    with tempfile.TemporaryDirectory() as tmp:
        can_out = str(Path(tmp) / "out.log")
        s = replay_scenario(name, config_path=config_path, can_out=can_out, on_result=on_result, progress=False,
                            overrides={"pipeline": {"preset": preset}} if preset else None, vehicle_look=vehicle_look)
        changes = warnings_in_can_log(can_out)
    warnings = [(t, ttc) for t, level, ttc in changes if level == FcwLevel.WARNING]
    out = {"scenario": name, "frames": s.frames, "warnings": len(warnings), "ttc_accuracy": _ttc_accuracy(ttc_errors),
           "prewarnings": sum(1 for _, level, _ in changes if level == FcwLevel.PREWARNING), "first_warning_t_s": None,
           "ttc_used_s": None, "true_ttc_s": None}
    if warnings:
        t, ttc_used = warnings[0]
        out.update(first_warning_t_s=round(t, 3), ttc_used_s=ttc_used, true_ttc_s=_true_ttc_at(truth_ttc, t))
    req = REQUIRED_TTC_S.get(name)
    if req is not None:
        out["required_ttc_s"] = req
        out["margin_s"] = None if out["true_ttc_s"] is None else out["true_ttc_s"] - req
        # the warning ending while the true TTC is below the required one: the buzzer stops as the car closes in
        out["dropped_at_ttc_s"] = [
            ttc for ttc in (_true_ttc_at(truth_ttc, t) for (t, level, _), (_, before, _) in zip(changes[1:], changes)
                            if before == FcwLevel.WARNING and level < FcwLevel.WARNING)
            if ttc is not None and LAST_USEFUL_TTC_S <= ttc < req]
        out["pass"] = out["margin_s"] is not None and out["margin_s"] >= 0 and not out["dropped_at_ttc_s"]
    else:
        out["pass"] = not warnings
    return out
