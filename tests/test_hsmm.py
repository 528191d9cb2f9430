"""The HSMM trainer against sequences sampled from models with known parameters."""

import numpy as np
import pytest

from instrument.models.hsmm import HSMM, Floors, expected_statistics, forward_backward, pad_segments
from instrument.training.average import TrainingReport, train_average

STATES = 4
TRUE_MEANS = np.array([[[0.0, 5.0], [4.0, -3.0], [8.0, 2.0], [-4.0, 0.0]], [[1.0, -5.0], [-3.0, 3.0], [6.0, 6.0], [2.0, -8.0]]])
TRUE_DURATION_MEANS = np.array([[3.0, 6.0, 2.0, 4.0], [5.0, 2.0, 4.0, 3.0]])
TRUE_DURATION_STD = 0.8
NOISE_STD = 0.7


def sample(label: int, count: int, rng: np.random.Generator) -> list[np.ndarray]:
    segments = []
    for _ in range(count):
        parts = []
        for n in range(STATES):
            d = max(1, int(round(rng.normal(TRUE_DURATION_MEANS[label, n], TRUE_DURATION_STD))))
            parts.append(TRUE_MEANS[label, n] + NOISE_STD * rng.standard_normal((d, 2)))
        segments.append(np.vstack(parts))
    return segments


@pytest.fixture(scope="module")
def trained():
    rng = np.random.default_rng(11)
    segments = [sample(0, 300, rng), sample(1, 300, rng)]
    report = TrainingReport()
    model = train_average(segments, STATES, Floors(np.full(2, 1e-3)), iterations=40, tolerance=1e-6, report=report)
    return model, report, segments


def test_recovers_means_and_mean_durations(trained):
    model, _, _ = trained
    np.testing.assert_allclose(model.means, TRUE_MEANS, atol=0.1)
    np.testing.assert_allclose(model.duration_means, TRUE_DURATION_MEANS, atol=0.15)
    np.testing.assert_allclose(np.sqrt(model.variances), NOISE_STD, atol=0.1)


def test_likelihood_never_decreases(trained):
    _, report, _ = trained
    history = np.array(report.loglik_per_frame)
    assert len(history) >= 3
    assert np.all(np.diff(history) >= -1e-9 * np.abs(history[1:]))
    assert history[-1] > history[0]


def test_forward_backward_matches_brute_force_enumeration():
    rng = np.random.default_rng(3)
    model = HSMM(rng.normal(size=(1, 3, 2)), rng.uniform(0.5, 2, (1, 3, 2)), np.array([[2.0, 1.5, 3.0]]), np.array([[1.0, 0.7, 2.0]]))
    segment = rng.normal(size=(7, 2))
    from itertools import combinations

    from instrument.models.hsmm import duration_logpdf, gaussian_loglik

    emission = gaussian_loglik(segment, model.means[0], model.variances[0])
    durations = duration_logpdf(model.duration_means[0], model.duration_variances[0], 7)
    total = []
    occupancy = np.zeros((7, 3))
    for cuts in combinations(range(1, 7), 2):  # every way to split 7 frames into 3 non-empty parts
        bounds = (0,) + cuts + (7,)
        score = sum(emission[bounds[n] : bounds[n + 1], n].sum() + durations[n, bounds[n + 1] - bounds[n]] for n in range(3))
        total.append(score)
        for n in range(3):
            occupancy[bounds[n] : bounds[n + 1], n] += np.exp(score)
    expected = np.logaddexp.reduce(total)
    obs, lengths = pad_segments([segment])
    loglik, occ, _ = forward_backward(obs, lengths, model.means[0], model.variances[0], model.duration_means[0], model.duration_variances[0])
    assert loglik[0] == pytest.approx(expected, abs=1e-9)
    np.testing.assert_allclose(occ[0], occupancy / np.exp(expected), atol=1e-9)


def test_padded_batches_score_like_single_segments(trained):
    model, _, segments = trained
    some = segments[0][:5]
    together = expected_statistics(model, 0, some)
    apart = sum(expected_statistics(model, 0, [s]).loglik for s in some)
    assert together.loglik == pytest.approx(apart, rel=1e-12)
    assert together.frames == sum(len(s) for s in some)
