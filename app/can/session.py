"""CanSession: everything CAN of one run, wired together. Vehicle inputs come in (from the bus
live, from an input log in replay), Headway's frames go out (on the bus, into an output log, or
both) at the configured rates, and the CAN layer's own faults are reported.

Per camera frame the supervisor calls::

    state = session.vehicle_state(t)          # ego speed etc., None where not available
    ... FCW decision with state.speed_mps ...
    session.publish(t, result, fcw={...}, status={...})

Clock: ``t`` is the frame clock in replay (the recording's media time, frame 0 at 0 s; the input
log is put on it by ``vehicle.log_offset_s``) and ``time.time()`` live (the clock of python-can's
receive timestamps). Replay frames are stamped ``t0 + t`` with t0 the input log's first timestamp
(0 without one), so the output log lines up with the input log; nothing depends on the wall clock,
so two replays of the same input write identical logs.
"""
from __future__ import annotations

import collections
import math
from pathlib import Path
from typing import Any, Mapping, Optional, Union

import can

from app.contracts.fcw_level import FcwLevel
from app.contracts.faults import overall_state
from app.contracts.ttc_source import TtcSource

from . import messages as hm
from .bus import CanOutput, bus_from_config
from .config_schema import with_defaults
from .database import fault_names, headway_database
from .log_replay import CanLogReader, channel_map
from .packer import CanPacker
from .scheduler import CanScheduler
from .vehicle_input import VehicleInput, VehicleState

FRAME_RATE_WINDOW_S = 1.0
LATENCY_WINDOW = 100


def _fallbacks() -> dict:
    return {"fcw": ([("HW_FCW", hm.fcw_signals(available=False))], (0, False)),
            "lead": ([("HW_LEAD", hm.lead_signals(None)), ("HW_LEAD_TTC", hm.lead_ttc_signals(None))], None),
            "objects": ([("HW_OBJECT_HEADER", hm.object_header_signals(0, 0, None))], None)}


