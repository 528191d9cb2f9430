"""The engine's gesture stage: a wave or a raise of the hands layered on the gait's upper body.

A gesture is a second label stream for one body part, not a second pipeline: a second `Crowd`
(stream.py) over the same lambda* tables as the gait (the gesture's labels are rows of the same
model arrays, models/gestures.py, so the style weights, exaggeration, inversion and the crowd's
spread shape a wave as they shape the walk), planned through the gesture's phases:

    raise -> repeat-a -> repeat-b -> (repeat-a -> repeat-b ...) -> lower -> the stand's rest

The planner moves from a label to the other foot's label of the unit in `counters[:, UNIT]`
(label = 2 * unit + foot); a gesture's four labels are two such pairs, (lower, raise) and
(repeat-a, repeat-b), so choosing the unit from the label under way strings the phases: with the
repeat's unit, the raise goes on to repeat-a, and a and b follow each other for as long as the
unit stays (the look-ahead the window solves sees the loop as it will be played); the other
pair's unit takes repeat-b to the lower, and the stand's takes the lower to rest. The
repeat loops while the gesture's target is held; let go during the raise (a tap), it repeats as
many half cycles as its takes hold (it plays as the actors did); let go later, it lowers at the
end of the half cycle under way.

The gesture's stream starts from the two frames the character has just shown (its window's fixed
frames), so the arms leave the walk's swing without a jump; its upper-body features (the `upper`
group: spine, neck, head, arms) then replace the gait's with a weight that eases in over EASE_IN
frames and out over EASE_OUT once the lower has ended, the legs and the root staying the gait's:
the feet keep their plan and the foot lock, the walk its speed and heading. While no gesture
plays the stage costs nothing.
"""

from __future__ import annotations

from typing import Collection

import numpy as np

from ..models.gestures import gesture_labels, gesture_repeats
from ..models.modelfile import Model
from .interpolation import StyleSpace, body_groups
from .parameters import GROUPS
from .stream import FOLLOWER, LABEL, UNIT, Crowd

EASE_IN = 6  # frames the gesture's upper body takes to come in (its stream starts where the gait is)
EASE_OUT = 12  # frames it takes to hand the arms back to the gait after the lower


