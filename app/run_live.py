"""`headway run`: the live camera through the pipeline until SIGINT/SIGTERM.

Results are popped from the core's queue (the GIL is released while waiting) and written to the
tracks file; a status line goes to stderr every few seconds. A signal stops the core and returns 0.
"""
from __future__ import annotations

import logging
import signal
import sys
import threading
from contextlib import ExitStack
from typing import Optional

from app import config as configuration
from app.core import EndOfStream, Pipeline, SourceError, monotonic_s
from app.tracks_file import TracksWriter

log = logging.getLogger("headway.run")


class RunError(RuntimeError):
    pass


def run(config_path: Optional[str], tracks_path: Optional[str] = None, status_every_s: float = 5.0,
        stop: Optional[threading.Event] = None) -> int:
    cfg = configuration.load(config_path)
    spec = configuration.source_spec(cfg)
    stop = stop or threading.Event()
    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, lambda *_: stop.set())
    with ExitStack() as stack:
        pipe = stack.enter_context(Pipeline(configuration.core_sections(cfg)))
        writer = TracksWriter(stack.enter_context(open(tracks_path, "w"))) if tracks_path else None
        try:
            pipe.start(spec)
        except SourceError as exc:
            raise RunError(str(exc)) from None
        log.info("running %s on %s", cfg["pipeline"]["preset"], spec)
        next_status = monotonic_s() + status_every_s
        while not stop.is_set():
            try:
                r = pipe.pop(timeout_s=0.2)
            except EndOfStream:
                break
            if r is not None and writer:
                writer.write(r)
            if monotonic_s() >= next_status:
                h = pipe.health()
                log.info("source %s, %d frames, %d dropped, last %.2f ms", h["source_state"], h["frames_processed"],
                         h["results_dropped"], h["last_total_ms"] or float("nan"))
                next_status += status_every_s
        pipe.stop()
    return 0


def main(args) -> int:
    logging.basicConfig(level=logging.INFO, stream=sys.stderr, format="%(levelname)s %(name)s: %(message)s")
    return run(args.config, args.tracks)
