"""What goes into each Headway message: pure functions from the supervisor's values to the signal
dicts of ``headway.dbc`` (physical units, ``None`` = not available). No I/O, no clocks.

Tracks are read by attribute, as ``app.core.Track`` has them (``id``, ``box``, ``confidence``,
``range_m``, ``lateral_m``, ``range_rate_mps``, ``ttc_s``, ``ttc_scale_s``, ``lane_index``,
``in_path``, ``confirmed``), so that this module does not need the core.
"""
from __future__ import annotations

import math
from typing import Any, Iterable, Mapping, Optional

from app.contracts.fcw_level import FcwLevel
from app.contracts.faults import FAULT, FAULTS, STATES
from app.contracts.ttc_source import TtcSource

from .database import wire_id

# Faults of severity "fault" in the health registry: Headway cannot warn the driver reliably.
FATAL_FAULTS = frozenset(f.name for f in FAULTS if f.severity == FAULT)


def _num(x: Any) -> Optional[float]:
    if x is None:
        return None
    x = float(x)
    return None if math.isnan(x) else x


def fcw_signals(level: int = FcwLevel.NONE, available: bool = False, ttc_s: Optional[float] = None,
                ttc_source: str = TtcSource.NONE, lead: Any = None) -> dict:
    """HW_FCW. ``level`` is forced to none when FCW is not available: no warning without its inputs."""
    if not available:
        level = FcwLevel.NONE
    return {"FCW_LEVEL": int(level), "FCW_AVAILABLE": int(bool(available)),
            "TTC_SOURCE": TtcSource(ttc_source).raw if _num(ttc_s) is not None else TtcSource.NONE.raw,
            "TTC_USED_S": _num(ttc_s),
            "LEAD_RANGE_M": _num(getattr(lead, "range_m", None)),
            "LEAD_RANGE_RATE_MPS": _num(getattr(lead, "range_rate_mps", None)),
            "LEAD_ID": wire_id(getattr(lead, "id", None))}


def ttc_of(lead: Any) -> tuple[Optional[float], TtcSource]:
    """(TTC, source) of a lead: range-based when available, else scale-based, else (None, NONE)."""
    for attr, source in (("ttc_s", TtcSource.RANGE), ("ttc_scale_s", TtcSource.SCALE)):
        ttc = _num(getattr(lead, attr, None))
        if ttc is not None:
            return ttc, source
    return None, TtcSource.NONE


def lead_signals(lead: Any) -> dict:
    """HW_LEAD; ``lead`` None sends 'no lead' (id 0, everything SNA)."""
    return {"LEAD_ID": wire_id(getattr(lead, "id", None)),
            "RANGE_M": _num(getattr(lead, "range_m", None)),
            "LATERAL_M": _num(getattr(lead, "lateral_m", None)),
            "RANGE_RATE_MPS": _num(getattr(lead, "range_rate_mps", None)),
            "CONFIDENCE": _num(getattr(lead, "confidence", None))}


def lead_ttc_signals(lead: Any) -> dict:
    """HW_LEAD_TTC: both TTC estimates of the lead."""
    return {"LEAD_ID": wire_id(getattr(lead, "id", None)),
            "TTC_RANGE_S": _num(getattr(lead, "ttc_s", None)),
            "TTC_SCALE_S": _num(getattr(lead, "ttc_scale_s", None))}


def object_header_signals(frame_number: int, count: int, lead_id: Optional[int]) -> dict:
    return {"OBJECT_COUNT": count, "FRAME_NUMBER": int(frame_number) % 65536, "LEAD_ID": wire_id(lead_id)}


def _angles(box: Any, camera: Optional[Mapping[str, float]]) -> tuple[Optional[float], Optional[float]]:
    """(azimuth of the bottom-centre, angular width), rad, right positive; None without intrinsics."""
    if camera is None or box is None:
        return None, None
    fx, cx = float(camera["fx"]), float(camera["cx"])
    left, _top, right, _bottom = box
    a_left, a_right = math.atan((left - cx) / fx), math.atan((right - cx) / fx)
    return math.atan(((left + right) / 2 - cx) / fx), a_right - a_left


