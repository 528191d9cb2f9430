"""Style recognition: a linear discriminant on per-step features, trained on real takes.

A step is described by the mean and spread of every static feature over it and its length, so
the classifier works for any skeleton the features describe. A walk is labelled by the summed
scores of its steps; single steps are labelled on their own.
"""

from __future__ import annotations

import numpy as np


SPEEDS, YAW_RATE = [1, 2], 3  # root.vx, root.vz and root.yaw_rate among the static features


def step_features(static: np.ndarray, steps) -> np.ndarray:
    """(steps, 2D + 1): mean and standard deviation of each static feature over each step, and
    its frames. Where the walk is heading is no part of its style (takes of one style may all
    curve one way): the mean speeds become the mean horizontal speed and the mean yaw rate is
    left out, so a walk and its mirror image look alike."""
    rows = []
    for s in steps:
        part = static[s.start : s.end]
        mean = part.mean(axis=0)
        mean[SPEEDS] = np.hypot(part[:, SPEEDS[0]], part[:, SPEEDS[1]]).mean()
        mean[YAW_RATE] = 0.0
        rows.append(np.concatenate([mean, part.std(axis=0), [s.frames]]))
    return np.array(rows).reshape(len(rows), 2 * static.shape[1] + 1)


class LinearDiscriminant:
    """Class means and one shared, shrunk covariance over standardised features."""

    def __init__(self, features: np.ndarray, labels: list[str], shrinkage: float = 0.3):
        self.classes = sorted(set(labels))
        self.center, self.scale = features.mean(axis=0), features.std(axis=0) + 1e-9
        x = (features - self.center) / self.scale
        y = np.array(labels)
        self.means = np.array([x[y == c].mean(axis=0) for c in self.classes])
        within = np.vstack([x[y == c] - m for c, m in zip(self.classes, self.means)])
        covariance = np.cov(within.T)
        covariance = (1 - shrinkage) * covariance + shrinkage * np.eye(len(covariance))
        self.precision = np.linalg.inv(covariance)

    def scores(self, features: np.ndarray) -> np.ndarray:
        x = (features - self.center) / self.scale
        diff = x[:, None, :] - self.means[None]
        return -0.5 * np.einsum("nci,ij,ncj->nc", diff, self.precision, diff)

    def step_labels(self, features: np.ndarray) -> list[str]:
        return [self.classes[k] for k in np.argmax(self.scores(features), axis=1)]

    def take_label(self, features: np.ndarray) -> str:
        return self.classes[int(np.argmax(self.scores(features).sum(axis=0)))]
