"""systemd's notify protocol (sd_notify), without libsystemd: one datagram per message to the
unix socket named in $NOTIFY_SOCKET.

`READY=1` once the first frame has gone out, `WATCHDOG=1` from the frame loop itself (so a loop
that freezes stops petting and systemd restarts the service after WatchdogSec), `STATUS=` for
`systemctl status`, `STOPPING=1` on the way out. Outside systemd (no $NOTIFY_SOCKET) it does
nothing.
"""

from __future__ import annotations

import os
import socket
import time
from typing import Callable, Mapping

PETS_PER_INTERVAL = 3  # systemd's advice is at least twice per WatchdogSec; three leaves room for a slow frame


class SystemdNotifier:
    def __init__(self, environ: Mapping[str, str] = os.environ, now: Callable[[], float] = time.monotonic):
        self.now = now
        path = environ.get("NOTIFY_SOCKET", "")
        self.address = ("\0" + path[1:]) if path.startswith("@") else path  # "@name": Linux abstract namespace
        self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) if path else None
        self.interval = _watchdog_seconds(environ)
        self.last_pet = -float("inf")
        self.failed: str | None = None  # why the last message did not go out

    @property
    def active(self) -> bool:
        return self.sock is not None

    def send(self, message: str) -> bool:
        if self.sock is None:
            return False
        try:
            self.sock.sendto(message.encode("utf-8"), self.address)
            self.failed = None
            return True
        except OSError as error:  # systemd gone or restarting: the performance goes on
            self.failed = error.strerror or str(error)
            return False

    def ready(self, status: str = "") -> None:
        self.send("READY=1" + (f"\nSTATUS={status}" if status else ""))

    def status(self, text: str) -> None:
        self.send(f"STATUS={text}")

    def pet(self) -> None:
        """Tell the watchdog the loop is alive, a few times per watchdog interval."""
        if self.interval is None:
            return
        now = self.now()
        if now - self.last_pet >= self.interval / PETS_PER_INTERVAL:
            self.last_pet = now
            self.send("WATCHDOG=1")

    def stopping(self) -> None:
        self.send("STOPPING=1")

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None


def _watchdog_seconds(environ: Mapping[str, str]) -> float | None:
    """WatchdogSec as systemd passes it (WATCHDOG_USEC, for WATCHDOG_PID if given), or None."""
    try:
        usec = int(environ.get("WATCHDOG_USEC", ""))
    except ValueError:
        return None
    pid = environ.get("WATCHDOG_PID")
    if usec <= 0 or (pid and pid.strip() != str(os.getpid())):
        return None
    return usec / 1e6
