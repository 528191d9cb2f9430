"""Control events and controller logs (JSON Lines, one event a line)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..errors import located
from ..textfile import read_text
from .targets import is_number


@dataclass(frozen=True)
class ControlEvent:
    time: float  # seconds since the performance started
    source: str  # which device: "demo", "midi:nanoKONTROL2", "hid:054c:09cc", "osc"
    control: str  # the device's control id, or a target name for a direct source
    value: float

    def to_json(self) -> str:
        return json.dumps({"t": self.time, "source": self.source, "control": self.control, "value": self.value})  # exact: replays hit the same frame


def read_log(path: str | Path, warn: Callable[[str], None] | None = None) -> list[ControlEvent]:
    """Every event of a log, in time order; a bad line is a one-line error naming file and line.

    A last line without its newline that does not parse was cut by a killed run: the events
    before it are kept, and `warn` is told (what each event means is checked when it is applied).
    """
    path = Path(path)
    text = read_text(path)
    lines = text.splitlines()
    cut = bool(text) and not text.endswith(("\n", "\r"))
    events = []
    for number, line in enumerate(lines, 1):
        if not line.strip() or line.lstrip().startswith("#"):
            continue
        try:
            item = json.loads(line)
        except (json.JSONDecodeError, RecursionError) as e:
            if cut and number == len(lines):
                if warn is not None:
                    warn(f"{path}:{number}: the last line is cut off (a killed run?): "
                         f"replaying the {len(events)} events before it")
                break
            raise located(path, f"not JSON: {getattr(e, 'msg', 'nested too deeply')}", number) from None
        if isinstance(item, dict) and "instrument_log" in item:
            continue  # the header line: the mappings in force (control.loghead)
        if not isinstance(item, dict):
            raise located(path, "expected an object with t, source, control, value", number)
        missing = [k for k in ("t", "source", "control", "value") if k not in item]
        if missing:
            raise located(path, f"missing key {missing[0]!r}", number)
        t, value = item["t"], item["value"]
        if not (is_number(t) and is_number(value)) or t < 0:
            raise located(path, "'t' and 'value' must be finite numbers, 't' not negative", number)
        events.append(ControlEvent(float(t), str(item["source"]), str(item["control"]), float(value)))
    events.sort(key=lambda e: e.time)
    return events


class LogReplay:
    """Hands out a log's events as performance time passes; loops when asked."""

    def __init__(self, events: list[ControlEvent], loop: bool = False):
        self.events = events
        self.loop = loop and bool(events)
        self.length = (events[-1].time + 1.0) if events else 0.0
        self.position = 0
        self.offset = 0.0

    def due(self, now: float) -> list[ControlEvent]:
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

    @property
    def finished(self) -> bool:
        return not self.loop and self.position >= len(self.events)
