"""Straight when told: the right and left step models made mirror images of each other in the
root's motion, so the turning of one step is undone by the next and a walk at turn = 0 keeps
its heading (the `turn` control alone steers).

Recorded walks are never quite symmetric (and the takes curve a little), so the two step
models learn slightly different yaw rates, which integrate into a circle. For each state, the
sideways speed and the yaw rate (and their deltas) of the right step become the negative of the
left step's, their common size the mean of the two; the height and forward speed, all variances
and the state durations become the mean of the two. It is what mirroring the data (left and
right swapped, lateral components negated) does to the root, for any skeleton, without knowing
how its joints' local axes were set up; the limbs keep what each step learnt.
"""

from __future__ import annotations

import numpy as np

from ..models.hsmm import HSMM

ROOT_EVEN = (0, 2)  # root.height, root.vz: the same in a step and its mirror image
ROOT_ODD = (1, 3)  # root.vx, root.yaw_rate: negated in the mirror image
WINDOWS = 3  # static, delta, delta-delta


def _columns(features: tuple[int, ...], dimension: int) -> list[int]:
    return [w * dimension + f for w in range(WINDOWS) for f in features]


def _forward_is_x(average: HSMM, dimension: int) -> bool:
    """Which heading-frame axis the data walks along (the other one is sideways)."""
    means = average.means[..., :dimension]
    return abs(means[..., 1].mean()) > abs(means[..., 2].mean())


def mirror_root(model: HSMM, dimension: int, forward_is_x: bool, pairs: list[tuple[int, int]] | None = None) -> HSMM:
    """Each (right, left) pair of labels (axis -3 of the means: ..., labels, states, 3D; default the
    first two) made mirror images."""
    even, odd = (ROOT_EVEN, ROOT_ODD) if not forward_is_x else ((0, 1), (2, 3))
    means, variances = model.means.copy(), model.variances.copy()
    duration_means, duration_variances = model.duration_means.copy(), model.duration_variances.copy()
    for r, l in pairs if pairs is not None else [(0, 1)]:
        right, left = means[..., r, :, :], means[..., l, :, :]  # views: writing them writes `means`
        right_var, left_var = variances[..., r, :, :], variances[..., l, :, :]
        for columns, sign in ((_columns(even, dimension), 1.0), (_columns(odd, dimension), -1.0)):
            shared = 0.5 * (right[..., columns] + sign * left[..., columns])
            right[..., columns], left[..., columns] = shared, sign * shared
            spread = np.sqrt(right_var[..., columns] * left_var[..., columns])  # the mean in log space
            right_var[..., columns], left_var[..., columns] = spread, spread
        durations = 0.5 * (duration_means[..., r, :] + duration_means[..., l, :])
        duration_vars = np.sqrt(duration_variances[..., r, :] * duration_variances[..., l, :])
        duration_means[..., r, :], duration_means[..., l, :] = durations, durations
        duration_variances[..., r, :], duration_variances[..., l, :] = duration_vars, duration_vars
    return HSMM(means, variances, duration_means, duration_variances)


def symmetric_models(average: HSMM, styles: HSMM, dimension: int,
                     pairs: list[tuple[int, int]] | None = None) -> tuple[HSMM, HSMM]:
    """lambda 0 and every style model with mirror-image steps (the same axes for all, from lambda 0)."""
    forward_is_x = _forward_is_x(average, dimension)
    return mirror_root(average, dimension, forward_is_x, pairs), mirror_root(styles, dimension, forward_is_x, pairs)
