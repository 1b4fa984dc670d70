"""The host end of the cabin-MCU link: owns the serial port, the handshake, heartbeats, warnings out,
vehicle signals in, and reconnection.

Contract (the supervisor's side):

    link = McuLink("/dev/ttyMCU")
    every loop:   link.poll()                       # non-blocking I/O and timers; never raises on I/O trouble
    on FCW:       link.send_warning(level, ttc_s, lead_range_m)
    when needed:  link.vehicle_signals(), link.health(), link.set_system_ok(ok)

`poll(now)` does everything and returns quickly (it blocks only up to `write_timeout_s` when the
MCU stops draining its receive buffer); call it at least every `heartbeat_period_s / 2`. Tests drive
it with their own clock. `LinkThread` runs the same poll in a background thread for callers that
prefer it; every public method of McuLink takes one lock, so the two may be mixed.

States (health()["state"]):

    disconnected  port not open; reopened with back-off reopen_min_s .. reopen_max_s (doubling)
    handshaking   port open, HELLO sent every hello_period_s, waiting for a compatible HELLO_ACK
    up            handshake done; HEARTBEAT and WARNING go out every heartbeat_period_s
    silent        port open but no valid frame from the MCU for silence_timeout_s: a health fault.
                  HEARTBEAT and WARNING still go out (the MCU may still hear us), and HELLO too;
                  the first valid frame heard starts a new handshake
    incompatible  the MCU answered with another protocol major version: nothing but HELLO (every
                  incompatible_retry_s) is sent until a compatible HELLO_ACK arrives

Any read/write error (SerialException, OSError), the port path vanishing or pointing at another
device closes the port and goes to `disconnected`. An MCU reset (its uptime going back) starts a
new handshake. close() closes the port for good: poll() does not reopen it.
"""
from __future__ import annotations

import logging
import math
import os
import stat
import threading
import time
from dataclasses import dataclass
from enum import Enum
from typing import Callable, Protocol

import serial

from . import messages as m
from .framing import FrameDecoder, encode_message

log = logging.getLogger(__name__)


class LinkState(str, Enum):
    DISCONNECTED = "disconnected"
    HANDSHAKING = "handshaking"
    UP = "up"
    SILENT = "silent"
    INCOMPATIBLE = "incompatible"


@dataclass(frozen=True)
class LinkConfig:
    baudrate: int = 115200  # 8N1, no flow control
    heartbeat_period_s: float = 0.1  # host HEARTBEAT period, and the WARNING repeat period
    silence_timeout_s: float = 0.5  # no valid MCU frame this long -> silent (5 MCU heartbeats)
    hello_period_s: float = 0.25  # HELLO repeat while handshaking or silent
    incompatible_retry_s: float = 2.0  # HELLO repeat while incompatible (the MCU may be reflashed)
    reopen_min_s: float = 0.1  # first reopen delay after the port failed or vanished
    reopen_max_s: float = 2.0  # the delay doubles per failure up to this
    signals_stale_s: float = 0.3  # vehicle signals older than this are stale (6 MCU periods)
    port_check_s: float = 0.25  # how often the port path is checked for vanishing or re-pointing
    write_timeout_s: float = 0.05  # a write that cannot finish this fast is dropped and counted
    max_read_per_poll: int = 65536  # bytes; bounds the time one poll() spends reading

    def __post_init__(self):
        for name in ("heartbeat_period_s", "silence_timeout_s", "hello_period_s", "incompatible_retry_s",
                     "reopen_min_s", "reopen_max_s", "signals_stale_s", "port_check_s"):
            if not getattr(self, name) > 0:
                raise ValueError(f"LinkConfig.{name} must be > 0, got {getattr(self, name)!r}")
        if self.silence_timeout_s <= self.heartbeat_period_s:
            raise ValueError("LinkConfig.silence_timeout_s must exceed heartbeat_period_s")
        if self.reopen_max_s < self.reopen_min_s:
            raise ValueError("LinkConfig.reopen_max_s must be >= reopen_min_s")
        if not 1 <= round(self.silence_timeout_s * 1000) <= 0xFFFF:
            raise ValueError("LinkConfig.silence_timeout_s must be 0.001..65.535 s (sent to the MCU in ms)")


class Port(Protocol):
    """What McuLink needs of a port: pyserial's Serial with timeout=0 provides it."""

    def read(self, size: int) -> bytes: ...
    def write(self, data: bytes) -> int | None: ...
    def close(self) -> None: ...


def open_serial(path: str, config: LinkConfig) -> serial.Serial:
    """The real port: 8N1, no flow control, non-blocking reads, exclusive (flock) access."""
    return serial.Serial(port=path, baudrate=config.baudrate, bytesize=serial.EIGHTBITS,
                         parity=serial.PARITY_NONE, stopbits=serial.STOPBITS_ONE, timeout=0,
                         write_timeout=config.write_timeout_s, exclusive=True)


