"""Where raw events meet the control state: each device's mapping, direct sources, presets, and
the controller log that records every raw event as it is applied."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import UserError
from .events import ControlEvent
from .mapping import Mapper, Mapping
from .state import ControlState
from .values import preset_values


class ControlHub:
    def __init__(self, mappings: list[Mapping], presets: dict[str, dict[str, float]] | None = None,
                 record: str | Path | None = None, morph: float = 0.0):
        self.presets: dict[str, dict[str, float]] = {}
        for m in mappings:
            self.presets.update(m.presets)
        self.presets.update(presets or {})  # a show file's presets win over a mapping's
        self.morph = morph or max([m.morph for m in mappings], default=0.0)
        self.midi = next((Mapper(m, self.presets, self.morph) for m in mappings if m.midi is not None), None)
        self.hid = next((Mapper(m, self.presets, self.morph) for m in mappings if m.hid is not None), None)
        self.record_fd = None
        if record:
            try:
                self.record_fd = os.open(record, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o644)
            except FileExistsError:
                raise UserError(f"{record}: already exists; record to a new file (nothing is overwritten)") from None
            except OSError as e:
                raise UserError(f"{record}: cannot record: {e.strerror or e}") from None

    def apply(self, state: ControlState, event: ControlEvent) -> bool:
        """Record the raw event, then apply it; False if nothing knows what it means."""
        if self.record_fd is not None:
            os.write(self.record_fd, (event.to_json() + "\n").encode("utf-8"))  # one write: whole lines survive a kill
        if event.source.startswith("midi:"):
            return self.midi.apply(state, event) if self.midi else False
        if event.source.startswith("hid:"):
            return self.hid.apply(state, event) if self.hid else False
        if event.control.startswith("preset/"):
            preset = self.presets.get(event.control[len("preset/"):])
            if preset is None:
                return False
            state.recall(preset, event.time, self.morph)
            return True
        if event.control.startswith("store/"):  # a console's "store": the current values as a preset
            self.presets[event.control[len("store/"):]] = preset_values(state)
            return True
        return state.set(event.control, event.value)

    def close(self) -> None:
        if self.record_fd is not None:
            os.close(self.record_fd)
            self.record_fd = None
