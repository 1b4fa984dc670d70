"""Message ids, payload layouts and version constants of the cabin-MCU protocol.

docs/firmware-protocol.md is the contract; this file is its executable form. Every payload is a fixed
little-endian layout (a `struct.Struct`). Physical values are SI units sent as unsigned fixed point
(u16, 0.01 per count, so 0..655.34); the raw value 0xFFFF means "not available". Constructing a
message checks every field, so an out-of-range value raises `FieldRangeError` both when the host
builds a message to send and when a received payload decodes to a value the protocol does not
allow. A frame whose CRC is right can still carry nonsense (a byte flipped before the CRC was computed,
a peer out of step), so a received payload is also checked against what the peer's protocol version
sends: from a peer of this minor version (or an older one) the payload has exactly its layout's length
and every reserved bit is 0; from a newer minor one (which may append fields and use reserved bits) it is
at least the layout's length and reserved bits are ignored. Anything else is a `PayloadLengthError` or
a `FieldRangeError`, counted by the decoder as a bad payload.
"""
from __future__ import annotations

import math
import struct
from dataclasses import astuple, dataclass
from enum import IntEnum, IntFlag
from typing import ClassVar

from app.contracts.fcw_level import FcwLevel

from .errors import FieldRangeError, PayloadLengthError, UnknownMessageError

PROTOCOL_MAJOR = 1  # a change here means an incompatible layout: the host refuses the MCU
PROTOCOL_MINOR = 0  # new messages or fields appended at the end of a payload; compatible

NOT_AVAILABLE = 0xFFFF  # u16 fixed-point value meaning "no value" (no lead, unknown speed...)
CENTI = 100  # counts per SI unit in the u16 fixed-point fields (resolution 0.01)
MAX_CENTI_VALUE = (NOT_AVAILABLE - 1) / CENTI  # 655.34, the largest value a u16 field carries
MAX_SPEED_MPS = 150.0  # m/s (540 km/h); a vehicle speed above it is a corrupt value, not a car


class MsgId(IntEnum):
    """Message ids: 0x01-0x0F link management, 0x10-0x1F host to MCU, 0x20-0x2F MCU to host."""

    HELLO = 0x01
    HELLO_ACK = 0x02
    HEARTBEAT = 0x03
    WARNING = 0x10
    VEHICLE_SIGNALS = 0x20


# The WARNING message's level is the FCW state machine's output, with the same numbers on the wire.
WarningLevel = FcwLevel

_LEVELS = frozenset(int(v) for v in WarningLevel)
_LEVELS_TEXT = ", ".join(f"{int(v)} ({v.label})" for v in WarningLevel)


class HostStatus(IntFlag):
    """HEARTBEAT.status bits sent by the host."""

    SYSTEM_OK = 0x01  # camera pipeline healthy: FCW available (MCU shows "unavailable" otherwise)


class McuStatus(IntFlag):
    """HEARTBEAT.status bits sent by the MCU."""

    BUZZER_FAULT = 0x01
    LED_FAULT = 0x02
    VEHICLE_BUS_FAULT = 0x04  # vehicle signals cannot be read (speed/brake/turn inputs dead)
    WATCHDOG_RESET = 0x08  # the last reset was caused by the MCU's watchdog


class SignalFlags(IntFlag):
    """VEHICLE_SIGNALS.flags bits; bits 3-7 are reserved: sent as 0, ignored on receipt."""

    BRAKE = 0x01
    TURN_LEFT = 0x02
    TURN_RIGHT = 0x04


def _check_uint(msg: str, field: str, value: object, bits: int, low: int = 0) -> None:
    high = (1 << bits) - 1
    if isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high:
        raise FieldRangeError(f"{msg}.{field}={value!r} is not an integer in {low}..{high}")


def _check_centi(msg: str, field: str, value: object) -> None:
    if value is None:
        return
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not ok or not math.isfinite(value) or not 0.0 <= value <= MAX_CENTI_VALUE:
        raise FieldRangeError(f"{msg}.{field}={value!r} is outside 0..{MAX_CENTI_VALUE} (None: not available)")


