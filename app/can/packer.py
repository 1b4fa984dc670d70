"""CanPacker: physical signal values in, a finished ``can.Message`` out.

Like opendbc's packer it owns what the sender must get right on every frame: the rolling COUNTER
(+1 per frame of that message, wrapping) and the CHECKSUM byte (CRC-8 SAE J1850, see ``checksum``).
Values are given in the DBC's units. ``None`` or NaN sends the signal's SNA value (not available);
a signal left out is sent as SNA when it has one, else as raw 0. Numbers outside the DBC range are
clamped to it (a TTC of 60 s goes out as the saturated 20.46 s): real measurements never make the
packer fail. Unknown message or signal names are programming errors and raise ``KeyError``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping, Optional

import can
from cantools.database.can import Database, Message

from .checksum import frame_checksum

COUNTER = "COUNTER"
CHECKSUM = "CHECKSUM"
SNA = "SNA"


def checksum_byte(message: Message) -> Optional[int]:
    """Index of the byte holding CHECKSUM, or None; it must be 8 bits on a byte boundary."""
    try:
        sig = message.get_signal_by_name(CHECKSUM)
    except KeyError:
        return None
    aligned = sig.start % 8 == (0 if sig.byte_order == "little_endian" else 7)
    if sig.length != 8 or not aligned:
        raise ValueError(f"{message.name}: CHECKSUM must be one whole byte (8 bits, byte-aligned)")
    return sig.start // 8


def sna_raw(signal) -> Optional[int]:
    """The raw value a signal's value table names SNA, or None."""
    for raw, name in (signal.choices or {}).items():
        if str(name) == SNA:
            return int(raw)
    return None


@dataclass
class _Layout:
    message: Message
    checksum_byte: Optional[int]
    counter_mod: int                     # 0 when the message has no COUNTER
    limits: dict[str, tuple[float, float]]
    defaults: dict[Optional[int], dict[str, Any]]  # mux value (None: not multiplexed) -> signals sent,
    has_sna: frozenset[str]                        # each with what it is sent as when left out
    mux: Optional[str]


def _layout(message: Message) -> _Layout:
    limits, defaults, has_sna = {}, {}, set()
    for s in message.signals:
        lo = s.minimum if s.minimum is not None else -math.inf
        hi = s.maximum if s.maximum is not None else math.inf
        limits[s.name] = (lo, hi)
        if sna_raw(s) is not None:
            has_sna.add(s.name)
            defaults[s.name] = SNA
        else:
            defaults[s.name] = s.offset  # raw 0
    mux_sig = next((s for s in message.signals if s.is_multiplexer), None)
    mux_values = [None] if mux_sig is None else sorted({i for s in message.signals for i in (s.multiplexer_ids or ())})
    active = {i: {s.name: defaults[s.name] for s in message.signals
                  if i is None or s.multiplexer_ids is None or i in s.multiplexer_ids} for i in mux_values}
    try:
        counter = message.get_signal_by_name(COUNTER)
        counter_mod = 1 << counter.length
    except KeyError:
        counter_mod = 0
    return _Layout(message, checksum_byte(message), counter_mod, limits, active, frozenset(has_sna),
                   mux_sig.name if mux_sig else None)


class CanPacker:
    """Packs the messages of one DBC; one instance per sender, since it owns the counters."""

    def __init__(self, db: Database, channel: Optional[str] = None):
        self.db = db
        self.channel = channel
        self._layouts = {m.name: _layout(m) for m in db.messages}
        self._counters = {name: 0 for name in self._layouts}

    def next_counter(self, name: str) -> int:
        return self._counters[name]

    def pack(self, name: str, signals: Mapping[str, Any], timestamp: float = 0.0) -> can.Message:
        try:
            lay = self._layouts[name]
        except KeyError:
            raise KeyError(f"{name}: no such message in the DBC") from None
        mux_value = None
        if lay.mux is not None:
            if lay.mux not in signals:
                raise KeyError(f"{name}: the multiplexer {lay.mux} must be given")
            mux_value = int(signals[lay.mux])
            if mux_value not in lay.defaults:
                raise KeyError(f"{name}: {lay.mux} = {mux_value} has no signals in the DBC")
        values = dict(lay.defaults[mux_value])
        for sig, v in signals.items():
            if sig not in values:
                raise KeyError(f"{name}: no signal {sig}" + (f" for {lay.mux} = {mux_value}" if lay.mux else ""))
            values[sig] = self._value(lay, sig, v)
        if lay.counter_mod:
            values[COUNTER] = self._counters[name]
            self._counters[name] = (self._counters[name] + 1) % lay.counter_mod
        if lay.checksum_byte is not None:
            values[CHECKSUM] = 0
        data = bytearray(lay.message.encode(values, scaling=True, padding=False, strict=False))
        if lay.checksum_byte is not None:
            data[lay.checksum_byte] = frame_checksum(lay.message.frame_id, data, lay.checksum_byte)
        return can.Message(timestamp=timestamp, arbitration_id=lay.message.frame_id,
                           is_extended_id=lay.message.is_extended_frame, data=data, channel=self.channel,
                           is_rx=False)

    @staticmethod
    def _value(lay: _Layout, sig: str, v: Any) -> Any:
        if isinstance(v, str):
            return v  # a value-table name such as "warning"; cantools checks it
        if v is None or (isinstance(v, float) and math.isnan(v)):
            if sig not in lay.has_sna:
                raise ValueError(f"{lay.message.name}.{sig}: has no SNA value, a number is required")
            return SNA
        lo, hi = lay.limits[sig]
        return min(max(v, lo), hi)
