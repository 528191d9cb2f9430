"""Where raw events meet the control state: each device's mapping, direct sources, presets, and
the controller log that records every raw event as it is applied."""

from __future__ import annotations

import os
from pathlib import Path

from ..errors import UserError
from .events import ControlEvent
from .loghead import header_line
from .mapping import Mapper, Mapping
from .state import ControlState


class ControlHub:
    def __init__(self, mappings: list[Mapping], presets: dict[str, dict[str, float]] | None = None,
                 record: str | Path | None = None, morph: float = 0.0):
        self.presets: dict[str, dict[str, float]] = {}
        for m in mappings:
            self.presets.update(m.presets)
        self.presets.update(presets or {})  # a show file's presets win over a mapping's
        self.morph = morph or max([m.morph for m in mappings], default=0.0)
        self.midi = next((Mapper(m, self.presets, self.morph) for m in mappings if m.midi is not None), None)
        self.hid = next((Mapper(m, self.presets, self.morph) for m in mappings if m.hid is not None or m.hid_usages), None)
        self.record_fd = None
        if record:
            self.start_recording(record, header_line(mappings))

    def start_recording(self, path: str | Path, header: str, replace: bool = False) -> None:
        """Record every raw event from now on to a new log at `path` (an existing one only with `replace`)."""
        exclusive = os.O_TRUNC if replace else os.O_EXCL
        try:
            self.record_fd = os.open(path, os.O_WRONLY | os.O_CREAT | exclusive, 0o644)
        except FileExistsError:
            raise UserError(f"{path}: already exists; record to a new file, or give --force") from None
        except OSError as e:
            raise UserError(f"{path}: cannot record: {e.strerror or e}") from None
        os.write(self.record_fd, (header + "\n").encode("utf-8"))

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
        return state.set(event.control, event.value)

    def close(self) -> None:
        if self.record_fd is not None:
            os.close(self.record_fd)
            self.record_fd = None