def _check_bool(msg: str, field: str, value: object) -> None:
    if not isinstance(value, bool):
        raise FieldRangeError(f"{msg}.{field}={value!r} is not a bool")


def to_centi(value: float | None) -> int:
    """SI value (already range-checked) to its u16 count; None -> NOT_AVAILABLE."""
    return NOT_AVAILABLE if value is None else round(value * CENTI)


def from_centi(raw: int) -> float | None:
    """u16 count to its SI value; NOT_AVAILABLE -> None."""
    return None if raw == NOT_AVAILABLE else raw / CENTI


class Message:
    """Base of all messages: a frozen dataclass with MSG_ID, LAYOUT, SENDER and RATE."""

    MSG_ID: ClassVar[MsgId]
    LAYOUT: ClassVar[struct.Struct]
    SENDER: ClassVar[str]  # "host", "mcu" or "both"
    RATE: ClassVar[str]  # when it is sent (at the default periods), as in the protocol document
    RESERVED: ClassVar[dict[str, int]] = {}  # {raw layout field: its reserved bits}, 0 from this minor version

    def fields(self) -> tuple:
        """The raw layout values, in layout order (the dataclass fields, unless scaled)."""
        return astuple(self)

    @classmethod
    def from_fields(cls, *raw):
        """The message from raw layout values (inverse of fields())."""
        return cls(*raw)

    def pack(self) -> bytes:
        return self.LAYOUT.pack(*self.fields())

    @classmethod
    def unpack(cls, payload: bytes, peer_minor: int = PROTOCOL_MINOR):
        """The message in a received payload, checked as sent by a peer of protocol minor ``peer_minor``."""
        if len(payload) < cls.LAYOUT.size:
            raise PayloadLengthError(
                f"{cls.MSG_ID.name} payload is {len(payload)} bytes, its layout needs {cls.LAYOUT.size}")
        raw = cls.LAYOUT.unpack_from(payload)
        # HELLO and HELLO_ACK state their sender's version themselves
        own = raw[cls.LAYOUT_FIELDS.index("protocol_minor")] if "protocol_minor" in cls.LAYOUT_FIELDS else 0
        newer = max(peer_minor, own) > PROTOCOL_MINOR
        if len(payload) > cls.LAYOUT.size and not newer:
            raise PayloadLengthError(
                f"{cls.MSG_ID.name} payload is {len(payload)} bytes, its layout in protocol "
                f"{PROTOCOL_MAJOR}.{PROTOCOL_MINOR} is {cls.LAYOUT.size}")
        if not newer:
            names = cls.LAYOUT_FIELDS
            for name, mask in cls.RESERVED.items():
                value = raw[names.index(name)]
                if value & mask:
                    raise FieldRangeError(f"{cls.MSG_ID.name}.{name}=0x{value:02X} has reserved bits set "
                                          f"(0x{value & mask:02X})")
        return cls.from_fields(*raw)


@dataclass(frozen=True)
class Hello(Message):
    """Host -> MCU: opens (or re-opens) the session and states the host's protocol version."""

    MSG_ID: ClassVar[MsgId] = MsgId.HELLO
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<BBHH")
    LAYOUT_FIELDS: ClassVar[tuple[str, ...]] = ("protocol_major", "protocol_minor", "heartbeat_period_ms",
                                                "host_timeout_ms")
    SENDER: ClassVar[str] = "host"
    RATE: ClassVar[str] = "every 250 ms until HELLO_ACK; again after silence or an MCU reset"

    protocol_major: int = PROTOCOL_MAJOR
    protocol_minor: int = PROTOCOL_MINOR
    heartbeat_period_ms: int = 100  # how often the host sends HEARTBEAT and WARNING
    host_timeout_ms: int = 500  # MCU: no frame from the host this long -> host lost, buzzer off

    def __post_init__(self):
        _check_uint("HELLO", "protocol_major", self.protocol_major, 8)
        _check_uint("HELLO", "protocol_minor", self.protocol_minor, 8)
        _check_uint("HELLO", "heartbeat_period_ms", self.heartbeat_period_ms, 16, low=1)
        _check_uint("HELLO", "host_timeout_ms", self.host_timeout_ms, 16, low=1)


