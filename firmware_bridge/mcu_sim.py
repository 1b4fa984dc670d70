"""MCU simulator: the cabin microcontroller's end of the protocol, in Python, for tests and the bench.

It behaves as docs/firmware-protocol.md asks of real firmware: HEARTBEAT and VEHICLE_SIGNALS from
start-up on, a HELLO_ACK for every HELLO, WARNINGs acted on only after a HELLO with its major
version, buzzer and LED off ("unavailable") when the host falls silent for its host timeout. It can
also misbehave on purpose (`SimFaults`): go silent or deaf, send garbage, truncated or bit-flipped
frames, or answer with another protocol version. `SimStats` counts what it wrote, so a test can
say exactly how many good frames and how many rejected frames the host must see.

Drive it with poll(now) from the test's loop, like McuLink. On the bench:

    python -m firmware_bridge.mcu_sim --pty            # prints the pty path to give the host
    python -m firmware_bridge.mcu_sim --port /dev/ttyUSB1 --speed-mps 20 --bitflip-every 10
"""
from __future__ import annotations

import argparse
import os
import random
import sys
import termios
import time
import tty
from dataclasses import dataclass
from typing import Callable, NamedTuple

from . import cobs
from . import messages as m
from .framing import DELIMITER, FrameDecoder, pack_frame


@dataclass
class SimConfig:
    protocol_major: int = m.PROTOCOL_MAJOR  # answer HELLO with this (another value: "wrong version")
    protocol_minor: int = m.PROTOCOL_MINOR
    fw_version: tuple[int, int, int] = (0, 1, 0)
    fw_name: str = "MCUSIM"
    heartbeat_period_s: float = 0.1
    signals_period_s: float = 0.05
    seed: int = 0  # for garbage bytes and the choice of flipped bits / cut points


@dataclass
class SimFaults:
    silent: bool = False  # write nothing (hung firmware, broken TX wire); input is still read
    deaf: bool = False  # drop everything received (broken RX wire)
    bitflip_every: int = 0  # flip one bit of every Nth frame before stuffing: one certain CRC error
    truncate_every: int = 0  # cut every Nth frame short, without its closing 0x00
    garbage_every: int = 0  # write garbage_len random bytes before every Nth frame
    garbage_len: int = 16


@dataclass
class SimStats:
    frames_sent: int = 0  # frames written whole and unmodified
    frames_bitflipped: int = 0
    frames_truncated: int = 0
    garbage_bytes: int = 0
    wire_segments: int = 0  # non-empty runs between 0x00 bytes written: good frames and the rest
    write_errors: int = 0  # writes that failed or were cut short (nobody reading)
    hellos: int = 0
    host_heartbeats: int = 0
    unexpected_messages: int = 0

    def bad_segments(self) -> int:
        """How many frames the receiver must reject: every closed run that was not a good frame."""
        return self.wire_segments - self.frames_sent


class Outputs(NamedTuple):
    buzzer: bool
    led: str  # "off", "amber" (pre-warning), "red" (warning), "unavailable" (no host / not OK)


class FdTransport:
    """Non-blocking reads and writes on a file descriptor (pty master, serial port or pipe ends)."""

    def __init__(self, fd: int, write_fd: int | None = None):
        self.fd = fd
        self.write_fd = fd if write_fd is None else write_fd
        os.set_blocking(self.fd, False)
        os.set_blocking(self.write_fd, False)

    def read(self) -> bytes:
        try:
            return os.read(self.fd, 4096)
        except (BlockingIOError, InterruptedError):
            return b""
        except OSError:  # EIO: the other side of a pty is not open (yet); like a line with no host
            return b""

    def write(self, data: bytes) -> bool:
        """Write all of data; False when it could not be written completely."""
        view = memoryview(data)
        while view:
            try:
                n = os.write(self.write_fd, view)
            except (BlockingIOError, InterruptedError):
                return False
            except OSError:
                return False
            view = view[n:]
        return True