@dataclass(frozen=True)
class SignalsReading:
    """The latest VEHICLE_SIGNALS with when it arrived (host clock) and whether it is stale."""

    speed_mps: float | None
    brake: bool
    turn_left: bool
    turn_right: bool
    received_at: float
    age_s: float
    stale: bool


# SerialException derives from IOError (= OSError); both named for the reader.
IO_ERRORS = (serial.SerialException, OSError)


class McuLink:
    """Host side of the MCU protocol. See the module docstring for the contract and states."""

    def __init__(self, port: str | os.PathLike, config: LinkConfig | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 opener: Callable[[str, LinkConfig], Port] = open_serial):
        self.port_path = os.fspath(port)
        self.config = config or LinkConfig()
        self._clock = clock
        self._opener = opener
        self._lock = threading.RLock()
        self._decoder = FrameDecoder()
        self._port: Port | None = None
        self._port_rdev: int | None = None
        self._state = LinkState.DISCONNECTED
        self._state_since = self._created_at = clock()
        self._fault: str | None = "port not opened yet"
        self._counters = dict(opens=0, open_failures=0, disconnects=0, handshakes=0, mcu_resets=0,
                              rx_seq_gaps=0, unexpected_messages=0, tx_frames=0, tx_bytes=0, tx_timeouts=0)
        self._backoff_s = self.config.reopen_min_s
        self._next_open = -math.inf
        self._next_port_check = 0.0
        self._next_hello = self._next_heartbeat = self._next_warning = 0.0
        self._opened_at = 0.0
        self._tx_seq = 0
        self._rx_seq: int | None = None
        self._last_heard: float | None = None
        self._mcu: m.HelloAck | None = None
        self._mcu_heartbeat: m.Heartbeat | None = None
        self._last_tx_heartbeat: m.Heartbeat | None = None
        self._signals: m.VehicleSignals | None = None
        self._signals_at: float | None = None
        self._warning = m.FcwWarning()
        self._warning_dirty = True
        self._system_ok = True

    # ---- the supervisor's calls -------------------------------------------------------------------

    @property
    def state(self) -> LinkState:
        return self._state

    def send_warning(self, level: int, ttc_s: float | None = None, lead_range_m: float | None = None) -> None:
        """Set the warning the MCU shows; sent at the next poll() and repeated every heartbeat period.

        ttc_s / lead_range_m: None, NaN, infinite or negative mean "not available"; values above
        655.34 are sent as 655.34. An invalid level raises FieldRangeError (a programming error).
        """
        warning = m.FcwWarning(level, _saturate(ttc_s), _saturate(lead_range_m))
        with self._lock:
            if warning != self._warning:
                self._warning = warning
                self._warning_dirty = True

    def set_system_ok(self, ok: bool) -> None:
        """Whether FCW is available (HostStatus.SYSTEM_OK in the host's heartbeats)."""
        with self._lock:
            self._system_ok = bool(ok)

    def vehicle_signals(self, now: float | None = None) -> SignalsReading | None:
        """The latest vehicle signals (None before the first since the link came up)."""
        with self._lock:
            if self._signals is None:
                return None
            now = self._clock() if now is None else now
            age = now - self._signals_at
            s = self._signals
            return SignalsReading(s.speed_mps, s.brake, s.turn_left, s.turn_right, self._signals_at, age,
                                  age > self.config.signals_stale_s)

    def health(self, now: float | None = None) -> dict:
        """State, fault text (None when up), ages and counters; plain JSON-able values."""
        with self._lock:
            now = self._clock() if now is None else now
            mcu = None
            if self._mcu is not None:
                beat = self._mcu_heartbeat
                mcu = {"protocol": f"{self._mcu.protocol_major}.{self._mcu.protocol_minor}",
                       "firmware": self._mcu.firmware,
                       "uptime_s": None if beat is None else beat.uptime_ms / 1000.0,
                       "status": None if beat is None else [f.name.lower() for f in m.McuStatus(beat.status)]}
            return {
                "state": self._state.value,
                "ok": self._state is LinkState.UP,
                "fault": None if self._state is LinkState.UP else self._fault,
                "port": self.port_path,
                "state_age_s": now - self._state_since,
                "last_heard_age_s": None if self._last_heard is None else now - self._last_heard,
                "vehicle_signals_age_s": None if self._signals_at is None else now - self._signals_at,
                "mcu": mcu,
                "last_rx_error": self._decoder.last_error,
                "counters": {**self._decoder.stats.as_dict(), **self._counters},
            }

    def close(self) -> None:
        with self._lock:
            self._drop_port(self._clock(), "closed by the host", reopen=False)

    def poll(self, now: float | None = None) -> LinkState:
        """Open/read/decode/handle/send as due; returns the state. Never raises on I/O trouble."""
        with self._lock:
            now = self._clock() if now is None else now
            if self._port is None:
                if now < self._next_open:
                    return self._state
                self._try_open(now)
            if self._port is not None and now >= self._next_port_check:
                self._check_port_path(now)
            if self._port is not None:
                self._receive(now)
            if self._port is not None:
                self._run_timers(now)
            return self._state

    # ---- port handling ------------------------------------------------------------------------------

    def _try_open(self, now: float) -> None:
        try:
            port = self._opener(self.port_path, self.config)
        except (*IO_ERRORS, ValueError) as e:
            self._counters["open_failures"] += 1
            fault = f"cannot open {self.port_path}: {e}"
            if fault != self._fault:
                log.warning("MCU link: %s", fault)
            self._fault = fault
            self._schedule_reopen(now)
            return
        self._port = port
        self._port_rdev = _char_device(port)
        self._counters["opens"] += 1
        self._opened_at = now
        self._next_port_check = now + self.config.port_check_s
        self._last_heard = None
        self._rx_seq = None
        self._mcu = self._mcu_heartbeat = None
        self._signals = self._signals_at = None
        self._start_handshake(now)
        log.info("MCU link: opened %s", self.port_path)

    def _check_port_path(self, now: float) -> None:
        self._next_port_check = now + self.config.port_check_s
        try:
            st = os.stat(self.port_path)
        except OSError as e:
            self._drop_port(now, f"port path vanished: {e}")
            return
        if self._port_rdev is not None and stat.S_ISCHR(st.st_mode) and st.st_rdev != self._port_rdev:
            self._drop_port(now, f"{self.port_path} now points to another device")

    def _drop_port(self, now: float, reason: str, reopen: bool = True) -> None:
        if self._port is not None:
            try:
                self._port.close()
            except IO_ERRORS:
                pass
            self._port = None
            self._counters["disconnects"] += 1
            self._decoder.reset()
            log.warning("MCU link: %s closed: %s", self.port_path, reason)
        self._set_state(LinkState.DISCONNECTED, now, reason)
        if reopen:
            self._schedule_reopen(now)
        else:
            self._next_open = math.inf

    def _schedule_reopen(self, now: float) -> None:
        self._next_open = now + self._backoff_s
        self._backoff_s = min(self._backoff_s * 2, self.config.reopen_max_s)

    # ---- receive ------------------------------------------------------------------------------------

    def _receive(self, now: float) -> None:
        budget = self.config.max_read_per_poll
        while budget > 0 and self._port is not None:
            try:
                data = self._port.read(min(4096, budget))
            except IO_ERRORS as e:
                self._drop_port(now, f"read failed: {e}")
                return
            if not data:
                return
            budget -= len(data)
            for seq, msg in self._decoder.feed_messages(data):
                self._handle(now, seq, msg)

    def _handle(self, now: float, seq: int, msg: m.Message) -> None:
        if msg.SENDER == "host" or msg == self._last_tx_heartbeat:
            # Our own frames coming back: an echoing line, or a loop-back plug.
            self._counters["unexpected_messages"] += 1
            return
        if self._rx_seq is not None:
            self._counters["rx_seq_gaps"] += (seq - self._rx_seq - 1) % 256
        self._rx_seq = seq
        self._last_heard = now
        if isinstance(msg, m.HelloAck):
            self._on_hello_ack(now, msg)
            return
        if self._state is LinkState.SILENT:
            self._start_handshake(now)
        if isinstance(msg, m.Heartbeat):
            previous = self._mcu_heartbeat
            self._mcu_heartbeat = msg
            went_back = previous is not None and (msg.uptime_ms - previous.uptime_ms) % 2**32 >= 2**31
            if went_back and self._state is LinkState.UP:
                self._counters["mcu_resets"] += 1
                log.warning("MCU link: MCU uptime went back (%d -> %d ms): MCU reset, handshaking again",
                            previous.uptime_ms, msg.uptime_ms)
                self._start_handshake(now)
        elif isinstance(msg, m.VehicleSignals) and self._state is LinkState.UP:
            self._signals, self._signals_at = msg, now

    def _on_hello_ack(self, now: float, ack: m.HelloAck) -> None:
        self._mcu = ack
        self._decoder.peer_minor = ack.protocol_minor
        if ack.protocol_major != m.PROTOCOL_MAJOR:
            if self._state is not LinkState.INCOMPATIBLE:
                log.error("MCU link: MCU speaks protocol %d.%d, host %d.%d", ack.protocol_major,
                          ack.protocol_minor, m.PROTOCOL_MAJOR, m.PROTOCOL_MINOR)
            self._set_state(LinkState.INCOMPATIBLE, now,
                            f"MCU protocol {ack.protocol_major}.{ack.protocol_minor} ({ack.firmware}) "
                            f"is incompatible with host protocol {m.PROTOCOL_MAJOR}.{m.PROTOCOL_MINOR}")
            self._next_hello = now + self.config.incompatible_retry_s
            return
        if self._state is not LinkState.UP:
            self._counters["handshakes"] += 1
            self._backoff_s = self.config.reopen_min_s
            log.info("MCU link: MCU %s speaks protocol %d.%d", ack.firmware, ack.protocol_major, ack.protocol_minor)
            self._set_state(LinkState.UP, now, None)
            self._next_heartbeat = self._next_warning = now
            self._warning_dirty = True

    # ---- send ---------------------------------------------------------------------------------------

    def _start_handshake(self, now: float) -> None:
        self._set_state(LinkState.HANDSHAKING, now, "waiting for HELLO_ACK")
        self._next_hello = now

    def _run_timers(self, now: float) -> None:
        cfg = self.config
        state = self._state
        if state in (LinkState.HANDSHAKING, LinkState.UP):
            heard = self._opened_at if self._last_heard is None else self._last_heard
            if now - heard > cfg.silence_timeout_s:
                self._set_state(LinkState.SILENT, now, f"nothing heard from the MCU for {now - heard:.2f} s")
                state = LinkState.SILENT
        if state is not LinkState.UP and now >= self._next_hello:
            period = cfg.incompatible_retry_s if state is LinkState.INCOMPATIBLE else cfg.hello_period_s
            self._next_hello = now + period
            self._send(now, m.Hello(heartbeat_period_ms=round(cfg.heartbeat_period_s * 1000),
                                    host_timeout_ms=round(cfg.silence_timeout_s * 1000)))
        if state not in (LinkState.UP, LinkState.SILENT):
            return
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + cfg.heartbeat_period_s
            status = m.HostStatus.SYSTEM_OK if self._system_ok else 0
            uptime_ms = int((now - self._created_at) * 1000) % 2**32
            self._last_tx_heartbeat = m.Heartbeat(uptime_ms, int(status))
            self._send(now, self._last_tx_heartbeat)
        if self._warning_dirty or now >= self._next_warning:
            self._next_warning = now + cfg.heartbeat_period_s
            self._warning_dirty = False
            self._send(now, self._warning)

    def _send(self, now: float, msg: m.Message) -> None:
        if self._port is None:
            return
        data = encode_message(msg, self._tx_seq)
        self._tx_seq = (self._tx_seq + 1) % 256
        try:
            self._port.write(data)
        except serial.SerialTimeoutException:
            # The MCU is not draining its input; the frame may be cut short, the next one's
            # leading 0x00 resynchronises the MCU. Silence detection reports a dead MCU.
            self._counters["tx_timeouts"] += 1
            return
        except IO_ERRORS as e:
            self._drop_port(now, f"write failed: {e}")
            return
        self._counters["tx_frames"] += 1
        self._counters["tx_bytes"] += len(data)

    # ---- state --------------------------------------------------------------------------------------

    def _set_state(self, state: LinkState, now: float, fault: str | None) -> None:
        if state is not self._state:
            log.info("MCU link: %s -> %s%s", self._state.value, state.value, f" ({fault})" if fault else "")
            self._state = state
            self._state_since = now
        self._fault = fault


