"""Input devices: MIDI ports (mido + python-rtmidi), HID game controllers (hidapi), OSC surfaces.

Each device is polled once per frame and returns raw control events; it never raises into the
performance. A device that goes away is reported on the console and reopened about once a
second, while the walk goes on.
"""

from __future__ import annotations

import re
import socket
import time
from collections import deque

from ..errors import UserError
from ..runtime.console import Console
from .events import ControlEvent

RETRY_SECONDS = 1.0


def midi_backend(api: str | None = None):
    """mido's rtmidi backend; api 'jack' for JACK, 'alsa' for ALSA (default: rtmidi's own choice)."""
    import mido

    name = "mido.backends.rtmidi" + {"jack": "/UNIX_JACK", "alsa": "/LINUX_ALSA", None: "", "": ""}[api]
    return mido.Backend(name, load=True)


def midi_raw(message) -> tuple[str, float] | None:
    """A mido message as a raw control id and value, or None for messages no mapping uses."""
    channel = getattr(message, "channel", 0) + 1
    if message.type == "control_change":
        return f"cc/{channel}/{message.control}", float(message.value)
    if message.type == "note_on":
        return f"note/{channel}/{message.note}", float(message.velocity)
    if message.type == "note_off":
        return f"note/{channel}/{message.note}", 0.0
    if message.type == "pitchwheel":
        return f"pitchbend/{channel}/0", float(message.pitch + 8192)
    return None


class MidiInput:
    """The first input port whose name matches a pattern, or a virtual port others connect to."""

    def __init__(self, console: Console, pattern: str | None = None, virtual: str | None = None, api: str | None = None):
        self.console, self.pattern, self.virtual = console, pattern, virtual
        try:
            self.backend = midi_backend(api)
        except Exception as error:  # no MIDI system at all (no ALSA, no JACK server)
            raise UserError(f"MIDI is not available ({api or 'default'} API): {error}") from None
        self.pending: deque = deque()
        self.port = None
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
                self.port = self.backend.open_input(self.virtual, virtual=True, callback=self._receive)
                self.port_name = self.virtual
            else:
                names = [n for n in self.backend.get_input_names() if re.search(self.pattern, n, re.IGNORECASE)]
                if not names:
                    if first:
                        self.console.warn(f"midi {self.pattern}", f"no MIDI input matches {self.pattern!r} yet; waiting for it")
                    return
                self.port = self.backend.open_input(names[0], callback=self._receive)
                self.port_name = names[0]
                if not first:
                    self.console.say(f"MIDI input {names[0]!r} connected")
        except Exception as error:
            self.port = None
            self.console.warn(f"midi {self.pattern or self.virtual}", f"cannot open MIDI input: {error}")

    def _receive(self, message) -> None:  # called on rtmidi's thread
        self.pending.append(message)

    def poll(self, now: float) -> list[ControlEvent]:
        if self.port is None:
            self._open()
        elif not self.virtual and time.monotonic() >= self.next_attempt:
            self.next_attempt = time.monotonic() + RETRY_SECONDS
            if self.port_name not in self.backend.get_input_names():
                self.console.warn(f"midi gone {self.port_name}", f"MIDI input {self.port_name!r} unplugged; the walk goes on, waiting for it")
                self.port.close()
                self.port = None
        events = []
        while self.pending:
            raw = midi_raw(self.pending.popleft())
            if raw is not None:
                events.append(ControlEvent(now, self.source, raw[0], raw[1]))
        self.received += len(events)
        return events

    def describe(self) -> str:
        return f"{self.source} {'on' if self.port else 'waiting'}"

    def close(self) -> None:
        if self.port is not None:
            self.port.close()
            self.port = None


DS4_IDS = ((0x054C, 0x05C4), (0x054C, 0x09CC))
DS4_FACE = ("square", "cross", "circle", "triangle")
DS4_SHOULDER = ("l1", "r1", "l2", "r2", "share", "options", "l3", "r3")
HAT = {0: ("up",), 1: ("up", "right"), 2: ("right",), 3: ("down", "right"), 4: ("down",), 5: ("down", "left"),
       6: ("left",), 7: ("up", "left")}


def ds4_values(report: list[int]) -> dict[str, float] | None:
    """Controls of a DualShock 4 USB input report (id 0x01), or None for other reports."""
    if len(report) < 10 or report[0] != 0x01:
        return None
    values = {"lx": report[1], "ly": report[2], "rx": report[3], "ry": report[4], "l2": report[8], "r2": report[9]}
    hat = report[5] & 0x0F
    values["hat"] = hat
    for direction in ("up", "down", "left", "right"):
        values[f"button/{direction}"] = float(direction in HAT.get(hat, ()))
    for bit, name in enumerate(DS4_FACE):
        values[f"button/{name}"] = float(bool(report[5] & (0x10 << bit)))
    for bit, name in enumerate(DS4_SHOULDER):
        values[f"button/{name}"] = float(bool(report[6] & (1 << bit)))
    return {k: float(v) for k, v in values.items()}


class HidInput:
    """A HID game controller by vendor and product id, polled without blocking.

    `hid` is the hidapi module (or a stand-in with the same `enumerate` and `device`)."""

    def __init__(self, console: Console, vendor: int, product: int, hid=None):
        if hid is None:
            try:
                import hid
            except ImportError as error:
                raise UserError(f"HID is not available: {error} (pip install hidapi)") from None
        self.hid, self.console, self.vendor, self.product = hid, console, vendor, product
        self.device = None
        self.values: dict[str, float] = {}
        self.next_attempt = 0.0
        self.connected_once = False

    @property
    def source(self) -> str:
        return f"hid:{self.vendor:04x}:{self.product:04x}"

    def _open(self) -> None:
        now = time.monotonic()
        if now < self.next_attempt:
            return
        self.next_attempt = now + RETRY_SECONDS
        found = self.hid.enumerate(self.vendor, self.product)
        if not found:
            self.console.warn(f"hid {self.source}", f"HID device {self.vendor:04x}:{self.product:04x} not found; waiting for it")
            return
        try:
            device = self.hid.device()
            device.open_path(found[0]["path"])
            device.set_nonblocking(1)
        except OSError as error:
            self.console.warn(f"hid {self.source}", f"cannot open HID device {self.source}: {error}")
            return
        self.device = device
        self.console.say(f"HID device {self.source} {'reconnected' if self.connected_once else 'connected'}")
        self.connected_once = True

    def poll(self, now: float) -> list[ControlEvent]:
        if self.device is None:
            self._open()
            if self.device is None:
                return []
        events = []
        for _ in range(64):  # drain what is pending, bounded
            try:
                report = self.device.read(64)
            except OSError as error:  # unplugged: close, say so, reopen later
                self.console.warn(f"hid gone {self.source}", f"HID device {self.source} lost ({error}); the walk goes on, reconnecting")
                try:
                    self.device.close()
                finally:
                    self.device = None
                    self.next_attempt = time.monotonic() + RETRY_SECONDS
                break
            if not report:
                break
            values = ds4_values(list(report))
            if values is None:
                continue
            for control, value in values.items():
                if self.values.get(control) != value:
                    self.values[control] = value
                    events.append(ControlEvent(now, self.source, control, value))
        return events

    def describe(self) -> str:
        return f"{self.source} {'on' if self.device else 'waiting'}"

    def close(self) -> None:
        if self.device is not None:
            self.device.close()
            self.device = None


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
