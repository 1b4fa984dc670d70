"""Frames from another process through a named pipe (FIFO): raw 8-bit gray, width x height bytes each.

For a bench or a camera stack Headway has no driver for (e.g. `gst-launch-1.0 ... ! video/x-raw,
format=GRAY8,width=640,height=480 ! filesink location=/run/headway/frames.fifo`), and for the service
tests. A thread reads whole frames and pushes them into the core's push source stamped with the
monotonic clock at arrival; a writer that goes away is waited for again (the camera is then "lost"
and comes back when frames do). The core's real-time thread is never touched by this thread's Python.
"""
from __future__ import annotations

import os
import select
import stat
import threading
import time
from typing import Callable

import numpy as np


class FifoError(ValueError):
    """The FIFO path is taken by something that is not a FIFO."""


class FifoReader:
    def __init__(self, path: str, width: int, height: int, push: Callable[[np.ndarray, float], None],
                 clock: Callable[[], float] = time.monotonic):
        self.path, self.width, self.height = path, width, height
        self._push, self._clock = push, clock
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="fifo-frames", daemon=True)
        self.frames = 0
        self.errors = 0

    def start(self) -> "FifoReader":
        if not os.path.exists(self.path):
            os.mkfifo(self.path, 0o660)
        elif not stat.S_ISFIFO(os.stat(self.path).st_mode):
            # a regular file would be read again and again at full speed, as if a camera filmed it
            raise FifoError(f"source.path {self.path}: is not a FIFO; remove it or give the path of a named pipe")
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def _run(self) -> None:
        size = self.width * self.height
        while not self._stop.is_set():
            try:
                # O_NONBLOCK: opening a FIFO for reading must not wait for a writer, so stop() works
                fd = os.open(self.path, os.O_RDONLY | os.O_NONBLOCK)
            except OSError:
                self.errors += 1
                self._stop.wait(0.2)
                continue
            buf = bytearray()
            try:
                while not self._stop.is_set():
                    ready, _, _ = select.select([fd], [], [], 0.1)
                    if not ready:
                        continue
                    chunk = os.read(fd, size - len(buf))
                    if not chunk:  # writer closed: wait for the next one
                        self._stop.wait(0.05)
                        break
                    buf += chunk
                    if len(buf) == size:
                        frame = np.frombuffer(bytes(buf), np.uint8).reshape(self.height, self.width)
                        buf.clear()
                        try:
                            self._push(frame, self._clock())
                            self.frames += 1
                        except Exception:  # the core refused it (stopped meanwhile): count, go on
                            self.errors += 1
            finally:
                os.close(fd)
