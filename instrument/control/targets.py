"""The one table of what each control target accepts, and the one check every input goes through.

Every path by which a value reaches the control state (OSC surfaces, MIDI and HID through their
mappings, replayed logs, mapping files, presets, show files, the browser console) asks `problem`
or `raw_problem` here first, so a value is accepted or refused by the same rule whatever
brought it. A refused value changes nothing; the caller counts it and warns once per kind.

Accepted values are real numbers (not booleans, not strings, not NaN or infinity). A number
outside a target's range is not refused: it is clamped to the nearest end, because a knob
turned past the end of a range means "as far as it goes".
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from numbers import Real

from ..synthesis.parameters import GROUPS, MAX_SPEED, MIN_SPEED

MAX_TURN = 3.0  # rad/s
WEIGHT_LIMIT = 10.0
MAX_MORPH = 600.0  # seconds: as --morph (cli/arguments.py) accepts


@dataclass(frozen=True)
class Target:
    pattern: str  # how the name is written; <style>, <group>, <k> are filled from the model
    low: float
    high: float
    meaning: str


# name -> what it accepts; `check` below decides which row a target name belongs to
TABLE: dict[str, Target] = {
    "style": Target("style/<style>", -WEIGHT_LIMIT, WEIGHT_LIMIT,
                    "weight of a style (0 absent, 1 the style, >1 exaggerated, <0 inverted)"),
    "part": Target("part/<style>/<group>", -WEIGHT_LIMIT, WEIGHT_LIMIT,
                   f"weight of a style for one body part ({', '.join(GROUPS)})"),
    "speed": Target("speed", MIN_SPEED, MAX_SPEED, "step rate relative to the model's"),
    "phase": Target("phase/<k>", MIN_SPEED, MAX_SPEED, "stretch of state k (1-based) of every step"),
    "turn": Target("turn", -MAX_TURN, MAX_TURN, "steering, radians per second (positive turns left)"),
    "liveliness": Target("liveliness", 0.0, 1.0, "0: every step alike; 1: durations drawn from the model"),
    "spread": Target("spread", 0.0, 1.0, "a crowd's style spread: 0 every character as performed; 1 each its own style mix"),
    "morph": Target("morph", 0.0, MAX_MORPH, "seconds a recalled preset takes to arrive (0: at once)"),
    "reset": Target("reset", -math.inf, math.inf, "a value above 0: everything back to the start"),
    "cue": Target("cue", -math.inf, math.inf, "a value above 0: a score waiting for the performer goes on"),
}

# raw controls of devices as they appear in events and logs: id pattern -> highest raw value
PRESET_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,40}$")  # preset names: plain TOML keys, safe in a URL and on screen
MIDI_RAW = re.compile(r"(cc|note|pitchbend)/([0-9]{1,2})/([0-9]{1,3})", re.ASCII)
HID_RAW_HIGH = 255.0  # the DualShock 4's old raw names (lx, r2, ...); controls named by usage read 0 to 1
HID_RELEASED = -1.0  # a hat switch let go (control/hid.py: `Hat`, `Hat#2`, ...; the old name `hat` read 8)


def is_number(value: object) -> bool:
    """A real, finite number: what every target and raw control takes (booleans are not numbers)."""
    if isinstance(value, bool) or not isinstance(value, Real):
        return False
    try:
        return math.isfinite(value)
    except OverflowError:  # an integer too large for a float
        return False


def kind_of(target: object, style_index: dict[str, int], states: int) -> str | None:
    """The table row of a target name for this model, or None if the model has no such target."""
    if not isinstance(target, str):
        return None
    parts = target.split("/")
    head = parts[0]
    if head == "style" and len(parts) == 2 and parts[1] in style_index:
        return head
    if head == "part" and len(parts) == 3 and parts[1] in style_index and parts[2] in GROUPS:
        return head
    if head == "phase" and len(parts) == 2 and re.fullmatch(r"[1-9][0-9]{0,3}", parts[1], re.ASCII) \
            and int(parts[1]) <= states:
        return head
    if len(parts) == 1 and head in ("speed", "turn", "liveliness", "spread", "morph", "reset", "cue"):
        return head
    return None


def problem(target: object, value: object, style_index: dict[str, int], states: int) -> str | None:
    """Why (target, value) is refused, as a short kind ('unknown target', 'not a number'), or None."""
    if kind_of(target, style_index, states) is None:
        return "unknown target"
    if not is_number(value):
        return "not a finite number"
    return None


def clamped(kind: str, value: float) -> float:
    row = TABLE[kind]
    return float(min(max(value, row.low), row.high))


def raw_problem(source: str, control: object, value: object) -> str | None:
    """Why a device's raw event is refused before its mapping sees it, or None.

    MIDI ids are cc/<channel 1-16>/<0-127>, note/<channel>/<0-127>, pitchbend/<channel>/0 with
    values 0 to 127 (pitch bend 0 to 16383); HID values are 0 to 1 (controls named by usage) or
    0 to 255 (the DualShock 4's old raw names), and a released hat is -1. Names a mapping does
    not use are left to the mapping (not an error of the input, just not mapped)."""
    if not is_number(value):
        return "not a finite number"
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
