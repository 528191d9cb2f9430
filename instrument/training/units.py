"""Which motion unit a take holds (walk, run, turn-left, turn-right, stand), and what training does
per unit that it does not do for the walk.

The unit is read from the file name, as the style is: by default the "_"-separated part before
the style (`dataset-2_walk-turn-left_active_001` -> `walk-turn-left`), given a unit by words in
it (`UNIT_WORDS`); a name with no such part, or no word known, is a walk, so a corpus of walks
trains as it always did. `--unit-from` or a manifest's `unit` column says otherwise.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..errors import UserError
from ..models.gestures import gesture_of_words
from ..models.hsmm import HSMM
from ..models.units import GESTURES, UNITS, named_by_words

# the part before the style, starting with a letter: dataset-2_run_elderly_003 -> run
DEFAULT_UNIT_PATTERN = r"(?:^|_)([A-Za-z][A-Za-z0-9-]*)_[A-Za-z][A-Za-z0-9-]*_[^_]*$"
# words in a file's content part and the unit they name, the first that matches wins
UNIT_WORDS = (
    (("turn-left", "turn_left", "left-turn", "turnleft"), "turn-left"),
    (("turn-right", "turn_right", "right-turn", "turnright"), "turn-right"),
    (("run", "jog", "sprint"), "run"),
    (("stand", "idle", "wave", "raise", "gesture", "rest"), "stand"),
    (("walk",), "walk"),
)


def unit_of_words(content: str) -> str | None:
    """The unit a content name says (`walk-turn-left` -> turn-left), or None."""
    return content if content in UNITS else named_by_words(content, UNIT_WORDS)


def _content(path: Path, pattern: str | None) -> str:
    """The part of a take's file name that says its unit (and a stand's gesture): `pattern`'s
    (--unit-from's) group, else the part before the style; "" where none matches."""
    match = re.search(pattern or DEFAULT_UNIT_PATTERN, path.stem)
    return match.group(1) if match and match.groups() and match.group(1) else ""


def unit_from_name(path: Path, pattern: str | None = None) -> str:
    """The unit of a take from its file name: a walk unless the name says otherwise. With a
    `pattern` (--unit-from) its group must name a unit, or the error names the file."""
    content = _content(path, pattern)
    unit = unit_of_words(content) if content else None
    if pattern is not None and unit is None:
        raise UserError(f"{path}: --unit-from found {content!r}, not a unit ({', '.join(UNITS)}) or a word for one")
    return unit or "walk"


def unit_said_elsewhere(path: Path) -> str | None:
    """For a take the default reading takes for a walk: the other unit a part of its name says
    (`actorB_Active_Jog01` -> "'Jog01' says run"), or None. Such names (a studio's own scheme,
    the unit after the style) trained every run, turn and stand as a walk, saying only `units: walk`."""
    for part in path.stem.split("_"):
        unit = unit_of_words(part) if part else None
        if unit not in (None, "walk"):
            return f"{part!r} says {unit}"
    return None


def gesture_from_name(path: Path, pattern: str | None = None) -> str | None:
    """The gesture a standing take performs, from the part of its name that says its unit
    (`dataset-2_wave-both-hands_active_001` -> wave; with --unit-from `_([A-Za-z]+?)[0-9]+$`,
    `actorB_Active_IdleWave01` -> wave: read from the default part alone, such a corpus trained
    no gesture, silently), or None (models/gestures.py)."""
    content = _content(path, pattern)
    return gesture_of_words(content) if content else None


def take_gesture(path: Path, unit: str, said: str = "") -> str | None:
    """The gesture a take is trained for: a standing take's as said (a manifest's), else as its
    name says (None: none); other units make none (gestures are made standing)."""
    return (said or gesture_from_name(path)) if unit == "stand" else None


# a turning take is taken as a turn the way its root turns over its steps; below this it does not turn
LEAST_TURN_DEG = 30.0


def turn_as_taken(unit: str, yaw_rates: np.ndarray, fps: float) -> tuple[str | None, str | None]:
    """The unit a turning take's steps are trained as, and a warning when that is not the one named:
    a take named turn-left whose root turns right (a mislabelled file, or an actor who turned the
    other way: 3 of the 16 masculine turning takes in the Bandai set) is used as a right turn, and
    a take that turns less than LEAST_TURN_DEG either way is left out (None): its steps would
    teach a turning unit to walk straight. `yaw_rates` (rad/s, + to the left) are the frames of
    its steps. Other units are returned as they are."""
    if not unit.startswith("turn-"):
        return unit, None
    turned = float(np.degrees(yaw_rates.sum() / fps))
    if abs(turned) < LEAST_TURN_DEG:
        return None, f"named {unit} but turns {turned:+.0f} degrees over its steps: left out"
    found = "turn-left" if turned > 0 else "turn-right"
    if found != unit:
        return found, f"named {unit} but turns {abs(turned):.0f} degrees to the {found[5:]}: used as {found}"
    return unit, None


def checked_unit(where: str, unit: str) -> str:
    """A manifest's unit, one of UNITS (in any case), or an error naming where it is; left empty
    (a CSV's blank field, a TOML take's `unit = ""`, or none given) a walk, alike in both. Not read
    as leniently as a file name (`unit_of_words`): a name is guessed from, a manifest is the
    user's word, and `runn` or `walking-fast` read by its words trained a run or a walk unasked."""
    found = unit.strip().lower() or "walk"
    if found not in UNITS:
        raise UserError(f"{where}: unit {unit!r} is not one of {', '.join(UNITS)}")
    return found


def checked_gesture(where: str, gesture: str, unit: str, unit_said: bool = True) -> str:
    """A manifest's gesture ("" for none said), one of GESTURES (in any case), or an error naming
    where it is: exact, as a manifest's unit is (`waves` is no gesture), of a standing take
    (gestures are made standing; a take whose unit was left empty, `unit_said` False, is a walk,
    and the error says so)."""
    if not gesture:
        return ""
    found = gesture.strip().lower()
    if found not in GESTURES:
        raise UserError(f"{where}: gesture {gesture!r} is not one of {', '.join(GESTURES)}")
    if unit != "stand":
        raise UserError(f"{where}: gesture {gesture!r} given to a {unit} take{'' if unit_said else ' (no unit given: a walk)'}: "
                        "a gesture is a standing take's (unit stand)")
    return found


def model_units(present: set[str]) -> list[str]:
    """The units a model holds, in UNITS' order; refused without walks (every gait falls back on the walk)."""
    if "walk" not in present:
        raise UserError(f"no walking takes among the units found ({', '.join(sorted(present))}): a model needs walks")
    return [u for u in UNITS if u in present]


def mirrored_pairs(units: list[str]) -> list[tuple[int, int]]:
    """The (right, left) label pairs made mirror images (training/symmetry.py): every unit's but the
    turns' (a turning step and the next turn the same way; mirroring them would cancel the turn)."""
    return [(2 * k, 2 * k + 1) for k, unit in enumerate(units) if not unit.startswith("turn")]


def held_posture(model: HSMM, labels: list[int], columns: np.ndarray, dimension: int,
                 still: tuple[int, ...] = ()) -> HSMM:
    """The model with `columns` (static features) of the given labels' states held at their
    duration-weighted mean, and their deltas at 0: the stand's arms, which the standing takes
    never hold still (standing.py), keep the style's posture instead of a half gesture. The
    `still` columns (the root's speeds over the floor and its yaw rate) are set to 0 outright: the
    takes creep a few cm/s, and a stand held for minutes must not walk off."""
    means = model.means.copy()
    rows = (slice(None),) * (means.ndim - 3) + (labels,)  # the labels' axis is the third from the end
    weights = model.duration_means[rows][..., None]  # (..., labels, states, 1)
    static = means[rows][..., columns]
    held = (static * weights).sum(axis=(-3, -2), keepdims=True) / weights.sum(axis=(-3, -2), keepdims=True)
    block = means[rows]
    block[..., columns] = np.broadcast_to(held, static.shape)
    for window in (1, 2):
        block[..., window * dimension + columns] = 0.0
    block[..., list(still)] = 0.0
    means[rows] = block
    return HSMM(means, model.variances, model.duration_means, model.duration_variances)
