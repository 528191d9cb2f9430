"""Footfalls: which feet landed in a frame, read from the foot lock (it already knows).

The lock (footlock.py) starts blending a foot in at the frame the foot is planted after being
free: its blend weight leaves 0. `Footfalls.after` compares every character's weights with the
frame before's, so a footfall is reported in the frame the lock plants the foot, once, for every
gait the lock handles. The foot's speed at impact is its pivot's (the front-most foot joint's)
speed over the frame before, in metres per second: what a sampler turns into velocity.

A stand's closing step (footlock.settle_feet: a foot stepping to where the stand's pose puts it,
lifted and set down again while its lock holds) is a footfall too, in the frame the step is done
(the foot's `settling` reaching CLOSED), so a footstep sound plays for it; it is marked `closing`,
since it paces nothing: the beat lock reads only the walk's and run's footfalls (`pacing`), and
a stand has none of those.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from .footlock import CLOSED
from .posing import CrowdPose, CrowdPoses

SIDES = ("left", "right")
# "left" in any case, or a lone l/L between separators, or a capital L before a capital (LHipJoint)
LEFT = re.compile(r"(?i:left)|(^|[_.])[Ll]($|[_.])|^L(?=[A-Z])")
RIGHT = re.compile(r"(?i:right)|(^|[_.])[Rr]($|[_.])|^R(?=[A-Z])")


def side_of(name: str, fallback: int) -> int:
    """0 (left) or 1 (right) from a hip joint's name (UpperLeg_L, LeftUpLeg, LHipJoint), or the
    leg's place in the lock (`fallback`) for a name that says neither."""
    left, right = LEFT.search(name) is not None, RIGHT.search(name) is not None
    return fallback if left == right else (0 if left else 1)


@dataclass(frozen=True)
class Footfall:
    """One foot contact."""

    character: int
    side: int  # 0 left, 1 right (SIDES)
    time: float  # seconds of performance time (the frame's)
    speed: float  # metres per second of the foot just before it landed
    closing: bool = False  # a stand's closing step (the foot set down beside the other), not a gait's step


def pacing(footfalls: list[Footfall]) -> list[Footfall]:
    """The footfalls that pace a walk or a run (what the beat lock times): all but closing steps."""
    return [f for f in footfalls if not f.closing]


class Footfalls:
    """Detects footfalls frame by frame from a crowd's lock state (nothing without a lock)."""

    def __init__(self, poses: CrowdPoses):
        self.poses = poses
        lock = poses.lock
        self.weights = None if lock is None else np.zeros((poses.count, 2))  # the lock's blends in the frame before
        self.settling = None if lock is None else np.zeros((poses.count, 2))  # and its closing steps' progress
        self.pivots: np.ndarray | None = None  # (N, 2, 3) the feet's pivots in the frame before
        self.metres = 0.0 if lock is None else lock.cm / 100.0  # metres per model unit
        names = [] if lock is None else lock.layout.skeleton.names
        self.sides = [] if lock is None else [side_of(names[leg.hip], f) for f, leg in enumerate(lock.limbs.legs)]

    def after(self, pose: CrowdPose) -> list[Footfall]:
        """The footfalls of the frame just posed (`pose`, made by `poses.next`)."""
        lock = self.poses.lock
        if lock is None:
            return []
        weights = self.poses.lock_state.weights
        pivots = lock.pivots(pose.world_rotations, pose.world_positions)  # (N, 2, 3)
        settling = self.poses.lock_state.settling
        landed = (self.weights == 0.0) & (weights > 0.0)
        closed = (self.settling > 0.0) & (self.settling < CLOSED) & (settling == CLOSED)  # a closing step set down
        characters, feet = np.nonzero(landed | closed)
        if self.pivots is None:
            moved = np.zeros(len(characters))
        else:  # every landed foot's pivot's move at once (a crowd of 1,000 lands some 60 feet a frame)
            step = pivots[characters, feet] - self.pivots[characters, feet]
            moved = np.linalg.norm(step, axis=1)
        closing = (closed & ~landed)[characters, feet]
        time_s, sides = float(pose.time), self.sides
        out = [Footfall(n, sides[side], time_s, speed, shut)
               for n, side, speed, shut in zip(characters.tolist(), feet.tolist(),
                                               (moved * self.metres * self.poses.fps).tolist(), closing.tolist())]
        self.weights = weights.copy()
        self.settling = settling.copy()
        self.pivots = pivots  # a copy already (the feet's columns taken out)
        return out
