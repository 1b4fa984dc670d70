"""CanParser: frames in, the latest decoded values out, never an exception.

Like opendbc's parser it checks what a receiver must check before it trusts a frame, in this order,
and counts each frame it drops under one reason:

- ``error_frame`` / ``remote_frame``: not data;
- ``unknown_id``: no message of the parser has this id (on a car bus most frames are of this kind:
  the parser only decodes the messages it was given);
- ``wrong_length``: the data length differs from the DBC's;
- ``bad_checksum``: (messages with a CHECKSUM byte, when a checksum function is given);
- ``counter_jump``: (messages with a COUNTER, when counters are checked) the counter skipped or
  repeated on 5 frames in a row, as opendbc does: one lost frame is counted in ``counter_jumps``
  but the frame itself is good and is used; a sender stuck or garbled long enough is not;
- ``decode_error``: cantools could not decode it.

Freshness is kept per signal on the bus clock (the frame's timestamp, or the time given to
``update``): ``age_s(message, signal, now)`` and ``is_stale(...)`` against the timeouts.
"""
from __future__ import annotations

import math
from collections import Counter
from typing import Any, Callable, Iterable, Mapping, Optional, Union

import can
from cantools.database.can import Database, Message

from .checksum import frame_checksum
from .packer import CHECKSUM, COUNTER, SNA, checksum_byte

MAX_BAD_COUNTER = 5  # consecutive counter errors before frames are dropped (opendbc's value)

ChecksumFn = Callable[[int, bytes, int], int]


class _State:
    __slots__ = ("message", "checksum_byte", "counter_mod", "last_counter", "bad_counter", "values",
                 "signal_t", "t", "timeout_s")

    def __init__(self, message: Message, timeout_s: float, check_counter: bool, checksum: bool):
        self.message = message
        self.checksum_byte = checksum_byte(message) if checksum else None
        self.counter_mod = 0
        if check_counter and any(s.name == COUNTER for s in message.signals):
            self.counter_mod = 1 << message.get_signal_by_name(COUNTER).length
        self.last_counter: Optional[int] = None
        self.bad_counter = 0
        self.values: dict[str, Any] = {}
        self.signal_t: dict[str, float] = {}
        self.t: Optional[float] = None
        self.timeout_s = timeout_s


