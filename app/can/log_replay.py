"""Reading a recorded CAN log for replay, in timestamp order, on the frame clock.

Any format python-can reads (``can.LogReader``: candump .log, .asc, .blf, .csv, .trc, also
gzipped). A candump .log is read line by line: a line that is not a candump ``-L`` frame (garbage,
a truncated write, an odd number of hex digits) is counted in ``bad_lines`` and skipped, and only
good lines reach python-can's ``CanutilsLogReader``, which would otherwise stop at the first bad
line. Other formats are read by python-can directly; if one fails part-way, what was read is kept
and ``read_error`` says where it stopped.

Times: ``t0`` is the first frame's timestamp; a frame's replay time is ``timestamp - t0 + offset_s``
(``vehicle.log_offset_s``), the clock of the video's frames (frame 0 at t = 0).
"""
from __future__ import annotations

import gzip
import heapq
import itertools
import re
from pathlib import Path
from typing import Iterable, Iterator, Optional, Union

import can

# (timestamp) channel id#data [R|T]; data: hex pairs, R[dlc] (remote) or #F + hex (CAN FD)
_CANDUMP = re.compile(r"^\((\d+(?:\.\d+)?)\)\s+\S+\s+([0-9A-Fa-f]{3}|[0-9A-Fa-f]{8})#"
                      r"(?:R\d?|#[0-9A-Fa-f](?:[0-9A-Fa-f]{2}){0,64}|(?:[0-9A-Fa-f]{2}){0,8})(?:\s+[RTrt])?$")


# Epoch timestamps in a double carry ~0.2 us of noise and logs have 1 us resolution: a frame within
# 1 us of a camera frame's time counts as simultaneous (delivered with that frame).
SAME_TIME_S = 1e-6


class CanLogError(ValueError):
    """A CAN log that cannot be read at all; the message names the file."""


class _GoodLines:
    """The well-formed lines of a candump log, as a text file for CanutilsLogReader; counts the others.
    Iterating it again continues where it stopped (a new reader picks up after a failed one)."""

    closed = False

    def __init__(self, lines: Iterator[str], ids: Optional[frozenset[int]]):
        self.bad = 0
        self.first_bad: Optional[tuple[int, str]] = None
        self.first_t: Optional[float] = None
        self.skipped = 0
        self._ids = ids
        self._gen = self._filter(lines)

    def _filter(self, lines: Iterator[str]) -> Iterator[str]:
        for n, line in enumerate(lines, 1):
            s = line.strip()
            if not s:
                continue
            m = _CANDUMP.match(s)
            if m is None:
                self.bad_line(n, s)
                continue
            if self.first_t is None:
                self.first_t = float(m.group(1))
            if self._ids is not None and int(m.group(2), 16) not in self._ids:
                self.skipped += 1
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


def _open_text(path: Path):
    if path.suffix.lower() == ".gz":
        return gzip.open(path, "rt", errors="replace")
    return path.open("r", errors="replace")


class CanLogReader:
    """Frames of a CAN log in timestamp order.

    Out-of-order frames (several buses merged into one log) are put in order within
    ``reorder_window_s``; a frame later than that is still delivered and counted in ``out_of_order``.
    """

    def __init__(self, path: Union[str, Path], offset_s: float = 0.0, reorder_window_s: float = 0.5,
                 ids: Optional[Iterable[int]] = None):
        self.path = Path(path)
        if not self.path.is_file():
            raise CanLogError(f"{self.path}: no such CAN log")
        suffixes = [s.lower() for s in self.path.suffixes[-2:]]
        self._candump = suffixes[-1] == ".log" or suffixes == [".log", ".gz"]
        if not self._candump:
            try:
                can.LogReader(str(self.path)).stop()
            except Exception as exc:
                raise CanLogError(f"{self.path}: cannot be read as a CAN log: {exc}") from None
        self.offset_s = offset_s
        self._ids = None if ids is None else frozenset(ids)
        self.skipped = 0  # frames of other ids than ``ids`` (not an error)
        self.window_s = reorder_window_s
        self._t0: Optional[float] = None
        self.messages_read = 0
        self._good: Optional[_GoodLines] = None
        self.out_of_order = 0
        self.read_error: Optional[str] = None
        self._iter = self._ordered()
        self._next: Optional[can.Message] = None
        self._done = False
        self._peek()  # reads up to the first frame, so that t0 is known before the replay starts

    # ---- raw reading -------------------------------------------------------------------------------
    def _raw_candump(self) -> Iterator[can.Message]:
        with _open_text(self.path) as f:
            self._good = _GoodLines(iter(f), self._ids)
            while True:
                # A fresh reader after any surprise: the line that raised is consumed and skipped.
                try:
                    yield from can.CanutilsLogReader(self._good)
                    return
                except (ValueError, IndexError) as exc:
                    self._good.bad_line(0, str(exc))

    def _raw_other(self) -> Iterator[can.Message]:
        n = 0
        try:
            for msg in can.LogReader(str(self.path)):
                n += 1
                if self._t0 is None and msg.timestamp is not None:
                    self._t0 = msg.timestamp
                if self._ids is not None and msg.arbitration_id not in self._ids:
                    self.skipped += 1
                    continue
                yield msg
        except Exception as exc:
            self.read_error = f"stopped after {n} frames: {type(exc).__name__}: {exc}"

    def _ordered(self) -> Iterator[can.Message]:
        raw = self._raw_candump() if self._candump else self._raw_other()
        heap: list = []
        seq = itertools.count()
        newest = -float("inf")
        last_out = -float("inf")
        for msg in raw:
            if msg.timestamp is None:
                continue
            self.messages_read += 1
            if self._t0 is None:
                self._t0 = msg.timestamp if self.t0 is None else self.t0
            newest = max(newest, msg.timestamp)
            heapq.heappush(heap, (msg.timestamp, next(seq), msg))
            while heap and heap[0][0] <= newest - self.window_s:
                m = heapq.heappop(heap)[2]
                self.out_of_order += m.timestamp < last_out
                last_out = max(last_out, m.timestamp)
                yield m
        while heap:
            m = heapq.heappop(heap)[2]
            self.out_of_order += m.timestamp < last_out
            last_out = max(last_out, m.timestamp)
            yield m

    # ---- the frame clock ---------------------------------------------------------------------------
    @property
    def t0(self) -> Optional[float]:
        """Timestamp of the log's first frame (of any id); None for a log without frames."""
        if self._t0 is None and self._good is not None:
            return self._good.first_t
        return self._t0

    @property
    def bad_lines(self) -> int:
        return self._good.bad if self._good else 0

    @property
    def first_bad_line(self) -> Optional[tuple[int, str]]:
        return self._good.first_bad if self._good else None

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
            yield t, msg

    def __iter__(self) -> Iterator[tuple[float, can.Message]]:
        return self.messages_until(float("inf"))

    @property
    def exhausted(self) -> bool:
        return self._peek() is None

    def summary(self) -> str:
        skipped = self._good.skipped if self._good else self.skipped
        parts = [f"{self.path.name}: {self.messages_read} frames read"
                 + (f" ({skipped} of other ids passed over)" if skipped else "")]
        if self.bad_lines:
            where = (f", first at line {self.first_bad_line[0]}: {self.first_bad_line[1]!r}"
                     if self.first_bad_line and self.first_bad_line[0] else "")
            parts.append(f"{self.bad_lines} malformed lines skipped{where}")
        if self.out_of_order:
            parts.append(f"{self.out_of_order} frames out of time order")
        if self.read_error:
            parts.append(f"reading {self.read_error}")
        return "; ".join(parts)
