"""Training the average model (lambda 0) by EM on every style at once.

The style models are adapted from it in adaptation.py.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from ..models.hsmm import HSMM, Floors, expected_statistics, map_update, uniform_statistics

VARIANCE_FLOOR_RATIO = 0.01  # of the global variance of each feature, as in HTS


@dataclass
class TrainingReport:
    loglik_per_frame: list[float] = field(default_factory=list)  # one entry per EM iteration
    warnings: list[str] = field(default_factory=list)
    capture_rates: list[float] = field(default_factory=list)  # each file's frame rate as captured (the model's is `fps`)


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
