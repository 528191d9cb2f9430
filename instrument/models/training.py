"""Training: the average model by EM, then one MAP-adapted model per style.

The average model (lambda 0) learns from every style at once. Each style model is then adapted
from lambda 0 using lambda 0's own alignment of that style's steps, so every style shares lambda
0's states: state 3 of "elderly" and state 3 of "youthful" are the same phase of the step, which
is what makes interpolating and extrapolating between them meaningful.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .hsmm import HSMM, Floors, expected_statistics, map_update, uniform_statistics

VARIANCE_FLOOR_RATIO = 0.01  # of the global variance of each feature, as in HTS
MIN_STEPS_PER_LABEL = 10  # fewer steps than this for a style: warn, it stays near lambda 0


@dataclass
class TrainingReport:
    loglik_per_frame: list[float] = field(default_factory=list)  # one entry per EM iteration
    warnings: list[str] = field(default_factory=list)


def variance_floors(segments: list[list[np.ndarray]]) -> Floors:
    frames = np.vstack([s for label in segments for s in label])
    return Floors(np.maximum(VARIANCE_FLOOR_RATIO * frames.var(axis=0), 1e-10))


def _stack(parameters: list[tuple[np.ndarray, ...]]) -> HSMM:
    return HSMM(*(np.stack([p[k] for p in parameters]) for k in range(4)))


def train_average(
    segments: list[list[np.ndarray]],
    states: int,
    floors: Floors,
    iterations: int = 30,
    tolerance: float = 1e-3,
    report: TrainingReport | None = None,
    on_iteration: Callable[[int, float], None] | None = None,
) -> HSMM:
    """EM from a uniform segmentation until the log-likelihood per frame gains less than `tolerance`."""
    report = report or TrainingReport()
    model = _stack([map_update(uniform_statistics(label, states), None, floors) for label in segments])
    previous = -np.inf
    for iteration in range(iterations):
        stats = [expected_statistics(model, k, label) for k, label in enumerate(segments)]
        per_frame = sum(s.loglik for s in stats) / sum(s.frames for s in stats)
        report.loglik_per_frame.append(per_frame)
        if on_iteration:
            on_iteration(iteration + 1, per_frame)
        model = _stack([map_update(s, None, floors) for s in stats])
        if per_frame - previous < tolerance:
            break
        previous = per_frame
    return model


def adapt(
    average: HSMM,
    segments: list[list[np.ndarray]],
    floors: Floors,
    tau: float = 10.0,
    tau_duration: float = 5.0,
) -> HSMM:
    """A style model: MAP estimates from lambda 0's alignment of the style's steps, lambda 0 as prior.

    With no segments at all the result is lambda 0 itself.
    """
    parameters = []
    for k, label in enumerate(segments):
        prior = (average.means[k], average.variances[k], average.duration_means[k], average.duration_variances[k])
        if not label:
            parameters.append(prior)
            continue
        stats = expected_statistics(average, k, label)
        parameters.append(map_update(stats, prior, floors, tau, tau_duration))
    return _stack(parameters)


def adapt_styles(
    average: HSMM,
    segments_per_style: dict[str, list[list[np.ndarray]]],
    floors: Floors,
    report: TrainingReport,
    tau: float = 10.0,
    tau_duration: float = 5.0,
) -> HSMM:
    """All style models stacked on a leading style axis, in the order of `segments_per_style`."""
    models = []
    for style, segments in segments_per_style.items():
        fewest = min(len(label) for label in segments)
        if fewest < MIN_STEPS_PER_LABEL:
            message = f"style {style!r} has only {fewest} steps of one label: it stays close to the average model"
            report.warnings.append(message)  # said once, by whoever reads the report (train prints it unless --quiet)
        models.append(adapt(average, segments, floors, tau, tau_duration))
    return HSMM(*(np.stack([getattr(m, name) for m in models]) for name in ("means", "variances", "duration_means", "duration_variances")))
