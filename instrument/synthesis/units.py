"""The engine's units stage: which motion unit each character's next steps are of.

A model holds units (models/units.py: walk, run, turn-left, turn-right, stand), each a right and a
left step's labels. As HTS concatenates phone models along a label sequence, the planner
(stream.py) strings steps together, and this stage decides, frame by frame, the unit of the steps
after the current one (`Crowd.counters[:, UNIT]`): the one the performer's gait names, and for a
walk steered hard enough, turning steps. A change therefore shows in the very next frame's
look-ahead (the window MLPG solves), and takes the body at the next step boundary: the step under
way is finished, so a run never stops in mid-flight. ST-MLPG joins the last step of one unit and
the first of the next as it joins any two steps; the foot lock keeps the feet planted through it.

Turning steps are taken in proportion to the steering: with `turn` at f times the rate the
model's turning steps turn (their duration-weighted mean yaw rate), a share f of the steps are
turning ones, chosen by error diffusion (each step adds f to a running sum; a step is a turning
one when the sum passes one half, which takes one away), so over a few steps the walk turns at the
rate asked for and no step is half of each. Steering beyond what every step turning gives, a run
steered (there are no turning runs in the data), or a model without turning steps adds the rest
as yaw rate (the engine's drive, as before units); a standing character does not turn.
"""

from __future__ import annotations

import numpy as np

from ..models.modelfile import Model
from ..motion.features import ROOT_FEATURES
from .parameters import GAITS
from .stream import LABEL, STATE, UNIT, Crowd

YAW = ROOT_FEATURES.index("root.yaw_rate")


class UnitChooser:
    """Per character: the unit of the coming steps and the yaw rate the drive adds."""

    name = "units"

    def __init__(self, model: Model, count: int):
        self.units = model.units
        self.count = count
        walk = self.units.index("walk")
        # the unit each gait plays: the model's unit of that name, else the walk
        self.gait_units = np.array([self.units.index(g) if g in self.units else walk for g in GAITS])
        self.missing = [g for g in GAITS if g not in self.units]  # gaits this model plays as a walk
        self.walk = walk
        self.stand = self.units.index("stand") if "stand" in self.units else -1
        states = model.states
        means, durations = model.average.means[..., YAW], model.average.duration_means  # (labels, states)

        def rate(unit: str) -> float:
            k = self.units.index(unit)
            rows = slice(2 * k, 2 * k + 2)
            return float((means[rows] * durations[rows]).sum() / durations[rows].sum())

        self.turn_units = {side: self.units.index(unit) for side, unit in ((1, "turn-left"), (-1, "turn-right"))
                           if unit in self.units}
        self.turn_rates = {side: abs(rate(self.units[k])) for side, k in self.turn_units.items()}  # rad/s
        self.sum = np.zeros(count)  # the error diffusion's running sum, per character
        self.turning = np.zeros(count, dtype=np.int64)  # +1 / -1: the coming step turns left / right; 0 straight
        self.step_label = np.full(count, -1)  # the label of the step under way at the last frame
        self.states = states
        self.added_yaw = np.zeros(count)  # rad/s the drive adds to each character's frame
        self._settled: tuple[int, float] | None = None  # (gait, turn) that left nothing to do frame by frame

    def __call__(self, gait: int, turn: float, stream: Crowd) -> None:
        """Set every character's coming unit for this frame's controls (before the stream's step).
        Once every character walks the gait's unit with no turning steps to choose, the same
        controls leave everything as it is: the stage costs nothing frame by frame."""
        if self._settled == (gait, turn):
            return
        counters = stream.counters
        unit = self.gait_units[gait]
        started = (counters[:, LABEL] != self.step_label) & (counters[:, STATE] == 0)
        self.step_label = counters[:, LABEL].copy()
        side = 1 if turn > 0 else -1
        share = 0.0
        if unit == self.walk and turn != 0.0 and side in self.turn_units:
            share = min(abs(turn) / max(self.turn_rates[side], 1e-9), 1.0)
        if share == 0.0:
            self.turning[:] = 0
            self.sum[:] = 0.0
        else:
            changed_side = (self.turning != 0) & (self.turning != side)
            decide = started | changed_side | (stream.sent == 0)
            self.sum[decide] += share
            turns = decide & (self.sum >= 0.5)
            self.sum[turns] -= 1.0
            self.turning[decide] = np.where(turns[decide], side, 0)
        coming = np.where(self.turning > 0, self.turn_units.get(1, unit),
                          np.where(self.turning < 0, self.turn_units.get(-1, unit), unit))
        counters[:, UNIT] = coming
        if stream.sent == 0:
            stream.begin_in(coming)
        current = counters[:, LABEL] // 2
        rest = turn - side * share * self.turn_rates.get(side, 0.0)  # what turning steps do not give
        self.added_yaw[:] = np.where(current == self.stand, 0.0, rest)
        self._settled = (gait, turn) if share == 0.0 and stream.sent > 0 and (current == unit).all() else None
