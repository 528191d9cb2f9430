"""A plain UDP receiver on 127.0.0.1 for the tests: keeps every datagram (and when it arrived),
parsed by python-osc."""

from __future__ import annotations

import socket
import threading
import time

from pythonosc.osc_bundle import OscBundle
from pythonosc.osc_message import OscMessage


class Receiver:
    def __init__(self, port: int = 0):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", port))
        self.sock.settimeout(0.2)
        self.port = self.sock.getsockname()[1]
        self.datagrams: list[bytes] = []
        self.arrivals: list[float] = []  # time.monotonic() as each datagram was read, one a datagram
        self.running = True
        self.thread = threading.Thread(target=self._loop, daemon=True)
        self.thread.start()

    def _loop(self) -> None:
        while self.running:
            try:
                data = self.sock.recv(65536)
            except socket.timeout:
                continue
            except OSError:
                return
            self.arrivals.append(time.monotonic())
            self.datagrams.append(data)

    def close(self) -> None:
        self.running = False
        self.thread.join(2)
        self.sock.close()

    def messages(self) -> list[tuple[str, list]]:
        out = []
        for dgram in self.datagrams:
            if OscBundle.dgram_is_bundle(dgram):
                out += [(m.address, list(m.params)) for m in OscBundle(dgram) if isinstance(m, OscMessage)]
            else:
                message = OscMessage(dgram)
                out.append((message.address, list(message.params)))
        return out


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def frame_count(receiver: Receiver) -> int:
    """How many /walk/frame messages (flat profile) have come in so far."""
    return sum(d.count(b"/walk/frame\x00") for d in list(receiver.datagrams))