FW_NAME_LEN = 8  # bytes of HELLO_ACK.fw_name: printable ASCII, NUL-padded


@dataclass(frozen=True)
class HelloAck(Message):
    """MCU -> host: the answer to every HELLO, with the MCU's protocol version and firmware id."""

    MSG_ID: ClassVar[MsgId] = MsgId.HELLO_ACK
    LAYOUT: ClassVar[struct.Struct] = struct.Struct(f"<BBBBB{FW_NAME_LEN}s")
    LAYOUT_FIELDS: ClassVar[tuple[str, ...]] = ("protocol_major", "protocol_minor", "fw_major", "fw_minor",
                                                "fw_patch", "fw_name")
    SENDER: ClassVar[str] = "mcu"
    RATE: ClassVar[str] = "once per HELLO received, within 50 ms"

    protocol_major: int = PROTOCOL_MAJOR
    protocol_minor: int = PROTOCOL_MINOR
    fw_major: int = 0
    fw_minor: int = 0
    fw_patch: int = 0
    fw_name: str = ""

    def __post_init__(self):
        for name in ("protocol_major", "protocol_minor", "fw_major", "fw_minor", "fw_patch"):
            _check_uint("HELLO_ACK", name, getattr(self, name), 8)
        name = self.fw_name
        if not isinstance(name, str) or len(name) > FW_NAME_LEN or not all(" " <= c <= "~" for c in name):
            raise FieldRangeError(
                f"HELLO_ACK.fw_name={name!r} is not up to {FW_NAME_LEN} printable ASCII characters")

    @property
    def firmware(self) -> str:
        return f"{self.fw_name} {self.fw_major}.{self.fw_minor}.{self.fw_patch}".strip()

    def fields(self) -> tuple:
        return (self.protocol_major, self.protocol_minor, self.fw_major, self.fw_minor, self.fw_patch,
                self.fw_name.encode("ascii"))

    @classmethod
    def from_fields(cls, *raw):
        *numbers, name = raw
        text = name.rstrip(b"\0")
        if b"\0" in text:
            raise FieldRangeError(f"HELLO_ACK.fw_name={name!r} has a NUL before its last character")
        return cls(*numbers, fw_name=text.decode("latin-1"))


@dataclass(frozen=True)
class Heartbeat(Message):
    """Both ways: "I am alive", with uptime (an MCU reset shows as uptime going back) and status."""

    MSG_ID: ClassVar[MsgId] = MsgId.HEARTBEAT
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<IB")
    LAYOUT_FIELDS: ClassVar[tuple[str, ...]] = ("uptime_ms", "status")
    SENDER: ClassVar[str] = "both"
    # neither side's status bits: the host's (HostStatus) and the MCU's (McuStatus) together
    RATE: ClassVar[str] = "every 100 ms, each side"

    RESERVED: ClassVar[dict[str, int]] = {"status": 0xFF & ~0x0F}

    uptime_ms: int = 0  # since the sender started, wraps after 2^32 ms (49.7 days)
    status: int = 0  # HostStatus bits from the host, McuStatus bits from the MCU

    def __post_init__(self):
        _check_uint("HEARTBEAT", "uptime_ms", self.uptime_ms, 32)
        _check_uint("HEARTBEAT", "status", self.status, 8)
        if self.status & self.RESERVED["status"]:
            raise FieldRangeError(f"HEARTBEAT.status=0x{self.status:02X} has reserved bits set "
                                  f"(0x{self.status & self.RESERVED['status']:02X})")


