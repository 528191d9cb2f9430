"""The body follows its stance foot: part of a planted foot's generated slide moves the body.

The foot lock (contact.py) holds a planted foot where it landed while the generated body
travels on. Where the generated leg sweeps less ground than the body travels, the lock's leg IK
makes up the difference by stretching the leg and swinging the thigh further back than the
data does (the hip's range grows, the knee's shrinks). Here the body takes STRENGTH of that
slide instead: each frame, the horizontal step each foot's pivot (the joint the lock holds)
made in the generated pose since the frame before, weighted by how far that foot's lock is
blended in (eased as the lock eases it), is taken off the body's path. The rest is left to the
IK, because what the body takes it no longer travels: all of it (STRENGTH 1) slows the walk by
7-11% and a quarter by up to 3% (docs/evaluate.md has the figures), against the target of
speed within 3% of the real takes. Outside the data (x2, -1) the generated slide is larger and
speed has nothing real to match, so the body takes more (`strength`).

The offset grows by at most STRENGTH times a foot's slide per frame, so nothing jumps, and a
style change shows in the next frame. It is causal: it uses the lock's blend of the frame
before. Its state is arrays with one row per character, so it batches over a crowd.
"""

from __future__ import annotations

import numpy as np
from numba import njit

STRENGTH = 0.2  # share of a planted foot's generated slide the body takes inside the data (chosen by `instrument evaluate`)
STRENGTH_OFF_DATA = 0.5  # ... a whole weight unit outside it (x2, -1), where speed has no real takes to match
HORIZONTAL = np.array([1.0, 0.0, 1.0])


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
        pivots = np.array(pivots, dtype=np.float64)
        slide = np.nan_to_num((pivots - self.previous) * HORIZONTAL)  # a character's first frame has no slide
        weight = ease(np.asarray(blend, dtype=np.float64))
        share = weight / np.maximum(weight.sum(axis=1, keepdims=True), 1.0)  # both feet planted: their mean
        self.offset -= (np.asarray(strengths)[:, None, None] * share[:, :, None] * slide).sum(axis=1)
        self.previous = pivots
        return self.offset.copy()
