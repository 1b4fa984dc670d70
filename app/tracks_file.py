"""The tracks file: one JSON object per frame, the record of what Headway saw.

{"frame", "t", "tracks": [{"id", "box": [l,t,r,b], "range_m", "lateral_m", "range_rate_mps", "ttc_s",
"ttc_scale_s", "in_path"}], "lead_id", "fcw", "lanes": {"width_m", "offset_m", "certain", "boundaries": [{"position",
"observed", "points": [[x, y], ...]}]}, "calibration": {"pitch_deg", "yaw_deg", "height_m", "pitch_sigma_deg",
"yaw_sigma_deg", "height_sigma_m", "updates", "active", "state"}} with null where a value is not available. Only
confirmed tracks are written: they are what the rest of the system acts on. Lanes are written for every frame:
the boundaries the lane model holds (position -1 ego left, +1 ego right, -2 / +2 the adjacent lanes' outer
boundaries, -3 / +3 one lane further out with lanes.outer_lanes; observed false when carried over by lane tracking) as image points from the bottom up (straight lines between
them), the ego-lane width and the car's lateral offset from the ego lane's centre (m, right positive), and
whether the model is certain (both ego boundaries have paint along the road: only then do the road prior and the
lead selection believe it). The calibration is the camera as self-calibration has it, when it runs, with its
state (off, learning, converged, at_limit).
"""
from __future__ import annotations

import json
from typing import IO, Optional

from app.core import FrameResult
from app.contracts.fcw_level import FcwLevel


def _r(x: Optional[float], nd: int = 2) -> Optional[float]:
    return None if x is None else round(x, nd)


def frame_record(r: FrameResult, fcw_level: Optional[int] = None) -> dict:
    tracks = [
        {
            "id": t.id,
            "box": [round(v, 1) for v in t.box],
            "range_m": _r(t.range_m),
            "lateral_m": _r(t.lateral_m),
            "range_rate_mps": _r(t.range_rate_mps),
            "ttc_s": _r(t.ttc_s),
            "ttc_scale_s": _r(t.ttc_scale_s),
            "in_path": t.in_path,
        }
        for t in r.tracks
        if t.confirmed
    ]
    level = FcwLevel.NONE if fcw_level is None else fcw_level
    rec = {"frame": r.frame, "t": round(r.t_s, 6), "tracks": tracks, "lead_id": r.lead_id,
           "fcw": FcwLevel(level).label, "lanes": lanes_record(r)}
    if r.calibration is not None:
        c = r.calibration
        rec["calibration"] = {k: (round(v, 4) if isinstance(v, float) else v) for k, v in c.items()}
    return rec


def lanes_record(r: FrameResult) -> dict:
    boundaries = [
        {"position": ln.position, "observed": ln.observed,
         "points": [[round(x, 1), round(y, 1)] for x, y in
                    (ln.points or [(ln.x_bottom, ln.y_bottom), (ln.x_top, ln.y_top)])]}
        for ln in r.lanes
    ]
    return {"width_m": _r(r.lane_width_m), "offset_m": _r(r.lane_offset_m), "certain": r.lanes_certain,
            "boundaries": boundaries}


class TracksWriter:
    """Writes one line per frame and flushes it, so a run that is stopped keeps what it recorded."""

    def __init__(self, stream: IO[str]):
        self._f = stream
        self.lines = 0

    def write(self, r: FrameResult, fcw_level: Optional[int] = None) -> None:
        self._f.write(json.dumps(frame_record(r, fcw_level), separators=(",", ":")) + "\n")
        self._f.flush()
        self.lines += 1

    def close(self) -> None:
        self._f.close()
