"""A crowd in the live instrument: N walkers around the performed walk (docs/crowds.md).

Character 0 walks exactly as performed, as a run of one character does. Every other character
k has, drawn once from its own seed (0 + k, so a replay is exact):

- a style offset of its own: a style mix (a Dirichlet draw over the styles: mostly one or two
  of them) minus the even mix, so its weights add up to 0. The `spread` control scales it: a
  character's weights are the performed ones plus `spread` times its offset (0: all as
  performed; 1: each its own mix around the performed one). The offsets change no total: a
  walk inside the styles' blends stays near them. Part weights set for a body part move the
  same way; those that follow the overall weights keep following;
- a start phase: the step and state it starts in, so the crowd does not step in unison;
- its own liveliness draws (the walker's generator, seeded the same way).

On the floor the characters stand in a grid, character 0 at the origin, the others in rows
beside it (across the direction of travel) and behind it, `spacing` metres apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.features import FeatureLayout
from ..motion.kinematics import forward_kinematics, local_transforms
from ..output.vmc import forward_direction, units_to_metres
from ..synthesis.contact import ContactSpace
from ..synthesis.durations import MIN_FRAMES, state_durations
from ..synthesis.follow import strength as follow_strength
from ..synthesis.interpolation import MAX_LOG_VARIANCE_CHANGE, StyleSpace
from ..synthesis.parameters import DEFAULT_SPACING
from ..synthesis.stream import Controls, Crowd
from ..synthesis.widen import EASE_FRAMES as RANGE_EASE_FRAMES
from ..synthesis.widen import KEPT as RANGE_KEPT
from ..synthesis.widen import LIMIT as RANGE_LIMIT
from ..synthesis.widen import STRENGTH as RANGE_STRENGTH
from ..synthesis.widen import RangeSpace

MIX_CONCENTRATION = 0.5  # of the Dirichlet draw: below 1 a character's own mix leans on one or two styles
MIX_STREAM = 1  # the draws of a character's mix and phase come from seed sequence (seed, MIX_STREAM)


@dataclass(frozen=True)
class Cast:
    """Who is in the crowd: per character its seed, style offset and start phase."""

    seeds: list[int]
    offsets: np.ndarray  # (N, styles) each character's style offset at spread 1; row 0 zeros (the performance itself)
    phases: np.ndarray  # (N, 2): label (which foot steps) and state it starts in; row 0 zeros


def make_cast(count: int, styles: int, states: int, seed: int = 0) -> Cast:
    seeds = [seed + k for k in range(count)]
    offsets = np.zeros((count, styles))
    phases = np.zeros((count, 2), dtype=np.int64)
    for k in range(1, count):
        rng = np.random.default_rng([seeds[k], MIX_STREAM])
        offsets[k] = rng.dirichlet(np.full(styles, MIX_CONCENTRATION)) - 1.0 / styles
        phases[k] = rng.integers(0, 2), rng.integers(0, states)
    return Cast(seeds, offsets, phases)


class CastControls:
    """Each character's Controls from the performed ones and the spread, and the tables that
    follow from them for characters 1..N-1, computed together in one batched pass.

    Character 0 gets the performed controls themselves (its walker refreshes them as a single
    character's does). The others' objects stay the same while neither the performed controls
    (what lambda* depends on) nor the spread change; when either does, their lambda*, state
    durations, range-filter targets and contact tables are recomputed for all of them at once
    and handed to the walker (`Crowd.assign`), which then skips them in its own refresh."""

    def __init__(self, cast: Cast, space: StyleSpace, ranges: RangeSpace | None = None, contact: ContactSpace | None = None):
        self.offsets = cast.offsets
        self.space, self.ranges, self.contact = space, ranges, contact
        # lambda*'s change is linear in the weights, and a character's are the performed ones plus spread times its
        # offset (part weights too): so its change is the performance's plus spread times its offset's, made once here
        styles = len(space.style_names)
        self.offset_change = (self.offsets[1:] @ space.offsets.reshape(styles, -1)).reshape((-1,) + space.base.shape)
        self.offset_duration_change = (self.offsets[1:] @ space.duration_offsets.reshape(styles, -1)).reshape(
            (-1,) + space.duration_base.shape)
        self._key: tuple | None = None
        self._others: list[Controls] = []
        self.range_targets: tuple[np.ndarray, np.ndarray] | None = None  # (N-1, D) stride means and swing factors
        self.share_tables: np.ndarray | None = None  # (N-1, labels * states, 2)
        self.follow_strengths: np.ndarray | None = None  # (N-1,) how much of a planted foot's slide each body takes
        self._spread_terms: tuple[float, np.ndarray, np.ndarray] | None = None  # spread, its share of the means and precisions

    def __call__(self, controls: Controls, spread: float, walker: Crowd) -> list[Controls]:
        if self.offsets.shape[0] == 1:
            return [controls]
        key = (controls.key(), float(spread))
        if key != self._key:
            self._key = key
            self._others = [spread_controls(controls, offset, spread) for offset in self.offsets[1:]]
            self._retune(controls, spread, walker)
        return [controls] + self._others

    def _retune(self, controls: Controls, spread: float, walker: Crowd) -> None:
        """The others' tables from their weights (the performed ones plus spread times each offset)."""
        space = self.space
        weights = controls.weights + spread * self.offsets[1:]  # (M, styles)
        parts = None
        if controls.part_weights is not None:
            parts = controls.part_weights[None] + spread * self.offsets[1:, :, None]  # NaN (follows) stays NaN
        if self._spread_terms is None or self._spread_terms[0] != spread:
            self._spread_terms = spread_terms(self.offset_change, spread)
        means, variances = interpolate_around(space, controls.weights, controls.part_weights, spread, self.offset_change,
                                              self.offset_duration_change, self._spread_terms, walker.means[1:],
                                              walker.precisions[1:])
        scale = np.ones(space.states) if controls.state_scale is None else np.asarray(controls.state_scale, dtype=np.float64)
        base = state_durations(means, variances, controls.speed, scale)
        sigma = controls.liveliness * np.sqrt(variances) * scale
        cadence = np.maximum(means, MIN_FRAMES).sum(axis=(1, 2)) / base.sum(axis=(1, 2))
        walker.assign(1, self._others, None, None, base, sigma, cadence)  # lambda* already written into the walker
        if self.ranges is not None:
            frames = base.reshape(len(base), -1)
            dimension = walker.means.shape[2] // 3
            stride_means = np.einsum("mk,mkd->md", frames, walker.means[1:, :, :dimension]) / frames.sum(axis=1)[:, None]
            self.range_targets = stride_means, range_factors_many(self.ranges, weights, parts)
        if self.contact is not None:
            legs = self.contact.leg_weights(weights, parts)  # (M, styles)
            self.share_tables = np.clip(self.contact.base + np.einsum("ms,sif->mif", legs, self.contact.offsets), 0.0, 1.0)
            self.follow_strengths = follow_strength(legs)


def spread_controls(controls: Controls, offset: np.ndarray, spread: float) -> Controls:
    """`controls` with `spread` times `offset` added to the style weights (and to the part
    weights set for a body part; NaN, following the overall weights, stays NaN)."""
    weights = controls.weights + spread * offset
    parts = None
    if controls.part_weights is not None:
        parts = controls.part_weights + spread * offset[:, None]
    return Controls(weights, parts, controls.speed, controls.state_scale, controls.liveliness, controls.turn)


def style_change(space: StyleSpace, weights: np.ndarray, parts: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """How far lambda* moves from lambda 0 at these weights, before the variances' limit:
    (2, labels * states, 3D) means and log variances, (2, labels * states) of the durations
    (as `interpolate` moves them; tests/test_crowd.py holds the two equal)."""
    styles = len(weights)
    if parts is None:
        change = (weights @ space.offsets.reshape(styles, -1)).reshape(space.base.shape)
    else:
        per_dim = np.where(np.isnan(parts), weights[:, None], parts) @ space.group_masks
        change = np.einsum("sf,sxkf->xkf", per_dim, space.offsets)
    return change, (weights @ space.duration_offsets.reshape(styles, -1)).reshape(space.duration_base.shape)


def spread_terms(offset_change: np.ndarray, spread: float) -> tuple[float, np.ndarray, np.ndarray]:
    """What the spread adds to the others' means, and the factor it puts on their precisions
    when no variance reaches its limit: kept while the spread stays (a moving style weight then
    costs one pass over the tables for each, no exponential)."""
    return spread, spread * offset_change[:, 0], np.exp(-spread * offset_change[:, 1])


def interpolate_around(space: StyleSpace, weights: np.ndarray, parts: np.ndarray | None, spread: float, offset_change: np.ndarray,
                       offset_duration_change: np.ndarray, terms: tuple[float, np.ndarray, np.ndarray], means: np.ndarray,
                       precisions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """lambda* for M characters whose change from lambda 0 is the one at (weights, parts) plus
    `spread` times their own `offset_change` (M, 2, labels * states, 3D) and
    `offset_duration_change` (M, 2, labels * states), `terms` being `spread_terms` of it: means
    and precisions written into the given (M, labels * states, 3D) arrays (in place: a crowd's
    tables are megabytes, and fresh ones cost page faults every time); returns the duration
    means and variances (M, labels, states)."""
    change, duration_change = style_change(space, weights, parts)
    limit = MAX_LOG_VARIANCE_CHANGE
    _, mean_term, precision_factor = terms
    np.add(mean_term, space.base[0] + change[0], out=means)
    if np.abs(change[1]).max() + abs(spread) * np.abs(offset_change[:, 1]).max() <= limit:  # no variance at its limit:
        np.multiply(precision_factor, np.exp(-(space.base[1] + change[1])), out=precisions)  # exp(-(a + b)) = exp(-a) exp(-b)
    else:
        np.multiply(offset_change[:, 1], spread, out=precisions)
        precisions += change[1]
        np.clip(precisions, -limit, limit, out=precisions)
        precisions += space.base[1]
        np.negative(precisions, out=precisions)
        np.exp(precisions, out=precisions)
    duration_change = duration_change + spread * offset_duration_change
    shape = (len(means), space.labels, space.states)
    return ((space.duration_base[0] + duration_change[:, 0]).reshape(shape),
            np.exp(space.duration_base[1] + np.clip(duration_change[:, 1], -limit, limit)).reshape(shape))


def range_factors_many(ranges: RangeSpace, weights: np.ndarray, parts: np.ndarray | None = None) -> np.ndarray:
    """`RangeSpace.factors` for M characters at once, (M, D) (tests/test_crowd.py holds them equal)."""
    if parts is None:  # every feature has its style's one weight: the sums are per style, not per feature
        positive = np.maximum(weights, 0.0)
        total = positive.sum(axis=1)
        outside = np.maximum(-weights, 0.0).sum(axis=1) + np.maximum(total - 1.0, 0.0)
        blended = ranges.base + (positive / np.maximum(total, 1.0)[:, None]) @ ranges.offsets
        return np.exp(RANGE_STRENGTH * np.clip(1.0 - outside, 0.0, 1.0)[:, None] * np.clip(blended, -RANGE_LIMIT, RANGE_LIMIT))
    per_dim = np.where(np.isnan(parts), weights[:, :, None], parts) @ ranges.group_masks
    positive = np.maximum(per_dim, 0.0)
    total = positive.sum(axis=1)
    outside = np.maximum(-per_dim, 0.0).sum(axis=1) + np.maximum(total - 1.0, 0.0)
    inside = positive / np.maximum(total, 1.0)[:, None]
    blended = ranges.base + np.einsum("msd,sd->md", inside, ranges.offsets)
    return np.exp(RANGE_STRENGTH * np.clip(1.0 - outside, 0.0, 1.0) * np.clip(blended, -RANGE_LIMIT, RANGE_LIMIT))


class CrowdWiden:
    """The range filter (synthesis/widen.py's `Widen`) for characters 1..N-1 at once, from the
    targets CastControls computes: each frame the stride mean and the factor move a quarter of
    the way to them, and each feature's swing about the mean is scaled."""

    def __init__(self):
        self.mean: np.ndarray | None = None
        self.factor: np.ndarray | None = None
        self.kept = list(RANGE_KEPT)

    def next(self, frames: np.ndarray, targets: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
        mean, factor = targets
        if self.mean is None:
            self.mean, self.factor = mean, factor
        else:
            self.mean = self.mean + (mean - self.mean) / RANGE_EASE_FRAMES
            self.factor = self.factor + (factor - self.factor) / RANGE_EASE_FRAMES
        out = self.mean + self.factor * (frames - self.mean)
        out[:, self.kept] = frames[:, self.kept]
        return out


def metres_to_units(layout: FeatureLayout) -> float:
    """Model units per metre, from the template pose's hip height (as the VMC profile guesses)."""
    template = Motion(layout.skeleton, np.asarray(layout.template)[None], 30.0)
    positions = forward_kinematics(layout.skeleton, *local_transforms(template))[1][0]
    return 1.0 / units_to_metres(float(positions[layout.root][1] - positions[:, 1].min()))


def floor_positions(model: Model, count: int, spacing_m: float = DEFAULT_SPACING) -> np.ndarray:
    """(N, 3) where each character starts, in model units: a grid of ceil(sqrt(N)) columns
    across the direction of travel, rows behind one another, character 0 at the origin."""
    layout = model.layout
    forward = forward_direction(model.average.means[..., : layout.dimension])
    forward = forward / max(np.linalg.norm(forward), 1e-12)
    across = np.cross(np.array([0.0, 1.0, 0.0]), forward)
    columns = int(np.ceil(np.sqrt(count)))
    k = np.arange(count)
    step = spacing_m * metres_to_units(layout)
    return step * ((k % columns)[:, None] * across - (k // columns)[:, None] * forward) + 0.0  # + 0.0: no -0.0
