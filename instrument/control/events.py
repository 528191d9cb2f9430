"""The two kinds of event and controller logs (JSON Lines, one raw event a line).

A `RawEvent` is what a device produced, in the device's own terms: a MIDI message as its control
id (cc/1/7 = 64), a HID report's changed controls by usage (X = 0.5), an OSC surface's or a
console page's message (speed = 1.2), a score's cue. It is what the hub checks, what a log records
and what a replay hands back. A `TargetEvent` is what a decoder makes of it: a target of the
control state and its value. For a device with a mapping (MIDI, HID) the mapping decides; for a
direct device (OSC, console, score) the control id already is the target name.

A log recorded by a run that stopped (Ctrl-C, SIGTERM, `--seconds`, a score's end) ends with the
line `{"end": T}`, T the performance time it stopped at: a replay plays until then, so a take's
last stretch without a control move is not lost. A log without it (a killed run, an older one,
one written by hand) plays until its last event.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

from ..errors import located, quoted
from ..textfile import NotJson, parse_json, read_text
from .targets import is_number


class Source(str):
    """Which device an event came from, as a log writes it: "midi:nanoKONTROL2", "hid:054c:09cc",
    "osc". It is that text (a log line, a message or a test reads it as before) with its parts read
    once, here: `kind`, the registry's key (control/kinds.py), and `name`, the device within its kind."""

    kind: str
    name: str

    def __new__(cls, text: str) -> Source:
        self = super().__new__(cls, text)
        self.kind, _, self.name = text.partition(":")
        return self

    @classmethod
    def of(cls, kind: str, name: str = "") -> Source:
        """The source of device `name` (may be empty) of `kind`."""
        return cls(f"{kind}:{name}" if name else kind)


@dataclass(frozen=True)
class RawEvent:
    """What a device produced, before any mapping (see the module docstring)."""

    time: float  # seconds since the performance started
    source: Source  # which device (a plain str is made a Source)
    control: str  # the device's control id, or a target name for a direct source
    value: float

    def __post_init__(self) -> None:
        if type(self.source) is str:  # noqa: E721 (a Source is a str too, and is kept)
            object.__setattr__(self, "source", Source(self.source))

    def to_json(self) -> str:
        return json.dumps({"t": self.time, "source": self.source, "control": self.control, "value": self.value})  # exact: replays hit the same frame


ControlEvent = RawEvent  # the older name, kept for the modules and logs' readers that use it


class TargetEvent(NamedTuple):
    """A target of the control state and the value a decoder asks for it (the hub checks it
    against the table of targets before it changes anything). A tuple: made for every event of
    a direct device, it costs a third of a frozen dataclass."""

    time: float
    target: str  # speed, style/NAME, preset/NAME, store/NAME, ...
    value: float


MAX_TIME = 1e9  # seconds (32 years): a later event was not recorded but edited in (t = 1e308 would make a replay endless)


def end_line(time: float) -> str:
    """The last line of a log recorded by a run that stopped at performance time `time`."""
    return json.dumps({"end": time})  # exact, as an event's t: the replay stops at the same frame


def read_log(path: str | Path, warn: Callable[[str], None] | None = None) -> list[RawEvent]:
    """Every event of a log, in time order (see `read_log_and_end`)."""
    return read_log_and_end(path, warn)[0]


def read_log_and_end(path: str | Path, warn: Callable[[str], None] | None = None) -> tuple[list[RawEvent], float | None]:
    """Every event of a log, in time order, and the time the recorded run stopped at (None when
    the log does not say); a bad line is a one-line error naming file and line.

    A last line without its newline that does not parse was cut by a killed run: the events
    before it are kept, and `warn` is told (what each event means is checked when it is applied).
    """
    path = Path(path)
    text = read_text(path)
    lines = text.splitlines()
    cut = bool(text) and not text.endswith(("\n", "\r"))
    events = []
    end: float | None = None
    end_number = 0
    for number, line in enumerate(lines, 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            item = parse_json(line)
        except NotJson as e:
            if cut and number == len(lines):
                if warn is not None:
                    warn(f"{path}:{number}: the last line is cut off (a killed run?): "
                         f"replaying the {len(events)} events before it")
                break
            raise located(path, f"not JSON: {e}", number) from None
        if isinstance(item, dict) and "instrument_log" in item:
            continue  # the header line: the mappings in force (control.loghead)
        if isinstance(item, dict) and "end" in item:
            if set(item) != {"end"} or not is_number(item["end"]) or not 0 <= item["end"] <= MAX_TIME or end is not None:
                raise located(path, f"expected one last line {{\"end\": T}}, T from 0 to {MAX_TIME:.0f} seconds", number)
            end, end_number = float(item["end"]), number
            continue
        if not isinstance(item, dict):
            raise located(path, "expected an object with t, source, control, value", number)
        missing = [k for k in ("t", "source", "control", "value") if k not in item]
        if missing:
            raise located(path, f"missing key {quoted(missing[0])}", number)
        t, value = item["t"], item["value"]
        if not (is_number(t) and is_number(value)) or not 0 <= t <= MAX_TIME:
            raise located(path, f"'t' and 'value' must be finite numbers, 't' from 0 to {MAX_TIME:.0f} seconds", number)
        events.append(RawEvent(float(t), Source(str(item["source"])), str(item["control"]), float(value)))
    events.sort(key=lambda e: e.time)
    if end is not None and events and events[-1].time > end:
        raise located(path, f"the log ends at {end:g} s, before its event at {events[-1].time:g} s", end_number)
    return events, end


class LogReplay:
    """Hands out a log's events as performance time passes; loops when asked. A device like any
    other (control/kinds.py): `poll` is `due`."""

    def __init__(self, events: list[RawEvent], loop: bool = False, end: float | None = None):
        """`end`: the time the recorded run stopped at (a log's last line), or None: a second
        after the last event. A loop starts again there."""
        self.events = events
        self.loop = loop and bool(events)
        last = events[-1].time if events else 0.0
        self.length = end if end is not None and end > last else last + 1.0 if events else 0.0
        self.position = 0
        self.offset = 0.0

    def due(self, now: float) -> list[RawEvent]:
        out = []
        while True:
            if self.position >= len(self.events):
                if not self.loop:
                    return out
                self.position, self.offset = 0, self.offset + self.length
            event = self.events[self.position]
            if event.time + self.offset > now:
                return out
            out.append(event)
            self.position += 1

    poll = due

    @property
    def finished(self) -> bool:
        return not self.loop and self.position >= len(self.events)

    def describe(self) -> str:
        return f"log of {len(self.events)} events" + (" (looped)" if self.loop else "")

    def close(self) -> None:
        pass
