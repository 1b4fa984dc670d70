"""Health: one overall state (starting, ok, degraded, fault) and fault bits, from what the service sees.

Pure logic: the service feeds it results, the core's counters and the state of the bus, the vehicle
inputs and the MCU link, with the time; tests do the same with made-up inputs.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from app.contracts.faults import fault_bits, overall_state
from app.contracts.health_config import HEALTH_SCHEMA


@dataclass
class HealthParams:
    """The section `health`; units, meaning and defaults are HEALTH_SCHEMA's."""

    camera_timeout_s: float = HEALTH_SCHEMA["camera_timeout_s"]["default"]
    stall_timeout_s: float = HEALTH_SCHEMA["stall_timeout_s"]["default"]
    blinded_stddev: float = HEALTH_SCHEMA["blinded_stddev"]["default"]
    blinded_frames: int = HEALTH_SCHEMA["blinded_frames"]["default"]
    frozen_change: float = HEALTH_SCHEMA["frozen_change"]["default"]
    frozen_frames: int = HEALTH_SCHEMA["frozen_frames"]["default"]
    latency_budget_ms: float = HEALTH_SCHEMA["latency_budget_ms"]["default"]
    window_frames: int = HEALTH_SCHEMA["window_frames"]["default"]

    @classmethod
    def from_config(cls, section: dict) -> "HealthParams":
        return cls(**section)


@dataclass
class HealthReport:
    state: str
    faults: list[str]
    bits: int
    fps: Optional[float]
    latency_median_ms: Optional[float]
    latency_p99_ms: Optional[float]
    frames: int
    queue_drops: int
    camera: str

    def as_dict(self) -> dict:
        return dict(self.__dict__)

    def summary(self) -> str:
        """One line for systemd's STATUS= and the journal."""
        fps = f"{self.fps:.1f} fps" if self.fps else "no frames"
        lat = f", p99 {self.latency_p99_ms:.1f} ms" if self.latency_p99_ms is not None else ""
        return f"{self.state}: {fps}{lat}" + (f"; faults: {', '.join(self.faults)}" if self.faults else "")


@dataclass
class HealthMonitor:
    params: HealthParams = field(default_factory=HealthParams)

    def __post_init__(self) -> None:
        n = self.params.window_frames
        self._frame_times: deque[float] = deque(maxlen=n)
        self._latency_ms: deque[float] = deque(maxlen=n)
        self._last_frame_s: Optional[float] = None
        self._blinded_run = 0
        self._frozen_run = 0
        self._drops_seen = 0
        self._last_drop_s = -float("inf")
        self._start_s: Optional[float] = None
        self.frames = 0

    def start(self, now_s: float) -> None:
        """The camera was asked for frames at `now_s`: from camera_timeout_s later, none is a fault."""
        self._start_s = now_s

    def on_result(self, now_s: float, latency_ms: float, image_stddev: Optional[float],
                  image_change: Optional[float]) -> None:
        """A frame result arrived at `now_s`; `latency_ms` from capture (or processing) to here."""
        self.frames += 1
        self._last_frame_s = now_s
        self._frame_times.append(now_s)
        self._latency_ms.append(latency_ms)
        p = self.params
        self._blinded_run = self._blinded_run + 1 if (image_stddev is not None and image_stddev < p.blinded_stddev) else 0
        self._frozen_run = self._frozen_run + 1 if (image_change is not None and image_change < p.frozen_change) else 0

    def evaluate(self, now_s: float, loop_alive_s: Optional[float], loop_running: bool, queue_drops: int,
                 can_ok: Optional[bool] = None, ego_speed_fresh: Optional[bool] = None,
                 mcu_up: Optional[bool] = None) -> HealthReport:
        """The health now. None for an input means "not configured" (never a fault)."""
        p = self.params
        faults = []
        camera = "ok"
        if self._last_frame_s is None:
            if self._start_s is not None and now_s - self._start_s > p.camera_timeout_s:
                faults.append("camera_lost")
                camera = "no frames"
        elif now_s - self._last_frame_s > p.camera_timeout_s:
            faults.append("camera_lost")
            camera = f"no frame for {now_s - self._last_frame_s:.1f} s"
        if self._blinded_run >= p.blinded_frames:
            faults.append("camera_blinded")
            camera = "blinded"
        if self._frozen_run >= p.frozen_frames:
            faults.append("camera_frozen")
            camera = "frozen"
        if not loop_running or loop_alive_s is None or now_s - loop_alive_s > p.stall_timeout_s:
            faults.append("core_stalled")
        p99 = float(np.percentile(self._latency_ms, 99)) if self._latency_ms else None
        median = float(np.median(self._latency_ms)) if self._latency_ms else None
        if queue_drops > self._drops_seen:
            self._last_drop_s = now_s
        self._drops_seen = queue_drops
        # drops are events: the bit stays up for a few seconds after the last one so it can be seen
        if (p99 is not None and p99 > p.latency_budget_ms) or now_s - self._last_drop_s < 5.0:
            faults.append("overload")
        if can_ok is False:
            faults.append("can_error")
        if ego_speed_fresh is False:
            faults.append("ego_speed_stale")
        if mcu_up is False:
            faults.append("mcu_silent")

        fps = None
        if len(self._frame_times) >= 2 and self._frame_times[-1] > self._frame_times[0]:
            fps = (len(self._frame_times) - 1) / (self._frame_times[-1] - self._frame_times[0])
        return HealthReport(state=overall_state(faults, started=self.frames > 0), faults=faults,
                            bits=fault_bits(faults), fps=fps,
                            latency_median_ms=median, latency_p99_ms=p99, frames=self.frames,
                            queue_drops=queue_drops, camera=camera)
