"""Vehicle inputs from the car's own bus: ego speed, yaw rate, brake, turn signals.

Each input is mapped in the configuration to a DBC file, a message and one or more signals (the
``vehicle`` section, see ``config_schema``), converted to SI units. A ``VehicleState`` snapshot gives
every input's value, age and stale flag on the bus clock. An input that is stale (no frame for
``stale_after_s``) or never arrived has value ``None``: consumers are told "not available", never a
guessed or held value. Once the start-up grace period (the same ``stale_after_s``) has passed, a
stale input is listed in ``stale_inputs``, and a stale ego speed is the health fault
``ego_speed_stale``. Invalid frames (wrong length, undecodable) are counted in ``stats()``; they
make no value, so an input fed only by them goes stale.
"""
from __future__ import annotations

import difflib
import math
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping, Optional

import can

from .config_schema import INPUTS
from .database import DbcError, load_dbc
from .parser import CanParser

UNIT_TO_SI = {"m/s": 1.0, "mps": 1.0, "km/h": 1 / 3.6, "kph": 1 / 3.6, "kmh": 1 / 3.6, "mph": 0.44704,
              "rad/s": 1.0, "deg/s": math.pi / 180, "degree/s": math.pi / 180, "°/s": math.pi / 180}
# parser drop reasons -> the reasons a frame of the vehicle bus is counted under when no input uses it
REASONS = {"wrong_channel": "wrong_channel", "unknown_id": "unknown_id", "wrong_length": "wrong_length",
           "decode_error": "undecodable", "bad_checksum": "undecodable", "counter_jump": "undecodable",
           "error_frame": "error_frame", "remote_frame": "remote_frame"}
COMBINE = {"mean": lambda v: sum(v) / len(v), "min": min, "max": max, "first": lambda v: v[0]}


class VehicleInputError(ValueError):
    """A vehicle-input mapping that cannot be used; the message names the configuration key."""


@dataclass(frozen=True)
class InputSpec:
    name: str
    dbc: str
    message: str
    signals: tuple[str, ...]
    combine: str = "mean"
    factor: float = 1.0            # unit conversion to SI times the configured scale
    offset: float = 0.0
    true_value: Optional[int] = None  # flags: raw value meaning on; None = any non-zero
    stale_after_s: float = 0.5

    @property
    def is_flag(self) -> bool:
        return INPUTS[self.name][0] == "flag"


@dataclass(frozen=True)
class InputValue:
    value: Any                     # SI number or bool; None unless configured and fresh
    age_s: Optional[float]         # since the last accepted frame; None if never
    stale: bool                    # configured but missing or too old
    configured: bool

    @property
    def available(self) -> bool:
        return self.value is not None


@dataclass(frozen=True)
class VehicleState:
    t_s: float
    inputs: Mapping[str, InputValue]
    stale_inputs: tuple[str, ...] = ()     # configured inputs missing or stale past the start-up grace
    faults: frozenset[str] = field(default_factory=frozenset)  # health registry names: ego_speed_stale

    @property
    def ego_speed_fresh(self) -> Optional[bool]:
        """For the health monitor: None = no ego speed configured, False = the ego_speed_stale fault."""
        if not self.inputs["speed"].configured:
            return None
        return "speed" not in self.stale_inputs

    def _v(self, name: str) -> Any:
        iv = self.inputs.get(name)
        return iv.value if iv else None

    @property
    def speed_mps(self) -> Optional[float]:
        return self._v("speed")

    @property
    def yaw_rate_rps(self) -> Optional[float]:
        return self._v("yaw_rate")

    @property
    def brake(self) -> Optional[bool]:
        return self._v("brake")

    @property
    def turn_left(self) -> Optional[bool]:
        return self._v("turn_left")

    @property
    def turn_right(self) -> Optional[bool]:
        return self._v("turn_right")


def _close(word: str, options: Iterable[str]) -> str:
    m = difflib.get_close_matches(word, list(options), n=1)
    return f" (did you mean {m[0]}?)" if m else ""


