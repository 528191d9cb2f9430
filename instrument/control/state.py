"""Control state: what the performer has set, as named targets, snapshotted once per frame.

The targets, what each accepts and where it starts are the rows of control/spec.py; every value
is checked by control/checks.py before it lands here (a refused value changes nothing). The
action rows preset/<name> and store/<name> are the hub's (it holds the presets).

Presets are named sets of target values; recalling one moves there at once or over the morph
time, by performance time (so a replayed performance morphs identically). The morph time is a
target like the others, so a page, a knob or a log can change it and every surface shows it.
"""

from __future__ import annotations

import numpy as np

from ..synthesis.parameters import GESTURES, GROUPS
from ..synthesis.stream import Controls, gait_index
from . import spec
from .checks import Refusal, between, refusal, row_of


class LockSpeeds(dict):
    """The beat lock's speed of each character (K -> speed, runtime/tempo.py), which also keeps
    them as an array (`array`, `known`) brought up to date by the characters set since it was last
    read (`runtime.tempo.locked_speed`), so a crowd's frame does not build one character by character."""

    def __init__(self) -> None:
        super().__init__()
        self.changed: list[int] = []  # characters set since the array was last brought up to date
        self.array: np.ndarray | None = None  # (N,) each character's speed, where `known`
        self.known: np.ndarray | None = None  # (N,) bool

    def __setitem__(self, character: int, speed: float) -> None:
        super().__setitem__(character, speed)
        self.changed.append(character)

    def clear(self) -> None:
        super().clear()
        self.changed.clear()
        self.array = self.known = None

    def per_character(self, characters: int, performed: float) -> np.ndarray:
        """(characters,) each character's speed: the lock's, or `performed` where it has set none;
        the array brought up to date by the characters set since the last call only."""
        if self.array is None or len(self.array) != characters:
            self.array, self.known = np.zeros(characters), np.zeros(characters, dtype=bool)
            self.changed[:] = list(self)
        for k in self.changed:
            if k < characters:
                self.array[k], self.known[k] = self[k], True
        self.changed.clear()
        return np.where(self.known, self.array, performed)


