"""Reading a recorded CAN log for replay, in timestamp order, on the frame clock.

Any format python-can reads (``can.LogReader``: candump .log, .asc, .blf, .csv, .trc, also
gzipped). A candump .log is read line by line: a line that is not a candump ``-L`` frame (garbage,
a truncated write, an odd number of hex digits) is counted in ``bad_lines`` and skipped, and only
good lines reach python-can's ``CanutilsLogReader``, which would otherwise stop at the first bad
line. An .asc frame line python-can cannot parse is counted in ``bad_lines`` and skipped the same way
(``_ASCReader``). Other formats are read by python-can directly; if one fails part-way, what was read is
kept and ``read_error`` says where it stopped.

Timestamps are checked before anything else: a frame whose timestamp is more than ``OUTLIER_S`` from
the median of its neighbours (a stray line at time 0, a clock glitch) is dropped and counted as
``time_outlier``; a frame that comes later than ``reorder_window_s`` out of time order is dropped and
counted as ``out_of_order`` (it would set an input back in time). Every frame read ends in exactly one
count: delivered, or dropped by reason (``drops``), or not reached (after the replay's end).

Times: ``t0`` is the log's start as its first CLOCK_FRAMES frames give it (``robust_start``: a stray frame a
second early neither sets it nor shifts the inputs; it is counted as ``out_of_order``); a frame's replay time is ``timestamp - t0 + offset_s``
(``vehicle.log_offset_s``), the clock of the video's frames (frame 0 at t = 0).
"""
from __future__ import annotations

import collections
import gzip
import math
import heapq
import itertools
import re
import statistics
from collections import Counter
from pathlib import Path
from typing import Callable, Iterable, Iterator, Optional, TypeVar, Union

import can

T = TypeVar("T")
# (timestamp) channel id#data [R|T]; data: hex pairs, R[dlc] (remote) or #F + hex (CAN FD)
_CANDUMP = re.compile(r"^\((\d+(?:\.\d+)?)\)\s+\S+\s+([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#"
                      r"(?:R\d?|#[0-9A-Fa-f](?:[0-9A-Fa-f]{2}){0,64}|(?:[0-9A-Fa-f]{2}){0,8})(?:\s+[RTrt])?$")


# Epoch timestamps in a double carry ~0.2 us of noise and logs have 1 us resolution: a frame within
# 1 us of a camera frame's time counts as simultaneous (delivered with that frame).
SAME_TIME_S = 1e-6
# A frame's timestamp further than this from the median of the NEIGHBOURS frames around it is an outlier
# (s): far above any pause between frames of a live bus, far below the jump of a stray line at t = 0.
OUTLIER_S = 10.0
NEIGHBOURS = 9  # odd: the frame and 4 on each side; up to 4 stray frames in a row are recognised
# The log's clock (t0, the time of replay 0) is set by this many first frames (after the outlier filter), not
# by the first alone: a stray frame a second early would shift every input by that second.
CLOCK_FRAMES = 25


def robust_start(items: Iterator[tuple[float, T]], window_s: float, drops: Counter,
                 on_t0: Callable[[float], None]) -> Iterator[tuple[float, T]]:
    """(timestamp, item) pairs as they come; first calls ``on_t0`` with the log's start, fixed by the first
    CLOCK_FRAMES frames: the median of ``t_k - k dt`` (dt: their median gap) is where a steady log starts,
    and t0 is the earliest of them no more than ``window_s`` before it. A frame further before t0 than that is
    outside the log's time: dropped and counted as ``out_of_order``."""
    head = list(itertools.islice(items, CLOCK_FRAMES))
    if not head:
        return
    ts = [t for t, _ in head]
    dt = statistics.median(b - a for a, b in zip(ts, ts[1:])) if len(ts) > 1 else 0.0
    start = statistics.median(t - k * dt for k, t in enumerate(ts))
    t0 = min(t for t in ts if t >= start - window_s)
    on_t0(t0)
    for t, item in itertools.chain(head, items):
        if t < t0 - window_s:
            drops["out_of_order"] += 1
            continue
        yield t, item