def specs_from_config(vehicle: Mapping[str, Any], databases: Optional[dict] = None) -> list[InputSpec]:
    """The configured inputs of a validated ``vehicle`` section, each checked against its DBC
    (``databases``, if given, receives the loaded DBCs by path)."""
    specs = []
    dbs = {} if databases is None else databases
    for name, (kind, _si, _units, stale_default, _what, _why) in INPUTS.items():
        message = vehicle.get(f"{name}_message", "")
        if not message:
            continue
        key = f"vehicle.{name}"
        dbc = vehicle.get(f"{name}_dbc") or vehicle.get("dbc", "")
        if not dbc:
            raise VehicleInputError(f"{key}_message is set but neither {key}_dbc nor vehicle.dbc names a DBC file")
        if dbc not in dbs:
            try:
                dbs[dbc] = load_dbc(dbc, strict=False)
            except DbcError as exc:
                raise VehicleInputError(f"{key}_dbc / vehicle.dbc: {exc}") from None
        db = dbs[dbc]
        try:
            msg = db.get_message_by_name(message)
        except KeyError:
            raise VehicleInputError(f"{key}_message: {message} is not in {dbc}"
                                    f"{_close(message, (m.name for m in db.messages))}") from None
        signals = tuple(s.strip() for s in vehicle.get(f"{name}_signals", "").split(",") if s.strip())
        if not signals:
            raise VehicleInputError(f"{key}_signals: give the signal name(s) of {message}")
        names = {s.name: s for s in msg.signals}
        for s in signals:
            if s not in names:
                raise VehicleInputError(f"{key}_signals: {s} is not a signal of {message} in {dbc}{_close(s, names)}")
        factor, offset, true_value = 1.0, 0.0, None
        if kind == "number":
            unit = vehicle.get(f"{name}_unit", "dbc")
            if unit == "dbc":
                units = {(names[s].unit or "").strip() for s in signals}
                if len(units) != 1 or next(iter(units)).lower() not in UNIT_TO_SI:
                    raise VehicleInputError(f"{key}_unit: the DBC gives {sorted(units)} for {', '.join(signals)}; "
                                            f"set {name}_unit to one of {INPUTS[name][2].replace('|', ', ')}")
                unit = next(iter(units)).lower()
            factor = UNIT_TO_SI[unit] * float(vehicle.get(f"{name}_scale", 1.0))
            offset = float(vehicle.get(f"{name}_offset", 0.0))
        else:
            tv = int(vehicle.get(f"{name}_true_value", -1))
            true_value = None if tv < 0 else tv
        specs.append(InputSpec(name, str(dbc), message, signals, vehicle.get(f"{name}_combine", "mean"),
                               factor, offset, true_value, float(vehicle.get(f"{name}_stale_after_s", stale_default))))
    return specs


