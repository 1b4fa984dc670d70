"""Firmware bridge, the link: McuLink against the MCU simulator.

Over a pseudo-terminal pair (the host opens a symlink, like /dev/ttyMCU, to the pty slave; the
simulator speaks on the master): handshake, heartbeats, warnings, vehicle signals, a silent MCU, a
wrong protocol version, corrupt frames, a port that vanishes and comes back. Both ends run on a
`SteppedClock`, which follows the monotonic clock but stands still while the test process gets no
CPU, so a loaded machine cannot fake a silent MCU. Over pipes with a fake clock, where timing is
asserted exactly: silence detection, re-open back-off, MCU reset, I/O errors.
"""
from __future__ import annotations

import os
import time
from dataclasses import replace

import pytest
import serial

from firmware_bridge import messages as m
from firmware_bridge.link import LinkConfig, LinkState, LinkThread, McuLink
from firmware_bridge.mcu_sim import FdTransport, McuSimulator, SimConfig, SimFaults, open_pty

# Short periods so the tests are quick. Over the pty the silence timeout is 1 s except in the silence
# test; the fake-clock tests use 0.3 s throughout.
FAST = LinkConfig(heartbeat_period_s=0.05, silence_timeout_s=0.3, hello_period_s=0.1, incompatible_retry_s=0.5,
                  reopen_min_s=0.05, reopen_max_s=0.4, signals_stale_s=0.2, port_check_s=0.05)
PTY = replace(FAST, silence_timeout_s=1.0)
SIM_PERIOD_S = 0.05  # simulator heartbeat and vehicle-signals period
MARGIN_S = 0.3  # slack over the pty: loop period, and the kernel passing bytes between the two ends

COUNTERS = ("frames_ok", "crc_errors", "cobs_errors", "length_errors")


def sim_config(**kw) -> SimConfig:
    return SimConfig(heartbeat_period_s=SIM_PERIOD_S, signals_period_s=SIM_PERIOD_S, **kw)


class SteppedClock:
    """Follows time.monotonic(), but one advance() moves it by at most max_step_s."""

    def __init__(self, max_step_s: float = 0.01):
        self.t = 1000.0
        self.max_step_s = max_step_s
        self._real = time.monotonic()

    def advance(self) -> float:
        real = time.monotonic()
        self.t += min(real - self._real, self.max_step_s)
        self._real = real
        return self.t

    def __call__(self) -> float:
        return self.t


class Bench:
    """The simulator on a pty master; `path` (a symlink to the slave) is the host's serial port."""

    def __init__(self, tmp_path, config: SimConfig | None = None, faults: SimFaults | None = None):
        self.path = tmp_path / "ttyMCU"
        self.config = config or sim_config()
        self.faults = faults or SimFaults()
        self.clock = SteppedClock()
        self.sim: McuSimulator | None = None
        self._fds: tuple[int, ...] = ()
        self.plug_in()

    def link(self, config: LinkConfig = PTY) -> McuLink:
        return McuLink(self.path, config, clock=self.clock)

    def plug_in(self) -> None:
        master, slave, name = open_pty()
        self._fds = (master, slave)
        self.path.symlink_to(name)
        self.sim = McuSimulator(FdTransport(master), self.config, clock=self.clock, faults=self.faults)

    def unplug(self) -> None:
        """Like pulling a USB adapter: the pty pair closes and the device path disappears."""
        for fd in self._fds:
            os.close(fd)
        self._fds = ()
        self.path.unlink()
        self.sim = None

    def close(self) -> None:
        if self._fds:
            self.unplug()

    def run(self, link: McuLink, seconds: float, until=None, always=None) -> float | None:
        """Poll both ends about every 2 ms for up to `seconds` of bench time. Returns the bench time
        at which `until()` first held (None if it never did); `always()` must hold at every step."""
        t0 = self.clock()
        while (now := self.clock.advance()) - t0 < seconds:
            link.poll(now)
            if self.sim is not None:
                self.sim.poll(now)
            if always is not None:
                assert always(), link.health()
            if until is not None and until():
                return now - t0
            time.sleep(0.002)
        return None

    def settle(self, link: McuLink, until, timeout_s: float = 5.0) -> bool:
        """With the bench clock stopped (nothing new is due), poll both ends until until() holds:
        the bytes in flight have arrived. False if it does not hold within timeout_s real seconds."""
        deadline = time.monotonic() + timeout_s
        while not until():
            if time.monotonic() > deadline:
                return False
            time.sleep(0.005)
            link.poll()
            if self.sim is not None:
                self.sim.poll()
        return True


