"""The CAN bus and the output side: opening any python-can interface from the configuration, and
``CanOutput``, which sends Headway's frames, counts failures for health, and mirrors every frame
it sends to a log file (candump .log, .asc or .blf), flushed after every batch so that a stop
loses nothing already sent.

The service's log is a record across runs (``rotate_log``): at start the previous run's log is never
overwritten but renamed NAME.1.SUFFIX (older ones shifted to .2, .3, ... and the oldest beyond
``can.output_log_keep`` removed), and a last line cut by a crash or power cut is trimmed from it, so every
kept log parses whole. While running, every batch of frames is written whole and flushed to the
operating system at once (a killed process loses nothing already sent), and forced to the disk
(fsync, by a thread of its own) at least every ``can.output_log_sync_s``: a power cut loses at most that much."""
from __future__ import annotations

import math
import os
import threading
from datetime import datetime
from pathlib import Path
from typing import Any, Iterable, Mapping, Optional, Union

import can


class CanBusError(RuntimeError):
    """A CAN interface that cannot be opened; the message says why and what to do."""


def _hint(interface: str, channel: str, exc: BaseException) -> str:
    text = str(exc)
    if interface == "socketcan":
        if "Address family not supported" in text or getattr(exc, "errno", None) == 97:
            return ("this kernel has no SocketCAN (the can/can_raw modules are missing or not loadable here): "
                    "use interface: virtual to run without a bus, or on a machine with SocketCAN load the modules "
                    "(sudo modprobe can can_raw vcan)")
        if "No such device" in text or getattr(exc, "errno", None) == 19:
            virtual = channel.startswith("vcan")
            setup = (f"sudo modprobe vcan && sudo ip link add dev {channel} type vcan && sudo ip link set up {channel}"
                     if virtual else
                     f"sudo ip link set {channel} type can bitrate 500000 && sudo ip link set up {channel}")
            return f"there is no network interface {channel}: create it with `{setup}` (see docs/can.md)"
        if "Network is down" in text or getattr(exc, "errno", None) == 100:
            return f"{channel} is down: `sudo ip link set up {channel}`"
    if "serial module" in text:
        return "slcan and serial need pyserial: pip install pyserial"
    if "Unknown interface" in text:
        return f"python-can does not know interface {interface!r}"
    return "check the interface's driver and that the adapter is plugged in; interface: virtual runs without one"


def open_bus(interface: str, channel: str, bitrate: Optional[int] = None, receive_own_messages: bool = False,
             **kwargs: Any) -> can.BusABC:
    """A python-can bus, or CanBusError saying why not (never a bare driver exception)."""
    args: dict[str, Any] = {"interface": interface, "channel": channel,
                            "receive_own_messages": receive_own_messages, **kwargs}
    if bitrate and interface not in ("socketcan", "virtual"):
        args["bitrate"] = bitrate  # socketcan takes its bitrate from `ip link`; virtual has none
    try:
        return can.Bus(**args)
    except Exception as exc:  # drivers raise OSError, CanError, NameError (missing vendor library), ...
        raise CanBusError(f"CAN interface {interface} channel {channel}: cannot be opened "
                          f"({type(exc).__name__}: {exc}); {_hint(interface, channel, exc)}") from None


def bus_from_config(can_cfg: Mapping[str, Any], channel: Optional[str] = None) -> can.BusABC:
    return open_bus(can_cfg["interface"], channel or can_cfg["channel"], can_cfg.get("bitrate"),
                    bool(can_cfg.get("receive_own_messages", False)))


class _ASCWriter(can.ASCWriter):
    """python-can's ASCWriter puts the wall-clock date in its header; a replay's log must depend only
    on its input, so the header date comes from the given start time instead."""

    def __init__(self, file: str, start_s: float, **kwargs: Any):
        self._start = datetime.fromtimestamp(start_s)  # local time, as python-can writes "Begin Triggerblock"
        super().__init__(file, **kwargs)

    def _format_header_datetime(self, dt: datetime) -> str:
        return super()._format_header_datetime(self._start)


LOG_BUFFER_BYTES = 1 << 20  # bytes; a batch of frames is a few kB


def open_log_writer(path: Union[str, Path], channel: str = "can0", start_s: float = 0.0) -> can.Listener:
    """A log writer chosen by suffix: .log (candump -L), .asc, .blf."""
    p = Path(path)
    suffix = p.suffix.lower()
    p.parent.mkdir(parents=True, exist_ok=True)
    if suffix == ".log":
        # a buffer larger than any batch: each flush is one write() of whole lines
        return can.CanutilsLogWriter(open(p, "w", buffering=LOG_BUFFER_BYTES), channel=channel)
    if suffix == ".asc":
        return _ASCWriter(str(p), start_s)
    if suffix == ".blf":
        return can.BLFWriter(str(p), channel=1)
    raise CanBusError(f"{p}: unknown CAN log format {suffix!r}: use .log (candump), .asc or .blf")


