"""Input devices: MIDI ports (mido + python-rtmidi) and OSC surfaces (HID controllers are in hid.py).

Each follows the device protocol of control/kinds.py: polled once per frame, it returns raw
events and never raises into the performance. A device that goes away is reported on the
console and reopened about once a second, while the walk goes on.
"""

from __future__ import annotations

import ctypes
import functools
import os
import re
import socket
import time
from collections.abc import Iterator
from contextlib import contextmanager

from ..errors import UserError, printable
from ..terminal import Console
from . import oscparse
from .checks import row_of, value_refusal
from .events import RawEvent, Source
from .jackwatch import Remaker, quiet_libjack, release
from .spec import TABLE, Row

RETRY_SECONDS = 1.0
POLL_BUDGET = 0.0005  # seconds a device's poll may spend decoding; the rest stays queued for the next


def midi_backend(api: str | None = None):
    """mido's rtmidi backend; api 'jack' for JACK, 'alsa' for ALSA (default: rtmidi's own choice)."""
    import mido

    name = "mido.backends.rtmidi" + {"jack": "/UNIX_JACK", "alsa": "/LINUX_ALSA", None: "", "": ""}[api]
    return mido.Backend(name, load=True)


def midi_raw(message) -> tuple[str, float] | None:
    """A mido message as a raw control id and value (cc/<channel>/<number>, note/<channel>/<note>,
    pitchbend/<channel>/0 with 0..16383, a note off as velocity 0), or None for any other message."""
    kind = message.type
    if kind == "control_change":
        return f"cc/{message.channel + 1}/{message.control}", float(message.value)
    if kind == "note_on":
        return f"note/{message.channel + 1}/{message.note}", float(message.velocity)
    if kind == "note_off":
        return f"note/{message.channel + 1}/{message.note}", 0.0
    if kind == "pitchwheel":
        return f"pitchbend/{message.channel + 1}/0", float(message.pitch + 8192)
    return None


def raw_from_bytes(data: list[int]) -> tuple[str, float] | None:
    """A MIDI message as the port delivered it (status and data bytes), parsed by mido, as a raw
    control id and value; None for other messages and for bytes that are no message at all."""
    return _raw_from_bytes(tuple(data))


@functools.lru_cache(maxsize=4096)
def _raw_from_bytes(data: tuple[int, ...]) -> tuple[str, float] | None:
    """Remembered: a controller sends the same few hundred messages over and over, and mido's
    parsing (a few microseconds) would otherwise cost a flood several times what the frame
    loop's input budget takes of the old hand decoding."""
    import mido

    try:
        return midi_raw(mido.Message.from_bytes(data))
    except (ValueError, TypeError):  # a status byte with the wrong number of data bytes, ...
        return None


def midi_hint(api: str | None) -> str:
    """What to try when MIDI through `api` fails: the other system (rtmidi's default is ALSA)."""
    if api == "jack":
        return " (is the JACK server running? for ALSA MIDI give --midi-api alsa)"
    return " (for JACK MIDI give --midi-api jack)"


# libasound's error handler: void (*)(const char *file, int line, const char *function, int err, const char *fmt, ...)
_ALSA_HANDLER = ctypes.CFUNCTYPE(None, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p)


def _libasound():
    """libasound as rtmidi loaded it (None where there is none)."""
    try:
        return ctypes.CDLL("libasound.so.2")
    except OSError:
        return None


@contextmanager
def alsa_errors_caught(caught: list[str]) -> Iterator[None]:
    """libasound prints its own line on stderr when it fails ("ALSA lib seq_hw.c:466:... open
    /dev/snd/seq failed"), before rtmidi raises: inside this, those go to `caught` ("function:
    reason") instead, for the one line that says what failed and what to do."""
    library = _libasound()
    if library is None:
        yield
        return

    def handler(file, line, function, err, fmt):  # the format's arguments are not reachable from here
        reason = os.strerror(abs(err)) if err else (fmt or b"").decode(errors="replace")
        caught.append(f"{(function or b'?').decode(errors='replace')}: {reason}")

    keep = _ALSA_HANDLER(handler)  # referenced until the default handler is back
    library.snd_lib_error_set_handler(keep)
    try:
        yield
    finally:
        library.snd_lib_error_set_handler(None)  # libasound's default again


