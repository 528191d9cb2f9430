"""Full range: a causal variance-scaling post-filter (after Silen et al. 2012) on streamed features.

MLPG averages: a walk it makes swings through a smaller range than the takes it learnt from
(the knee 24-38% short for some styles) and, for others, through a larger one. Training
measures, for the average model and for each style, every static feature's variance in the real
walking frames (about each take's mean) and in a walk the model makes (about its stride mean,
below), and stores half the log of their ratio: the factor by which a generated feature's
swing must grow (or shrink) to have the data's variance.

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

from ..motion.features import ROOT_FEATURES
from .stream import Controls, Crowd

STRENGTH = 1.0  # share of the learnt log factor applied (chosen by `instrument evaluate`, docs/evaluate.md)
LIMIT = np.log(2.0)  # no feature's swing is scaled by more than 2x or less than 1/2
EASE_FRAMES = 4
KEPT = tuple(ROOT_FEATURES.index(name) for name in ("root.vx", "root.vz", "root.yaw_rate"))  # never scaled
TRAINING_FRAMES = 600  # frames of each generated walk measured in training (the first SETTLE dropped)
SETTLE = 60


@dataclass(frozen=True)
class RangeSpace:
    """Log variance-scaling factors as lambda 0 plus style offsets, per static feature."""

    base: np.ndarray  # (D,)
    offsets: np.ndarray  # (styles, D)
    group_masks: np.ndarray  # (groups, D) which body part each feature belongs to

    def factors(self, weights: np.ndarray, part_weights: np.ndarray | None = None) -> np.ndarray:
        """(D,) how far each feature's swing about the stride mean is scaled at these weights
        (each feature by the weights of its body part when given per part).

        Inside the styles' blends (weights 0..1 adding to at most 1) the log factors blend like
        the other parameters. Outside, the learnt factors say nothing (an extrapolated walk's
        smoothing was never measured, and extrapolating them widened inverted walks into
        skating: elderly -1 from 23 to 85 cm/s), so the factor fades to 1 with the distance
        from that region: by an inverted weight of 1 or a total of 2 the walk is as made."""
        weights = np.asarray(weights, dtype=np.float64)
        per_dim = np.broadcast_to(weights[:, None], self.offsets.shape)
        if part_weights is not None:
            per_group = np.where(np.isnan(part_weights), weights[:, None], part_weights)
            per_dim = per_group @ self.group_masks
        positive = np.maximum(per_dim, 0.0)
        total = positive.sum(axis=0)
        outside = np.maximum(-per_dim, 0.0).sum(axis=0) + np.maximum(total - 1.0, 0.0)
        inside = positive / np.maximum(total, 1.0)
        blended = self.base + np.einsum("sd,sd->d", inside, self.offsets)
        return np.exp(STRENGTH * np.clip(1.0 - outside, 0.0, 1.0) * np.clip(blended, -LIMIT, LIMIT))


def range_space(model) -> RangeSpace | None:
    """None for a model trained without range statistics (it then runs as before)."""
    from .interpolation import body_groups

    extras = getattr(model, "extras", {}) or {}
    base, styles = extras.get("range_average"), extras.get("range_styles")
    dimension = model.layout.dimension
    if base is None or styles is None or base.shape != (dimension,) or styles.shape != (len(model.style_names), dimension):
        return None
    return RangeSpace(base, styles - base, body_groups(model.layout).astype(np.float64))


def stride_mean(walker: Crowd, n: int = 0) -> np.ndarray:
    """(D,) what character n's walk averages over a stride: its lambda* state means weighted by
    the frames planned for each state."""
    frames = walker.base[n].reshape(-1)
    dimension = walker.means.shape[2] // 3
    return frames @ walker.means[n, :, :dimension] / frames.sum()


class Widen:
    """One character's post-filter, carried from frame to frame (see the module's docstring)."""

    def __init__(self, space: RangeSpace):
        self.space = space
        self.mean: np.ndarray | None = None
        self.factor: np.ndarray | None = None
        self._controls: Controls | None = None
        self._key: tuple | None = None
        self._targets: tuple[np.ndarray, np.ndarray] | None = None
        self._kept = list(KEPT)

    def next(self, frame: np.ndarray, walker: Crowd, controls: Controls, n: int = 0) -> np.ndarray:
        """The frame character n of `walker` just made (after its controls were applied), its swing scaled."""
        if controls is not self._controls:  # the targets change only with the controls (as lambda* does)
            self._controls = controls
            key = controls.key()
            if key != self._key:
                self._key = key
                self._targets = stride_mean(walker, n), self.space.factors(controls.weights, controls.part_weights)
        mean, factor = self._targets
        if self.mean is None:
            self.mean, self.factor = mean, factor
        else:
            self.mean = self.mean + (mean - self.mean) / EASE_FRAMES
            self.factor = self.factor + (factor - self.factor) / EASE_FRAMES
        out = self.mean + self.factor * (frame - self.mean)
        out[self._kept] = frame[self._kept]
        return out


# ---- training -------------------------------------------------------------------------------

def _generated_variance(space, weights: np.ndarray) -> np.ndarray:
    """Variance of each feature of a walk the model makes at `weights`, about its stride mean."""
    walker = Crowd(space)
    controls = Controls(weights)
    frames = np.array([walker.step([controls])[0] for _ in range(TRAINING_FRAMES)])[SETTLE:]
    return np.mean((frames - stride_mean(walker)) ** 2, axis=0)


def _real_variance(takes, dimension: int) -> np.ndarray:
    """Pooled variance of the walking frames (inside steps) about each one's stride mean (the
    average over the stride around it), as the made walk's is about its stride mean: a take's
    slower changes (turning, speeding up, settling) are not swing the model should make."""
    from scipy.ndimage import uniform_filter1d  # training only: the live path does not load it

    squares, count = np.zeros(dimension), 0
    for take in takes:
        if not take.steps:
            continue
        stride = max(3, int(round(2.0 * np.mean([s.frames for s in take.steps]))))
        static = take.observations[:, :dimension]
        mean = uniform_filter1d(static, stride, axis=0, mode="nearest")
        rows = np.concatenate([np.arange(s.start, s.end) for s in take.steps])
        squares += ((static[rows] - mean[rows]) ** 2).sum(axis=0)
        count += len(rows)
    return squares / max(count, 1)


def train_range(model, takes) -> dict[str, np.ndarray]:
    """Model-file arrays `range_average` (D,) and `range_styles` (styles, D): half the log ratio
    of each feature's variance in the data to its variance in a walk the model makes."""
    from .interpolation import style_space

    space = style_space(model)
    dimension = model.layout.dimension
    names = model.style_names

    def log_factor(chosen, weights):
        real = _real_variance(chosen, dimension)
        made = _generated_variance(space, weights)
        out = 0.5 * np.log(np.maximum(real, 1e-12) / np.maximum(made, 1e-12))
        out[list(KEPT)] = 0.0
        return np.clip(out, -LIMIT, LIMIT)

    average = log_factor(takes, np.zeros(len(names)))
    styles = np.stack([log_factor([t for t in takes if t.style == name], np.eye(len(names))[s]) for s, name in enumerate(names)])
    return {"range_average": average, "range_styles": styles}