@pytest.fixture
def bench(tmp_path):
    b = Bench(tmp_path)
    yield b
    b.close()


@pytest.fixture
def link(bench):
    lk = bench.link()
    yield lk
    lk.close()


@pytest.fixture
def fast_link(bench):
    """A link with the 0.3 s silence timeout."""
    lk = bench.link(FAST)
    yield lk
    lk.close()


def is_up(link):
    return lambda: link.state is LinkState.UP


def bring_up(bench, link) -> float:
    elapsed = bench.run(link, 2.0, until=is_up(link))
    assert elapsed is not None, link.health()
    return elapsed


# ---- over a pseudo-terminal, bench clock ------------------------------------------------------------

def test_handshake_completes_and_heartbeats_keep_the_link_up(bench, link):
    assert bring_up(bench, link) < MARGIN_S
    sim = bench.sim
    bench.run(link, 1.0, always=is_up(link))
    counters = lambda: link.health()["counters"]
    # Every frame each end wrote arrives at the other, none is rejected.
    assert bench.settle(link, lambda: counters()["frames_ok"] == sim.stats.frames_sent
                        and sim.decoder.stats.frames_ok == counters()["tx_frames"]), (counters(), sim.stats)
    h = link.health()
    assert h["state"] == "up" and h["ok"] and h["fault"] is None
    assert h["mcu"]["protocol"] == "1.0" and h["mcu"]["firmware"] == "MCUSIM 0.1.0"
    assert h["last_heard_age_s"] < SIM_PERIOD_S + MARGIN_S
    c = h["counters"]
    assert (c["handshakes"], c["opens"], c["disconnects"]) == (1, 1, 0)
    assert c["crc_errors"] + c["cobs_errors"] + c["length_errors"] + sim.decoder.stats.frame_errors() == 0
    assert c["frames_ok"] >= 1.0 / SIM_PERIOD_S  # heartbeats and signals for a second of bench time
    assert sim.stats.hellos == 1 and sim.stats.host_heartbeats >= 0.8 * 1.0 / PTY.heartbeat_period_s
    assert sim.outputs() == (False, "off")


def test_warnings_arrive_at_the_mcu_with_level_ttc_and_range(bench, link):
    bring_up(bench, link)
    sim = bench.sim
    cases = [
        ((2, 1.85, 23.4), m.FcwWarning(2, 1.85, 23.4), (True, "red")),
        ((1, 3.2, 41.0), m.FcwWarning(1, 3.2, 41.0), (False, "amber")),
        ((2, 1e6, -5.0), m.FcwWarning(2, 655.34, None), (True, "red")),  # saturated / not available
        ((2, float("inf"), None), m.FcwWarning(2, None, None), (True, "red")),
        ((0, None, None), m.FcwWarning(0, None, None), (False, "off")),
    ]
    for args, expected, outputs in cases:
        link.send_warning(*args)
        elapsed = bench.run(link, 1.0, until=lambda: sim.warning == expected)
        assert elapsed is not None and elapsed < MARGIN_S, (args, sim.warning)
        assert sim.outputs() == outputs
    seqs = [seq for _, seq, _ in sim.warnings]
    assert len(seqs) >= len(cases)


def test_vehicle_signals_arrive_within_one_period_and_go_stale(bench, link):
    bring_up(bench, link)
    sim = bench.sim
    sim.set_vehicle(20.0, brake=True, turn_left=True)  # a discrete change: sent at once
    got = lambda: (r := link.vehicle_signals()) is not None and (r.speed_mps, r.brake, r.turn_left) == (20.0, True, True)
    elapsed = bench.run(link, 1.0, until=got)
    assert elapsed is not None and elapsed < MARGIN_S
    sim.set_vehicle(25.5, brake=True, turn_left=True)  # speed only: goes out with the next period
    elapsed = bench.run(link, 1.0, until=lambda: link.vehicle_signals().speed_mps == 25.5)
    assert elapsed is not None and elapsed < SIM_PERIOD_S + MARGIN_S
    reading = link.vehicle_signals()
    assert reading.age_s < SIM_PERIOD_S + MARGIN_S and not reading.stale and not reading.turn_right
    bench.faults.silent = True
    elapsed = bench.run(link, 2.0, until=lambda: link.vehicle_signals().stale)
    assert elapsed is not None and PTY.signals_stale_s - SIM_PERIOD_S <= elapsed < PTY.signals_stale_s + MARGIN_S