@dataclass(frozen=True)
class FcwWarning(Message):
    """Host -> MCU: the forward-collision warning to show (LED) and sound (buzzer)."""

    MSG_ID: ClassVar[MsgId] = MsgId.WARNING
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<BHH")
    LAYOUT_FIELDS: ClassVar[tuple[str, ...]] = ("level", "ttc", "lead_range")
    SENDER: ClassVar[str] = "host"
    RATE: ClassVar[str] = "on every change, and repeated every 100 ms"

    level: WarningLevel = WarningLevel.NONE
    ttc_s: float | None = None  # time to collision with the lead vehicle; None: not available
    lead_range_m: float | None = None  # range to the lead vehicle; None: no lead

    def __post_init__(self):
        level = self.level
        if isinstance(level, bool) or not isinstance(level, int) or level not in _LEVELS:
            raise FieldRangeError(f"WARNING.level={self.level!r} is not one of {_LEVELS_TEXT}")
        object.__setattr__(self, "level", WarningLevel(self.level))
        _check_centi("WARNING", "ttc_s", self.ttc_s)
        _check_centi("WARNING", "lead_range_m", self.lead_range_m)

    def fields(self) -> tuple:
        return (int(self.level), to_centi(self.ttc_s), to_centi(self.lead_range_m))

    @classmethod
    def from_fields(cls, *raw):
        level, ttc, lead_range = raw
        return cls(level, from_centi(ttc), from_centi(lead_range))


@dataclass(frozen=True)
class VehicleSignals(Message):
    """MCU -> host: the vehicle signals the MCU reads (speed sensor, brake switch, turn stalk)."""

    MSG_ID: ClassVar[MsgId] = MsgId.VEHICLE_SIGNALS
    LAYOUT: ClassVar[struct.Struct] = struct.Struct("<HB")
    LAYOUT_FIELDS: ClassVar[tuple[str, ...]] = ("speed", "flags")
    SENDER: ClassVar[str] = "mcu"
    RESERVED: ClassVar[dict[str, int]] = {"flags": 0xFF & ~0x07}
    RATE: ClassVar[str] = "every 50 ms, and at once when brake or a turn signal changes"

    speed_mps: float | None = None  # vehicle speed magnitude; None: unknown
    brake: bool = False
    turn_left: bool = False
    turn_right: bool = False

    def __post_init__(self):
        _check_centi("VEHICLE_SIGNALS", "speed_mps", self.speed_mps)
        if self.speed_mps is not None and self.speed_mps > MAX_SPEED_MPS:
            raise FieldRangeError(f"VEHICLE_SIGNALS.speed_mps={self.speed_mps!r} is above {MAX_SPEED_MPS:g} m/s, "
                                  f"faster than any road vehicle (None: unknown)")
        for name in ("brake", "turn_left", "turn_right"):
            _check_bool("VEHICLE_SIGNALS", name, getattr(self, name))

    def fields(self) -> tuple:
        flags = ((SignalFlags.BRAKE if self.brake else 0) | (SignalFlags.TURN_LEFT if self.turn_left else 0)
                 | (SignalFlags.TURN_RIGHT if self.turn_right else 0))
        return (to_centi(self.speed_mps), int(flags))

    @classmethod
    def from_fields(cls, *raw):
        speed, flags = raw
        return cls(from_centi(speed), bool(flags & SignalFlags.BRAKE), bool(flags & SignalFlags.TURN_LEFT),
                   bool(flags & SignalFlags.TURN_RIGHT))


MESSAGES: dict[int, type[Message]] = {cls.MSG_ID: cls for cls in (Hello, HelloAck, Heartbeat, FcwWarning, VehicleSignals)}
MAX_PAYLOAD_LEN = 64  # bytes; every layout is far below it, so later minor versions can grow


def decode(msg_id: int, payload: bytes, peer_minor: int = PROTOCOL_MINOR) -> Message:
    """The message for one frame's id and payload, sent by a peer of protocol minor ``peer_minor``; raises a
    ProtocolError naming what was wrong."""
    cls = MESSAGES.get(msg_id)
    if cls is None:
        raise UnknownMessageError(f"message id 0x{msg_id:02X} is not defined in protocol {PROTOCOL_MAJOR}.{PROTOCOL_MINOR}")
    return cls.unpack(payload, peer_minor)