class VehicleInput:
    """Feed it every frame of the vehicle bus (``on_message``); ask ``snapshot(now)`` per camera frame.

    Times are on the bus clock: a frame's timestamp (or the ``t_s`` given with it) and ``now`` must
    come from the same clock (the replay clock in replay, the receive clock live).
    """

    def __init__(self, specs: Iterable[InputSpec], channel: Optional[str] = None,
                 databases: Optional[Mapping[str, Any]] = None):
        self.specs = {s.name: s for s in specs}
        self._parsers: dict[str, CanParser] = {}
        for dbc in sorted({s.dbc for s in self.specs.values()}):
            db = (databases or {}).get(dbc) or load_dbc(dbc, strict=False)
            mine = [s for s in self.specs.values() if s.dbc == dbc]
            timeouts = {}
            for s in mine:
                timeouts[s.message] = min(timeouts.get(s.message, math.inf), s.stale_after_s)
            # A car's counters and checksums follow the maker's own rules: not checked here.
            self._parsers[dbc] = CanParser(db, sorted(timeouts), timeouts, checksum=None, check_counter=False,
                                           channel=channel or None)
        self.start_s: Optional[float] = None
        self.channel = channel or None
        self.used = 0                      # frames at least one input was decoded from
        self.drops: Counter = Counter()    # every other frame, by reason (REASONS)
        # for the configured messages' ids: (reason, detail) -> frames, to say why one was never decoded
        self._why: dict[int, Counter] = {mid: Counter() for mid in self.frame_ids()}

    @classmethod
    def from_config(cls, vehicle: Mapping[str, Any]) -> "VehicleInput":
        databases: dict = {}
        specs = specs_from_config(vehicle, databases)
        return cls(specs, vehicle.get("channel") or None, databases)

    def frame_ids(self) -> set[int]:
        """The frame ids the configured inputs are decoded from."""
        return {self._parsers[s.dbc].db.get_message_by_name(s.message).frame_id for s in self.specs.values()}

    def on_message(self, msg: can.Message, t_s: Optional[float] = None) -> bool:
        """Takes one frame of the vehicle bus; True if an input was decoded from it, else it is counted
        under the reason it was dropped for."""
        t = msg.timestamp if t_s is None else t_s
        if self.start_s is None:
            self.start_s = t
        reasons = []
        for p in self._parsers.values():
            if p.update(msg, t) is not None:
                self.used += 1
                return True
            reasons.append(p.last_drop or "unknown_id")
        # the most telling reason among the DBCs: one that knows the id says more than one that does not
        reason = REASONS.get(min(reasons, key=lambda r: r == "unknown_id"), "undecodable") if reasons else "unknown_id"
        self.drops[reason] += 1
        why = self._why.get(msg.arbitration_id)
        if why is not None:
            detail = {"wrong_channel": str(msg.channel), "wrong_length": len(msg.data)}.get(reason, "")
            why[(reason, detail)] += 1
        return False

    def counts(self) -> dict[str, Any]:
        """{"used": frames an input was decoded from, "dropped": {reason: frames}}."""
        return {"used": self.used, "dropped": dict(sorted(self.drops.items()))}

    def never_decoded(self) -> list[str]:
        """For every configured input of which no frame was ever decoded: one line naming the message and
        the likely cause (the frames of its id that were dropped, and why)."""
        out = []
        for name, spec in self.specs.items():
            p = self._parsers[spec.dbc]
            msg = p.db.get_message_by_name(spec.message)
            if p.age_s(spec.message) is not None:
                continue
            why = self._why.get(msg.frame_id, Counter())
            head = f"vehicle.{name}: {spec.message} (id 0x{msg.frame_id:X}) was never decoded: "
            by_reason: Counter = Counter()
            for (reason, _d), n in why.items():
                by_reason[reason] += n
            if not by_reason:
                out.append(head + f"no frame with id 0x{msg.frame_id:X} was read; check {name}_message and the "
                                  f"DBC, or that the log is of the right bus")
                continue
            reason, n = by_reason.most_common(1)[0]
            details = sorted({str(d) for (r, d) in why if r == reason})
            if reason == "wrong_channel":
                cause = (f"its {n} frames came on channel {', '.join(details)} but vehicle.channel is "
                         f"{self.channel}: set vehicle.log_channels (e.g. 'any', or '{details[0]}={self.channel}') "
                         f"or vehicle.channel")
            elif reason == "wrong_length":
                cause = (f"its {n} frames are {', '.join(details)} bytes long but the DBC gives {msg.length}: "
                         f"the DBC does not match this car, or the log lost bytes")
            else:
                cause = (f"its {n} frames could not be decoded with the DBC ({reason}): check the signals of "
                         f"{spec.message} (length, start bit) in {Path(spec.dbc).name}")
            out.append(head + cause)
        return out

    def _read(self, spec: InputSpec, now: float) -> InputValue:
        p = self._parsers[spec.dbc]
        age = p.age_s(spec.message, spec.signals[0], now)
        for s in spec.signals[1:]:
            a = p.age_s(spec.message, s, now)
            age = None if a is None or age is None else max(age, a)
        stale = age is None or age > spec.stale_after_s
        value = None
        if not stale:
            raw = [p.value(spec.message, s) for s in spec.signals]
            if all(isinstance(v, (int, float)) for v in raw):
                x = COMBINE[spec.combine](raw)
                if spec.is_flag:
                    value = bool(x != 0) if spec.true_value is None else bool(x == spec.true_value)
                else:
                    value = x * spec.factor + spec.offset
        return InputValue(value, age, stale, True)

    def snapshot(self, now_s: float) -> VehicleState:
        if self.start_s is None:
            self.start_s = now_s
        inputs = {name: InputValue(None, None, False, False) for name in INPUTS}
        stale = []
        for name, spec in self.specs.items():
            inputs[name] = iv = self._read(spec, now_s)
            if iv.stale and now_s - self.start_s >= spec.stale_after_s:
                stale.append(name)
        faults = frozenset({"ego_speed_stale"} if "speed" in stale else ())
        return VehicleState(now_s, inputs, tuple(stale), faults)

    def stats(self) -> dict[str, Any]:
        return {Path(dbc).name: p.stats() for dbc, p in self._parsers.items()}