def test_a_silent_mcu_is_a_health_fault_within_timeout_plus_one_period_then_recovers(bench, fast_link):
    link = fast_link
    bring_up(bench, link)
    bench.run(link, 0.3)
    bench.faults.silent = True
    elapsed = bench.run(link, 2.0, until=lambda: link.state is LinkState.SILENT)
    assert elapsed is not None
    # Last frame heard at most one MCU period before the MCU fell silent.
    assert FAST.silence_timeout_s - SIM_PERIOD_S - 0.01 <= elapsed <= FAST.silence_timeout_s + SIM_PERIOD_S + MARGIN_S
    h = link.health()
    assert not h["ok"] and "nothing heard from the MCU" in h["fault"]
    # While silent the host keeps sending, so a warning still reaches an MCU that only lost its TX line.
    link.send_warning(2, 1.2, 15.0)
    assert bench.run(link, 1.0, until=lambda: bench.sim.warning == m.FcwWarning(2, 1.2, 15.0)) is not None
    bench.faults.silent = False
    elapsed = bench.run(link, 2.0, until=is_up(link))
    assert elapsed is not None and elapsed < SIM_PERIOD_S + FAST.hello_period_s + MARGIN_S
    assert link.health()["counters"]["handshakes"] == 2


def test_a_wrong_protocol_version_makes_the_link_incompatible_without_crashing(tmp_path):
    bench = Bench(tmp_path, config=sim_config(protocol_major=2, protocol_minor=3))
    link = bench.link()
    try:
        elapsed = bench.run(link, 2.0, until=lambda: link.state is LinkState.INCOMPATIBLE)
        assert elapsed is not None and elapsed < MARGIN_S
        link.send_warning(2, 1.0, 10.0)
        bench.run(link, 1.2, always=lambda: link.state is LinkState.INCOMPATIBLE)
        h = link.health()
        assert not h["ok"] and "MCU protocol 2.3" in h["fault"] and "host protocol 1.0" in h["fault"]
        sim = bench.sim
        assert sim.stats.host_heartbeats == 0 and sim.warnings == []  # nothing but HELLO goes out
        assert 2 <= sim.stats.hellos <= 1 + 1.2 / PTY.incompatible_retry_s + 1
        # Reflashed with the right version: the next HELLO brings the link up.
        sim.config.protocol_major, sim.config.protocol_minor = 1, 0
        assert bench.run(link, 2.0, until=is_up(link)) < PTY.incompatible_retry_s + MARGIN_S
    finally:
        link.close()
        bench.close()


def test_corrupt_frames_from_the_mcu_are_counted_and_dropped_every_good_one_decoded(bench, link):
    bring_up(bench, link)
    sim = bench.sim
    bench.run(link, 0.2)
    counters = lambda: link.health()["counters"]
    assert bench.settle(link, lambda: counters()["frames_ok"] == sim.stats.frames_sent)
    sim0, host0 = (sim.stats.frames_sent, sim.stats.bad_segments()), counters()
    bench.faults.bitflip_every, bench.faults.truncate_every, bench.faults.garbage_every = 5, 7, 3
    bench.faults.garbage_len = 24
    enough = lambda: sim.stats.frames_bitflipped >= 8 and sim.stats.frames_truncated >= 8
    assert bench.run(link, 20.0, until=enough, always=lambda: link.state is not LinkState.DISCONNECTED)
    bench.faults.bitflip_every = bench.faults.truncate_every = bench.faults.garbage_every = 0
    bench.run(link, 0.2)  # a few clean frames close the last corrupt run
    good = sim.stats.frames_sent - sim0[0]
    bad = sim.stats.bad_segments() - sim0[1]
    assert good > 30 and bad > 30
    delta = lambda: {k: counters()[k] - host0[k] for k in COUNTERS}
    # Every good frame arrives (none lost, none invented), every corrupt run is rejected once.
    expected = lambda d: (d["frames_ok"], d["crc_errors"] + d["cobs_errors"] + d["length_errors"]) == (good, bad)
    assert bench.settle(link, lambda: expected(delta())), (delta(), good, bad)
    d, host1 = delta(), counters()
    assert d["crc_errors"] >= sim.stats.frames_bitflipped  # a flipped bit is always a CRC error
    assert host1["bytes_discarded"] > host0["bytes_discarded"]
    assert link.state is LinkState.UP and host1["disconnects"] == 0, link.health()