def drop_time_outliers(items: Iterator[tuple[float, T]], drops: Counter) -> Iterator[tuple[float, T]]:
    """(timestamp, item) pairs, without those whose timestamp is an outlier (counted in drops["time_outlier"]).

    The centred median of NEIGHBOURS timestamps follows a real gap in the log (both sides of it have
    their own majority) but not an isolated stray timestamp."""
    half = NEIGHBOURS // 2
    buf: collections.deque = collections.deque()
    i = 0  # index in buf of the next item to decide

    def decide(k: int):
        lo, hi = max(0, k - half), min(len(buf), k + half + 1)
        window = sorted(buf[j][0] for j in range(lo, hi))
        mid = len(window) // 2
        med = window[mid] if len(window) % 2 else 0.5 * (window[mid - 1] + window[mid])
        if abs(buf[k][0] - med) > OUTLIER_S:
            drops["time_outlier"] += 1
            return None
        return buf[k]

    for pair in items:
        buf.append(pair)
        while len(buf) - 1 - i >= half:
            kept = decide(i)
            if kept is not None:
                yield kept
            i += 1
            if i > half:
                buf.popleft()
                i -= 1
    while i < len(buf):
        kept = decide(i)
        if kept is not None:
            yield kept
        i += 1


class CanLogError(ValueError):
    """A CAN log that cannot be read at all; the message names the file."""


def channel_map(text: str) -> Union[None, str, dict]:
    """``vehicle.log_channels``: "" = as recorded, "any" = channels ignored, "0=can0,1=can1" = mapped."""
    text = (text or "").strip()
    if not text or text == "any":
        return text or None
    out = {}
    for pair in text.split(","):
        src, sep, dst = (x.strip() for x in pair.partition("="))
        if not sep or not src or not dst:
            raise CanLogError(f"vehicle.log_channels: {pair.strip()[:40]!r} is not LOG=BUS; write e.g. '0=can0,1=can1', "
                              f"or 'any' to ignore the log's channels")
        out[src] = dst
    return out


class _GoodLines:
    """The well-formed lines of a candump log, as a text file for CanutilsLogReader; counts the others.
    Iterating it again continues where it stopped (a new reader picks up after a failed one)."""

    closed = False

    def __init__(self, lines: Iterator[str], ids: Optional[frozenset[int]], drops: Counter, window_s: float):
        self.bad = 0
        self.read = 0
        self.first_bad: Optional[tuple[int, str]] = None
        self.first_t: Optional[float] = None
        self._ids = ids
        self._drops = drops
        self._window_s = window_s
        self._gen = self._filter(lines)

    def _frames(self, lines: Iterator[str]) -> Iterator[tuple[float, tuple[int, str]]]:
        for n, line in enumerate(lines, 1):
            s = line.strip()
            if not s:
                continue
            m = _CANDUMP.match(s)
            if m is None:
                self.bad_line(n, s)
                continue
            self.read += 1
            yield float(m.group(1)), (int(m.group(2), 16), s)

    def _filter(self, lines: Iterator[str]) -> Iterator[str]:
        def start(t0: float) -> None:
            self.first_t = t0

        frames = drop_time_outliers(self._frames(lines), self._drops)
        for _t, (frame_id, s) in robust_start(frames, self._window_s, self._drops, start):
            if self._ids is not None and frame_id not in self._ids:
                self._drops["unknown_id"] += 1
            else:
                yield s + "\n"

    def bad_line(self, n: int, text: str) -> None:
        self.bad += 1
        if self.first_bad is None:
            self.first_bad = (n, text[:60])

    def __iter__(self) -> Iterator[str]:
        return self._gen

    def close(self) -> None:  # the reader closes its file when done; the real file is ours
        pass


