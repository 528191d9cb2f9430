"""The one check every control value goes through, whatever brought it (control/spec.py's rows).

`refusal(target, value, ...)` says why a (target, value) pair is refused, or None: a live event
(OSC, the console, a replayed log, a score, MIDI and HID after their mapping) is then counted
and warned about by its `kind`; a file (presets, show, mapping, score) names its file, line and
key before the `text`. A value outside its row's range is refused, never clamped: a typo of 50
for 0.5 is a mistake to point at, not "as far as it goes". Accepted values are real numbers
(not booleans, strings, NaN or infinity).
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection
from dataclasses import dataclass
from numbers import Real

from ..errors import printable, quoted
from ..synthesis.parameters import GESTURES, GROUPS
from .spec import PRESET_NAME, TABLE, Row

# raw controls of devices as they appear in events and logs: id pattern -> highest raw value
MIDI_RAW = re.compile(r"(cc|note|pitchbend)/([0-9]{1,2})/([0-9]{1,3})", re.ASCII)
HID_RAW_HIGH = 255.0  # the DualShock 4's old raw names (lx, r2, ...); controls named by usage read 0 to 1
HID_RELEASED = -1.0  # a hat switch let go (control/hid.py: `Hat`, `Hat#2`, ...; the old name `hat` read 8)
UNKNOWN, NOT_A_NUMBER, OUT_OF_RANGE, ACTION = "unknown target", "not a finite number", "out of range", "not a value"


@dataclass(frozen=True)
class Refusal:
    """Why a value is refused: `kind` to count and warn by, `text` (naming the target) to show."""

    kind: str
    text: str

    def __str__(self) -> str:
        return self.text


def is_number(value: object) -> bool:
    """A real, finite number: what every target and raw control takes (booleans are not numbers)."""
    if isinstance(value, bool) or not isinstance(value, Real):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer too large for a float
        return False


def row_of(target: object, styles: Collection[str], states: int) -> Row | None:
    """The row of a target name for a model with these styles and states, or None if it has no such target."""
    if not isinstance(target, str):
        return None
    parts = target.split("/")
    head = parts[0]
    if head == "style" and len(parts) == 2 and parts[1] in styles:
        return TABLE[head]
    if head == "part" and len(parts) == 3 and parts[1] in styles and parts[2] in GROUPS:
        return TABLE[head]
    if head == "phase" and len(parts) == 2 and re.fullmatch(r"[1-9][0-9]{0,3}", parts[1], re.ASCII) \
            and int(parts[1]) <= states:
        return TABLE[head]
    if head == "gesture" and len(parts) == 2 and parts[1] in GESTURES:
        return TABLE[head]
    if head in ("preset", "store") and len(parts) == 2 and PRESET_NAME.match(parts[1]):
        return TABLE[head]
    if len(parts) == 1 and head in TABLE and "<" not in TABLE[head].pattern:
        return TABLE[head]
    return None


def unknown(target: object, styles: Collection[str] | None = None, states: int | None = None) -> Refusal:
    """The refusal of a name no row answers, with what the name's kind takes: the model's styles
    when a style was meant, the body parts when the style is known, the phases, the gestures."""
    shown = printable(str(target))
    parts = shown.split("/")
    head = parts[0]
    if styles is not None and head == "part" and len(parts) == 3 and parts[1] in styles:
        hint = f" (the parts are {', '.join(GROUPS)})"
    elif styles is not None and head in ("style", "part"):
        hint = f" (this model's styles: {', '.join(sorted(styles))})"
    elif head == "phase":
        hint = f" (phase/1 to phase/{states}: the states of this model's step)" if states else " (phase/K, K from 1)"
    elif head == "gesture":
        hint = f" (gestures: {', '.join(GESTURES)})"
    elif head in ("preset", "store"):
        hint = " (a preset name is 1 to 40 letters, digits, '_', '.', '-')"
    else:
        hint = f" (targets: {', '.join(row.pattern for row in TABLE.values())})"
    return Refusal(UNKNOWN, f"{shown}: {UNKNOWN}{hint}")


def value_refusal(row: Row, target: str, value: object) -> Refusal | None:
    """Why `value` is refused for `target` of `row` (a name already known), or None. A row with
    named values (gait) takes a name for its number."""
    value = row.number(value)
    if not is_number(value) and row.choices:
        return Refusal(NOT_A_NUMBER, f"{target}: {NOT_A_NUMBER} or one of {', '.join(row.choices)}, not {quoted(value)}")
    if not is_number(value):
        return Refusal(NOT_A_NUMBER, f"{target}: {NOT_A_NUMBER}, not {quoted(value)}")
    if not row.low <= value <= row.high:
        return Refusal(OUT_OF_RANGE, f"{target}: {quoted(value)} is {OUT_OF_RANGE} ({row.describe_range()})")
    return None


def refusal(target: object, value: object, styles: Collection[str], states: int) -> Refusal | None:
    """Why (target, value) is refused for a model with these styles and states, or None."""
    row = row_of(target, styles, states)
    if row is None:
        return unknown(target, styles, states)
    return value_refusal(row, str(target), value)


def held_refusal(target: object, value: object, styles: Collection[str], states: int) -> Refusal | None:
    """As `refusal`, for a value a preset or a score's ramp holds: actions (reset, cue, preset/...) are refused."""
    row = row_of(target, styles, states)
    if row is not None and row.action:
        return Refusal(ACTION, f"{target}: {ACTION} a preset or a ramp can hold (it is pressed: {row.help})")
    return refusal(target, value, styles, states)


def between(value: float, a: float, b: float) -> float:
    """`value` kept between `a` and `b`: arithmetic between two accepted values (a morph, a ramp,
    a fader's travel) may land an ulp outside them, and must not then be refused."""
    return min(max(value, min(a, b)), max(a, b))


def raw_problem(source: str, control: object, value: object) -> str | None:
    """Why a device's raw event is refused before its mapping sees it, or None.

    MIDI ids are cc/<channel 1-16>/<0-127>, note/<channel>/<0-127>, pitchbend/<channel>/0 with
    values 0 to 127 (pitch bend 0 to 16383); HID values are 0 to 1 (controls named by usage) or
    0 to 255 (the DualShock 4's old raw names), and a released hat is -1. Names a mapping does
    not use are left to the mapping (not an error of the input, just not mapped)."""
    if not is_number(value):
        return NOT_A_NUMBER
    if not isinstance(control, str):
        return "not a control id"
    if source.startswith("midi:"):
        match = MIDI_RAW.fullmatch(control)
        if not match or not 1 <= int(match.group(2)) <= 16 or int(match.group(3)) > 127:
            return "not a MIDI control id"
        high = 16383 if match.group(1) == "pitchbend" else 127
        if not 0 <= value <= high:
            return "MIDI value out of range"
    elif source.startswith("hid:") and not 0 <= value <= HID_RAW_HIGH \
            and not (value == HID_RELEASED and control.partition("#")[0] == "Hat"):
        return "HID value out of range"
    return None
