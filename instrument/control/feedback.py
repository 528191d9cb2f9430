"""MIDI feedback: LEDs, knob rings and motor faders follow the control state.

After every frame, each absolute control (and toggle and set button) of the mapping whose target changed (a preset recall,
a morph, another controller, a reset) is sent its value back in its own message, so the
surface shows where every parameter is; a control awaiting pick-up is told its parameter's
value each time it is moved, so a motor fader goes there and an LED ring shows where to go.
It is an output of the live loop: a device that is gone is reported and the performance goes on.
"""

from __future__ import annotations

import math
import re

from ..terminal import Console
from .devices import midi_backend, midi_system
from .jackwatch import Remaker, release
from .mapping import ControlSpec, Mapper
from .spec import TABLE
from .state import ControlState


def raw_values(spec: ControlSpec, value: float) -> list[tuple[str, int, int]]:
    """The (message type, number, value) a control would send to stand at `value`; a button in
    mode "set" is lit while its target is nearest its value (gait 1.6 lights "run")."""
    if spec.mode == "set":
        named = bool(TABLE[spec.target.split("/")[0]].choices)  # a named value stands for the nearest whole one
        lit = 127 if (math.floor(value + 0.5) if named else value) == spec.value else 0
        return [("control_change" if spec.message == "cc" else "note_on", spec.number, lit)]
    low, high = spec.travel
    unit = min(max((value - low) / (high - low), 0.0), 1.0)
    if spec.curve == "exp":
        unit = unit ** 0.5
    if spec.invert:
        unit = 1.0 - unit
    if spec.message == "cc":
        return [("control_change", spec.number, round(unit * 127))]
    if spec.message == "cc14":
        fine = round(unit * 16383)
        return [("control_change", spec.number, fine >> 7), ("control_change", spec.number + 32, fine & 0x7F)]
    if spec.message == "pitchbend":
        return [("pitchwheel", 0, round(unit * 16383) - 8192)]
    if spec.message == "note":
        return [("note_on", spec.number, 127 if unit >= 0.5 else 0)]
    return []


class MidiFeedback:
    def __init__(self, mapper: Mapper, state: ControlState, console: Console, pattern: str | None = None,
                 virtual: str | None = None, api: str | None = None):
        import mido

        self.mido, self.mapper, self.state, self.console = mido, mapper, state, console
        mapping = mapper.mapping
        self.name = f"midi feedback {virtual or pattern}"
        self.controls = [c for c in mapping.controls
                         if c.message in ("cc", "cc14", "pitchbend", "note") and c.mode in ("absolute", "toggle", "set")
                         and state.knows(c.target)]
        self.backend, self.pattern, self.virtual = midi_backend(api), pattern, virtual
        with midi_system(api):
            self.port = self._open_port()
        if self.port is None:
            console.warn(self.name, f"no MIDI output matches {pattern!r}: no feedback to the controller")
        self.remaker = Remaker(self._open_port, lambda port: release(port, port.close)) if api == "jack" else None
        self.sent: dict[ControlSpec, float] = {c: state.get(c.target) for c in self.controls}

    def _open_port(self):
        if self.virtual:
            return self.backend.open_output(f"{self.virtual} feedback", virtual=True)
        names = [n for n in self.backend.get_output_names() if re.search(self.pattern, n, re.IGNORECASE)]
        return self.backend.open_output(names[0]) if names else None

    def _restarts(self) -> bool:
        """Follow a JACK server restart (port made again in the background); True while there is none."""
        if self.remaker is None:
            return False
        event, self.port = self.remaker.follow(self.port)
        if event == "back":
            self.sent = {c: math.nan for c in self.controls}  # a new port: show every value again
        return event in ("lost", "waiting")

    def prepare(self, frame) -> list:
        messages = []
        awaiting, self.mapper.awaiting = self.mapper.awaiting, set()
        for spec in self.controls:
            value = frame.values.get(spec.target, 0.0)  # a button (reset, cue) has no value to show
            if value != self.sent[spec] or spec in awaiting:
                self.sent[spec] = value
                for kind, number, raw in raw_values(spec, value):
                    channel = spec.channel - 1
                    if kind == "control_change":
                        messages.append(self.mido.Message(kind, channel=channel, control=number, value=raw))
                    elif kind == "pitchwheel":
                        messages.append(self.mido.Message(kind, channel=channel, pitch=raw))
                    else:
                        messages.append(self.mido.Message(kind, channel=channel, note=number, velocity=raw))
        return messages

    def send(self, messages: list) -> None:
        if self._restarts():
            return
        if self.port is not None:
            for message in messages:
                self.port.send(message)

    def close(self) -> None:
        if self.remaker is not None:
            self.remaker.close()
        if self.port is not None:
            release(self.port, self.port.close)
            self.port = None
