"""Input devices: MIDI ports (mido + python-rtmidi) and OSC surfaces (HID controllers are in hid.py).

Each device is polled once per frame and returns raw control events; it never raises into the
performance. A device that goes away is reported on the console and reopened about once a
second, while the walk goes on.
"""

from __future__ import annotations

import re
import socket
import time

from ..errors import UserError
from ..runtime.console import Console
from .events import ControlEvent

RETRY_SECONDS = 1.0


def midi_backend(api: str | None = None):
    """mido's rtmidi backend; api 'jack' for JACK, 'alsa' for ALSA (default: rtmidi's own choice)."""
    import mido

    name = "mido.backends.rtmidi" + {"jack": "/UNIX_JACK", "alsa": "/LINUX_ALSA", None: "", "": ""}[api]
    return mido.Backend(name, load=True)


def raw_from_bytes(data: list[int]) -> tuple[str, float] | None:
    """A MIDI message (status and data bytes) as a raw control id and value, or None."""
    if len(data) < 2:
        return None
    kind, channel = data[0] & 0xF0, (data[0] & 0x0F) + 1
    if kind == 0xB0 and len(data) >= 3:
        return f"cc/{channel}/{data[1]}", float(data[2])
    if kind == 0x90 and len(data) >= 3:
        return f"note/{channel}/{data[1]}", float(data[2])
    if kind == 0x80 and len(data) >= 3:
        return f"note/{channel}/{data[1]}", 0.0
    if kind == 0xE0 and len(data) >= 3:
        return f"pitchbend/{channel}/0", float(data[1] | (data[2] << 7))
    return None


def midi_raw(message) -> tuple[str, float] | None:
    """A mido message as a raw control id and value (for MIDI files)."""
    return None if message.is_meta else raw_from_bytes(message.bytes())


RTMIDI_APIS = {"jack": "API_UNIX_JACK", "alsa": "API_LINUX_ALSA", None: "API_UNSPECIFIED", "": "API_UNSPECIFIED"}
QUEUE_LIMIT = 65536  # messages rtmidi holds between two polls: a flood is queued, not lost


class MidiInput:
    """The first input port whose name matches a pattern, or a virtual port others connect to.

    python-rtmidi queues incoming messages in C++; the performance loop drains the queue each
    frame. No Python callback thread competes with the clock for the interpreter, so a flood of
    messages costs only their decoding.
    """

    def __init__(self, console: Console, pattern: str | None = None, virtual: str | None = None, api: str | None = None):
        import rtmidi

        self.rtmidi = rtmidi
        self.console, self.pattern, self.virtual = console, pattern, virtual
        self.api = getattr(rtmidi, RTMIDI_APIS[api])
        try:
            self.port = rtmidi.MidiIn(self.api, name="instrument", queue_size_limit=QUEUE_LIMIT)
        except Exception as error:  # no MIDI system at all (no ALSA, no JACK server)
            raise UserError(f"MIDI is not available ({api or 'default'} API): {error}") from None
        self.port.ignore_types(sysex=True, timing=True, active_sense=True)
        self.open = False
        self.port_name = ""
        self.next_attempt = 0.0
        self.received = 0
        self._open(first=True)

    @property
    def source(self) -> str:
        return f"midi:{self.virtual or self.port_name or self.pattern}"

    def _open(self, first: bool = False) -> None:
        now = time.monotonic()
        if now < self.next_attempt:
            return
        self.next_attempt = now + RETRY_SECONDS
        try:
            if self.virtual:
                self.port.open_virtual_port(self.virtual)
                self.port_name = self.virtual
            else:
                names = self.port.get_ports()
                matching = [k for k, n in enumerate(names) if re.search(self.pattern, n, re.IGNORECASE)]
                if not matching:
                    if first:
                        self.console.warn(f"midi {self.pattern}", f"no MIDI input matches {self.pattern!r} yet; waiting for it")
                    return
                self.port.open_port(matching[0], name="input")
                self.port_name = names[matching[0]]
                if not first:
                    self.console.say(f"MIDI input {self.port_name!r} connected")
            self.open = True
        except Exception as error:
            self.console.warn(f"midi {self.pattern or self.virtual}", f"cannot open MIDI input: {error}")

    def read_raw(self) -> list[tuple[str, float]]:
        """Every message queued since the last read, decoded."""
        out = []
        while True:
            item = self.port.get_message()
            if item is None:
                return out
            raw = raw_from_bytes(item[0])
            if raw is not None:
                out.append(raw)

    def poll(self, now: float) -> list[ControlEvent]:
        if not self.open:
            self._open()
        elif not self.virtual and time.monotonic() >= self.next_attempt:
            self.next_attempt = time.monotonic() + RETRY_SECONDS
            if self.port_name not in self.port.get_ports():
                self.console.warn(f"midi gone {self.port_name}", f"MIDI input {self.port_name!r} unplugged; the walk goes on, waiting for it")
                self.port.close_port()
                self.open = False
        events = [ControlEvent(now, self.source, control, value) for control, value in self.read_raw()] if self.open else []
        self.received += len(events)
        return events

    def describe(self) -> str:
        return f"{self.source} {'on' if self.open else 'waiting'}"

    def close(self) -> None:
        if self.open:
            self.port.close_port()
            self.open = False
        self.port.delete()


class OscInput:
    """Control surfaces (TouchOSC, Open Stage Control) sending the flat profile's control
    addresses: /walk/style/<name>, /walk/speed, /walk/turn, /walk/liveliness, /walk/preset/<name>."""

    source = "osc"

    def __init__(self, console: Console, address: str):
        host, _, port = address.rpartition(":")
        try:
            number = int(port)
        except ValueError:
            raise UserError(f"--osc-in {address!r}: expected [HOST:]PORT") from None
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            self.sock.bind((host or "127.0.0.1", number))
        except OSError as e:
            raise UserError(f"--osc-in {address!r}: cannot listen: {e.strerror}") from None
        self.sock.setblocking(False)
        self.console = console
        self.address = f"{host or '127.0.0.1'}:{number}"

    def poll(self, now: float) -> list[ControlEvent]:
        from pythonosc.osc_bundle import OscBundle
        from pythonosc.osc_message import OscMessage

        events = []
        for _ in range(1000):
            try:
                data = self.sock.recv(65536)
            except (BlockingIOError, OSError):
                break
            try:
                messages = list(OscBundle(data)) if OscBundle.dgram_is_bundle(data) else [OscMessage(data)]
            except Exception:
                self.console.warn("osc-in bad", f"ignored a malformed OSC packet on {self.address}")
                continue
            for m in messages:
                if isinstance(m, OscMessage) and m.address.startswith("/walk/"):
                    value = m.params[0] if m.params and isinstance(m.params[0], (int, float)) else 1.0
                    events.append(ControlEvent(now, self.source, m.address[len("/walk/"):], float(value)))
        return events

    def describe(self) -> str:
        return f"osc-in {self.address}"

    def close(self) -> None:
        self.sock.close()