@contextmanager
def midi_system(api: str | None) -> Iterator[None]:
    """Make MIDI ports inside: when the MIDI system itself fails (no ALSA sequencer, no JACK
    server) the failure is one UserError saying why, ALSA's reason included, and what to give instead."""
    caught: list[str] = []
    if api == "jack":
        quiet_libjack()
    with alsa_errors_caught(caught):
        try:
            yield
        except UserError:
            raise
        except Exception as error:
            alsa = f"; ALSA: {caught[0]}" if caught else ""
            raise UserError(f"MIDI is not available ({api or 'default'} API): {str(error).rstrip('.')}{alsa}"
                            f"{midi_hint(api)}") from None


RTMIDI_APIS = {"jack": "API_UNIX_JACK", "alsa": "API_LINUX_ALSA", None: "API_UNSPECIFIED", "": "API_UNSPECIFIED"}
QUEUE_LIMIT = 65536  # messages rtmidi holds between two polls: a flood is queued, not lost


CLOCK_KINDS = {0xF8: "clock", 0xFA: "start", 0xFB: "continue", 0xFC: "stop", 0xF2: "songpos"}


class MidiClockReader:
    """MIDI clock messages (clock, start, continue, stop, song position) from an input port to a
    tempo follower (runtime/tempo.py `TempoFollower.message`), each stamped with when it arrived.

    rtmidi gives each message the seconds since the one before, timed by the MIDI system when it
    came in. The messages of one read are put on `time.monotonic()` by those gaps, the newest at
    the time of the read: the device is read every frame and every 2 ms while the loop waits
    (runtime/clock.py), so that is a few milliseconds late at most, and the tempo's line fit
    averages it out. (Anchoring on the smallest read-minus-stamp difference over a window was
    tried: each time the window's minimum moved, every later tick jumped with it, and the fitted
    phase with them, by tens of milliseconds on this busy machine.)"""

    def __init__(self, follow):
        self.follow = follow  # callable(kind, moment, value)
        self.stamp = 0.0  # rtmidi's clock: the running sum of the gaps
        self.pending: list[tuple[str, float, int]] = []  # this read's clock messages: (kind, stamp, value)

    def take(self, data: list[int], delta: float) -> bool:
        """True if the message was a clock message (kept for `flush`)."""
        self.stamp += delta
        kind = CLOCK_KINDS.get(data[0]) if data else None
        if kind is None:
            return False
        value = data[1] | data[2] << 7 if kind == "songpos" and len(data) == 3 else 0
        self.pending.append((kind, self.stamp, value))
        return True

    def flush(self) -> None:
        """Give this read's clock messages to the follower, the newest message stamped now."""
        now = time.monotonic()
        for kind, stamp, value in self.pending:
            self.follow(kind, now - (self.stamp - stamp), value)
        self.pending.clear()


