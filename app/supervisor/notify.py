"""systemd's notify protocol: one datagram of "KEY=value" lines to the socket in $NOTIFY_SOCKET.

Written out (a dozen lines) rather than pulled in as a dependency: the protocol is documented in
sd_notify(3) and stable. Without $NOTIFY_SOCKET (not started by systemd) every call is a no-op.
"""
from __future__ import annotations

import os
import socket
from typing import Optional


class Notifier:
    def __init__(self, address: Optional[str] = None):
        addr = address if address is not None else os.environ.get("NOTIFY_SOCKET", "")
        if addr.startswith("@"):  # abstract namespace socket
            addr = "\0" + addr[1:]
        self._addr = addr or None
        self._sock: Optional[socket.socket] = None
        if self._addr:
            self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
        self.failures = 0

    @property
    def enabled(self) -> bool:
        return self._sock is not None

    def send(self, **fields: str) -> bool:
        """send(READY="1", STATUS="...") -> True if delivered (or nothing to deliver to)."""
        if not self._sock:
            return True
        msg = "\n".join(f"{k}={v}" for k, v in fields.items()).encode()
        try:
            # never block: a notify socket nobody reads (a stuck manager, a test) must not hang the loop
            self._sock.sendto(msg, socket.MSG_DONTWAIT, self._addr)
            return True
        except OSError:
            self.failures += 1  # systemd gone or socket full: the watchdog will tell, never crash or wait here
            return False

    def ready(self, status: str) -> bool:
        return self.send(READY="1", STATUS=status)

    def watchdog(self) -> bool:
        return self.send(WATCHDOG="1")

    def status(self, text: str) -> bool:
        return self.send(STATUS=text)

    def stopping(self) -> bool:
        return self.send(STOPPING="1")

    def watchdog_interval_s(self) -> Optional[float]:
        """Half of WatchdogSec (systemd's advice), from $WATCHDOG_USEC, if this process is watched."""
        usec = os.environ.get("WATCHDOG_USEC")
        pid = os.environ.get("WATCHDOG_PID")
        if not usec or (pid and int(pid) != os.getpid()):
            return None
        return int(usec) / 2e6

    def close(self) -> None:
        if self._sock:
            self._sock.close()
            self._sock = None