class GestureLayer:
    """Per character: which gesture plays, where it is, and how much of the upper body it has."""

    name = "gestures"

    def __init__(self, model: Model, space: StyleSpace, count: int, lookahead: int, seeds: list[int]):
        self.labels = gesture_labels(model.metadata)  # {name: [lower, raise, repeat-a, repeat-b]}
        self.repeats = gesture_repeats(model.metadata)
        units = model.units
        self.rest_unit = units.index("stand") if "stand" in units else 0  # where a lowered gesture goes
        self.crowd = Crowd(space, count, lookahead, seeds=seeds) if self.labels else None
        self.columns = np.flatnonzero(body_groups(model.layout)[GROUPS.index("upper")])  # the features a gesture takes
        self._next_repeating = self._next_ending = np.zeros(6, dtype=np.int64)  # set by _start
        self.playing: str | None = None
        self.first = 0  # the playing gesture's first label
        self.done = np.zeros(count, dtype=np.int64)  # repeat half cycles finished, per character
        self.tapped = np.ones(count, dtype=bool)  # let go during the raise (or not yet): repeats as the takes do
        self.label = np.zeros(count, dtype=np.int64)  # the label under way at the last frame
        self.ease = np.zeros(count)  # 0..1 along the ease in, then back down along the ease out
        self.weights = np.zeros(count)  # the gesture's share of each character's upper body, this frame
        self.held: set[str] = set()  # the gesture targets held at the last frame
        self.shown: list[np.ndarray] = []  # the last two frames shown (N, D), where a gesture starts from
        self.shown_ids: list[np.ndarray] = []  # and their states
        self.started = 0  # gestures begun

    @property
    def names(self) -> list[str]:
        return list(self.labels)

    def retune(self, duration_means: np.ndarray, duration_variances: np.ndarray, stream: Crowd) -> None:
        """The gait's lambda* tables and the gesture's durations at the model's own pace (a walk
        sped up does not hurry the wave)."""
        if self.crowd is not None:
            self.crowd.tables = stream.tables
            self.crowd.tune(duration_means, duration_variances, 1.0, None, 0.0)

    def __call__(self, held: Collection[str], frames: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """The frame (N, D) with the gesture's upper body layered on, for the gesture targets held."""
        held = set(held)
        pressed = held - self.held
        if self.playing in self.held - held:  # let go: during the raise it was a tap (the takes' repeats), later a hold
            self.tapped = self.label == self.first + 1  # still raising
        self.held = held
        known = sorted(pressed & set(self.labels))  # one the model lacks: `run` says so, the walk goes on
        if known and self.playing is None:
            self._start(known[0])
        if self.playing is not None:
            frames = self._layer(frames)
        self.shown = (self.shown + [frames.copy()])[-2:]
        self.shown_ids = (self.shown_ids + [np.asarray(ids).copy()])[-2:]
        return frames

    def _start(self, name: str) -> None:
        crowd = self.crowd
        first = self.labels[name][0]
        self.playing, self.first, self.started = name, first, self.started + 1
        if len(self.shown) == 2:  # the window's fixed past: what the characters have just shown
            crowd.history[:] = np.stack(self.shown, axis=1)
            crowd.history_ids[:] = np.stack(self.shown_ids, axis=1)
            crowd.sent = 2
        else:  # at the very first frame: from nothing, as the gait begins
            crowd.sent = 0
        crowd.counters[:] = 0
        crowd.counters[:, LABEL] = first + 1  # the raise
        crowd.counters[:, FOLLOWER] = 1 - (first + 1) % 2
        crowd.carry[:] = 0.0
        self.done[:] = 0
        self.tapped[:] = True  # until let go after the raise
        self.label[:] = first + 1
        self.ease[:] = 0.0
        # the unit the plan goes on in, by phase: (before, lower, raise, a, b, after); (lower, raise) is
        # the pair `first // 2`, (a, b) the next: its unit loops a and b, the first pair's ends b in the lower
        ends, repeats, rest = first // 2, first // 2 + 1, self.rest_unit
        self._next_repeating = np.array([rest, rest, repeats, repeats, repeats, rest])
        self._next_ending = np.array([rest, rest, repeats, repeats, ends, rest])

    def _units(self) -> np.ndarray:
        """The unit each character's plan goes on in (module text): raise -> a, a -> b, b -> a
        while it repeats, b -> lower, lower -> the rest."""
        g = self.first
        going_on = (self.playing in self.held) | (self.tapped & (self.done < self.repeats[self.playing]))
        phase = np.clip(self.label - g, -1, 4) + 1  # 0: before the gesture, 1..4 its labels, 5: after
        return np.where(going_on, self._next_repeating[phase], self._next_ending[phase])

    def _layer(self, frames: np.ndarray) -> np.ndarray:
        crowd = self.crowd
        crowd.counters[:, UNIT] = self._units()
        gesture = crowd.step()
        label = crowd.history_ids[:, 1] // crowd.space.states
        g = self.first
        moved = label != self.label
        self.done += moved & ((label == g + 2) | (label == g + 3)) & (self.label != g + 1)  # a repeat half finished
        self.label = label
        inside = (label >= g) & (label <= g + 3)
        self.ease = np.clip(self.ease + np.where(inside, 1.0 / EASE_IN, -1.0 / EASE_OUT), 0.0, 1.0)
        self.weights = self.ease * self.ease * (3.0 - 2.0 * self.ease)  # smoothstep: no kink at either end
        if not inside.any() and not self.ease.any():
            self.playing = None
        w = self.weights[:, None]
        out = np.array(frames, dtype=np.float64)
        out[:, self.columns] += w * (gesture[:, self.columns] - out[:, self.columns])
        return out