def object_signals(index: int, track: Any, camera: Optional[Mapping[str, float]] = None) -> tuple[dict, dict]:
    """HW_OBJECT page 0 (kinematics) and page 1 (image, lane) of one track."""
    common = {"OBJECT_INDEX": index, "OBJECT_ID": wire_id(track.id)}
    azimuth, width = _angles(getattr(track, "box", None), camera)
    lane = getattr(track, "lane_index", None)
    in_path = getattr(track, "in_path", None)
    page0 = {**common, "OBJECT_PAGE": 0, "RANGE_M": _num(track.range_m), "LATERAL_M": _num(track.lateral_m),
             "RANGE_RATE_MPS": _num(track.range_rate_mps)}
    page1 = {**common, "OBJECT_PAGE": 1, "AZIMUTH_RAD": azimuth, "WIDTH_RAD": width,
             "LANE": None if lane is None or abs(lane) > 3 else int(lane),
             "IN_PATH": 3 if in_path is None else int(bool(in_path)),
             "CONFIDENCE": _num(getattr(track, "confidence", None)),
             "CONFIRMED": int(bool(getattr(track, "confirmed", False)))}
    return page0, page1


def objects_by_range(tracks: Iterable[Any], max_objects: int) -> list:
    """The tracks to send: nearest first (no range last, by id), at most ``max_objects``."""
    def key(t):
        r = _num(t.range_m)
        return (r is None, r if r is not None else 0.0, t.id)
    return sorted(tracks, key=key)[:max_objects]


CALIBRATION_STATES = ("off", "learning", "converged", "at_limit")  # STATE of HW_CALIBRATION, by value
CALIBRATION_PAGES = ({"PITCH_DEG": "pitch_deg", "YAW_DEG": "yaw_deg", "HEIGHT_M": "height_m"},
                     {"PITCH_SIGMA_DEG": "pitch_sigma_deg", "YAW_SIGMA_DEG": "yaw_sigma_deg",
                      "HEIGHT_SIGMA_M": "height_sigma_m"})
UPDATES_MAX = 255  # HW_CALIBRATION.UPDATES saturates here


def calibration_signals(cal: Mapping[str, Any], limits: Mapping[str, tuple[float, float]]) -> tuple[dict, dict]:
    """HW_CALIBRATION page 0 (estimate) and page 1 (uncertainties) of the core's calibration dict
    (``FrameResult.calibration``). ``limits``: {signal: (min, max)} of the DBC; a value outside them is
    sent at the range's end by the packer, and SATURATED says so on its page (never a wrapped number)."""
    state = CALIBRATION_STATES.index(cal["state"])
    pages = []
    for page, names in enumerate(CALIBRATION_PAGES):
        sig = {sname: _num(cal.get(key)) for sname, key in names.items()}
        over = any(v is not None and not (limits[s][0] <= v <= limits[s][1]) for s, v in sig.items())
        if page == 0:
            updates = int(cal.get("updates", 0))
            over |= updates > UPDATES_MAX
            sig["UPDATES"] = min(max(updates, 0), UPDATES_MAX)
        pages.append({"STATE": state, "CAL_PAGE": page, "SATURATED": int(over), **sig})
    return pages[0], pages[1]


def status_signals(state: str, faults: Iterable[str], known_faults: Iterable[str],
                   frame_rate_hz: Optional[float] = None, latency_p99_ms: Optional[float] = None) -> dict:
    """HW_STATUS. ``known_faults`` are the DBC's fault names (``database.fault_names``); a fault
    outside them is a programming error."""
    faults = set(faults)
    known = list(known_faults)
    unknown = faults - set(known)
    if unknown:
        raise KeyError(f"unknown fault bit(s) {sorted(unknown)}; headway.dbc defines {known}")
    sig = {"STATE": STATES.index(state), "FRAME_RATE_HZ": _num(frame_rate_hz), "LATENCY_P99_MS": _num(latency_p99_ms)}
    sig.update({f"FAULT_{f.upper()}": int(f in faults) for f in known})
    return sig