def test_a_port_that_vanishes_and_comes_back_is_reopened_and_handshaken_again(bench, link):
    bring_up(bench, link)
    bench.unplug()
    elapsed = bench.run(link, 2.0, until=lambda: link.state is LinkState.DISCONNECTED)
    assert elapsed is not None and elapsed < PTY.port_check_s + MARGIN_S
    bench.run(link, 0.5, always=lambda: link.state is LinkState.DISCONNECTED)
    h = link.health()
    assert h["counters"]["open_failures"] >= 2 and "cannot open" in h["fault"]
    bench.plug_in()
    elapsed = bench.run(link, 3.0, until=is_up(link))
    assert elapsed is not None and elapsed < PTY.reopen_max_s + PTY.hello_period_s + MARGIN_S
    c = link.health()["counters"]
    assert (c["opens"], c["disconnects"], c["handshakes"]) == (2, 1, 2)
    assert bench.sim.stats.hellos == 1  # the new MCU was greeted
    link.send_warning(1, 4.0, 50.0)
    assert bench.run(link, 1.0, until=lambda: bench.sim.warning == m.FcwWarning(1, 4.0, 50.0)) is not None


def test_link_thread_polls_in_the_background(bench):
    link = McuLink(bench.path, PTY)  # on the monotonic clock, polled by the thread
    with LinkThread(link, tick_s=0.005):
        t0 = time.monotonic()
        while link.state is not LinkState.UP and time.monotonic() - t0 < 5.0:
            bench.sim.poll(bench.clock.advance())
            time.sleep(0.002)
        assert link.state is LinkState.UP
        link.send_warning(2, 2.0, 20.0)
        t0 = time.monotonic()
        while bench.sim.warning.level != 2 and time.monotonic() - t0 < 5.0:
            bench.sim.poll(bench.clock.advance())
            time.sleep(0.002)
        assert bench.sim.warning == m.FcwWarning(2, 2.0, 20.0)
    assert link.state is LinkState.DISCONNECTED  # stop() closed the port


# ---- over pipes, fake clock -----------------------------------------------------------------------

class FakeClock:
    def __init__(self):
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


class PipePort:
    """A port made of two pipes, with pyserial's read/write/close; errors on demand."""

    def __init__(self, rfd: int, wfd: int):
        self.rfd, self.wfd = rfd, wfd
        os.set_blocking(rfd, False)
        self.read_error: Exception | None = None
        self.write_error: Exception | None = None
        self.closed = False

    def read(self, size: int) -> bytes:
        if self.read_error is not None:
            raise self.read_error
        try:
            return os.read(self.rfd, size)
        except BlockingIOError:
            return b""

    def write(self, data: bytes) -> int:
        if self.write_error is not None:
            raise self.write_error
        return os.write(self.wfd, data)

    def close(self) -> None:
        self.closed = True


@pytest.fixture
def piped(tmp_path):
    """(link, sim, port, clock, step) on pipes; step(seconds) advances the clock 5 ms at a time."""
    clock = FakeClock()
    to_mcu, to_host = os.pipe(), os.pipe()
    sim = McuSimulator(FdTransport(to_mcu[0], to_host[1]), sim_config(), clock=clock)
    port = PipePort(to_host[0], to_mcu[1])
    path = tmp_path / "ttyFAKE"
    path.touch()
    link = McuLink(path, FAST, clock=clock, opener=lambda p, cfg: port)

    def step(seconds: float, until=None) -> float | None:
        t0 = clock.t
        while clock.t - t0 < seconds - 1e-9:
            clock.t += 0.005
            link.poll()
            sim.poll()
            if until is not None and until():
                return clock.t - t0
        return None

    yield link, sim, port, clock, step
    for fd in (*to_mcu, *to_host):
        os.close(fd)


