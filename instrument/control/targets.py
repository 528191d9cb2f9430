"""The names other modules import from before the table moved: control/spec.py holds the rows
(what each target takes), control/checks.py the one check every input goes through."""

from __future__ import annotations

from collections.abc import Collection

from .checks import HID_RAW_HIGH, HID_RELEASED, MIDI_RAW, is_number, raw_problem, refusal
from .spec import MAX_MORPH, MAX_TURN, PRESET_NAME, TABLE, WEIGHT_LIMIT

__all__ = ["HID_RAW_HIGH", "HID_RELEASED", "MAX_MORPH", "MAX_TURN", "MIDI_RAW", "PRESET_NAME", "TABLE", "WEIGHT_LIMIT",
           "is_number", "problem", "raw_problem"]


def problem(target: object, value: object, styles: Collection[str], states: int) -> str | None:
    """The kind of refusal of (target, value) ('unknown target', 'out of range', ...), or None."""
    why = refusal(target, value, styles, states)
    return None if why is None else why.kind
