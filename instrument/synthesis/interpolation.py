"""Style space: lambda* from per-style weights, as offsets from the average model lambda 0.

A weight of 0 leaves a style out, 1 gives that style's model, 0 < w < 1 inhibits it, w > 1
exaggerates it and w < 0 inverts it; several weights blend. Means (of outputs and durations)
move linearly along the offsets. Variances move in log space, so they stay positive for any
weights (a linear sum, as in hts_engine, goes negative under extrapolation); far out, a
variance changes at most 10^4 times from lambda 0's so the solver stays well conditioned.

Weights can also be given per body part: the static dimensions fall into groups derived from
the skeleton (the root's motion, the legs, the upper body), and each style may weigh each group
differently ("legs youthful, upper body elderly"). Durations follow the overall weights.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.features import ROOT_FEATURES, FeatureLayout
from ..motion.kinematics import forward_kinematics, local_transforms

GROUPS = ("root", "legs", "upper")
MAX_LOG_VARIANCE_CHANGE = float(np.log(1e4))  # extreme weights may scale a variance 10^4 times, no more


@dataclass(frozen=True)
class StyleSpace:
    """lambda 0 and the style offsets, flattened over (label, state) for fast gathering."""

    style_names: tuple[str, ...]
    labels: int
    states: int
    mean0: np.ndarray  # (labels * states, 3D)
    log_var0: np.ndarray
    mean_offsets: np.ndarray  # (styles, labels * states, 3D)
    log_var_offsets: np.ndarray
    duration_mean0: np.ndarray  # (labels * states,)
    duration_log_var0: np.ndarray
    duration_mean_offsets: np.ndarray  # (styles, labels * states)
    duration_log_var_offsets: np.ndarray
    group_masks: np.ndarray  # (groups, 3D) which observation dimensions belong to each group
    max_step: np.ndarray  # (D,) largest frame-to-frame change of each static feature in the data


@dataclass(frozen=True)
class Lambda:
    """An interpolated model, ready for generation."""

    means: np.ndarray  # (labels * states, 3D)
    precisions: np.ndarray  # (labels * states, 3D)
    duration_means: np.ndarray  # (labels, states) in frames
    duration_variances: np.ndarray  # (labels, states)


def body_groups(layout: FeatureLayout) -> np.ndarray:
    """(groups, D) masks over the static features: root motion, legs, upper body.

    A leg is a subtree under the root that reaches near the ground in the template pose (its
    lowest joint is below a third of the root's height above the lowest point); the rest is
    upper body.
    """
    skeleton = layout.skeleton
    template = Motion(skeleton, np.asarray(layout.template)[None], 30.0)
    positions = forward_kinematics(skeleton, *local_transforms(template))[1][0]
    height = positions[:, 1] - positions[:, 1].min()
    parents = skeleton.parents
    top_child = {}
    for j in range(len(parents)):
        chain = j
        while parents[chain] >= 0 and parents[chain] != layout.root:
            chain = parents[chain]
        if parents[chain] == layout.root:
            top_child[j] = chain
    lowest = {}
    for j, child in top_child.items():
        lowest[child] = min(lowest.get(child, np.inf), height[j])
    legs = {child for child, low in lowest.items() if low < height[layout.root] / 3.0}
    masks = np.zeros((len(GROUPS), layout.dimension), dtype=bool)
    masks[0, : len(ROOT_FEATURES)] = True
    for k, joint in enumerate(layout.joints):
        columns = slice(len(ROOT_FEATURES) + 3 * k, len(ROOT_FEATURES) + 3 * k + 3)
        masks[1 if top_child.get(joint) in legs else 2, columns] = True
    return masks


def style_space(model: Model) -> StyleSpace:
    labels, states = len(model.labels), model.states
    flat = lambda a: a.reshape(a.shape[:-3] + (labels * states, a.shape[-1]))  # noqa: E731
    mean0, log_var0 = flat(model.average.means), np.log(flat(model.average.variances))
    dmean0 = model.average.duration_means.reshape(-1)
    dlog0 = np.log(model.average.duration_variances.reshape(-1))
    styles = len(model.style_names)
    masks = np.tile(body_groups(model.layout), (1, 3))
    return StyleSpace(
        style_names=tuple(model.style_names),
        labels=labels,
        states=states,
        mean0=mean0,
        log_var0=log_var0,
        mean_offsets=flat(model.styles.means) - mean0,
        log_var_offsets=np.log(flat(model.styles.variances)) - log_var0,
        duration_mean0=dmean0,
        duration_log_var0=dlog0,
        duration_mean_offsets=model.styles.duration_means.reshape(styles, -1) - dmean0,
        duration_log_var_offsets=np.log(model.styles.duration_variances.reshape(styles, -1)) - dlog0,
        group_masks=masks,
        max_step=model.static_step_max,
    )


def interpolate(space: StyleSpace, weights: np.ndarray, part_weights: np.ndarray | None = None) -> Lambda:
    """lambda* for style weights (styles,) and optional per-group weights (styles, groups).

    part_weights replaces the overall weight of a style for a body part; NaN entries fall back
    to the overall weight.
    """
    weights = np.asarray(weights, dtype=np.float64)
    if part_weights is None:
        means = space.mean0 + np.tensordot(weights, space.mean_offsets, axes=1)
        log_var = space.log_var0 + np.tensordot(weights, space.log_var_offsets, axes=1)
    else:
        per_group = np.where(np.isnan(part_weights), weights[:, None], part_weights)
        per_dim = per_group @ space.group_masks  # (styles, 3D): each dimension is in one group
        means = space.mean0 + np.einsum("sf,skf->kf", per_dim, space.mean_offsets)
        log_var = space.log_var0 + np.einsum("sf,skf->kf", per_dim, space.log_var_offsets)
    log_var = space.log_var0 + np.clip(log_var - space.log_var0, -MAX_LOG_VARIANCE_CHANGE, MAX_LOG_VARIANCE_CHANGE)
    duration_means = space.duration_mean0 + weights @ space.duration_mean_offsets
    duration_log_change = np.clip(weights @ space.duration_log_var_offsets, -MAX_LOG_VARIANCE_CHANGE, MAX_LOG_VARIANCE_CHANGE)
    duration_vars = np.exp(space.duration_log_var0 + duration_log_change)
    shape = (space.labels, space.states)
    return Lambda(means, np.exp(-log_var), duration_means.reshape(shape), duration_vars.reshape(shape))