class CanSession:
    def __init__(self, cfg: Mapping[str, Mapping[str, Any]], output: CanOutput,
                 vehicle: Optional[VehicleInput] = None, input_log: Optional[CanLogReader] = None,
                 rx_bus: Optional[can.BusABC] = None, play_bus: Optional[can.BusABC] = None,
                 deterministic: bool = False, clock_base_s: float = 0.0):
        cfg = with_defaults(cfg)
        c = cfg["can"]
        self.cfg = cfg
        self.db = headway_database(int(c["id_base"]))
        self.faults_known = fault_names(self.db)
        self._own_ids = {(m.frame_id, bool(m.is_extended_frame)) for m in self.db.messages}
        self.packer = CanPacker(self.db, channel=output.channel)
        rates = {"fcw": c["fcw_rate_hz"], "lead": c["lead_rate_hz"], "objects": c["objects_rate_hz"],
                 "status": c["status_rate_hz"], "calibration": c["calibration_rate_hz"]}
        self.scheduler = CanScheduler(self.packer, rates, float(c["data_timeout_s"]), _fallbacks())
        self.output = output
        self.vehicle = vehicle
        self.input_log = input_log
        self.rx_bus = rx_bus
        self.play_bus = play_bus
        self.deterministic = deterministic
        self.clock_base_s = clock_base_s
        self.camera = cfg.get("camera")
        self.max_objects = int(c["max_objects"])
        self._cal_limits = {sig.name: (sig.minimum, sig.maximum)
                            for sig in self.db.get_message_by_name("HW_CALIBRATION").signals}
        self.tx_error_hold_s = float(c["tx_error_hold_s"])
        self._frame_times: collections.deque = collections.deque()
        self._latency_ms: collections.deque = collections.deque(maxlen=LATENCY_WINDOW)
        self._started = False
        self._state: Optional[VehicleState] = None
        self.frames_published = 0

    # ---- construction ----------------------------------------------------------------------------
    @classmethod
    def for_replay(cls, cfg: Mapping[str, Mapping[str, Any]], can_in: Optional[Union[str, Path]] = None,
                   can_out: Optional[Union[str, Path]] = None, via_bus: bool = False) -> "CanSession":
        """Replay: inputs from ``can_in`` on the frame clock, frames to ``can_out``. ``via_bus`` also
        plays the input log onto the configured bus, reads the inputs back from it and sends
        Headway's frames there (the bench test over vcan0)."""
        cfg = with_defaults(cfg)
        veh = cfg["vehicle"]
        vehicle = VehicleInput.from_config(veh)
        reader = None
        if can_in:
            ids = vehicle.frame_ids() if not via_bus else None  # the reader passes over other ids early
            reader = CanLogReader(can_in, offset_s=float(veh["log_offset_s"]), ids=ids,
                                  channels=channel_map(veh.get("log_channels", "")))
        base = (reader.t0 or 0.0) - float(veh["log_offset_s"]) if reader else 0.0
        rx = play = tx = None
        if via_bus:
            tx = bus_from_config(cfg["can"])
            rx = bus_from_config(cfg["can"], cfg["can"].get("input_channel") or None)
            play = bus_from_config(cfg["can"], cfg["can"].get("input_channel") or None)
        output = CanOutput(tx, can_out, channel=cfg["can"]["channel"], start_s=base)
        return cls(cfg, output, vehicle, reader, rx_bus=rx, play_bus=play, deterministic=True, clock_base_s=base)

    @classmethod
    def for_live(cls, cfg: Mapping[str, Mapping[str, Any]]) -> "CanSession":
        cfg = with_defaults(cfg)
        c, veh = cfg["can"], cfg["vehicle"]
        vehicle = VehicleInput.from_config(veh)
        tx = bus_from_config(c)
        rx = bus_from_config(c, c.get("input_channel") or None) if c.get("input_channel") else tx
        output = CanOutput(tx, c.get("output_log") or None, channel=c["channel"],
                           sync_s=float(c["output_log_sync_s"]), keep=int(c["output_log_keep"]))
        return cls(cfg, output, vehicle, rx_bus=rx)

    # ---- inputs ------------------------------------------------------------------------------------
    def _play_and_receive(self, now_s: float) -> None:
        played = 0
        for _t, msg in self.input_log.messages_until(now_s):
            try:
                self.play_bus.send(msg, timeout=0.1)
                played += 1
            except Exception:
                pass
        received = 0
        while received < played:
            msg = self.rx_bus.recv(timeout=1.0)
            if msg is None:
                break
            if (msg.arbitration_id, msg.is_extended_id) not in self._own_ids:
                received += 1
                self.vehicle.on_message(msg, now_s)

    def vehicle_state(self, now_s: float) -> VehicleState:
        """The vehicle inputs at ``now_s``, after every input frame up to then was taken in."""
        if self.input_log is not None and self.play_bus is not None:
            self._play_and_receive(now_s)
        elif self.input_log is not None:
            for t, msg in self.input_log.messages_until(now_s):
                self.vehicle.on_message(msg, t)
        elif self.rx_bus is not None and self.vehicle is not None:
            while (msg := self.rx_bus.recv(timeout=0)) is not None:
                if (msg.arbitration_id, msg.is_extended_id) not in self._own_ids:
                    self.vehicle.on_message(msg)
        self._state = self.vehicle.snapshot(now_s) if self.vehicle else None
        return self._state

    def faults(self, now_s: float) -> set[str]:
        """The CAN layer's faults now (health registry names): ego_speed_stale, can_error."""
        f = set(self._state.faults) if self._state is not None else set()
        if self.output.tx_error(now_s, self.tx_error_hold_s):
            f.add("can_error")
        return f

    def health_inputs(self, now_s: float) -> dict[str, Optional[bool]]:
        """What the health monitor takes from the CAN layer (``HealthMonitor.evaluate(**...)``)."""
        fresh = self._state.ego_speed_fresh if self._state is not None else None
        return {"can_ok": not self.output.tx_error(now_s, self.tx_error_hold_s), "ego_speed_fresh": fresh}

    # ---- outputs -----------------------------------------------------------------------------------
    def _frame_stats(self, result: Any, now_s: float) -> None:
        self._started = True
        self._frame_times.append(now_s)
        while self._frame_times and now_s - self._frame_times[0] > FRAME_RATE_WINDOW_S:
            self._frame_times.popleft()
        if not self.deterministic:
            t_done, t = getattr(result, "t_done_s", None), getattr(result, "t_s", None)
            if t_done is not None and t is not None and t_done >= t:
                self._latency_ms.append((t_done - t) * 1000.0)

    def _frame_rate(self) -> Optional[float]:
        ts = self._frame_times
        if len(ts) < 2 or ts[-1] <= ts[0]:
            return None
        return (len(ts) - 1) / (ts[-1] - ts[0])

    def _latency_p99(self) -> Optional[float]:
        if not self._latency_ms:
            return None
        xs = sorted(self._latency_ms)
        return xs[min(len(xs) - 1, math.ceil(0.99 * len(xs)) - 1)]

    def publish(self, now_s: float, result: Any = None, fcw: Any = None,
                status: Optional[Mapping[str, Any]] = None) -> list[can.Message]:
        """Hands the newest frame result (None if none this tick) and decisions to the scheduler and
        sends what is due. ``fcw``: the FCW decision, a mapping {level, available, ttc_s, ttc_source}
        or an object with ``level``, ``ttc_used_s``, ``ttc_source`` (``app.fcw.FcwOutput``); without
        it the result's own level. Not given, ``available`` means a fresh ego speed. ``status``: the
        health monitor's report {state, faults, fps, latency_p99_ms} (a ``HealthReport.as_dict()``), sent as
        it is; without one (replay) the session reports its own faults, state and frame rate."""
        if result is not None:
            self._frame_stats(result, now_s)
            self._update_frame(now_s, result, fcw)
        if status is not None:
            faults = set(status.get("faults", ()))
            state, fps = status["state"], status.get("fps")
            latency = None if self.deterministic else status.get("latency_p99_ms")
        else:
            faults = self.faults(now_s)
            state, fps = overall_state(faults, self._started), self._frame_rate()
            latency = None if self.deterministic else self._latency_p99()
        self.scheduler.update("status", [("HW_STATUS", hm.status_signals(state, faults, self.faults_known, fps,
                                                                        latency))], now_s)
        frames = self.scheduler.due(now_s)
        for m in frames:
            m.timestamp = self.clock_base_s + m.timestamp
        self.output.send(frames, now_s)
        return frames

    def on_result(self, result: Any, *_frame: Any, fcw: Optional[Any] = None,
                  status: Optional[Mapping[str, Any]] = None) -> VehicleState:
        """One frame result on its own clock (``result.t_s``): inputs up to then, then publish. Fits the
        ``on_result`` hook of ``app.replay.replay`` as it is (a scenario's frame, passed second, is
        not needed here)."""
        state = self.vehicle_state(result.t_s)
        self.publish(result.t_s, result, fcw, status)
        return state

    def _update_frame(self, now_s: float, result: Any, fcw: Any) -> None:
        self.frames_published += 1
        tracks = list(getattr(result, "tracks", []) or [])
        lead = getattr(result, "lead", None)
        speed_ok = self._state is not None and self._state.speed_mps is not None
        if fcw is None:
            ttc, src = hm.ttc_of(lead)
            fcw = {"level": FcwLevel.NONE, "ttc_s": ttc, "ttc_source": src}
        get = fcw.get if isinstance(fcw, Mapping) else (lambda k, d=None: getattr(fcw, k, d))
        available = get("available")
        ttc = get("ttc_s")
        f = hm.fcw_signals(get("level", FcwLevel.NONE), speed_ok if available is None else available,
                           get("ttc_used_s") if ttc is None else ttc, get("ttc_source") or TtcSource.NONE, lead)
        self.scheduler.update("fcw", [("HW_FCW", f)], now_s, key=(f["FCW_LEVEL"], f["FCW_AVAILABLE"]))
        lead_frames = [("HW_LEAD", hm.lead_signals(lead)), ("HW_LEAD_TTC", hm.lead_ttc_signals(lead))]
        self.scheduler.update("lead", lead_frames, now_s)
        chosen = hm.objects_by_range(tracks, self.max_objects)
        header = hm.object_header_signals(getattr(result, "frame", 0), len(chosen), None if lead is None else lead.id)
        objs = [("HW_OBJECT_HEADER", header)]
        for i, t in enumerate(chosen):
            p0, p1 = hm.object_signals(i, t, self.camera)
            objs += [("HW_OBJECT", p0), ("HW_OBJECT", p1)]
        self.scheduler.update("objects", objs, now_s)
        cal = getattr(result, "calibration", None)
        if cal is not None:  # none from the single-image stages: the frame is not sent then
            p0, p1 = hm.calibration_signals(cal, self._cal_limits)
            self.scheduler.update("calibration", [("HW_CALIBRATION", p0), ("HW_CALIBRATION", p1)], now_s)

    # ---- end ---------------------------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        s: dict[str, Any] = {"frames_sent": self.output.sent, "send_errors": self.output.send_errors,
                             "groups_sent": dict(self.scheduler.sent_count)}
        if self.output.log_path:
            s["output_log"] = str(self.output.log_path)
        if self.input_log is not None:
            s["input_log"] = self.input_log.summary()
        if self.vehicle is not None:
            s["vehicle_inputs"] = self.vehicle.stats()
            s["input"] = self.input_counts()
            s["never_decoded"] = self.vehicle.never_decoded() if self.input_log is not None else []
        return s

    def input_counts(self) -> dict[str, Any]:
        """Every vehicle-bus frame read, accounted once: {"read", "used", "dropped": {reason: n}} and, in
        replay, "not_reached" (frames of the log after the recording's end). read = used + dropped (+ not_reached)."""
        if self.vehicle is None:
            return {}
        v = self.vehicle.counts()
        dropped = dict(v["dropped"])
        out: dict[str, Any] = {"read": v["used"] + sum(dropped.values()), "used": v["used"]}
        if self.input_log is not None and self.play_bus is None:
            r = self.input_log.counts()
            for k, n in r["dropped"].items():
                dropped[k] = dropped.get(k, 0) + n
            out.update(read=r["read"], not_reached=r["not_reached"])
        out["dropped"] = dict(sorted(dropped.items()))
        return out

    def close(self) -> None:
        self.output.close()
        for b in {id(x): x for x in (self.output.bus, self.rx_bus, self.play_bus) if x is not None}.values():
            b.shutdown()

    def __enter__(self) -> "CanSession":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

