"""Poses between the model's frames: the static features on a cubic Hermite curve through them.

A renderer or a VMC app runs at 60-144 Hz; the shipped model makes 30 frames a second. At an
output rate above the model's (`run --fps 120`) the engine samples between its two newest model
frames. Lerped, the features' velocity was constant over a model frame and jumped at the next,
the acceleration an impulse at every model frame, and the recorded walk's jitter (the joints'
third derivative) was ten times the 30 fps walk's at 120 fps (docs/evaluate.md, "Between the
model's frames").

The rule: between model frames k - 1 and k (the newest), at a fraction t of a frame,

    p(t) = p[k-1] + (3t^2 - 2t^3) (p[k] - p[k-1]) + (t^3 - 2t^2 + t) m[k-1] + (t^3 - t^2) m[k]

with each frame's tangent m (per model frame) made once, when the frame is made, and kept: the
segment after a frame starts with the tangent the segment before it ended with, so the velocity
is continuous (C1) whatever the tangent is. The tangent is the central difference through the
frames on either side: the next ones are not made yet (waiting for them would add latency), but
the stream's window solve already holds them provisionally (its look-ahead's first frames,
`Crowd.ahead`), which the engine carries through its stages' gains (`through_gains`,
`Engine._forward`): five points where two are known on each side, (p[k+1] - p[k-1]) 8/12 -
(p[k+2] - p[k-2]) / 12 (Catmull-Rom's three points gave 2-15% more jitter at 120 fps; a natural
spline through the frames made offline, the whole walk known, 0-4% less). With constant controls
the provisional frames are the frames to 1e-6; a change of the controls (a stop, a style, a
wave) moves the next frame from its guess, the curve then still C1. At t = 0 the sample is the
older frame, at t = 1 (and at the model's own rate, where nothing here runs) the newest, to the bit.

Every static feature is a value the model's frames move smoothly in, so each goes on the curve
as it is: the root's height; its speeds and yaw rate, which are rates (per second, not deltas a
frame) that posing integrates at the output's rate, so the path is smooth to its acceleration and
the ground a model frame covers differs from the lerp's by a multiple of m[k-1] - m[k], which
telescopes over frames (no drift); the root's tilt and every joint's rotation, exponential maps
relative to the template pose (made continuous over time and far from pi: motion/features.py),
the space the streaming MLPG makes its trajectories smooth in, so a cubic in it is a rotation
path with continuous angular velocity. The contact shares are not features: the engine draws
them on a line between the two frames' (`Engine.shares_at`), so the lock, which reads them
against thresholds with its own blends in seconds (footlock.py), takes a state's step where the
line crosses its threshold rather than at the first sample after the older frame.

The forward differences, the tangent and each sample are one compiled pass each: numpy's array
operations for them cost a character 1.4 window solves a model frame, these 0.3.
"""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True, nogil=True)
def through_gains(ahead, solved, factor, ranged, kept_from, kept_to, stride, rates_from, rates_to, scale,
                  out):  # pragma: no cover - compiled
    """out (N, A, D) = the stream's provisional frames `ahead` (N, A, D) less the frame it solved,
    `solved` (N, D), each feature times the gain the frame's stages gave it: the range filter's
    eased factor `factor` (N, D; when `ranged`, but for columns kept_from to kept_to, which it keeps
    as made), a braking or starting body's `stride` (N, D) but for the root's rates (columns
    rates_from to rates_to), which the drive scales by `scale` (N,: cadence times travel)."""
    for n in range(ahead.shape[0]):
        for d in range(ahead.shape[2]):
            gain = factor[n, d] if ranged and not kept_from <= d < kept_to else 1.0
            gain *= scale[n] if rates_from <= d < rates_to else stride[n, d]
            for j in range(ahead.shape[1]):
                out[n, j, d] = gain * (ahead[n, j, d] - solved[n, d])


@njit(cache=True, nogil=True)
def tangent(frame, previous, before, known, forward, out):  # pragma: no cover - compiled
    """out (N, D): the tangent (per model frame) at `frame` (N, D), from the `known` frames before
    it (0 to 2 of `previous`, p[k-1], and `before`, p[k-2]; each (N, D), read only when known) and
    `forward` (N, A, D), the provisional next A frames' differences from it: the five-point central
    difference where two frames are known on each side, else the three-point one (Catmull-Rom's),
    else the one-sided difference there is (0 with none)."""
    ahead = forward.shape[1]
    for n in range(frame.shape[0]):
        for d in range(frame.shape[1]):
            p = frame[n, d]
            if known >= 2 and ahead >= 2:
                out[n, d] = (8.0 * (forward[n, 0, d] + (p - previous[n, d])) - (forward[n, 1, d] + (p - before[n, d]))) / 12.0
            elif known >= 1 and ahead >= 1:
                out[n, d] = 0.5 * (forward[n, 0, d] + (p - previous[n, d]))
            elif ahead >= 1:
                out[n, d] = forward[n, 0, d]
            elif known >= 1:
                out[n, d] = p - previous[n, d]
            else:
                out[n, d] = 0.0


@njit(cache=True, nogil=True)
def hermite(p0, m0, p1, m1, t, out):  # pragma: no cover - compiled
    """out (N, D): the cubic Hermite curve from p0 (tangent m0) to p1 (tangent m1) at fraction t of the way."""
    t2 = t * t
    t3 = t2 * t
    h, a, b = 3.0 * t2 - 2.0 * t3, t3 - 2.0 * t2 + t, t3 - t2
    for n in range(p0.shape[0]):
        for d in range(p0.shape[1]):
            out[n, d] = p0[n, d] + h * (p1[n, d] - p0[n, d]) + a * m0[n, d] + b * m1[n, d]


class Knots:
    """The engine's newest model frames (N, D) and the two newest's tangents: what a sample
    between them is made of."""

    def __init__(self) -> None:
        self.frames: list[np.ndarray] = []  # the last three model frames, oldest first
        self.tangents: list[np.ndarray | None] = []  # the last two's (None: made at the model's rate, never sampled between)

    def add(self, frame: np.ndarray, forward: np.ndarray | None) -> None:
        """The newest model frame, with its provisional next frames' differences from it (N, A, D;
        None: the engine runs at the model's rate)."""
        made = None
        if forward is not None:
            made = np.empty(frame.shape)
            past = (self.frames[::-1] + [frame, frame])[:2]  # p[k-1], p[k-2] (the frame itself where not known: unread)
            tangent(frame, past[0], past[1], min(len(self.frames), 2), forward, made)
        self.frames = (self.frames + [frame])[-3:]
        self.tangents = (self.tangents + [made])[-2:]

    def at(self, fraction: float) -> np.ndarray:
        """The features a `fraction` of a model frame past the older frame (1: the newest, exactly)."""
        if fraction >= 1.0 - 1e-9 or len(self.frames) == 1:
            return self.frames[-1]
        if self.tangents[0] is None or self.tangents[1] is None:  # an engine at the model's rate asked off its grid
            return self.frames[-2] + (self.frames[-1] - self.frames[-2]) * fraction
        out = np.empty(self.frames[-1].shape)
        hermite(self.frames[-2], self.tangents[0], self.frames[-1], self.tangents[1], float(fraction), out)
        return out
