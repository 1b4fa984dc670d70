"""`headway service`: the in-vehicle daemon that systemd runs (systemd/headway.service).

A thin loop: pop results from the core, hand each to the stack (vehicle inputs -> FCW -> CAN -> MCU),
and several times a second evaluate health, refresh the status file and the status CAN frame, and
talk to systemd: READY=1 once the camera delivers and the bus is open, WATCHDOG=1 only while the
core's real-time loop goes round, STATUS= with a one-line summary. SIGTERM or SIGINT stop everything
within a second, flushing the logs; exit 0. SIGHUP runs the same stop path, then exits RESTART_EXIT
(75) so that systemd (Restart=on-failure) starts the service again with its configuration file read
anew: a reload that never runs half-reconfigured (check the file first: `headway config check`).

Before anything starts, the configuration and what it points to are checked (``app.config_check``, the
same as `headway config check` without opening the bus): a problem is exit 2 with the key named.
"""
from __future__ import annotations

import logging
import signal
import sys
import threading
import time
from contextlib import ExitStack
from typing import Optional

from firmware_bridge.link import LinkConfig, LinkThread, McuLink

from app import config as configuration
from app.can import CanBusError, CanSession
from app.config_check import problems
from app.contracts.faults import DEGRADED, FAULT
from app.core import Pipeline, SourceError
from app.supervisor.fifo_source import FifoReader
from app.supervisor.health import HealthMonitor, HealthParams
from app.supervisor.notify import Notifier
from app.supervisor.stack import Stack
from app.supervisor.status_file import STOPPED, write_status
from app.tracks_file import TracksWriter

log = logging.getLogger("headway")

LIVE_KINDS = ("v4l2", "firewire", "fifo")
STOP_SIGNALS = (signal.SIGTERM, signal.SIGINT, signal.SIGHUP)  # each runs the same stop path
RESTART_EXIT = 75  # EX_TEMPFAIL: after SIGHUP, so that systemd's Restart=on-failure starts it again
TICK_S = 0.05  # loop period when no frame arrives: health is evaluated at least this often


class JournalFormatter(logging.Formatter):
    """"<N>" syslog priority prefixes, which the journal turns into log levels; no colour codes."""

    PRIORITY = {logging.CRITICAL: 2, logging.ERROR: 3, logging.WARNING: 4, logging.INFO: 6, logging.DEBUG: 7}

    def format(self, record: logging.LogRecord) -> str:
        return f"<{self.PRIORITY.get(record.levelno, 6)}>{super().format(record)}"


def setup_logging(level: int = logging.INFO) -> None:
    handler = logging.StreamHandler(sys.stderr)
    fmt = "%(levelname)s %(name)s: %(message)s"
    handler.setFormatter(logging.Formatter(fmt) if sys.stderr.isatty() else JournalFormatter(fmt))
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(level)


