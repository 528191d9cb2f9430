"""Poses between the model's frames: the static features on a cubic Hermite curve through them.

A renderer or a VMC app runs at 60-144 Hz; the model makes 30 frames a second (its own rate).
At an output rate above the model's the engine samples between its two newest model frames.
Lerped, the features' velocity was constant over a model frame and jumped at the next: the
acceleration an impulse at every model frame, which a renderer shows as a buzz (the output's
jitter, the third derivative of the joint positions, was ten times the 30 fps walk's at 120 fps:
docs/evaluate.md, "Between the model's frames").

The rule: between model frames k - 1 and k (the newest), at a fraction t of a frame,

    p(t) = p[k-1] + h(t) (p[k] - p[k-1]) + (t^3 - 2t^2 + t) m[k-1] + (t^3 - t^2) m[k],  h = 3t^2 - 2t^3

with each frame's tangent m (per model frame) made once, when the frame is made, and kept: the
segment after a frame starts with the tangent the segment before it ended with, so the velocity
is continuous (C1) whatever the tangent is. The tangent is Catmull-Rom's, the mean of the
backward difference p[k] - p[k-1] and the forward one, p[k+1] - p[k]; the next frame is not made
yet (waiting for it would add a model frame of latency), but the stream's window solve already
holds a provisional one (its look-ahead's first frame, `Crowd.ahead`), which the engine carries
through its stages' gains to give the forward difference (`Engine.next_features`). At t = 0 the
sample is the older frame and at the model's own rate the newest frame itself, to the bit.

Every static feature is a value the model's frames move smoothly in, so each goes on the curve
as it is: the root's height, its speeds and yaw rate (rates, per second, which posing integrates
at the output's rate: a cubic speed gives a path smooth to its acceleration, and the distance a
model frame covers differs from the lerp's by (m[k-1] - m[k]) / 12 of a frame, which adds up over
frames to the first and last tangents' difference only, so no drift), the root's tilt and every
joint's rotation as exponential maps relative to the template pose (made continuous over time
and far from pi: motion/features.py), in which the streaming MLPG makes its trajectories smooth
(a cubic in the map is a rotation path with continuous angular velocity). The contact shares are
not interpolated: they belong to a frame's HSMM state (one state's share until the next state),
and the lock reads them against thresholds in seconds (footlock.py).
"""

from __future__ import annotations

import numpy as np


def tangent(frame: np.ndarray, past: list[np.ndarray], forward: np.ndarray) -> np.ndarray:
    """The tangent (per model frame) at `frame` (N, D), from the frames before it (`past`, oldest
    first) and `forward` (N, A, D), the provisional next A frames' differences from it: the
    five-point central difference where two frames are known on each side, else the three-point
    one (Catmull-Rom's), else the one-sided difference there is."""
    behind = [frame - p for p in past[::-1]]  # frame - p[k-1], frame - p[k-2]
    ahead = [forward[:, j] for j in range(forward.shape[1])]  # p[k+1] - frame, p[k+2] - frame
    if len(behind) >= 2 and len(ahead) >= 2:
        return (8.0 * (ahead[0] + behind[0]) - (ahead[1] + behind[1])) / 12.0
    if behind and ahead:
        return 0.5 * (ahead[0] + behind[0])
    if behind or ahead:
        return (behind or ahead)[0]
    return np.zeros(frame.shape)


def hermite(p0: np.ndarray, m0: np.ndarray, p1: np.ndarray, m1: np.ndarray, t: float) -> np.ndarray:
    """The cubic Hermite curve from p0 (tangent m0) to p1 (tangent m1) at fraction t of the way, (N, D)."""
    t2, t3 = t * t, t * t * t
    return p0 + (3.0 * t2 - 2.0 * t3) * (p1 - p0) + (t3 - 2.0 * t2 + t) * m0 + (t3 - t2) * m1


class Knots:
    """The engine's newest model frames (N, D) and the two newest's tangents: what a sample
    between them is made of."""

    def __init__(self) -> None:
        self.frames: list[np.ndarray] = []  # the last three model frames, oldest first
        self.tangents: list[np.ndarray | None] = []  # the last two's (None: made at the model's rate, never sampled between)

    def add(self, frame: np.ndarray, forward: np.ndarray | None) -> None:
        """The newest model frame, with its provisional next frames' differences from it (N, A, D;
        None: the engine runs at the model's rate)."""
        made = None if forward is None else tangent(frame, self.frames[-2:], forward)
        self.frames = (self.frames + [frame])[-3:]
        self.tangents = (self.tangents + [made])[-2:]

    def at(self, fraction: float) -> np.ndarray:
        """The features a `fraction` of a model frame past the older frame (1: the newest, exactly)."""
        if fraction >= 1.0 - 1e-9 or len(self.frames) == 1:
            return self.frames[-1]
        return hermite(self.frames[-2], self.tangents[0], self.frames[-1], self.tangents[1], fraction)
