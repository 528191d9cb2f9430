"""A style learnt from little data keeps what makes it itself: its step durations and its swing.

The adaptation (`adaptation.py`) pulls every state toward the average model with a prior weight
chosen for the features' many dimensions (tau 64 or 256 frames with one take), and its durations
with half that weight in steps: from one take of 5 to 12 steps a label, a style keeps most of
the average's timing. The range filter's factors (`widen.py`) follow the style's takes alone,
however few. Both are set here by the amount of data, MAP-style: the style's own figure
with the weight

    w = n / (n + tau),   n the style's walking steps, tau (steps) measured (LITTLE_TAU)

and the prior's with 1 - w:

- durations: each label's mean step (the sum of its state durations) becomes w times the
  style's own mean step (its takes' steps of that label) plus 1 - w times the adapted model's;
  the states keep their proportions (the adaptation's, floored) and their variances scale with
  them;
- swing: each feature's log range factor becomes w times the style's own (its takes' range
  against its made walk, knees calibrated) plus 1 - w times the average's (all takes against
  the average's walk): the average's correction is the prior of how much a made walk must widen.

tau = 0 follows the style's data alone; None leaves both as they were before (the adaptation's
durations, the style's own ranges). `examples/little_data.py` measures the trade-off on held-out
takes (docs/evaluate.md, "Styles from little data").
"""

from __future__ import annotations

import numpy as np

from ..models.hsmm import HSMM
from ..motion.features import REFERENCE_FPS
from .adaptation import duration_floor, floored_keeping_length

FIELDS = ("means", "variances", "duration_means", "duration_variances")

LITTLE_TAU: float | None = 4.0  # steps; chosen by examples/little_data.py (docs/evaluate.md)


def data_weight(steps: int, tau: float) -> float:
    """The weight of a style's own figures: n / (n + tau) (1 with tau 0, 0 without steps)."""
    if steps <= 0:
        return 0.0
    return steps / (steps + tau)


def own_durations(model: HSMM, segments: list[list[np.ndarray]], weight: float, labels: list[int],
                  floor: np.ndarray | None = None) -> HSMM:
    """`model` (one style: labels, states) with each of `labels`' mean step moved to `weight`
    times the mean length of that label's `segments` plus 1 - weight times the model's own (the
    sum of its state durations), states in proportion, none below `floor` (labels, states; the
    adaptation's duration floor, the frames it adds taken from the other states)."""
    means, variances = model.duration_means.copy(), model.duration_variances.copy()
    for k in labels:
        if not segments[k] or weight <= 0:
            continue
        made = means[k].sum()
        own = float(np.mean([len(s) for s in segments[k]]))
        scale = (weight * own + (1 - weight) * made) / made
        means[k] *= scale
        if floor is not None:
            means[k] = floored_keeping_length(means[k][None], floor[k][None])[0]
        variances[k] *= scale**2
    return HSMM(model.means, model.variances, means, variances)


def keep_own_steps(average: HSMM, styles: HSMM, segments: list[list[list[np.ndarray]]], units: list[str],
                   tau: float, floor_share: float, fps: float = REFERENCE_FPS) -> tuple[HSMM, dict[int, float]]:
    """The style models (stacked) with every unit's mean step moved toward each style's own by
    `data_weight` of its steps of that unit (`segments`: per style, per label, the steps), and
    the walk's weight per style (by index)."""
    kept, weights = [], {}
    for s, mine in enumerate(segments):
        model = HSMM(*(getattr(styles, f)[s] for f in FIELDS))
        floor = duration_floor(average, mine, floor_share, fps)
        for k, unit in enumerate(units):
            weight = data_weight(len(mine[2 * k]) + len(mine[2 * k + 1]), tau)
            model = own_durations(model, mine, weight, [2 * k, 2 * k + 1], floor)
            if unit == "walk":
                weights[s] = weight
        kept.append(model)
    return HSMM(*(np.stack([getattr(m, f) for m in kept]) for f in FIELDS)), weights


def pulled_factors(own: np.ndarray, average: np.ndarray, weight: float) -> np.ndarray:
    """A style's log range factors: `weight` of its own, the rest the average's."""
    return weight * own + (1.0 - weight) * average
