"""Where raw events meet the control state: each device's mapping, direct sources, presets, and
the controller log that records every raw event the state accepted.

Every event is checked against the table of targets (control/targets.py) first; one that is
refused changes nothing, is not recorded, is counted in `refused` by kind and warned about
once a minute per source and kind.
"""

from __future__ import annotations

from pathlib import Path

from ..terminal import Console
from .eventlog import EventLog
from .events import ControlEvent
from .loghead import header_line
from .mapping import Mapper, Mapping
from .state import ControlState
from .targets import PRESET_NAME, raw_problem
from .values import preset_values


class ControlHub:
    def __init__(self, mappings: list[Mapping], presets: dict[str, dict[str, float]] | None = None,
                 record: str | Path | None = None, morph: float = 0.0, console: Console | None = None):
        self.presets: dict[str, dict[str, float]] = {}
        for m in mappings:
            self.presets.update(m.presets)
        self.presets.update(presets or {})  # a show file's presets win over a mapping's
        self.morph = morph or max([m.morph for m in mappings], default=0.0)  # the state's start morph time (start())
        self.midi = next((Mapper(m, self.presets) for m in mappings if m.midi is not None), None)
        self.hid = next((Mapper(m, self.presets) for m in mappings if m.hid is not None or m.hid_usages), None)
        self.console = console
        self.refused: dict[str, int] = {}  # kind of refusal -> events refused
        self.log: EventLog | None = None
        if record:
            self.start_recording(record, header_line(mappings))

    def start(self, state: ControlState) -> None:
        """Give the state what the options and mappings set before the show: the morph time
        (`--morph`, else the longest of the mappings'); from then on it is a target like any other."""
        state.set("morph", self.morph)

    def start_recording(self, path: str | Path, header: str, replace: bool = False) -> None:
        """Record every accepted event from now on to a new log at `path` (an existing one only with `replace`)."""
        self.log = EventLog(path, header, replace)

    def apply(self, state: ControlState, event: ControlEvent) -> bool:
        """Apply the event and record it; False (nothing changes, nothing is recorded) if it is
        refused or nothing knows what it means."""
        why = self._apply(state, event)
        if why is not None:
            self.refused[why] = self.refused.get(why, 0) + 1
            if self.console is not None:
                origin = event.source.split(":")[0][:20]
                self.console.warn(f"refused {origin} {why}",
                                  f"ignored {_short(event.source)} {_short(event.control)!r} = {event.value!r}: {why} "
                                  "(such events are counted; the next is shown in a minute)")
            return False
        if self.log is not None:
            self.log.write(event)
        return True

    def _apply(self, state: ControlState, event: ControlEvent) -> str | None:
        """Why the event was refused, or None once it is applied."""
        if not isinstance(event.source, str):
            return "no source"
        device = event.source.split(":")[0]
        if device in ("midi", "hid"):
            why = raw_problem(event.source, event.control, event.value)
            if why is not None:
                return why
            mapper = self.midi if device == "midi" else self.hid
            if mapper is None:
                return f"no {device.upper()} mapping"
            return None if mapper.apply(state, event) else "not mapped"
        if isinstance(event.control, str) and event.control.startswith("preset/"):
            preset = self.presets.get(event.control[len("preset/"):])
            if preset is None:
                return "unknown preset"
            state.recall(preset, event.time)
            return None
        if isinstance(event.control, str) and event.control.startswith("store/"):  # the current values as a new preset
            name = event.control[len("store/"):]
            if not PRESET_NAME.match(name):
                return "bad preset name"
            self.presets[name] = preset_values(state)
            return None
        why = state.problem(event.control, event.value)
        if why is None:
            state.set(event.control, event.value)
        return why

    def close(self) -> None:
        if self.log is not None:
            self.log.close()
            if self.log.lost and self.console is not None:
                self.console.warn("record lost", f"{self.log.path}: {self.log.lost} events not recorded ({self.log.error})")


def _short(text: object, limit: int = 60) -> str:
    text = str(text)
    return text if len(text) <= limit else text[:limit] + "..."