class Service:
    def __init__(self, cfg: dict, notifier: Optional[Notifier] = None, stop: Optional[threading.Event] = None):
        self.cfg = cfg
        self.notifier = notifier or Notifier()
        self.stop = stop or threading.Event()
        self.health = HealthMonitor(HealthParams.from_config(cfg["health"]))
        self.ready_sent = False
        self.report = None
        self._status_warned = False
        self.can_session = None
        self._calibration = None  # the last frame's self-calibration estimate, for the status file
        self._last_status: dict = {}  # the last status written, the base of the "stopped" one
        self._concealed = 0  # frames the video decoder reported damaged and concealed (processed all the same)

    def _open_mcu(self, stack: ExitStack):
        port = self.cfg["mcu"]["port"]
        if not port:
            return None
        m = self.cfg["mcu"]
        link = McuLink(port, LinkConfig(baudrate=m["baudrate"], heartbeat_period_s=m["heartbeat_s"],
                                        silence_timeout_s=m["silent_after_s"]))
        thread = LinkThread(link).start()
        stack.callback(thread.stop)
        return link

    def run(self) -> int:
        cfg = self.cfg
        src = cfg["source"]
        live = src["kind"] in LIVE_KINDS
        with ExitStack() as stack:
            pipe = stack.enter_context(Pipeline(configuration.core_sections(cfg)))
            can_session = None
            if cfg["can"]["enabled"]:
                try:
                    can_session = self.can_session = stack.enter_context(CanSession.for_live(cfg))
                    if can_session.output.previous_log is not None:
                        log.info("CAN output log: the previous run's is kept as %s", can_session.output.previous_log)
                except CanBusError as exc:
                    log.error("CAN: %s", exc)
                    return 1
            mcu = self._open_mcu(stack)
            sup = Stack(cfg, can_session, mcu)
            fifo = None
            try:
                if src["kind"] == "fifo":
                    pipe.start({"kind": "push"})
                    cam = cfg["camera"]
                    fifo = FifoReader(src["path"], cam["width"], cam["height"], pipe.push).start()
                    stack.callback(fifo.stop)
                else:
                    pipe.start(configuration.source_spec(cfg))
            except SourceError as exc:
                log.error("camera: %s", exc)
                return 1
            stack.callback(pipe.stop)  # runs before the fifo reader stops (LIFO): no push into a stopped core
            log.info("started: preset %s, source %s, CAN %s, MCU %s", cfg["pipeline"]["preset"], src["kind"],
                     f"{cfg['can']['interface']}:{cfg['can']['channel']}" if can_session else "off",
                     cfg["mcu"]["port"] or "none")
            self.health.start(time.monotonic())
            self._loop(pipe, sup, can_session, mcu, live)
            self._publish_status(pipe.health())  # the counts up to the stop, the base of the "stopped" status
            self.notifier.stopping()
            log.info("stopping")
        # after the core, the CAN session and the MCU link have stopped: `headway status` reads "stopped"
        self._write_status({**self._last_status, "state": STOPPED, "faults": []})
        logging.shutdown()
        return 0

    def _loop(self, pipe: Pipeline, sup: Stack, can_session, mcu, live: bool) -> None:
        status_every = 1.0 / self.cfg["service"]["status_rate_hz"]
        watchdog_every = self.notifier.watchdog_interval_s() or 1.0
        next_status = next_watchdog = time.monotonic()
        last_state = None
        tracks = None
        if self.cfg["service"]["tracks_file"]:
            tracks = TracksWriter(open(self.cfg["service"]["tracks_file"], "a"))
        while not self.stop.is_set():
            r = pipe.pop(timeout_s=TICK_S)
            now = time.monotonic()
            if r is not None:
                latency_ms = (now - r.t_s) * 1000.0 if live else r.total_ms
                self.health.on_result(now, latency_ms, r.image_stddev, r.image_change)
                status = self.report.as_dict() if self.report else None
                decision = sup.step(r, time.time(), pipe, status=status)
                self._calibration = r.calibration
                self._concealed += "concealed" in r.events
                if tracks:
                    tracks.write(r, decision.level)
            if now >= next_status or r is None:
                h = pipe.health()
                inputs = can_session.health_inputs(time.time()) if can_session else {}
                mcu_up = None
                if mcu is not None:
                    mcu_up = mcu.health().get("state") == "up"
                    mcu.set_system_ok(self.report is None or self.report.state != FAULT)
                self.report = self.health.evaluate(now, h["last_alive_s"], h["running"], h["results_dropped"],
                                                   mcu_up=mcu_up, **inputs)
                if r is None and can_session is not None:
                    can_session.publish(time.time(), None, status=self.report.as_dict())
                if now >= next_status:
                    next_status = now + status_every
                    self._publish_status(h)
                if self.report.state != last_state:
                    level = logging.WARNING if self.report.state in (DEGRADED, FAULT) else logging.INFO
                    log.log(level, "%s", self.report.summary())
                    last_state = self.report.state
                if not self.ready_sent and self.health.frames > 0:
                    self.ready_sent = self.notifier.ready(self.report.summary())
                    log.info("ready: the camera delivers%s", " and the bus is open" if can_session else "")
                # The watchdog is fed only while the core's loop goes round: a stalled core stops the
                # pings and systemd restarts the service.
                if now >= next_watchdog and "core_stalled" not in self.report.faults:
                    self.notifier.watchdog()
                    next_watchdog = now + watchdog_every
        if tracks:
            tracks.close()

    def _publish_status(self, core_health: dict) -> None:
        rep = self.report
        self.notifier.status(rep.summary())
        st = rep.as_dict()
        st.update(camera=rep.camera, source_state=core_health["source_state"],
                  frames_captured=core_health["frames_captured"], fcw=None,
                  # frames the source could not use (undecodable, or of another size), and frames decoded
                  # with errors the decoder concealed
                  decode_errors={"skipped": core_health["decode_errors"], "concealed": self._concealed})
        if self.can_session is not None:
            st["can_input"] = self.can_session.input_counts()  # vehicle-bus frames read, used, dropped by reason
        if self._calibration is not None:
            st["calibration"] = self._calibration
        self._last_status = st
        self._write_status(st)

    def _write_status(self, st: dict) -> None:
        try:
            write_status(self.cfg["service"]["status_file"], st)
        except (OSError, ValueError) as exc:   # ValueError: a path the OS cannot take (config check refuses it)
            if not self._status_warned:  # once: a missing /run/headway outside systemd is no emergency
                log.warning("status file %s: %s", self.cfg["service"]["status_file"], exc)
                self._status_warned = True


def add_parser(subparsers) -> None:
    s = subparsers.add_parser("run", help="run on the live camera of the configuration until SIGINT/SIGTERM "
                                   "(the service, in a terminal)")
    s.add_argument("--config", help="configuration YAML (source:, camera:, can: sections)")
    s.add_argument("--tracks", help="also write the tracks here (.jsonl)")
    s.set_defaults(run=run)

    s = subparsers.add_parser("service", help="the in-vehicle daemon systemd runs (systemd/headway.service)")
    s.add_argument("--config", default="/etc/headway/config.yaml", help="configuration YAML")
    s.set_defaults(run=run)


def run(args) -> int:
    setup_logging()
    overrides = {"service": {"tracks_file": args.tracks}} if getattr(args, "tracks", None) else None
    cfg = configuration.load(args.config, overrides)  # a bad file raises before anything starts (exit 2)
    # the bus and the source are opened (and their failure reported) by run() itself
    found = problems(cfg, open_bus=False, open_source=False)
    if found:
        log.error("configuration error: %s", configuration.error_line(found[0], args.config))
        return 2
    service = Service(cfg)
    received: list[int] = []

    def on_signal(signum, _frame):
        received.append(signum)
        service.stop.set()

    for sig in STOP_SIGNALS:
        signal.signal(sig, on_signal)
    rc = service.run()
    if rc == 0 and received and received[0] == signal.SIGHUP:
        log.info("SIGHUP: stopped; exit %d so that systemd starts the service again with the configuration "
                 "read anew", RESTART_EXIT)
        return RESTART_EXIT
    return rc
