"""Health of a running installation, for the technician and for monitoring tools.

Driven by the frame loop once per frame (so what it reports is the loop's own pulse): it pets
the systemd watchdog, writes a status line every minute (to the journal under systemd), and
answers status requests on a local UDP port: an OSC message `/walk/status` gets an OSC reply
`/walk/status` (frames, late, dropped, uptime, rss MB, open files, outputs, devices), and a
plain `status` datagram gets the same as one JSON line. An output is "down" while it fails (and
DOWN_FOR seconds after), or while it says so itself (an OSC target's name not resolved, the
console's link stopped). Nothing in a line or a reply is secret: the status port answers anyone
who can reach it, and devices describe themselves without the console's token.
"""

from __future__ import annotations

import json
import os
import socket
import time
from typing import Callable

from ..control.options import host_port
from ..errors import UserError
from .clock import FrameClock
from ..terminal import Console
from .notify import SystemdNotifier

DOWN_FOR = 2.0  # seconds after an output's last failure during which it counts as down
PAGE = os.sysconf("SC_PAGE_SIZE") if hasattr(os, "sysconf") else 4096


def rss_bytes() -> int:
    """Resident memory of this process (Linux /proc; 0 elsewhere)."""
    try:
        with open("/proc/self/statm", "rb") as f:
            return int(f.read().split()[1]) * PAGE
    except OSError:
        return 0


def open_files() -> int:
    """File descriptors this process holds (Linux /proc; 0 elsewhere)."""
    try:
        return len(os.listdir("/proc/self/fd")) - 1  # less the one listdir itself opened
    except OSError:
        return 0


def _failures(output, errors: dict[str, int]) -> int:
    """How often an output has failed so far: raised errors, plus sends an OSC target refused."""
    return errors.get(output.name, 0) + int(getattr(getattr(output, "out", None), "failed", 0))


def _down(output) -> bool:
    """An output that says it is down, failures or not: an OSC target whose name never resolved
    (nothing is sent, so nothing fails), the console whose link has stopped."""
    return bool(getattr(output, "down", False) or getattr(getattr(output, "out", None), "down", False))


class Health:
    def __init__(self, console: Console, outputs: list, devices: list, notifier: SystemdNotifier | None = None,
                 every: float = 60.0, status_address: str | None = None, now: Callable[[], float] = time.monotonic):
        self.console, self.outputs, self.devices = console, outputs, devices
        self.notifier = notifier or SystemdNotifier({})
        self.every, self.now = every, now
        self.started = now()
        self.last_line = self.started
        self.failures = [0] * len(outputs)
        self.failed_at = [-float("inf")] * len(outputs)
        self.frames = self.late = self.dropped = 0
        self.sock = None
        if status_address:
            host, number, _ = host_port("run --status-port", status_address)
            self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
            try:
                self.sock.bind((host or "127.0.0.1", number))
            except (OSError, OverflowError) as e:
                self.sock.close()
                raise UserError(f"--status-port {status_address!r}: cannot listen: {getattr(e, 'strerror', None) or e}") from None
            self.sock.setblocking(False)

    def frame(self, index: int, clock: FrameClock, summary) -> None:
        """Called by the live loop after each frame is sent."""
        now = self.now()
        self.frames, self.late, self.dropped = summary.frames, clock.late, clock.dropped
        if summary.frames == 1:
            self.notifier.ready(f"walking, frame {index}")
        self.notifier.pet()
        for k, output in enumerate(self.outputs):
            count = _failures(output, summary.output_errors)
            if count != self.failures[k]:
                self.failures[k], self.failed_at[k] = count, now
        if self.sock is not None:
            self._answer()
        if self.every > 0 and now - self.last_line >= self.every:
            self.last_line = now
            line = self.line()
            self.console.say(line)
            self.notifier.status(line)

    def report(self) -> dict:
        now = self.now()
        return {
            "uptime": round(now - self.started, 3), "frames": self.frames, "late": self.late, "dropped": self.dropped,
            "outputs": {o.name: "down" if now - t < DOWN_FOR or _down(o) else "up" for o, t in zip(self.outputs, self.failed_at)},
            "devices": [d.describe() for d in self.devices], "rss_mb": round(rss_bytes() / 1e6, 1), "open_files": open_files(),
        }

    def line(self) -> str:
        r = self.report()
        hours, rest = divmod(int(r["uptime"]), 3600)
        outputs = ", ".join(f"{name} {state}" for name, state in r["outputs"].items()) or "none"
        return (f"health: up {hours}h{rest // 60:02d}m; frames {r['frames']}, late {r['late']}, dropped {r['dropped']}; "
                f"outputs: {outputs}; devices: {', '.join(r['devices']) or 'none'}; "
                f"rss {r['rss_mb']:.1f} MB, {r['open_files']} files")

    def _answer(self) -> None:
        for _ in range(16):  # a few requests a frame at most: a flood cannot hold the loop
            try:
                data, sender = self.sock.recvfrom(2048)
            except OSError:  # nothing waiting (or a refused earlier reply): try again next frame
                return
            try:
                if data.startswith(b"/walk/status"):
                    self.sock.sendto(self._osc_reply(), sender)
                elif data.strip().lower() == b"status":
                    self.sock.sendto((json.dumps(self.report()) + "\n").encode("utf-8"), sender)
            except OSError:
                pass  # the asker is gone: nothing to do

    def _osc_reply(self) -> bytes:
        from ..output.osc import message

        r = self.report()
        outputs = "; ".join(f"{name} {state}" for name, state in r["outputs"].items())
        return message("/walk/status", r["frames"], r["late"], r["dropped"], float(r["uptime"]), float(r["rss_mb"]),
                       r["open_files"], outputs, "; ".join(r["devices"]))

    def close(self) -> None:
        if self.sock is not None:
            self.sock.close()
            self.sock = None