class _ASCReader(can.ASCReader):
    """python-can's .asc reader, but a frame line it cannot parse (bad hex, missing bytes) is counted in ``bad``
    and skipped, and reading goes on; python-can's own stops the whole log at it."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.bad = 0
        self.first_bad: Optional[tuple[int, str]] = None

    def _skip_bad(self, parse, rest: str, kwargs: dict) -> Optional[can.Message]:
        try:
            return parse(rest, kwargs)
        except (ValueError, IndexError, KeyError) as exc:
            self.bad += 1
            if self.first_bad is None:
                self.first_bad = (0, f"{rest[:40]} ({type(exc).__name__})")
            return None

    def _process_classic_can_frame(self, line, msg_kwargs):
        return self._skip_bad(super()._process_classic_can_frame, line, msg_kwargs)

    def _process_fd_can_frame(self, line, msg_kwargs):
        return self._skip_bad(super()._process_fd_can_frame, line, msg_kwargs)


# python-can's LogReader looks its plugins up in the installed packages' entry points on every call
# (~25 ms); the formats it ships are opened directly.
_READERS = {".asc": _ASCReader, ".blf": can.BLFReader, ".csv": can.CSVReader, ".trc": can.TRCReader}


def _open_reader(path: Path):
    cls = _READERS.get(path.suffix.lower())
    return cls(str(path)) if cls is not None else can.LogReader(str(path))


def _open_text(path: Path):
    if path.suffix.lower() == ".gz":
        return gzip.open(path, "rt", errors="replace")
    return path.open("r", errors="replace")


class CanLogReader:
    """Frames of a CAN log in timestamp order.

    Out-of-order frames (several buses merged into one log) are put in order within
    ``reorder_window_s``; a frame later than that is dropped and counted in ``out_of_order``.
    ``channels``: the log's channel names mapped to the bus's (e.g. {"0": "can0"} for an .asc log),
    or "any" to take every frame as on no particular channel; None keeps them as recorded.
    """

    def __init__(self, path: Union[str, Path], offset_s: float = 0.0, reorder_window_s: float = 0.5,
                 ids: Optional[Iterable[int]] = None, channels: Union[None, str, dict] = None):
        self.path = Path(path)
        if not self.path.is_file():
            raise CanLogError(f"{self.path}: no such CAN log")
        suffixes = [s.lower() for s in self.path.suffixes[-2:]]
        self._candump = suffixes[-1] == ".log" or suffixes == [".log", ".gz"]
        if not self._candump:
            try:
                _open_reader(self.path).stop()
            except Exception as exc:
                raise CanLogError(f"{self.path}: cannot be read as a CAN log: {exc}") from None
        self.offset_s = offset_s
        self._ids = None if ids is None else frozenset(ids)
        self.channels = channels
        self.drops: Counter = Counter()  # frames read but not delivered, by reason
        self.delivered = 0
        self._read_other = 0
        self.window_s = reorder_window_s
        self._t0: Optional[float] = None
        self.messages_read = 0  # frames that passed the id and time filters
        self._good: Optional[_GoodLines] = None
        self._other = None   # the reader of a log other than candump
        self.read_error: Optional[str] = None
        self._iter = self._ordered()
        self._next: Optional[can.Message] = None
        self._done = False
        self._peek()  # reads up to the first frame, so that t0 is known before the replay starts

    # ---- raw reading -------------------------------------------------------------------------------
    def _raw_candump(self) -> Iterator[can.Message]:
        with _open_text(self.path) as f:
            self._good = _GoodLines(iter(f), self._ids, self.drops, self.window_s)
            while True:
                # A fresh reader after any surprise: the line that raised is consumed and skipped.
                try:
                    yield from can.CanutilsLogReader(self._good)
                    return
                except (ValueError, IndexError) as exc:
                    self._good.bad_line(0, str(exc))
                    self.drops["undecodable"] += 1

    def _raw_other(self) -> Iterator[can.Message]:
        def timed() -> Iterator[tuple[float, can.Message]]:
            # a read that fails part-way ends here, so the frames already read still go through the filter
            try:
                self._other = _open_reader(self.path)
                for msg in self._other:
                    self._read_other += 1
                    t = msg.timestamp
                    if t is None or not math.isfinite(t):
                        self.drops["time_outlier"] += 1
                        continue
                    yield t, msg
            except Exception as exc:
                self.read_error = f"stopped after {self._read_other} frames: {type(exc).__name__}: {exc}"[:200]

        def start(t0: float) -> None:
            self._t0 = t0

        for _t, msg in robust_start(drop_time_outliers(timed(), self.drops), self.window_s, self.drops, start):
            if self._ids is not None and msg.arbitration_id not in self._ids:
                self.drops["unknown_id"] += 1
                continue
            yield msg

    def _ordered(self) -> Iterator[can.Message]:
        raw = self._raw_candump() if self._candump else self._raw_other()
        heap: list = []
        seq = itertools.count()
        newest = -float("inf")
        last_out = -float("inf")
        for msg in raw:
            self.messages_read += 1
            if self._t0 is None:
                self._t0 = msg.timestamp if self.t0 is None else self.t0
            newest = max(newest, msg.timestamp)
            heapq.heappush(heap, (msg.timestamp, next(seq), msg))
            while heap and heap[0][0] <= newest - self.window_s:
                m = heapq.heappop(heap)[2]
                if m.timestamp < last_out:
                    self.drops["out_of_order"] += 1
                    continue
                last_out = m.timestamp
                yield self._on_channel(m)
        while heap:
            m = heapq.heappop(heap)[2]
            if m.timestamp < last_out:
                self.drops["out_of_order"] += 1
                continue
            last_out = m.timestamp
            yield self._on_channel(m)

    def _on_channel(self, msg: can.Message) -> can.Message:
        if self.channels == "any":
            msg.channel = None
        elif self.channels and msg.channel is not None:
            msg.channel = self.channels.get(str(msg.channel), msg.channel)
        return msg

    # ---- the frame clock ---------------------------------------------------------------------------
    @property
    def t0(self) -> Optional[float]:
        """Timestamp of the log's first frame (of any id); None for a log without frames."""
        if self._t0 is None and self._good is not None:
            return self._good.first_t
        return self._t0

    @property
    def bad_lines(self) -> int:
        """Lines that look like frames but cannot be read as one: counted and skipped."""
        return (self._good or self._other).bad if isinstance(self._good or self._other, (_GoodLines, _ASCReader)) else 0

    @property
    def first_bad_line(self) -> Optional[tuple[int, str]]:
        src = self._good or self._other
        return src.first_bad if isinstance(src, (_GoodLines, _ASCReader)) else None

    def replay_time(self, msg: can.Message) -> float:
        return msg.timestamp - (self.t0 or 0.0) + self.offset_s

    def _peek(self) -> Optional[can.Message]:
        if self._next is None and not self._done:
            self._next = next(self._iter, None)
            self._done = self._next is None
        return self._next

    def messages_until(self, t_s: float) -> Iterator[tuple[float, can.Message]]:
        """(replay time, frame) for every frame not yet delivered whose replay time is <= t_s."""
        while True:
            msg = self._peek()
            if msg is None:
                return
            t = self.replay_time(msg)
            if t > t_s + SAME_TIME_S:
                return
            self._next = None
            self.delivered += 1
            yield t, msg

    def __iter__(self) -> Iterator[tuple[float, can.Message]]:
        return self.messages_until(float("inf"))

    @property
    def exhausted(self) -> bool:
        return self._peek() is None

    @property
    def out_of_order(self) -> int:
        return self.drops["out_of_order"]

    @property
    def frames_read(self) -> int:
        """Well-formed frames read from the file so far (malformed lines are not frames)."""
        return self._good.read if self._good else self._read_other

    def counts(self) -> dict:
        """Every frame read, accounted once: {"read", "delivered", "dropped": {reason: n}, "not_reached"}
        (not_reached: read ahead but after the replay's end)."""
        dropped = {k: v for k, v in sorted(self.drops.items()) if v}
        return {"read": self.frames_read, "delivered": self.delivered, "dropped": dropped,
                "not_reached": self.frames_read - self.delivered - sum(dropped.values())}

    def summary(self) -> str:
        skipped = self.drops["unknown_id"]
        parts = [f"{self.path.name}: {self.frames_read} frames read"
                 + (f" ({skipped} of other ids passed over)" if skipped else "")]
        if self.bad_lines:
            where = (f", first at line {self.first_bad_line[0]}: {self.first_bad_line[1]!r}"
                     if self.first_bad_line and self.first_bad_line[0] else "")
            parts.append(f"{self.bad_lines} malformed lines skipped{where}")
        if self.drops["time_outlier"]:
            parts.append(f"{self.drops['time_outlier']} frames with outlying timestamps dropped")
        if self.out_of_order:
            parts.append(f"{self.out_of_order} frames out of time order dropped")
        if self.read_error:
            parts.append(f"reading {self.read_error}")
        return "; ".join(parts)
