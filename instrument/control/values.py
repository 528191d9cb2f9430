"""Every control value by target name: what a console shows and what a stored preset keeps
(which targets: the rows of control/spec.py)."""

from __future__ import annotations

import math

from .spec import TABLE
from .state import ControlState


def all_values(state: ControlState) -> dict[str, float]:
    """Every target that holds a value, in the rows' order; NaN for a part weight that follows its
    style (kept by the state until a value changes: read it, never write it)."""
    return state.values()


def preset_values(state: ControlState) -> dict[str, float]:
    """The current values a stored preset keeps: the rows marked `stored` (not steering, not the
    morph time), part weights left unset aside."""
    return {t: v for t, v in all_values(state).items() if TABLE[t.split("/")[0]].stored and not math.isnan(v)}