class MidiInput:
    """The first input port whose name matches a pattern, or a virtual port others connect to.

    python-rtmidi queues incoming messages in C++; the performance loop drains the queue each
    frame. No Python callback thread competes with the clock for the interpreter, so a flood of
    messages costs only their decoding.

    On JACK, a restart of the server kills our client with it: a `JackWatch` notices, and a
    background thread makes a new client (and virtual port) once the server is back, while the
    walk goes on and the status line says "waiting".
    """

    def __init__(self, console: Console, pattern: str | None = None, virtual: str | None = None, api: str | None = None,
                 clock: MidiClockReader | None = None):
        import rtmidi

        self.rtmidi = rtmidi
        self.clock = clock  # MIDI clock messages go here (with --sync midi), not through the mapping
        self.console, self.pattern, self.virtual = console, pattern, virtual
        # named by what the user gave (the virtual port, or the pattern), not by the port it finds:
        # the same device, with the same decoder, after it is unplugged and plugged back in
        self.source = Source.of("midi", virtual or pattern)
        self.api, self.api_name = getattr(rtmidi, RTMIDI_APIS[api]), api
        with midi_system(api):  # no MIDI system at all (no ALSA, no JACK server): one line
            self.port = self._new_port()
        # mido (and what it loads: its version's metadata, email's parser) loaded now, not by the
        # show's first message: 10 ms of imports in the live loop, which made a frame late and
        # the first control's response the slowest of the show (docs/crowds.md)
        raw_from_bytes([0xB0, 0, 0])
        self.open = False
        self.port_name = ""
        self.next_attempt = 0.0
        self.received = 0
        self.remaker = Remaker(self._remake, lambda port: release(port, port.delete)) if api == "jack" else None
        self._open(first=True)

    def _new_port(self):
        port = self.rtmidi.MidiIn(self.api, name="instrument", queue_size_limit=QUEUE_LIMIT)
        port.ignore_types(sysex=True, timing=self.clock is None, active_sense=True)
        return port

    def _remake(self):
        """A new client (and virtual port) on a JACK server that came back (background thread)."""
        port = self._new_port()
        if self.virtual:
            port.open_virtual_port(self.virtual)
        return port

    def _restarts(self) -> bool:
        """Follow a JACK server restart; True while there is no port to read."""
        if self.remaker is None:
            return False
        event, self.port = self.remaker.follow(self.port)
        if event == "back":
            self.next_attempt = 0.0
            if self.virtual:
                self.open = True
                self.console.say(f"the JACK server is back: MIDI input {self.source} on again")
        elif event == "lost":
            self.open = False
            self.console.warn(f"midi server {self.source}",
                              f"the JACK server went away: {self.source} waits for it; the walk goes on")
        return event in ("lost", "waiting")

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
            self.console.warn(f"midi {self.pattern or self.virtual}", f"cannot open MIDI input: {error}{midi_hint(self.api_name)}")

    def read_raw(self) -> list[tuple[str, float]]:
        """The messages queued since the last read, decoded, for at most POLL_BUDGET seconds
        (the rest stays in rtmidi's queue for the next read)."""
        out = []
        until = time.monotonic() + POLL_BUDGET
        taken = 0
        while taken % 64 or time.monotonic() < until:  # the clock is read every 64 messages
            item = self.port.get_message()
            if item is None:
                return out
            taken += 1
            if self.clock is not None and self.clock.take(item[0], item[1]):
                continue
            raw = raw_from_bytes(item[0])
            if raw is not None:
                out.append(raw)
        return out

    def poll(self, now: float) -> list[RawEvent]:
        if self._restarts():
            return []
        if not self.open:
            self._open()
        elif not self.virtual and time.monotonic() >= self.next_attempt:
            self.next_attempt = time.monotonic() + RETRY_SECONDS
            if self.port_name not in self.port.get_ports():
                self.console.warn(f"midi gone {self.port_name}", f"MIDI input {self.port_name!r} unplugged; the walk goes on, waiting for it")
                self.port.close_port()
                self.open = False
        events = [RawEvent(now, self.source, control, value) for control, value in self.read_raw()] if self.open else []
        if self.clock is not None:
            self.clock.flush()
        self.received += len(events)
        return events

    def describe(self) -> str:
        if self.remaker is not None and self.remaker.busy:
            return f"{self.source} waiting for the JACK server"
        return f"{self.source} {'on' if self.open else 'waiting'}"  # the port it found: said when it connects

    def close(self) -> None:
        if self.remaker is not None:
            self.remaker.close()
        if self.port is not None:
            release(self.port, self._close_port, leave_at_end=True)
        self.open = False

    def _close_port(self) -> None:
        if self.open:
            self.port.close_port()
        self.port.delete()


