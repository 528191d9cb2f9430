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

A change needs notice to be smooth: the window MLPG solves bends the motion towards the new
unit's means only from the frame it first sees them. Told a frame before its step ends, a run
stopped dead (a toe's velocity jumped 44 cm/frame^2, against 12 in the real runs); told 5 frames
or more before, it jumped 10 to 11 (measured on the shipped model, normal at weight 1, the change
moved frame by frame through a step). So a change that comes less than NOTICE_SECONDS before the
step under way ends lets one more step of the old unit come first (`Crowd.counters[:, NEXT]`):
the plan shows the new unit at once, one step further on.

A body setting off from a stand accelerates: its root's travel (the drive's speeds) is eased in
from 0 over START_SECONDS, about its first step, as a person's first step covers about half a
stride. Taken at full speed from the first frame (no take starts walking, so the model has no
start), the body shot forward (0 to 77 cm/s in a frame) and, half the times, left its planted
foot behind until the lock let go: a stance foot skated 4.9 m/s for a few frames.
"""

from __future__ import annotations

import numpy as np

from ..models.modelfile import Model
from ..motion.features import ROOT_FEATURES
from .parameters import GAITS
from .stream import ELAPSED, LABEL, NEXT, STATE, UNIT, Crowd

YAW = ROOT_FEATURES.index("root.yaw_rate")
NOTICE_SECONDS = 0.2  # the least notice a unit change takes at the coming step boundary
START_SECONDS = 0.5  # a body setting off from a stand reaches its gait's travel over this


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
        self.coming = np.full(count, -1)  # the unit each character's coming steps were of at the last frame
        self.notice = NOTICE_SECONDS * model.fps  # frames
        self.start_frames = START_SECONDS * model.fps
        self.moving_for = np.full(count, np.inf)  # frames each body has moved since it last stood
        self.travel = np.ones(count)  # the share of its root's travel each body takes this frame
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
        if stream.sent == 0:
            stream.begin_in(coming)
        else:
            late = (coming != self.coming) & (counters[:, NEXT] == 0) & (self._frames_left(stream) < self.notice)
            counters[late, NEXT] = self.coming[late] + 1  # the step after this one as planned, then the change
        counters[:, UNIT] = coming
        self.coming = coming
        current = counters[:, LABEL] // 2
        self._ease_starts(current == self.stand)
        rest = turn - side * share * self.turn_rates.get(side, 0.0)  # what turning steps do not give
        self.added_yaw[:] = np.where(current == self.stand, 0.0, rest)
        self._settled = ((gait, turn) if share == 0.0 and stream.sent > 0 and (current == unit).all()
                         and np.isinf(self.moving_for[current != self.stand]).all() else None)  # no start easing in

    def _ease_starts(self, standing: np.ndarray) -> None:
        """Count each body's frames since it last stood, and ease its travel in over the first
        START_SECONDS of them (smoothstep: no jump in speed nor in acceleration at either end)."""
        self.moving_for = np.where(standing, 0.0, self.moving_for + 1.0)
        x = np.minimum(self.moving_for / self.start_frames, 1.0)
        self.travel = x * x * (3.0 - 2.0 * x)
        self.moving_for[self.moving_for >= self.start_frames] = np.inf  # eased in: no longer counted

    @staticmethod
    def _frames_left(stream: Crowd) -> np.ndarray:
        """(N,) the frames of each character's step under way still to come, at mean durations."""
        counters = stream.counters
        base = stream.base[np.arange(stream.count), counters[:, LABEL]]  # (N, states)
        ahead = np.arange(base.shape[1]) >= counters[:, STATE, None]
        return (base * ahead).sum(axis=1) - counters[:, ELAPSED]
