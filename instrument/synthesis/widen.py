"""Full range: a causal post-filter scaling each feature's swing (after the variance scaling of Silen et al. 2012).

MLPG averages: a walk it makes swings through a smaller range than the takes it learnt from
(the knee 24-38% short for some styles) and, for others, through a larger one. Training
measures, for the average model and for each style, every static feature's range (1st to 99th
percentile) in the real walking frames (about each take's stride mean, averaged over the takes)
and in a walk the model makes (about its stride mean, below), and stores the log of their
ratio: the factor by which a generated feature's swing must grow (or shrink) to have the
data's range. (Matching variances instead left the peaks short: MLPG rounds them off more than
it lowers the variance.) The knees' factors are then calibrated on the walk as the instrument
plays it, feet planted (`_calibrate_knees`).

Live, frame by frame, each feature is moved away from (or towards) the stride mean of the
current lambda* (the state means weighted by the planned state durations: what the walk
averages over a stride) by that factor. The log factors move with the style weights like every
other parameter (offsets from the average, per body part when part weights are given) inside
the styles' blends, and fade to no scaling outside them (see `RangeSpace.factors`). Nothing
looks ahead; a style change moves mean and factor a quarter of
the way per frame (EASE_FRAMES), so it shows in the next frame and never jumps. Root speeds and
the yaw rate are left as made (the path, the cadence and the planted feet rely on them).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..motion.features import ROOT_FEATURES, heading_angle
from .interpolation import body_groups, part_weights_per_group

STRENGTH = 1.0  # share of the learnt log factor applied (chosen by `instrument evaluate`, docs/evaluate.md)
LIMIT = np.log(2.0)  # no feature's swing is scaled by more than 2x or less than 1/2
EASE_FRAMES = 4
KEPT = tuple(ROOT_FEATURES.index(name) for name in ("root.vx", "root.vz", "root.yaw_rate"))  # never scaled
TRAINING_FRAMES = 600  # frames of each generated walk measured in training (the first SETTLE dropped)
SETTLE = 60
RANGE_PERCENTILES = (1.0, 99.0)  # a feature's range, as `instrument evaluate` measures a joint's
CALIBRATION_ROUNDS = 3  # the knees' factors corrected on a played walk this many times
CALIBRATION_SECONDS = 12.0  # each calibration walk, after SETTLE frames from rest


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
        positive = np.maximum(per_dim, 0.0)
        total = positive.sum(axis=1)
        outside = np.maximum(-per_dim, 0.0).sum(axis=1) + np.maximum(total - 1.0, 0.0)
        inside = positive / np.maximum(total, 1.0)[:, None]
        blended = np.empty((len(inside), len(self.base)))
        _blend(self.base, inside, self.offsets, blended)
        return np.exp(STRENGTH * np.clip(1.0 - outside, 0.0, 1.0) * np.clip(blended, -LIMIT, LIMIT))


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
def _blend(base, inside, offsets, out):  # pragma: no cover - compiled
    """out[n, d] = base[d] + sum_s inside[n, s, d] offsets[s, d] (`inside`'s last axis 1 or D),
    added in the styles' order (as numpy's sum over that axis adds them)."""
    per_feature = inside.shape[2] > 1
    for n in range(out.shape[0]):
        for d in range(out.shape[1]):
            e = d if per_feature else 0
            total = inside[n, 0, e] * offsets[0, d]
            for s in range(1, offsets.shape[0]):
                total += inside[n, s, e] * offsets[s, d]
            out[n, d] = base[d] + total


class RangeFilter:
    """The engine's range stage for N characters, carried from frame to frame (see the module's
    docstring): each frame the stride mean and the factor move a quarter of the way to their
    targets, and each feature's swing about the mean is scaled."""

    def __init__(self):
        self.mean: np.ndarray | None = None
        self.factor: np.ndarray | None = None
        self.kept = list(KEPT)

    def __call__(self, frames: np.ndarray, mean: np.ndarray, factor: np.ndarray) -> np.ndarray:
        """Frames (N, D) as made, their swing scaled towards targets `mean` and `factor` (N, D)."""
        if self.mean is None:
            self.mean, self.factor = mean, factor
        else:
            self.mean = self.mean + (mean - self.mean) / EASE_FRAMES
            self.factor = self.factor + (factor - self.factor) / EASE_FRAMES
        out = self.mean + self.factor * (frames - self.mean)
        out[:, self.kept] = frames[:, self.kept]
        return out


# ---- training -------------------------------------------------------------------------------

def _spread(values: np.ndarray) -> np.ndarray:
    """Each column's range between its 1st and 99th percentiles: the peaks a viewer sees, which
    MLPG rounds off more than it lowers the variance (matching variances left the knee 5-18%
    short of the takes' range)."""
    low, high = np.percentile(values, RANGE_PERCENTILES, axis=0)
    return high - low


def _without_range(model):
    """The model with no range statistics: the walk as MLPG makes it, the filter off."""
    from dataclasses import replace

    return replace(model, extras={k: v for k, v in (model.extras or {}).items() if not k.startswith("range_")})


def _generated_range(model, weights: np.ndarray) -> np.ndarray:
    """Range of each feature of a walk the model makes at `weights` (the range filter off),
    about its stride mean."""
    from .engine import Engine
    from .stream import Controls

    engine = Engine(_without_range(model))
    controls = Controls(weights)
    frames = np.array([engine.next_features(controls)[0] for _ in range(TRAINING_FRAMES)])[SETTLE:]
    return _spread(frames - stride_means(engine.stream.base, engine.stream.means)[0])