class OscInput:
    """Control surfaces (TouchOSC, Open Stage Control) sending the flat profile's control
    addresses: /walk/style/<name>, /walk/speed, /walk/gait, /walk/turn, /walk/liveliness,
    /walk/preset/<name>. A number is the value; a target with named values (gait) also takes
    the name as a string (`/walk/gait s "run"`). The first argument is the value: more are left
    and said (`_left_over`)."""

    source = Source.of("osc")

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
        self.walking: Iterator[bytes] | None = None  # the messages of a packet not yet taken
        self.refused: dict[str, int] = {}  # kind -> messages refused before they became events

    def poll(self, now: float) -> list[RawEvent]:
        """What arrived, for at most POLL_BUDGET seconds of parsing: the rest of a big bundle
        and later packets wait for the next poll (the socket's buffer holds them)."""
        events: list[RawEvent] = []
        until = time.monotonic() + POLL_BUDGET
        while time.monotonic() < until:
            if self.walking is None:
                try:
                    self.walking = oscparse.messages(self.sock.recv(65536))
                except OSError:  # nothing more (BlockingIOError), or the socket is gone
                    break
            try:
                for _ in range(64):
                    self._take(next(self.walking), now, events)
            except StopIteration:
                self.walking = None
            except oscparse.Malformed as error:
                self.walking = None
                self._refuse("malformed", f"ignored a malformed OSC packet on {self.address} ({error})")
        return events

    def _take(self, message: bytes, now: float, events: list[RawEvent]) -> None:
        try:
            address, value, tag = oscparse.first_number(message)
        except oscparse.Malformed as error:
            self._refuse("malformed", f"ignored a malformed OSC message on {self.address} ({error})")
            return
        if not address.startswith("/walk/"):
            self._refuse("address", f"ignored OSC address {address[:60]!r} on {self.address}: controls are /walk/...",
                         address)
        elif tag == "s" and (row := TABLE.get(address[len("/walk/"):])) is not None and row.choices:
            self._take_name(message, row, now, events)
        elif not tag and (row := row_of(address[len("/walk/"):], (), 0)) is not None and row.action:
            # an action's message with no argument is a press: Max's, QLab's and TouchOSC's buttons send them so
            events.append(RawEvent(now, self.source, address[len("/walk/"):], 1.0))
        elif value is None:
            self._refuse("argument", f"ignored {address[:60]} on {self.address}: "
                         + (f"its argument (type {tag!r}) is not a number" if tag else "it has no argument (a number is needed)"),
                         address)
        else:
            events.append(RawEvent(now, self.source, address[len("/walk/"):], value))
            self._left_over(message, address)

    def _take_name(self, message: bytes, row: Row, now: float, events: list[RawEvent]) -> None:
        """A named value (`/walk/gait s "run"`) as its number, so the event, the log and the echo
        hold the number; a name the row lacks is refused by the one check's verdict."""
        try:
            name = oscparse.first_string(message)
        except oscparse.Malformed as error:
            self._refuse("malformed", f"ignored a malformed OSC message on {self.address} ({error})")
            return
        value = row.number(name)
        why = value_refusal(row, row.kind, value)
        if why is not None:
            self._refuse(why.kind, f"ignored /walk/{row.kind} on {self.address}: {why.text}", f"/walk/{row.kind}")
        else:
            events.append(RawEvent(now, self.source, row.kind, float(value)))
            self._left_over(message, f"/walk/{row.kind}")

    def _left_over(self, message: bytes, address: str) -> None:
        """A control takes one value: a message taken by its first argument that carries more
        (an XY pad's two) is said, once a minute, whatever its address; the first stands. Refused,
        a surface sending two would control nothing, and the show would say why only by counts."""
        extra = oscparse.extra_tags(message)
        if extra:
            self.console.warn("osc-in extra", f"took {printable(address)} on {self.address} by its first argument and left "
                              f"{len(extra)} more (type tags {extra[:16]!r}): a control takes one value "
                              "(such messages are taken so; the next is shown in a minute)")

    def _refuse(self, kind: str, message: str, address: str = "") -> None:
        """Counted by kind; said once a minute per kind and address (each distinct bad address named)."""
        self.refused[kind] = self.refused.get(kind, 0) + 1
        self.console.warn(f"osc-in {kind}", message + (" (counted; this address's next is shown in a minute)" if address
                                                       else " (counted; the next is shown in a minute)"), subject=address)

    def describe(self) -> str:
        return f"osc-in {self.address}"

    def close(self) -> None:
        self.sock.close()
