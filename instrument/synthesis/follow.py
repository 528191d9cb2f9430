"""The body follows its stance foot: part of a planted foot's generated slide moves the body.

The foot lock (footlock.py) holds a planted foot where it landed while the generated body
travels on. Where the generated leg sweeps less ground than the body travels, the lock makes up
the difference: the heel rises (a foot rolling onto its toes) and, past what that reaches, the
leg stretches. Here the body takes a share of that slide instead: each frame, the horizontal
step each foot's pivot (the joint the lock holds) made in the generated pose since the frame
before, weighted by how far that foot's lock is blended in (eased as the lock eases it), is
taken off the body's path. What the body takes it no longer travels, so inside the data
(STRENGTH) it takes nothing: there the made leg's sweep and the body's travel agree to within a
heel rise, and any share slowed the walk (a fifth: speed 2-3% short of the takes). Outside the
data (x2, -1) the generated slide is larger and speed has nothing real to match, so the body
takes more (`strength`): feminine x2 skated 25 cm/s without it.

The offset grows by at most the character's strength times a foot's slide per frame, so nothing
jumps, and a style change shows in the next frame. It is causal: it uses the lock's blend of
the frame before. Its state is arrays with one row per character, so it batches over a crowd.
"""

from __future__ import annotations

import numpy as np
from numba import njit

STRENGTH = 0.0  # share of a planted foot's generated slide the body takes inside the data (chosen by `instrument evaluate`)
STRENGTH_OFF_DATA = 0.5  # ... a whole weight unit outside it (x2, -1), where speed has no real takes to match


@njit(cache=True, error_model="numpy")
def ease(x):  # pragma: no cover - compiled
    """Smoothstep, on a number or an array: a lock (and the body's share of a slide) starts and
    ends with zero speed. Compiled, so the foot lock's kernels use it too."""
    return x * x * (3.0 - 2.0 * x)


def strength(leg_weights: np.ndarray) -> np.ndarray:
    """How much of the slide the body takes at these (legs') style weights (styles,) or
    (characters, styles): STRENGTH inside the data (no weight below 0, none above 1 in sum),
    growing to STRENGTH_OFF_DATA a whole weight unit outside it. Speed must match the real takes
    only inside; outside, the slide is larger (feminine x2 skated 25 cm/s at STRENGTH, 8 at
    STRENGTH_OFF_DATA)."""
    w = np.asarray(leg_weights, dtype=np.float64)
    outside = np.maximum(-w, 0.0).sum(axis=-1) + np.maximum(np.maximum(w, 0.0).sum(axis=-1) - 1.0, 0.0)
    return STRENGTH + (STRENGTH_OFF_DATA - STRENGTH) * np.minimum(outside, 1.0)


class RootFollow:
    """Characters' bodies following their stance feet, one row per character."""

    def __init__(self, characters: int = 1):
        self.offset = np.zeros((characters, 3))  # world offset added to each body's generated path
        self.previous = np.full((characters, 2, 3), np.nan)  # each pivot's generated position in the frame before

    def release(self, n: int) -> None:
        """Character n starts again (it was put somewhere else): no offset, no slide yet."""
        self.offset[n], self.previous[n] = 0.0, np.nan

    def step(self, pivots: np.ndarray, blend: np.ndarray, strengths: np.ndarray) -> np.ndarray:
        """The world offsets (N, 3) to add to this frame's bodies, given each foot's pivot in
        the frame's generated pose (N, 2, 3), how far each foot's lock was blended in, 0 to 1,
        over the step from the frame before to this one (N, 2), and each character's
        `strength` (N,)."""
        _follow_step(np.ascontiguousarray(pivots, dtype=np.float64), np.ascontiguousarray(blend, dtype=np.float64),
                     np.ascontiguousarray(strengths, dtype=np.float64), self.offset, self.previous)
        return self.offset.copy()


@njit(cache=True, error_model="numpy")
def _follow_step(pivots, blend, strengths, offset, previous):  # pragma: no cover - compiled
    """`RootFollow.step` in place on `offset` and `previous` (compiled: as numpy it cost a single
    character several times the foot lock itself)."""
    for n in range(pivots.shape[0]):
        w0, w1 = ease(blend[n, 0]), ease(blend[n, 1])
        total = max(w0 + w1, 1.0)  # both feet planted: their mean
        for f in range(2):
            share = (w0 if f == 0 else w1) / total
            for axis in (0, 2):  # horizontal only
                slide = pivots[n, f, axis] - previous[n, f, axis]
                if slide == slide:  # NaN: a character's first frame has no slide
                    offset[n, axis] -= strengths[n] * share * slide
            for axis in range(3):
                previous[n, f, axis] = pivots[n, f, axis]