def test_silence_is_declared_after_the_timeout_and_within_one_more_period_fake_clock(piped):
    link, sim, _, clock, step = piped
    assert step(1.0, until=is_up(link)) <= 0.015  # HELLO, HELLO_ACK: one poll each way
    step(1.0)
    assert link.state is LinkState.UP
    for _ in range(5):
        sim.faults.silent = True
        elapsed = step(2.0, until=lambda: link.state is LinkState.SILENT)
        assert FAST.silence_timeout_s - SIM_PERIOD_S < elapsed <= FAST.silence_timeout_s + SIM_PERIOD_S
        sim.faults.silent = False
        assert step(1.0, until=is_up(link)) <= SIM_PERIOD_S + 0.015
        step(0.123)  # shift the phase between the two ends
    assert link.health()["counters"]["handshakes"] == 6


def test_reopen_back_off_doubles_up_to_the_maximum_fake_clock(tmp_path):
    clock = FakeClock()
    attempts = []

    def failing_open(path, cfg):
        attempts.append(round(clock.t - 1000.0, 3))
        raise serial.SerialException(2, f"could not open port {path}: [Errno 2] No such file or directory")

    link = McuLink(tmp_path / "ttyNONE", FAST, clock=clock, opener=failing_open)
    while clock.t < 1002.0:
        assert link.poll() is LinkState.DISCONNECTED
        clock.t = round(clock.t + 0.001, 3)
    # 0.05, 0.1, 0.2, then the 0.4 s ceiling
    assert attempts == pytest.approx([0.0, 0.05, 0.15, 0.35, 0.75, 1.15, 1.55, 1.95], abs=0.0011)
    h = link.health()
    assert h["counters"]["open_failures"] == 8 and "No such file" in h["fault"]


def test_io_errors_close_the_port_and_never_escape_poll(piped):
    link, sim, port, clock, step = piped
    step(0.5, until=is_up(link))
    port.read_error = serial.SerialException("read failed: [Errno 5] Input/output error")
    assert link.poll() is LinkState.DISCONNECTED and port.closed
    assert "Input/output error" in link.health()["fault"]
    port.read_error, port.closed = None, False
    assert step(1.0, until=is_up(link)) is not None  # reopened after the back-off
    port.write_error = OSError(5, "Input/output error")
    link.send_warning(1, 3.0, 30.0)
    link.poll()
    assert link.state is LinkState.DISCONNECTED
    port.write_error = serial.SerialTimeoutException("Write timeout")  # MCU not draining: dropped, counted
    assert step(1.0, until=lambda: link.health()["counters"]["tx_timeouts"] > 0) is not None
    assert link.state is not LinkState.DISCONNECTED
    port.write_error = None
    assert step(1.0, until=is_up(link)) is not None
    c = link.health()["counters"]
    assert (c["disconnects"], c["opens"]) == (2, 3)


def test_an_mcu_reset_is_noticed_and_the_link_handshakes_again_fake_clock(piped):
    link, sim, _, clock, step = piped
    step(1.0, until=is_up(link))
    link.send_warning(2, 1.5, 12.0)
    step(0.5)
    assert sim.outputs() == (True, "red")
    sim.reset()  # uptime restarts, the host is forgotten: buzzer off until HELLO comes again
    assert sim.outputs() == (False, "unavailable")
    step(0.2)
    c = link.health()["counters"]
    assert c["mcu_resets"] == 1 and c["handshakes"] == 2 and sim.stats.hellos == 2
    assert link.state is LinkState.UP and sim.outputs() == (True, "red")


def test_the_host_ignores_its_own_frames_echoed_back(tmp_path):
    """A loop-back plug instead of the MCU: the host hears only its own HELLOs and never comes up."""
    clock = FakeClock()
    r, w = os.pipe()
    port = PipePort(r, w)
    path = tmp_path / "ttyLOOP"
    path.touch()
    link = McuLink(path, FAST, clock=clock, opener=lambda p, cfg: port)
    try:
        for _ in range(400):
            clock.t += 0.005
            link.poll()
        h = link.health()
        assert h["state"] == "silent" and h["counters"]["unexpected_messages"] >= 10
    finally:
        os.close(r)
        os.close(w)
