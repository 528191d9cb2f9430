"""How long each state of a step lasts: speed control, phase stretching, liveliness, and the
fractional carry that keeps a long performance from drifting."""

from __future__ import annotations

import math

import numpy as np

from .parameters import MAX_SPEED, MIN_SPEED

MIN_FRAMES = 1.0  # a state lasts a frame at least: a count at any rate (the HSMM's), not a time


def state_durations(
    means: np.ndarray,
    variances: np.ndarray,
    speed: float | np.ndarray = 1.0,
    state_scale: np.ndarray | None = None,
    deviation: np.ndarray | None = None,
) -> np.ndarray:
    """Real-valued frames per state, (..., states), from the duration pdfs (..., states).

    Speed follows HTS: for a target total T = sum(mu) / speed, rho = (T - sum(mu)) / sum(var)
    and d = mu + rho * var, so the states that vary most in the data stretch most. `speed` is
    clamped to [0.25, 4]. `state_scale` then stretches single phases of the step, and
    `deviation` (in standard deviations, for liveliness) moves each state off its mean.
    """
    means = np.asarray(means, dtype=np.float64)
    variances = np.asarray(variances, dtype=np.float64)
    if deviation is not None:
        means = means + deviation * np.sqrt(variances)
    means = np.maximum(means, MIN_FRAMES)
    speed = np.clip(speed, MIN_SPEED, MAX_SPEED)  # a number, or an array that broadcasts (a speed a character)
    total = means.sum(axis=-1, keepdims=True)
    rho = (total / speed - total) / variances.sum(axis=-1, keepdims=True)
    durations = means + rho * variances
    if state_scale is not None:
        durations = durations * state_scale
    return np.maximum(durations, MIN_FRAMES)


def whole_frames(duration: float, carry: float) -> tuple[int, float]:
    """Frames for a state of real-valued `duration` given the remainder carried so far, and the
    remainder to carry on. At least one frame; over many states the total never drifts by more
    than a frame from the sum of the real durations."""
    frames = max(1, math.floor(duration + carry))
    return frames, duration + carry - frames