class McuSimulator:
    def __init__(self, transport: FdTransport, config: SimConfig | None = None,
                 clock: Callable[[], float] = time.monotonic, faults: SimFaults | None = None):
        self.transport = transport
        self.config = config or SimConfig()
        self.faults = faults or SimFaults()
        self.stats = SimStats()
        self.decoder = FrameDecoder()
        self.warnings: list[tuple[float, int, m.FcwWarning]] = []  # (receive time, seq, message)
        self._clock = clock
        self._rng = random.Random(self.config.seed)
        self._signals = m.VehicleSignals(speed_mps=0.0)
        self._open_segment = 0
        self._frame_no = 0
        self.reset()

    # ---- what a test sets and reads -----------------------------------------------------------------

    def reset(self, now: float | None = None) -> None:
        """A power-on reset: uptime restarts, the host is forgotten, outputs off."""
        now = self._clock() if now is None else now
        self.decoder.reset()  # a half-received frame is lost with the RAM
        self._started = now
        self._tx_seq = 0
        self._next_heartbeat = self._next_signals = now
        self._signals_dirty = True
        self.host_hello: m.Hello | None = None
        self.host_status = 0
        self.warning = m.FcwWarning()
        self._last_host_frame: float | None = None

    def set_vehicle(self, speed_mps: float | None = None, brake: bool = False, turn_left: bool = False,
                    turn_right: bool = False) -> None:
        signals = m.VehicleSignals(speed_mps, brake, turn_left, turn_right)
        if (signals.brake, signals.turn_left, signals.turn_right) != (
                self._signals.brake, self._signals.turn_left, self._signals.turn_right):
            self._signals_dirty = True  # discrete inputs go out at once
        self._signals = signals

    @property
    def host_compatible(self) -> bool:
        return self.host_hello is not None and self.host_hello.protocol_major == self.config.protocol_major

    def host_alive(self, now: float | None = None) -> bool:
        now = self._clock() if now is None else now
        if self._last_host_frame is None or self.host_hello is None:
            return False
        return now - self._last_host_frame <= self.host_hello.host_timeout_ms / 1000.0

    def outputs(self, now: float | None = None) -> Outputs:
        """Buzzer and LED as the firmware would drive them now."""
        if not (self.host_compatible and self.host_alive(now) and self.host_status & m.HostStatus.SYSTEM_OK):
            return Outputs(False, "unavailable")
        level = self.warning.level
        if level is m.WarningLevel.WARNING:
            return Outputs(True, "red")
        return Outputs(False, "amber" if level is m.WarningLevel.PREWARNING else "off")

    def inject_garbage(self, data: bytes | None = None, n: int = 32) -> None:
        """Write garbage now (random n bytes unless given)."""
        data = self._rng.randbytes(n) if data is None else data
        self.stats.garbage_bytes += len(data)
        self._write(data)

    # ---- the loop ---------------------------------------------------------------------------------

    def poll(self, now: float | None = None) -> None:
        now = self._clock() if now is None else now
        while data := self.transport.read():
            if self.faults.deaf:
                continue
            for seq, msg in self.decoder.feed_messages(data):
                self._handle(now, seq, msg)
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + self.config.heartbeat_period_s
            uptime_ms = int((now - self._started) * 1000) % 2**32
            self._send(m.Heartbeat(uptime_ms, 0))
        if self._signals_dirty or now >= self._next_signals:
            self._next_signals = now + self.config.signals_period_s
            self._signals_dirty = False
            self._send(self._signals)

    def _handle(self, now: float, seq: int, msg: m.Message) -> None:
        if msg.SENDER == "mcu":
            self.stats.unexpected_messages += 1
            return
        self._last_host_frame = now
        if isinstance(msg, m.Hello):
            self.stats.hellos += 1
            self.host_hello = msg
            self.decoder.peer_minor = msg.protocol_minor
            cfg = self.config
            self._send(m.HelloAck(cfg.protocol_major, cfg.protocol_minor, *cfg.fw_version, fw_name=cfg.fw_name))
        elif isinstance(msg, m.Heartbeat):
            self.stats.host_heartbeats += 1
            self.host_status = msg.status
        elif isinstance(msg, m.FcwWarning) and self.host_compatible:
            self.warnings.append((now, seq, msg))
            self.warning = msg

    def _send(self, msg: m.Message) -> None:
        if self.faults.silent:
            return
        f = self.faults
        self._frame_no += 1
        nth = self._frame_no
        raw = pack_frame(msg.MSG_ID, self._tx_seq, msg.pack())
        self._tx_seq = (self._tx_seq + 1) % 256
        out = bytearray()
        if f.garbage_every and nth % f.garbage_every == 0:
            garbage = self._rng.randbytes(f.garbage_len)
            self.stats.garbage_bytes += len(garbage)
            out += garbage
        if f.bitflip_every and nth % f.bitflip_every == 0:
            bit = self._rng.randrange(len(raw) * 8)
            flipped = bytearray(raw)
            flipped[bit // 8] ^= 1 << (bit % 8)
            out += DELIMITER + cobs.encode(bytes(flipped)) + DELIMITER
            self.stats.frames_bitflipped += 1
        elif f.truncate_every and nth % f.truncate_every == 0:
            encoded = cobs.encode(raw)
            out += DELIMITER + encoded[:self._rng.randrange(1, len(encoded))]
            self.stats.frames_truncated += 1
        else:
            out += DELIMITER + cobs.encode(raw) + DELIMITER
            self.stats.frames_sent += 1
        self._write(bytes(out))

    def _write(self, data: bytes) -> None:
        if not self.transport.write(data):
            self.stats.write_errors += 1
        # Count the zero-delimited runs put on the wire (what the receiver will try to decode).
        for i, part in enumerate(data.split(DELIMITER)):
            if i > 0 and self._open_segment:
                self.stats.wire_segments += 1
                self._open_segment = 0
            self._open_segment += len(part)


# ---- ports for tests and the bench ------------------------------------------------------------------

def open_pty() -> tuple[int, int, str]:
    """A raw pseudo-terminal pair: (master fd for the simulator, slave fd, slave path for the host).

    Keep the slave fd open while the pair is in use: it keeps the line settings and the data written
    before the host opens the path. Closing the master makes the host's reads fail (EIO), as when a
    USB serial adapter is unplugged.
    """
    master, slave = os.openpty()
    tty.setraw(slave)
    return master, slave, os.ttyname(slave)


def open_port(path: str, baudrate: int = 115200) -> int:
    """A real serial port for the simulator: raw 8N1 at baudrate, non-blocking."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY | os.O_NONBLOCK)
    if os.isatty(fd):
        tty.setraw(fd)
        attrs = termios.tcgetattr(fd)
        speed = getattr(termios, f"B{baudrate}")
        attrs[4] = attrs[5] = speed
        termios.tcsetattr(fd, termios.TCSANOW, attrs)
    return fd


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m firmware_bridge.mcu_sim",
                                description="Simulate the cabin MCU on a serial port or a new pseudo-terminal.")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--pty", action="store_true", help="create a pty pair and print the path for the host")
    where.add_argument("--port", help="serial port to speak on (e.g. a USB adapter null-modemed to the host)")
    p.add_argument("--baud", type=int, default=115200)
    p.add_argument("--speed-mps", type=float, default=0.0, help="vehicle speed to report")
    p.add_argument("--brake", action="store_true")
    p.add_argument("--protocol-major", type=int, default=m.PROTOCOL_MAJOR, help="answer HELLO with this major")
    p.add_argument("--silent", action="store_true", help="send nothing")
    p.add_argument("--garbage-every", type=int, default=0, metavar="N")
    p.add_argument("--bitflip-every", type=int, default=0, metavar="N")
    p.add_argument("--truncate-every", type=int, default=0, metavar="N")
    p.add_argument("--duration", type=float, default=0.0, help="seconds to run (0: until Ctrl-C)")
    a = p.parse_args(argv)

    if a.pty:
        fd, _slave, path = open_pty()
        print(f"MCU simulator: host port is {path}", flush=True)
    else:
        fd = open_port(a.port, a.baud)
    faults = SimFaults(silent=a.silent, garbage_every=a.garbage_every, bitflip_every=a.bitflip_every,
                       truncate_every=a.truncate_every)
    sim = McuSimulator(FdTransport(fd), SimConfig(protocol_major=a.protocol_major), faults=faults)
    sim.set_vehicle(a.speed_mps, brake=a.brake)
    end = time.monotonic() + a.duration if a.duration > 0 else float("inf")
    shown = None
    try:
        while time.monotonic() < end:
            sim.poll()
            out = sim.outputs()
            if out != shown:
                w = sim.warning
                print(f"LED {out.led:11s} buzzer {'ON ' if out.buzzer else 'off'}  level {w.level.name} "
                      f"ttc_s {w.ttc_s} lead_range_m {w.lead_range_m}", flush=True)
                shown = out
            time.sleep(0.005)
    except KeyboardInterrupt:
        pass
    print(f"sent {sim.stats}, received {sim.decoder.stats}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
