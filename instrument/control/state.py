"""Control state: what the performer has set, as named targets, snapshotted once per frame.

Targets (what each accepts, and the one check every input goes through: control/targets.py):
    style/<name>            weight of a style (0 absent, 1 the style, >1 exaggerated, <0 inverted)
    part/<style>/<group>    weight of a style for one body part (root, legs, upper); NaN follows style/<name>
    speed                   step rate relative to the model's (0.25 to 4)
    phase/<k>               stretch of state k (1-based) of every step (0.25 to 4)
    turn                    steering, radians per second (positive turns left)
    liveliness              0: every step alike; 1: durations drawn from the model
    spread                  a crowd's style spread: 0 every character as performed; 1 each its own mix
    morph                   seconds a recalled preset takes to arrive (0: at once); a reset keeps it
    reset                   any value: everything back to the start
    cue                     a press: a score waiting for the performer goes on

Presets are named sets of target values; recalling one moves there at once or over the morph
time, by performance time (so a replayed performance morphs identically). The morph time is a
target like the others, so a page, a knob or a log can change it and every surface shows it.
"""

from __future__ import annotations

import numpy as np

from ..synthesis.parameters import GROUPS
from ..synthesis.stream import Controls
from .targets import clamped, kind_of, problem


class ControlState:
    def __init__(self, style_names: list[str], states: int):
        self.style_names = list(style_names)
        self.style_index = {name: k for k, name in enumerate(self.style_names)}
        self.states = states
        self.cue_presses = 0  # how often the performer pressed the score's cue button (a reset keeps it)
        self.morph_time = 0.0  # seconds a recall takes: how presets behave, not a performed value (a reset keeps it)
        self.reset()

    def reset(self) -> None:
        self.morph: tuple[float, float, dict[str, tuple[float, float]]] | None = None  # start, seconds, target: (from, to)
        self.weights = np.zeros(len(self.style_names))
        self.part_weights = np.full((len(self.style_names), len(GROUPS)), np.nan)
        self.speed = 1.0
        self.turn = 0.0
        self.liveliness = 0.0
        self.spread = 0.0  # read by a crowd (synthesis/engine.py), not part of one walker's Controls
        self.state_scale = np.ones(self.states)

    def targets(self) -> list[str]:
        names = [f"style/{s}" for s in self.style_names]
        names += [f"part/{s}/{g}" for s in self.style_names for g in GROUPS]
        names += ["speed", "turn", "liveliness", "spread", "morph", "reset", "cue"] + [f"phase/{k + 1}" for k in range(self.states)]
        return names

    def knows(self, target: str) -> bool:
        return kind_of(target, self.style_index, self.states) is not None

    def problem(self, target: object, value: object) -> str | None:
        """Why this state would refuse (target, value) (see control/targets.py), or None."""
        return problem(target, value, self.style_index, self.states)

    def set(self, target: str, value: float) -> bool:
        """Apply one value, clamped to the target's range; False (and nothing changes) for an
        unknown target or a value that is not a finite number."""
        if self.problem(target, value) is not None:
            return False
        kind = kind_of(target, self.style_index, self.states)
        parts = target.split("/")
        value = clamped(kind, value)
        if kind == "style":
            self.weights[self.style_index[parts[1]]] = value
        elif kind == "part":
            self.part_weights[self.style_index[parts[1]], GROUPS.index(parts[2])] = value
        elif kind == "phase":
            self.state_scale[int(parts[1]) - 1] = value
        elif kind == "reset":
            if value > 0:  # a button's press, not its release
                self.reset()
        elif kind == "cue":
            self.cue_presses += value > 0
        elif kind == "morph":
            self.morph_time = value
        else:  # speed, turn, liveliness, spread
            setattr(self, kind, value)
        return True

    def get(self, target: str) -> float:
        parts = target.split("/")
        if parts[0] == "style":
            return float(self.weights[self.style_index[parts[1]]])
        if parts[0] == "part":
            return float(self.part_weights[self.style_index[parts[1]], GROUPS.index(parts[2])])
        if parts[0] == "phase":
            return float(self.state_scale[int(parts[1]) - 1])
        if target == "cue":  # a button with no value to show
            return 0.0
        if target == "morph":
            return self.morph_time
        return float(getattr(self, target))

    def recall(self, preset: dict[str, float], now: float) -> None:
        """Go to a preset's values, at once or over the morph time (performance time)."""
        seconds = self.morph_time
        if seconds <= 0:
            for target, value in preset.items():
                self.set(target, value)
            self.morph = None
            return
        self.morph = (now, seconds, {t: (self.get(t), v) for t, v in preset.items() if self.knows(t)})

    def advance(self, now: float) -> None:
        """Move a running morph to performance time `now`."""
        if self.morph is None:
            return
        start, seconds, moves = self.morph
        share = min(max((now - start) / seconds, 0.0), 1.0)
        for target, (first, last) in moves.items():
            self.set(target, first + (last - first) * share)
        if share >= 1.0:
            self.morph = None

    def snapshot(self) -> Controls:
        parts = None if np.isnan(self.part_weights).all() else self.part_weights.copy()
        return Controls(self.weights.copy(), parts, self.speed, self.state_scale.copy(), self.liveliness, self.turn)

    def echo(self) -> dict[str, float]:
        """The values a control surface shows: every style weight, speed, turn, liveliness, spread."""
        out = {f"style/{s}": float(w) for s, w in zip(self.style_names, self.weights)}
        out.update(speed=self.speed, turn=self.turn, liveliness=self.liveliness, spread=self.spread)
        return out