class ControlState:
    def __init__(self, style_names: list[str], states: int):
        self.style_names = list(style_names)
        self.style_index = {name: k for k, name in enumerate(self.style_names)}
        self.states = states
        self.cue_presses = 0  # how often the performer pressed the score's cue button (a reset keeps it)
        self.morph_time = spec.TABLE["morph"].default  # seconds a recall takes: how presets behave (a reset keeps it)
        names = spec.names(self.style_names, states)
        self.value_targets = [t for t in names if not spec.TABLE[t.split("/")[0]].action]  # in the rows' order
        self.echoed_targets = [t for t in names if spec.TABLE[t.split("/")[0]].echoed]
        # the speed the beat lock set for each character (runtime/tempo.py), as its `tempo` events
        # said (control/kinds.py): not the performer's, so a reset keeps it
        self.lock_speeds = LockSpeeds()
        # every accepted set or reset counts one: what `values` and `echo` made is kept until the
        # next, so a frame with no change costs no pass over the targets (about 70 string splits)
        self.revision = 0
        self._made: dict[str, tuple[int, dict[str, float]]] = {}
        self.reset()

    def reset(self) -> None:
        self.revision = getattr(self, "revision", 0) + 1
        self.morph: tuple[float, float, dict[str, tuple[float, float]]] | None = None  # start, seconds, target: (from, to)
        rows = spec.TABLE
        self.weights = np.full(len(self.style_names), rows["style"].default)
        self.part_weights = np.full((len(self.style_names), len(GROUPS)), rows["part"].default)
        self.speed = rows["speed"].default
        self.turn = rows["turn"].default
        self.gait = rows["gait"].default
        self.liveliness = rows["liveliness"].default
        self.spread = rows["spread"].default  # read by a crowd (synthesis/engine.py), not part of one walker's Controls
        self.state_scale = np.full(self.states, rows["phase"].default)
        self.sync = rows["sync"].default  # the beat lock on (1) or off (0) (runtime/tempo.py)
        self.steps_per_beat = rows["steps-per-beat"].default  # read by the beat lock
        self.gestures = {g: rows["gesture"].default for g in GESTURES}  # above 0: held (synthesis/gestures.py)

    def targets(self) -> list[str]:
        """Every target of this model (spec.names: preset/<name> and store/<name> aside)."""
        return spec.names(self.style_names, self.states)

    def knows(self, target: str) -> bool:
        return row_of(target, self.style_index, self.states) is not None

    def refusal(self, target: object, value: object) -> Refusal | None:
        """Why this state would refuse (target, value) (control/checks.py), or None."""
        return refusal(target, value, self.style_index, self.states)

    def problem(self, target: object, value: object) -> str | None:
        """The kind of `refusal` ('unknown target', 'out of range', ...): what a live input counts by."""
        why = self.refusal(target, value)
        return None if why is None else why.kind

    def set(self, target: str, value: float) -> bool:
        """Apply one value; False (and nothing changes) when checks.refusal refuses it (an
        unknown target, not a finite number, out of range), or for the hub's preset/ and store/."""
        if self.refusal(target, value) is not None:
            return False
        parts = target.split("/")
        kind = parts[0]
        value = float(spec.TABLE[kind].number(value))
        if kind in ("preset", "store"):
            return False
        if kind == "style":
            self.weights[self.style_index[parts[1]]] = value
        elif kind == "part":
            self.part_weights[self.style_index[parts[1]], GROUPS.index(parts[2])] = value
        elif kind == "phase":
            self.state_scale[int(parts[1]) - 1] = value
        elif kind == "gesture":
            self.gestures[parts[1]] = value
        elif kind == "reset":
            if value > 0:  # a button's press, not its release
                self.reset()
        elif kind == "cue":
            self.cue_presses += value > 0
        elif kind == "morph":
            self.morph_time = value
        else:  # speed, gait, turn, liveliness, spread, sync, steps-per-beat
            setattr(self, kind.replace("-", "_"), value)
        self.revision += 1
        return True

    def get(self, target: str) -> float:
        parts = target.split("/")
        if parts[0] == "style":
            return float(self.weights[self.style_index[parts[1]]])
        if parts[0] == "part":
            return float(self.part_weights[self.style_index[parts[1]], GROUPS.index(parts[2])])
        if parts[0] == "phase":
            return float(self.state_scale[int(parts[1]) - 1])
        if parts[0] == "gesture":
            return float(self.gestures[parts[1]])
        if target == "cue":  # a button with no value to show
            return 0.0
        if target == "morph":
            return self.morph_time
        return float(getattr(self, target.replace("-", "_")))

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
            self.set(target, last if share >= 1.0 else between(first + (last - first) * share, first, last))
        if share >= 1.0:
            self.morph = None

    def snapshot(self) -> Controls:
        parts = None if np.isnan(self.part_weights).all() else self.part_weights.copy()
        return Controls(self.weights.copy(), parts, self.speed, self.state_scale.copy(), self.liveliness, self.turn,
                        gait_index(self.gait), tuple(g for g, v in self.gestures.items() if v > 0))

    def values(self) -> dict[str, float]:
        """Every target that holds a value, in the rows' order (NaN: a part weight that follows its
        style). The same dict until a value changes: read it, never write it."""
        return self._kept("values", self.value_targets)

    def echo(self) -> dict[str, float]:
        """The values a control surface shows: the targets of the rows marked `echoed`
        (control/spec.py). The same dict until a value changes: read it, never write it."""
        return self._kept("echo", self.echoed_targets)

    def _kept(self, name: str, targets: list[str]) -> dict[str, float]:
        made = self._made.get(name)
        if made is None or made[0] != self.revision:
            made = self._made[name] = (self.revision, {t: self.get(t) for t in targets})
        return made[1]