def _real_range(takes, dimension: int) -> np.ndarray | None:
    """Each feature's range in the walking frames (inside steps) of each take about its stride
    mean (the average over the stride around it, as the made walk's is about its stride mean: a
    take's slower changes, turning, speeding up, settling, are not swing the model should make),
    averaged over the takes by their walking frames."""
    from scipy.ndimage import uniform_filter1d  # training only: the live path does not load it

    total, count = np.zeros(dimension), 0
    for take in takes:  # None when no take has a step: nothing to match
        if not take.steps:
            continue
        stride = max(3, int(round(2.0 * np.mean([s.frames for s in take.steps]))))
        static = take.observations[:, :dimension]
        mean = uniform_filter1d(static, stride, axis=0, mode="nearest")
        rows = np.concatenate([np.arange(s.start, s.end) for s in take.steps])
        total += _spread(static[rows] - mean[rows]) * len(rows)
        count += len(rows)
    return total / count if count else None


def _knee_columns(layout, limbs) -> list[int]:
    """The feature columns of both knees' rotations."""
    return [len(ROOT_FEATURES) + 3 * layout.joints.index(leg.knee) + a for leg in limbs.legs if leg.knee in layout.joints
            for a in range(3)]


def _knee_range(motion, limbs, root: int) -> float:
    """The knees' range of a walk in degrees, as `instrument evaluate` measures it."""
    from ..motion.kinematics import forward_kinematics, local_transforms
    from ..motion.quality import limb_ranges

    world_rot, world_pos = forward_kinematics(motion.skeleton, *local_transforms(motion))
    return limb_ranges(world_pos, heading_angle(world_rot[:, root]), limbs, root)["knee_deg"]


def _calibrate_knees(model, takes, log_factors: np.ndarray, weights: np.ndarray, extras_with) -> None:
    """Moves the knees' log factors (in place, CALIBRATION_ROUNDS times) so that the walk the
    instrument plays at `weights`, feet planted, bends its knees through the takes' range (a
    walk it cannot measure leaves them as they are). The foot lock keeps a planted leg's
    generated bend where it can (a heel rises instead), but a swinging foot kept off the floor
    bends its knee more, so the features' range alone left the played knee up to 13% short
    (elderly). The hips are not calibrated: a planted thigh's swing is the lock's geometry, not
    its features (a correction on them did not converge). `extras_with(log_factors)` gives the
    model's extras with these factors in their place."""
    from dataclasses import replace

    from ..motion.bvh import Motion
    from ..motion.features import restore
    from ..motion.limbs import find_limbs
    from .engine import render
    from .stream import Controls

    layout = model.layout
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    chosen = [t for t in takes if t.steps]
    if limbs is None or not chosen:
        return
    knees = _knee_columns(layout, limbs)
    if not knees:  # the knees are not modelled (a skeleton whose legs the layout leaves out)
        return
    real = np.average([_knee_range(restore(t.observations[:, : layout.dimension], layout, model.fps), limbs, layout.root)
                       for t in chosen], weights=[t.frames for t in chosen])
    for _ in range(CALIBRATION_ROUNDS):
        trial = replace(model, extras=extras_with(log_factors))
        frames = int(round(CALIBRATION_SECONDS * model.fps))
        made = render(trial, Controls(weights), SETTLE + frames)
        made = Motion(made.skeleton, made.channels[SETTLE:], made.fps)
        step = np.log(real / _knee_range(made, limbs, layout.root))
        if not np.isfinite(step):  # a walk too short or too still to measure: keep what the features gave
            return
        log_factors[knees] += step
        np.clip(log_factors, -LIMIT, LIMIT, out=log_factors)


def train_range(model, takes) -> dict[str, np.ndarray]:
    """Model-file arrays `range_average` (D,) and `range_styles` (styles, D): the log ratio of
    each feature's range in the data to its range in a walk the model makes, the knees' then
    calibrated on the walk as it is played (`_calibrate_knees`)."""
    dimension = model.layout.dimension
    names = model.style_names

    def log_factor(chosen, weights):
        real = _real_range(chosen, dimension)
        if real is None:  # no walking frames (takes too short for a step): that walk is left as made
            return np.zeros(dimension)
        made = _generated_range(model, weights)
        out = np.log(np.maximum(real, 1e-12) / np.maximum(made, 1e-12))
        out[list(KEPT)] = 0.0
        return np.clip(out, -LIMIT, LIMIT)

    average = log_factor(takes, np.zeros(len(names)))
    styles = np.stack([log_factor([t for t in takes if t.style == name], np.eye(len(names))[s]) for s, name in enumerate(names)])
    def extras_with(_changed: np.ndarray) -> dict:  # the factors are calibrated in place, in these arrays
        return dict(model.extras) | {"range_average": average, "range_styles": styles}

    _calibrate_knees(model, takes, average, np.zeros(len(names)), extras_with)
    for s, name in enumerate(names):
        _calibrate_knees(model, [t for t in takes if t.style == name], styles[s], np.eye(len(names))[s], extras_with)
    return {"range_average": average, "range_styles": styles}
