"""Where raw events meet the control state: each device's decoder (its mapping, for MIDI and HID),
presets, and the controller log that records every raw event the state accepted.

Every event goes to the decoder of the device that sent it, made the first time the device is
heard from, by its kind's entry in the registry (control/kinds.py): one per device, so two
controllers of one kind, each with its own mapping, play at once. What a decoder asks for is
checked against the table of targets (control/targets.py) first; an event that is refused changes
nothing, is not recorded, is counted in `refused` by kind and warned about once a minute per
kind and control (each distinct control named: terminal.Console.warn).
"""

from __future__ import annotations

from pathlib import Path

from ..errors import UserError
from ..terminal import Console
from . import kinds
from .eventlog import EventLog
from .events import RawEvent, Source, TargetEvent
from .loghead import header_line
from .mapping import Mapper, Mapping
from .state import ControlState
from .targets import PRESET_NAME, raw_problem
from .values import preset_values

MAX_PRESETS = 1000  # presets a show holds at most: stores from a page or an OSC surface beyond it are refused


class Presets(dict):
    """The show's presets by name; `stored` counts the stores since the start, so the console
    notices one without comparing every preset each frame."""

    stored = 0

    def __setitem__(self, name: str, values: dict[str, float]) -> None:
        super().__setitem__(name, values)
        self.stored += 1


class ControlHub:
    def __init__(self, mappings: list[Mapping], presets: dict[str, dict[str, float]] | None = None,
                 record: str | Path | None = None, morph: float = 0.0, console: Console | None = None,
                 per_device: bool = True):
        """`per_device` False reads every device of a kind through one decoder of the kind's first
        mapping, as logs recorded before devices had their own were played (control/loghead.py)."""
        self.mappings = list(mappings)
        self.presets = Presets()
        for m in mappings:
            self.presets.update(m.presets)
        self.presets.update(presets or {})  # a show file's presets win over a mapping's
        if len(self.presets) > MAX_PRESETS:
            raise UserError(f"{len(self.presets)} presets (mappings, show file and --presets together): "
                            f"at most {MAX_PRESETS}")
        self.morph = morph or max([m.morph for m in mappings], default=0.0)  # the state's start morph time (start())
        self.per_device = per_device
        self.decoders: dict[str, kinds.Decoder | None] = {}  # by source (by kind when not per device)
        self.console = console
        self.refused: dict[str, int] = {}  # kind of refusal -> events refused
        self.log: EventLog | None = None
        if record:
            self.start_recording(record, header_line(mappings, per_device=per_device))

    def start(self, state: ControlState) -> None:
        """Give the state what the options and mappings set before the show: the morph time
        (`--morph`, else the longest of the mappings'); from then on it is a target like any other."""
        state.set("morph", self.morph)

    def start_recording(self, path: str | Path, header: str, replace: bool = False) -> None:
        """Record every accepted event from now on to a new log at `path` (an existing one only with `replace`)."""
        warn = None if self.console is None else lambda line: self.console.warn("record stopped", line)
        self.log = EventLog(path, header, replace, warn)

    def decoder(self, source: Source) -> kinds.Decoder | None:
        """The decoder of the device `source` names (made on first use); None for a device whose
        kind needs a mapping and has none."""
        key = source if self.per_device else source.kind
        if key not in self.decoders:
            kind = kinds.kind(source.kind)
            if kind.reads is None:
                self.decoders[key] = kind.decoder(None, self)
            else:
                mapping = (kind.mapping_for(source.name, self.mappings) if self.per_device
                           else next((m for m in self.mappings if kind.reads(m)), None))
                self.decoders[key] = None if mapping is None else kind.decoder(mapping, self)
        return self.decoders[key]

    def mapper(self, source: Source) -> Mapper | None:
        """The mapping reader of a device read through a mapping (feedback follows its controls)."""
        return getattr(self.decoder(source), "mapper", None)

    def apply(self, state: ControlState, event: RawEvent) -> bool:
        """Apply the event and record it; False (nothing changes, nothing is recorded) if it is
        refused or nothing knows what it means."""
        why = self._apply(state, event)
        if why is not None:
            self.refused[why] = self.refused.get(why, 0) + 1
            if self.console is not None:
                origin = event.source.kind[:20] if isinstance(event.source, Source) else "?"
                self.console.warn(f"refused {origin} {why}",
                                  f"ignored {_short(event.source)} {_short(event.control)!r} = {event.value!r}: {why} "
                                  "(counted; this control's next is shown in a minute)",
                                  subject=f"{_short(event.source)} {_short(event.control)}")
            return False
        if self.log is not None:
            self.log.write(event)
        return True

    def _apply(self, state: ControlState, event: RawEvent) -> str | None:
        """Why the event was refused, or None once it is applied."""
        if not isinstance(event.source, Source):
            return "no source"
        decoder = self.decoder(event.source)
        if decoder is None:  # a bad event is named as such first, as when there is a mapping
            return (raw_problem(event.source, event.control, event.value)
                    or f"no {kinds.kind(event.source.kind).title} mapping")
        return decoder.apply(state, event)

    def apply_target(self, state: ControlState, event: TargetEvent) -> str | None:
        """Set a target (recall or store a preset), checked against the table of targets; None
        once applied, else why it was refused. What a direct device's decoder does with its events."""
        target = event.target
        if isinstance(target, str) and target.startswith("preset/"):
            preset = self.presets.get(target[len("preset/"):])
            if preset is None:
                return "unknown preset"
            state.recall(preset, event.time)
            return None
        if isinstance(target, str) and target.startswith("store/"):  # the current values as a new preset
            name = target[len("store/"):]
            if not PRESET_NAME.fullmatch(name):
                return "bad preset name"
            if name not in self.presets and len(self.presets) >= MAX_PRESETS:
                return f"already {MAX_PRESETS} presets, the most a show holds (store over an existing name)"
            self.presets[name] = preset_values(state)
            return None
        why = state.problem(target, event.value)
        if why is None:
            state.set(target, event.value)
        return why

    def stopped_at(self, time: float) -> None:
        """The show stopped at performance time `time` (the first frame it did not play): the log
        ends with it, so its replay plays as long."""
        if self.log is not None:
            self.log.end = time

    def close(self) -> None:
        if self.log is not None:
            self.log.close()
            if self.log.lost and self.console is not None:
                self.console.warn("record lost", f"{self.log.path}: {self.log.lost} events not recorded ({self.log.error})")


def _short(text: object, limit: int = 60) -> str:
    text = str(text)
    return text if len(text) <= limit else text[:limit] + "..."