def _trim_partial_line(path: Path) -> int:
    """Cuts a text log after its last complete line; returns the bytes removed."""
    with path.open("rb+") as f:
        size = f.seek(0, os.SEEK_END)
        if size == 0:
            return 0
        pos = size
        while pos > 0:
            step = min(4096, pos)
            f.seek(pos - step)
            chunk = f.read(step)
            nl = chunk.rfind(b"\n")
            if nl >= 0:
                end = pos - step + nl + 1
                break
            pos -= step
        else:
            end = 0
        if end < size:
            f.truncate(end)
        return size - end


def rotated_name(path: Path, n: int) -> Path:
    """out.log -> out.1.log, out.2.log, ... (the suffix kept, so the format is still known)."""
    return path.with_name(f"{path.stem}.{n}{path.suffix}")


def rotate_log(path: Union[str, Path], keep: int) -> Optional[Path]:
    """Before a run writes ``path``: the previous run's log becomes ``rotated_name(path, 1)`` (trimmed to
    whole lines for text logs), older ones move up by one, those beyond ``keep`` are removed. Returns the
    name the previous log was kept under (None if there was none)."""
    p = Path(path)
    if not p.exists() or p.stat().st_size == 0:
        return None
    if suffix_is_text(p):
        _trim_partial_line(p)
    oldest = rotated_name(p, keep)
    if oldest.exists():
        oldest.unlink()
    for n in range(keep - 1, 0, -1):
        if rotated_name(p, n).exists():
            os.replace(rotated_name(p, n), rotated_name(p, n + 1))
    if keep < 1:
        p.unlink()
        return None
    os.replace(p, rotated_name(p, 1))
    return rotated_name(p, 1)


def suffix_is_text(path: Path) -> bool:
    return path.suffix.lower() in (".log", ".asc")


class CanOutput:
    """Sends frames on a bus (optional: replay may only log) and mirrors them to a log (optional).

    A send that fails is counted (``send_errors``, ``last_error``, ``last_error_s`` on the caller's
    clock) and the frame is not logged; nothing raises. Use as a context manager, or call
    ``close()``: a .log or .asc is complete on disk after every ``send`` (flushed), a .blf only after
    ``close()`` (its container format is written in blocks). ``sync_s``: also fsync at least this often
    (None = leave it to the operating system). ``keep``: rotate the previous log first (None = overwrite,
    as a replay's named output does).
    """

    def __init__(self, bus: Optional[can.BusABC] = None, log_path: Optional[Union[str, Path]] = None,
                 channel: str = "can0", start_s: float = 0.0, send_timeout_s: float = 0.01,
                 sync_s: Optional[float] = None, keep: Optional[int] = None):
        self.bus = bus
        self.channel = channel
        self.log_path = Path(log_path) if log_path else None
        self.previous_log = rotate_log(self.log_path, keep) if self.log_path and keep is not None else None
        self._log = open_log_writer(self.log_path, channel, start_s) if self.log_path else None
        self._sync_stop = threading.Event()
        if self._log is not None and sync_s is not None and suffix_is_text(self.log_path):
            # fsync off the caller's thread: on a busy disk it can take a second, the frame loop must not wait
            fd = self._log.file.fileno()
            threading.Thread(target=self._sync_loop, args=(fd, max(sync_s, 0.01)), name="can-log-sync",
                             daemon=True).start()
        self._timeout = send_timeout_s
        self.sent = 0
        self.logged = 0
        self.send_errors = 0
        self.last_error: Optional[str] = None
        self.last_error_s = -math.inf

    def send(self, messages: Iterable[can.Message], now_s: float = 0.0) -> int:
        """Sends in order; returns how many went out. Every frame that went out is logged."""
        n = 0
        for msg in messages:
            if msg.channel is None:
                msg.channel = self.channel
            if self.bus is not None:
                try:
                    self.bus.send(msg, timeout=self._timeout)
                except Exception as exc:  # CanOperationError, OSError (ENOBUFS, ENETDOWN), ...
                    self.send_errors += 1
                    self.last_error = f"{type(exc).__name__}: {exc}"
                    self.last_error_s = now_s
                    continue
            self.sent += 1
            n += 1
            if self._log is not None:
                self._log.on_message_received(msg)
                self.logged += 1
        self.flush()
        return n

    def flush(self) -> None:
        f = getattr(self._log, "file", None)
        if f is not None and not isinstance(self._log, can.BLFWriter) and not f.closed:
            f.flush()

    def _sync_loop(self, fd: int, every_s: float) -> None:
        while not self._sync_stop.wait(every_s):
            try:
                os.fsync(fd)
            except OSError:  # closed meanwhile
                return

    def tx_error(self, now_s: float, hold_s: float) -> bool:
        """True while the last send failure is less than ``hold_s`` old."""
        return now_s - self.last_error_s < hold_s

    def close(self) -> None:
        self._sync_stop.set()
        if self._log is not None:
            self._log.stop()
            self._log = None

    def __enter__(self) -> "CanOutput":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
