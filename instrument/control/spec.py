"""The one table of every control target: what each is called, what it takes, what it means.

Every way a value reaches the control state (OSC surfaces, MIDI and HID through mappings, the
browser console, replayed logs, scores, presets files, a show file's and a mapping's
[presets], attract mode, the command line) is checked against these rows by control/checks.py,
so the same value gets the same verdict whatever brought it. What other parts show of the
targets is derived from the rows too: the values a control surface is echoed (`echoed`), the
console's sliders (the hello message carries `rows_for_page`: those this run can use, by each
row's `needs`), learn's default ranges
(`Row.fader`), a stored preset's targets (`Row.stored`) and the table in docs/controls.md.

A row's `pattern` is how its targets are written: `<style>`, `<group>` and `<k>` are filled
from the model (its style names, the body-part groups, its states 1..N), `<gesture>` with a
gesture's name (synthesis/parameters.py: a model without that gesture ignores it), `<name>` with a
preset name. Action rows (reset, cue, preset/<name>, store/<name>) are pressed, not held: a
value above 0 acts (over OSC, a message with no argument too), and no preset or score ramp holds them.
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection
from dataclasses import dataclass

from ..synthesis.parameters import GAITS, GESTURES, GROUPS, MAX_SPEED, MIN_SPEED

MAX_TURN = 3.0  # rad/s
WEIGHT_LIMIT = 10.0
MAX_MORPH = 600.0  # seconds
# what a target may need of the run to do anything: a tempo source (run --sync), a crowd (--characters above 1)
NEEDS = ("sync", "crowd")
PRESET_NAME = re.compile(r"^[A-Za-z0-9_.-]{1,40}$")  # preset names: plain TOML keys, safe in a URL and on screen


@dataclass(frozen=True)
class Row:
    """One kind of control target."""

    pattern: str  # how its targets are written, e.g. "part/<style>/<group>"
    low: float  # the range a value must be inside (ends included); actions take any number
    high: float
    default: float  # where it starts and where a reset puts it (NaN: follows another target)
    units: str
    help: str
    action: bool = False  # pressed, not held: a value above 0 acts
    stored: bool = False  # kept when the console stores the current values as a preset
    echoed: bool = False  # sent back to control surfaces every frame (OSC /walk/..., MIDI feedback)
    section: str | None = None  # where the console shows its slider (an element of console/static/index.html)
    slider: tuple[float, float] | None = None  # the console slider's travel, when shorter than the range
    fader: tuple[float, float] | None = None  # the range `instrument learn` gives a learned control
    choices: tuple[str, ...] = ()  # names of the whole values low, low + 1, ... (a name is taken for its number)
    needs: str = ""  # what a run must have for the target to do anything (NEEDS); the console offers it only then

    def __post_init__(self):
        if self.needs and self.needs not in NEEDS:
            raise ValueError(f"Row {self.pattern}: needs {self.needs!r}, not one of {NEEDS}")

    @property
    def kind(self) -> str:
        return self.pattern.split("/")[0]

    def describe_range(self) -> str:
        if self.action:
            return "any number (above 0 acts)"
        named = f" ({', '.join(f'{k:g} {name}' for k, name in enumerate(self.choices))}, or the name)" if self.choices else ""
        return f"{self.low:g} to {self.high:g}{named}"

    def number(self, value: object) -> object:
        """A choice's name as its number (gait "run" -> 2.0); anything else as it is, for the checks."""
        if self.choices and isinstance(value, str) and value in self.choices:
            return float(self.choices.index(value))
        return value