class CanParser:
    """Decodes ``messages`` (names or frame ids; None = every message of the DBC).

    ``timeouts``: seconds after which a message's signals are stale, by message name (a missing
    name uses ``default_timeout_s``). ``checksum``: a function (frame_id, data, checksum_byte) ->
    expected byte for messages with a CHECKSUM signal (Headway's own: ``frame_checksum``); None
    skips the check. ``channel``: only frames from this channel (others are ignored, not dropped).
    """

    def __init__(self, db: Database, messages: Optional[Iterable[Union[str, int]]] = None,
                 timeouts: Optional[Mapping[str, float]] = None, default_timeout_s: float = math.inf,
                 checksum: Optional[ChecksumFn] = frame_checksum, check_counter: bool = True,
                 channel: Optional[str] = None):
        self.db = db
        self.channel = channel or None
        chosen = db.messages if messages is None else [self._lookup(db, m) for m in messages]
        timeouts = dict(timeouts or {})
        self._states: dict[tuple[int, bool], _State] = {}
        self._by_name: dict[str, _State] = {}
        for m in chosen:
            st = _State(m, float(timeouts.get(m.name, default_timeout_s)), check_counter, checksum is not None)
            self._states[(m.frame_id, bool(m.is_extended_frame))] = st
            self._by_name[m.name] = st
        self._checksum = checksum
        self.received = 0
        self.accepted = 0
        self.ignored = 0          # frames of another channel
        self.counter_jumps = 0    # every counter discontinuity, dropped or not
        self.drops: Counter[str] = Counter()
        self.last_drop: Optional[str] = None  # why the last frame given to update() was not used

    @staticmethod
    def _lookup(db: Database, m: Union[str, int]) -> Message:
        try:
            return db.get_message_by_frame_id(m) if isinstance(m, int) else db.get_message_by_name(m)
        except KeyError:
            raise KeyError(f"{m}: no such message in the DBC") from None

    # ---- receiving ---------------------------------------------------------------------------------
    def update(self, msg: can.Message, t_s: Optional[float] = None) -> Optional[tuple[str, dict]]:
        """Takes one frame; returns (message name, decoded values) if it was accepted, else None."""
        self.last_drop: Optional[str] = None
        try:
            return self._update(msg, msg.timestamp if t_s is None else t_s)
        except Exception:  # a frame must never take the receiver down
            return self._drop("decode_error")

    def _drop(self, reason: str) -> None:
        """Counts a dropped frame; ``last_drop`` tells the caller why the frame just given was not used."""
        self.drops[reason] += 1
        self.last_drop = reason

    def _update(self, msg: can.Message, t: float) -> Optional[tuple[str, dict]]:
        self.received += 1
        if self.channel is not None and msg.channel is not None and str(msg.channel) != self.channel:
            self.ignored += 1
            self.last_drop = "wrong_channel"
            return None
        if msg.is_error_frame:
            return self._drop("error_frame")
        if msg.is_remote_frame:
            return self._drop("remote_frame")
        st = self._states.get((msg.arbitration_id, bool(msg.is_extended_id)))
        if st is None:
            return self._drop("unknown_id")
        data = bytes(msg.data)
        if len(data) != st.message.length:
            return self._drop("wrong_length")
        if st.checksum_byte is not None and self._checksum is not None:
            if data[st.checksum_byte] != self._checksum(st.message.frame_id, data, st.checksum_byte):
                return self._drop("bad_checksum")
        values = st.message.decode(data, decode_choices=True, scaling=True)
        if st.counter_mod and not self._counter_ok(st, int(values[COUNTER])):
            return self._drop("counter_jump")
        out = {}
        for k, v in values.items():
            if k in (COUNTER, CHECKSUM):
                out[k] = int(v)
            elif hasattr(v, "name"):  # a value-table entry: SNA -> None, others -> the raw number
                out[k] = None if v.name == SNA else v.value
            else:
                out[k] = v
        st.values.update(out)
        for k in out:
            st.signal_t[k] = t
        st.t = t
        self.accepted += 1
        return st.message.name, out

    def _counter_ok(self, st: _State, counter: int) -> bool:
        if st.last_counter is not None and counter != (st.last_counter + 1) % st.counter_mod:
            self.counter_jumps += 1
            st.bad_counter = min(st.bad_counter + 1, MAX_BAD_COUNTER)
        elif st.bad_counter > 0:
            st.bad_counter -= 1
        st.last_counter = counter
        return st.bad_counter < MAX_BAD_COUNTER

    # ---- reading -------------------------------------------------------------------------------
    def values(self, message: str) -> dict[str, Any]:
        """The latest accepted values of a message (empty before the first)."""
        return dict(self._by_name[message].values)

    def value(self, message: str, signal: str) -> Any:
        return self._by_name[message].values.get(signal)

    def age_s(self, message: str, signal: Optional[str] = None, now_s: float = 0.0) -> Optional[float]:
        """Seconds since the signal (or the message) was last accepted; None if never."""
        st = self._by_name[message]
        t = st.t if signal is None else st.signal_t.get(signal)
        return None if t is None else now_s - t

    def is_stale(self, message: str, signal: Optional[str] = None, now_s: float = 0.0) -> bool:
        age = self.age_s(message, signal, now_s)
        return age is None or age > self._by_name[message].timeout_s

    def stats(self) -> dict[str, Any]:
        return {"received": self.received, "accepted": self.accepted, "ignored_other_channel": self.ignored,
                "counter_jumps": self.counter_jumps, "drops": dict(sorted(self.drops.items()))}
