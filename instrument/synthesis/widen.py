"""Full range: a causal post-filter scaling each feature's swing (after the variance scaling of Silen et al. 2012).

MLPG averages: a walk it makes swings through a smaller range than the takes it learnt from
(the knee 24-38% short for some styles) and, for others, through a larger one. Training
measures, for the average model and for each style, every static feature's range (1st to 99th
percentile) in the real walking frames (about each take's stride mean, averaged over the takes)
and in a walk the model makes (about its stride mean, below), and stores the log of their
ratio: the factor by which a generated feature's swing must grow (or shrink) to have the
data's range. (Matching variances instead left the peaks short: MLPG rounds them off more than
it lowers the variance.) The knees' factors are then calibrated on the walk as the instrument
plays it, feet planted. That measuring is in `instrument/training/widen.py`; this module is
what the engine runs.

Live, frame by frame, each feature is moved away from (or towards) the stride mean of the
current lambda* (the state means weighted by the planned state durations: what the walk
averages over a stride) by that factor. The log factors move with the style weights like every
other parameter (offsets from the average, per body part when part weights are given) inside
the styles' blends, and fade to no scaling outside them (see `RangeSpace.factors`). Nothing
looks ahead; a style change moves mean and factor a quarter of
the way per frame at 30 fps (EASE), so it shows in the next frame and never jumps. The ease is a
time (0.12 s to within 1/e of the target) at any rate: a quarter of the way per frame at 120 fps
would be 4 times as fast, a style change's swing settling in 30 ms (`ease_per_frame`). Root
speeds and the yaw rate are left as made (the path, the cadence and the planted feet rely on them).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from numba import njit

from ..motion.features import REFERENCE_FPS, ROOT_FEATURES
from .contact import eased_per_frame
from .direct import DirectCall
from .interpolation import body_groups, part_weights_per_group
from .mlpg import _part, _prefetch_row
from .stream import numpy_sum

STRENGTH = 1.0  # share of the learnt log factor applied (chosen by `instrument evaluate`, docs/evaluate.md)
LIMIT = np.log(2.0)  # no feature's swing is scaled by its range ratio by more than 2x or less than 1/2
CALIBRATED_LIMIT = np.log(4.0)  # nor the shoulders' swing, calibrated on the played walk, by more than 4x or less than 1/4
EASE = 0.25  # share of the way to the targets the range stage moves a frame at REFERENCE_FPS (see ease_per_frame)
KEPT = tuple(ROOT_FEATURES.index(name) for name in ("root.vx", "root.vz", "root.yaw_rate"))  # never scaled


@dataclass(frozen=True)
class RangeSpace:
    """Log range-scaling factors as lambda 0 plus style offsets, per static feature."""

    base: np.ndarray  # (D,)
    offsets: np.ndarray  # (styles, D)
    group_masks: np.ndarray  # (groups, D) which body part each feature belongs to

    def factors(self, weights: np.ndarray, part_weights: np.ndarray | None = None) -> np.ndarray:
        """(N, D) how far each feature's swing about the stride mean is scaled for N characters
        at weights (N, styles) and part weights (N, styles, groups) (each feature by the weights
        of its body part when given per part).

        Inside the styles' blends (weights 0..1 adding to at most 1) the log factors blend like
        the other parameters. Outside, the learnt factors say nothing (an extrapolated walk's
        smoothing was never measured, and extrapolating them widened inverted walks into
        skating: elderly -1 from 23 to 85 cm/s), so the factor fades to 1 with the distance
        from that region: by an inverted weight of 1 or a total of 2 the walk is as made."""
        weights = np.atleast_2d(np.asarray(weights, dtype=np.float64))
        if part_weights is None:  # every feature has its style's one weight: the sums are per style, not per feature
            per_dim = weights[:, :, None]
        else:
            per_dim = part_weights_per_group(weights, part_weights) @ self.group_masks  # (N, styles, D)
        logs = np.empty((len(per_dim), len(self.base)))
        _log_factors(np.ascontiguousarray(per_dim), self.base, self.offsets, logs)
        return np.exp(logs, out=logs)


def range_space(model) -> RangeSpace | None:
    """None for a model trained without range statistics (it then runs as before)."""
    extras = getattr(model, "extras", {}) or {}
    base, styles = extras.get("range_average"), extras.get("range_styles")
    dimension = model.layout.dimension
    if base is None or styles is None or base.shape != (dimension,) or styles.shape != (len(model.style_names), dimension):
        return None
    return RangeSpace(base, styles - base, body_groups(model.layout).astype(np.float64))


def stride_means(base: np.ndarray, means: np.ndarray, shared: np.ndarray | None = None) -> np.ndarray:
    """(N, D) what each character's walk averages over a stride: its lambda* state means
    (N, labels * states, 3D), plus `shared` (labels * states, 3D) when they are kept as two terms
    (`CrowdLambda`), weighted by the frames planned for each state (N, labels, states)."""
    frames = np.ascontiguousarray(base.reshape(len(base), -1))
    out = np.empty((len(base), means.shape[2] // 3))
    _stride_means(frames, frames.sum(axis=1), means, np.zeros(means.shape[1:]) if shared is None else shared, out)
    return out


@njit(cache=True, nogil=True)
def _stride_means(frames, totals, own, shared, out):  # pragma: no cover - compiled
    """out[n] = sum_k frames[n, k] (own[n, k] + shared[k]) / totals[n] over the static columns,
    added in k's order (as numpy's einsum adds them: the same numbers to the last bit)."""
    for n in range(out.shape[0]):
        for d in range(out.shape[1]):
            total = frames[n, 0] * (own[n, 0, d] + shared[0, d])
            for k in range(1, frames.shape[1]):
                total += frames[n, k] * (own[n, k, d] + shared[k, d])
            out[n, d] = total / totals[n]


@njit(cache=True, nogil=True)
def unit_targets(units, held, scaled, base, own, shared, factor, means, factors):  # pragma: no cover - compiled
    """The range targets of each character's frame, of unit units[n]: its stride mean into
    means[n] (`stride_means` over that unit's two steps, the same numbers to the bit), made only
    where held[n], the unit `means[n]` was made for, is another (-1: made for none since the
    tables changed), and the factors into factors[n]: factor[n] where the unit is `scaled`, else 1.
    A crowd's retune then makes no stride means: a character's are made at its next frame, for
    the one unit it walks (a stride mean of every unit of every character cost 17 us a character)."""
    states = base.shape[2]
    frames = np.empty(2 * states)
    for n in range(units.shape[0]):
        unit = units[n]
        if n + 1 < units.shape[0] and held[n + 1] != units[n + 1]:  # the next character's rows asked for meanwhile
            for k in range(2 * states):
                _prefetch_row(own[n + 1], 2 * units[n + 1] * states + k, 0, means.shape[1])
        if held[n] != unit:
            for k in range(2 * states):
                frames[k] = base[n, 2 * unit + k // states, k % states]
            total = numpy_sum(frames)
            first, width = 2 * unit * states, means.shape[1]
            # the sums run row by row (each in k's order), as the rows lie; rows as views that own
            # nothing (`mlpg._part`): indexed in the 2-D and 3-D tables the loops stayed scalar
            mean, mine = _part(means, n, 0, width), own[n]
            _weighted_row(frames[0], _part(mine, first, 0, width), _part(shared, first, 0, width), mean, False)
            for k in range(1, 2 * states):
                _weighted_row(frames[k], _part(mine, first + k, 0, width), _part(shared, first + k, 0, width), mean, True)
            for d in range(width):
                mean[d] /= total
            held[n] = unit
        for d in range(factors.shape[1]):
            factors[n, d] = factor[n, d] if scaled[unit] else 1.0


@njit(cache=True, nogil=True, inline="always")
def _weighted_row(weight, own, shared, out, adding):  # pragma: no cover - compiled
    """out = weight (own + shared), or out += that when `adding` (`unit_targets`' stride mean)."""
    if adding:
        for d in range(out.shape[0]):
            out[d] += weight * (own[d] + shared[d])
    else:
        for d in range(out.shape[0]):
            out[d] = weight * (own[d] + shared[d])


@njit(cache=True, nogil=True)
def _log_factors(per_dim, base, offsets, out):  # pragma: no cover - compiled
    """The log of `RangeSpace.factors` (N, D) for the style weights of each feature `per_dim`
    (N, styles, 1 or D): inside the blends the offsets blended by the positive weights (scaled to
    add up to at most 1), faded to 0 by the distance outside them, within +-CALIBRATED_LIMIT (training
bounds each feature's factors, within this: a blend of them stays inside). The numpy form
    of the same arithmetic, in the same order (each sum over the styles in their order), took ten
    passes over the crowd a retune."""
    styles, per_feature = per_dim.shape[1], per_dim.shape[2] > 1
    inside = np.empty(styles)
    for n in range(out.shape[0]):
        for e in range(per_dim.shape[2]):
            total, negative = 0.0, 0.0
            for s in range(styles):
                total += max(per_dim[n, s, e], 0.0)
                negative += max(-per_dim[n, s, e], 0.0)
            outside = negative + max(total - 1.0, 0.0)
            fade = STRENGTH * min(max(1.0 - outside, 0.0), 1.0)
            for s in range(styles):
                inside[s] = max(per_dim[n, s, e], 0.0) / max(total, 1.0)
            first, last = (e, e + 1) if per_feature else (0, out.shape[1])  # the features these weights are of
            row = out[n, first:last]  # the blend summed in it style by style (each feature's sum in the styles' order)
            for d in range(first, last):
                row[d - first] = inside[0] * offsets[0, d]
            for s in range(1, styles):
                for d in range(first, last):
                    row[d - first] += inside[s] * offsets[s, d]
            for d in range(first, last):
                row[d - first] = fade * min(max(base[d] + row[d - first], -CALIBRATED_LIMIT), CALIBRATED_LIMIT)


def ease_per_frame(fps: float) -> float:
    """The share of the way to its targets the range stage moves a frame at `fps`: EASE at
    REFERENCE_FPS, and at any rate as far in a second (1 - (1 - EASE) ** (REFERENCE_FPS / fps))."""
    return eased_per_frame(EASE, fps)


class RangeFilter:
    """The engine's range stage for N characters at `fps`, carried from frame to frame (see the
    module's docstring): each frame the stride mean and the factor move `ease_per_frame(fps)` of
    the way to their targets (a quarter at 30 fps), and each feature's swing about the mean is scaled.

    One compiled pass does it all (`_range_step`): the numpy form of the same arithmetic took
    nine array operations and a fancy-indexed copy a frame, some 15-20 us for one character,
    where this takes a few (docs/figures.md); the numbers are the same to the bit
    (tests/test_widen.py holds it to a numpy restatement)."""

    def __init__(self, fps: float = REFERENCE_FPS):
        self.ease = ease_per_frame(fps)
        self.mean: np.ndarray | None = None  # (N, D) where the swing is scaled about, eased
        self.factor: np.ndarray | None = None  # (N, D) by how much, eased
        # `_range_step` through its compiled entry point (direct.py), chosen at the first frame: every
        # argument's type is fixed (`begin` makes float64 C arrays of them, (N, D) ones: checked; the kernel
        # only reads the three given), so a frame does not pay the dispatcher's typing of seven arrays
        self._step = DirectCall(_range_step)

    def __call__(self, frames: np.ndarray, mean: np.ndarray, factor: np.ndarray) -> np.ndarray:
        """Frames (N, D) as made, their swing scaled towards targets `mean` and `factor` (N, D)."""
        mean, factor = np.ascontiguousarray(mean, dtype=np.float64), np.ascontiguousarray(factor, dtype=np.float64)
        frames, out, first = self.begin(frames, mean.shape, factor.shape)
        arguments = (frames, mean, factor, self.mean, self.factor, first, self.ease, KEPT_FROM, KEPT_TO, out)
        if frames.ndim != 2:
            _range_step(*arguments)
            return out
        self._step((), *arguments)
        return out

    def begin(self, frames: np.ndarray, mean_shape: tuple, factor_shape: tuple) -> tuple[np.ndarray, np.ndarray, bool]:
        """A frame's step begun: `frames` checked against the targets' shapes and the filter's, as
        a float64 C array, the array to write the filtered frames into, and whether this is the
        filter's first frame (its eased mean and factor then made, to be set to the targets)."""
        frames = np.ascontiguousarray(frames, dtype=np.float64)
        first = self.mean is None
        if mean_shape != frames.shape or factor_shape != frames.shape or not (first or self.mean.shape == frames.shape):
            raise ValueError(f"RangeFilter: frames {frames.shape}, targets {mean_shape} and {factor_shape} "
                             f"(the filter's characters: {None if first else self.mean.shape})")
        if first:  # the filter's own arrays, eased in place from now on (the targets are the engine's)
            self.mean, self.factor = np.empty(frames.shape), np.empty(frames.shape)
        return frames, np.empty(frames.shape), first


KEPT_FROM, KEPT_TO = min(KEPT), max(KEPT) + 1  # the kept features are one run of columns (root.vx, root.vz, root.yaw_rate)
assert KEPT == tuple(range(KEPT_FROM, KEPT_TO))


@njit(cache=True, nogil=True)
def _range_step(frames, target_mean, target_factor, mean, factor, first, ease, kept_from, kept_to, out):  # pragma: no cover
    """One frame of `RangeFilter`: mean and factor (N, D) moved `ease` of the way to their targets
    in place (set to them when `first`), out = mean + factor (frames - mean), columns kept_from to
    kept_to copied as made. The same operations, in the same order, as numpy's elementwise form
    (no fastmath: nothing is fused or reordered)."""
    for n in range(frames.shape[0]):
        for d in range(frames.shape[1]):
            if first:
                m, f = target_mean[n, d], target_factor[n, d]
            else:
                m = mean[n, d] + (target_mean[n, d] - mean[n, d]) * ease
                f = factor[n, d] + (target_factor[n, d] - factor[n, d]) * ease
            mean[n, d], factor[n, d] = m, f
            out[n, d] = frames[n, d] if kept_from <= d < kept_to else m + f * (frames[n, d] - m)


@njit(cache=True, nogil=True)
def range_part(units, held, scaled, base, own, shared, factor, means, factors, frames, mean, eased, first, ease,
               out):  # pragma: no cover
    """Some characters' range stage in one call (a part of a crowd, on a core of its own): their
    targets (`unit_targets`, into `means` and `factors`) and their frames filtered towards them
    (`_range_step`, `mean` and `eased` the filter's eased mean and factor, `ease` its share a frame, into `out`)."""
    unit_targets(units, held, scaled, base, own, shared, factor, means, factors)
    _range_step(frames, means, factors, mean, eased, first, ease, KEPT_FROM, KEPT_TO, out)


def without_range(model):
    """The model with its range statistics left out, so the engine runs without the range stage:
    the walk as streaming MLPG makes it. Training measures that walk to learn the factors
    (`instrument/training/widen.py`), and the tests and `examples/pose_cost.py` use it where they
    need the bare MLPG walk. The model itself is not changed (a copy with other extras)."""
    return replace(model, extras={k: v for k, v in (model.extras or {}).items() if not k.startswith("range_")})