_ROWS = (
    Row("style/<style>", -WEIGHT_LIMIT, WEIGHT_LIMIT, 0.0, "weight",
        "weight of a style (0 absent, 1 the style, >1 exaggerated, <0 inverted)",
        stored=True, echoed=True, section="styles", slider=(-2.0, 4.0), fader=(-1.0, 2.0)),
    Row("part/<style>/<group>", -WEIGHT_LIMIT, WEIGHT_LIMIT, math.nan, "weight",
        f"weight of a style for one body part ({', '.join(GROUPS)}); unset, it follows style/<style>",
        stored=True, section="parts", slider=(-2.0, 4.0), fader=(-1.0, 2.0)),
    Row("speed", MIN_SPEED, MAX_SPEED, 1.0, "x", "step rate relative to the model's",
        stored=True, echoed=True, section="walk", fader=(0.5, 2.0)),
    Row("gait", 0.0, float(len(GAITS) - 1), 1.0, "gait",
        "stand (0), walk (1) or run (2), the nearest; changes at the next step the motion allows",
        stored=True, echoed=True, section="walk", fader=(0.0, 2.0), choices=GAITS),
    Row("turn", -MAX_TURN, MAX_TURN, 0.0, "rad/s",
        "steering (positive turns left); a model with turning steps takes them in proportion to it",
        echoed=True, section="walk", fader=(-1.0, 1.0)),
    Row("liveliness", 0.0, 1.0, 0.0, "", "0: every step alike; 1: durations drawn from the model",
        stored=True, echoed=True, section="walk", fader=(0.0, 1.0)),
    Row("spread", 0.0, 1.0, 0.0, "", "a crowd's style spread: 0 every character as performed; 1 each its own style mix",
        stored=True, echoed=True, section="walk", fader=(0.0, 1.0), needs="crowd"),
    Row("sync", 0.0, 1.0, 1.0, "", "with run --sync: on (1) steps on the music's beat, off (0) keeps the walk's own time",
        section="walk", fader=(0.0, 1.0), choices=("off", "on"), needs="sync"),
    Row("steps-per-beat", 0.0, 2.0, 0.0, "steps",
        "with run --sync: steps per beat the walk locks to, 0.5, 1 or 2 (nearest); below 0.25 the lock chooses",
        stored=True, section="walk", fader=(0.0, 2.0), needs="sync"),
    Row("morph", 0.0, MAX_MORPH, 0.0, "s", "seconds a recalled preset takes to arrive (0: at once); a reset keeps it",
        section="morph", slider=(0.0, 10.0)),
    Row("phase/<k>", MIN_SPEED, MAX_SPEED, 1.0, "x", "stretch of state k (1-based) of every step",
        stored=True, section="phases", fader=(0.5, 2.0)),
    Row("gesture/<gesture>", 0.0, 1.0, 0.0, "press",
        f"held above 0: a gesture ({', '.join(GESTURES)}) over the gait's upper body; a tap plays it as the takes do, "
        "a hold repeats it until released", section="gestures"),
    Row("reset", -math.inf, math.inf, 0.0, "press", "everything back to the start (the morph time stays)", action=True),
    Row("cue", -math.inf, math.inf, 0.0, "press", "a score waiting for the performer goes on", action=True),
    Row("preset/<name>", -math.inf, math.inf, 0.0, "press", "recall preset <name> (over the morph time)", action=True),
    Row("store/<name>", -math.inf, math.inf, 0.0, "press", "store the current values as preset <name>", action=True),
)

# kind -> row, in the order pages and docs show them
TABLE: dict[str, Row] = {row.kind: row for row in _ROWS}
VALUES = tuple(kind for kind, row in TABLE.items() if not row.action)  # the rows that hold a value


def names(style_names: list[str], states: int) -> list[str]:
    """Every target of a model, row by row (preset/<name> and store/<name> aside: any name)."""
    out: list[str] = []
    for row in _ROWS:
        if row.kind == "style":
            out += [f"style/{s}" for s in style_names]
        elif row.kind == "part":
            out += [f"part/{s}/{g}" for s in style_names for g in GROUPS]
        elif row.kind == "phase":
            out += [f"phase/{k + 1}" for k in range(states)]
        elif row.kind == "gesture":
            out += [f"gesture/{g}" for g in GESTURES]
        elif "<" not in row.pattern:
            out.append(row.pattern)
    return out


def rows_for_page(has: Collection[str] = ()) -> list[dict]:
    """The rows as the console's hello message carries them: the page builds its sliders from these
    (a row with named values, gait, as one button a name). A row that needs what the run does not
    have (`has`: of NEEDS) is left out: the tempo lock's controls without --sync, the crowd's
    spread for one character, would move nothing."""
    return [{"kind": row.kind, "pattern": row.pattern, "range": [row.low, row.high],
             "travel": list(row.slider or (row.low, row.high)), "section": row.section, "units": row.units,
             "help": row.help, "choices": list(row.choices)} for row in _ROWS
            if row.section is not None and (not row.needs or row.needs in has)]


def markdown_table() -> str:
    """The rows as the table of docs/controls.md (a test keeps the page and the rows equal)."""
    lines = ["| target | range | units | what it does |", "|---|---|---|---|"]
    for row in _ROWS:
        lines.append(f"| `{row.pattern}` | {row.describe_range()} | {row.units} | {row.help} |")
    return "\n".join(lines)