def _saturate(value: float | None) -> float | None:
    """None for not-available inputs, else clamped to what a u16 centi field carries."""
    if value is None or not math.isfinite(value) or value < 0:
        return None
    return min(float(value), m.MAX_CENTI_VALUE)


def _char_device(port: object) -> int | None:
    """st_rdev of the port's open file when it is a character device, else None."""
    fileno = getattr(port, "fileno", None)
    if fileno is None:
        return None
    try:
        st = os.fstat(fileno())
    except (OSError, ValueError, TypeError, AttributeError):
        return None
    return st.st_rdev if stat.S_ISCHR(st.st_mode) else None


class LinkThread:
    """Runs link.poll() every tick_s in a daemon thread: `with LinkThread(link): ...`."""

    def __init__(self, link: McuLink, tick_s: float = 0.01):
        self.link = link
        self.tick_s = tick_s
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> LinkThread:
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="mcu-link", daemon=True)
            self._thread.start()
        return self

    def stop(self, timeout_s: float = 1.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout_s)
            self._thread = None
        self.link.close()

    def __enter__(self) -> LinkThread:
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def _run(self) -> None:
        while not self._stop.wait(self.tick_s):
            try:
                self.link.poll()
            except Exception:  # a bug must not kill the link silently: log it and keep polling
                log.exception("MCU link: poll() raised")
