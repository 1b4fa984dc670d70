"""CanScheduler: which of Headway's frames go out when, on the caller's clock.

Messages are sent in groups (``fcw``: HW_FCW; ``lead``: HW_LEAD + HW_LEAD_TTC; ``objects``:
HW_OBJECT_HEADER + HW_OBJECT pages; ``status``: HW_STATUS; ``calibration``: the two HW_CALIBRATION
pages), each at its own rate. A group whose
change key (FCW: level and availability) differs from the last one sent goes out at once and its
period restarts. Data older than ``data_timeout_s`` is never sent: the group's fallback frames
(FCW not available, no lead, no objects) go instead.

There is no wall clock in here: ``due(now_s)`` is called with the live receive clock in the car and
with the replay clock in a replay, so the same inputs give the same frames with the same
timestamps, byte for byte.
"""
from __future__ import annotations

import math
from typing import Any, Hashable, Mapping, Optional, Sequence

import can

from .packer import CanPacker

GROUPS = ("fcw", "lead", "objects", "status", "calibration")  # sending order within one tick: most urgent first
EPS_S = 1e-6  # frame times such as 3 * (1/30) land a hair before a 0.1 s period; they count as on time

Frames = Sequence[tuple[str, Mapping[str, Any]]]


class CanScheduler:
    def __init__(self, packer: CanPacker, rates_hz: Mapping[str, float], data_timeout_s: float = 0.5,
                 fallbacks: Optional[Mapping[str, tuple[Frames, Hashable]]] = None):
        unknown = set(rates_hz) - set(GROUPS)
        if unknown:
            raise KeyError(f"unknown message group(s) {sorted(unknown)}; groups are {', '.join(GROUPS)}")
        self.packer = packer
        self.period_s = {g: (1.0 / r if r > 0 else math.inf) for g, r in rates_hz.items()}
        self.data_timeout_s = data_timeout_s
        self.fallbacks = dict(fallbacks or {})
        self._data: dict[str, tuple[float, Frames, Hashable]] = {}
        self._next: dict[str, Optional[float]] = {g: None for g in self.period_s}
        self._sent_key: dict[str, Hashable] = {}
        self.sent_count = {g: 0 for g in self.period_s}

    def update(self, group: str, frames: Frames, t_s: float, key: Hashable = None) -> None:
        """New content for a group, measured at ``t_s``; ``key`` marks a change that must go out at once."""
        if group not in self.period_s:
            raise KeyError(f"{group}: not a scheduled group ({', '.join(self.period_s)})")
        self._data[group] = (t_s, frames, key)

    def _current(self, group: str, now_s: float) -> Optional[tuple[Frames, Hashable]]:
        data = self._data.get(group)
        if data is not None and (group == "status" or now_s - data[0] <= self.data_timeout_s + EPS_S):
            return data[1], data[2]
        return self.fallbacks.get(group)

    def due(self, now_s: float) -> list[can.Message]:
        """The frames to send at ``now_s`` (packed with that timestamp), in group order."""
        out: list[can.Message] = []
        for group in GROUPS:
            period = self.period_s.get(group, math.inf)
            if math.isinf(period):
                continue
            current = self._current(group, now_s)
            if current is None:
                continue
            frames, key = current
            nd = self._next[group]
            changed = key is not None and group in self._sent_key and key != self._sent_key[group]
            if not (nd is None or changed or now_s + EPS_S >= nd):
                continue
            for name, signals in frames:
                out.append(self.packer.pack(name, signals, timestamp=now_s))
            self._sent_key[group] = key
            self.sent_count[group] += 1
            # Keep the rhythm (no drift); restart it after a change or a gap of more than a period.
            self._next[group] = now_s + period if (nd is None or changed or now_s - nd >= period) else nd + period
        return out
