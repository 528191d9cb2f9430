"""Every control value by target name: what a console shows and what a stored preset keeps."""

from __future__ import annotations

import math

from ..synthesis.parameters import GROUPS
from .state import ControlState


def all_values(state: ControlState) -> dict[str, float]:
    """Every target's value (reset aside); NaN for a part weight that follows its style."""
    out = {f"style/{s}": float(w) for s, w in zip(state.style_names, state.weights)}
    for k, s in enumerate(state.style_names):
        out.update({f"part/{s}/{g}": float(state.part_weights[k, j]) for j, g in enumerate(GROUPS)})
    out.update(speed=state.speed, turn=state.turn, liveliness=state.liveliness, spread=state.spread, morph=state.morph_time)
    out.update({f"phase/{k + 1}": float(v) for k, v in enumerate(state.state_scale)})
    return out


def preset_values(state: ControlState) -> dict[str, float]:
    """The current values a stored preset keeps: all but steering and the morph time (and part
    weights left unset)."""
    return {t: v for t, v in all_values(state).items() if t not in ("turn", "morph") and not math.isnan(v)}
