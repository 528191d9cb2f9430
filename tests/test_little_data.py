"""Styles from little data (issue 30): a style learnt from one short take keeps its own step
durations and swing, with its data's weight n / (n + tau) against the average's prior
(instrument/training/little.py), and the held-out comparison (examples/little_data.py) refuses
bad settings in one line."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from instrument.models.hsmm import Floors
from instrument.training.adaptation import DEFAULT, adapt
from instrument.training.average import train_average
from instrument.training.little import data_weight, own_durations, pulled_factors
from test_hsmm import STATES, sample

FLOORS = Floors(np.full(2, 1e-3))
SCRIPT = Path(__file__).resolve().parents[1] / "examples" / "little_data.py"


@pytest.fixture(scope="module")
def average():
    rng = np.random.default_rng(11)
    return train_average([sample(0, 200, rng), sample(1, 200, rng)], STATES, FLOORS, iterations=40, tolerance=1e-6)


def slow_take(steps: int, seed: int, hold: int = 6) -> list[list[np.ndarray]]:
    """One short take of a slow style: every step's second state held `hold` frames longer."""
    rng = np.random.default_rng(seed)
    out = []
    for label in range(2):
        out.append([np.vstack([s[:4]] + [s[4:5]] * hold + [s[4:]]) for s in sample(label, steps, rng)])
    return out


def test_the_weight_of_a_styles_own_data_grows_with_it():
    assert data_weight(0, 4.0) == 0.0
    assert data_weight(10, 0.0) == 1.0
    assert data_weight(12, 4.0) == pytest.approx(0.75)
    weights = [data_weight(n, 16.0) for n in (1, 4, 16, 64, 256)]
    assert all(a < b for a, b in zip(weights, weights[1:])) and weights[2] == pytest.approx(0.5)


def test_a_style_from_one_short_take_keeps_its_own_step_duration(average):
    take = slow_take(6, 3)
    own = np.array([np.mean([len(s) for s in label]) for label in take])
    adapted = adapt(average, take, FLOORS, DEFAULT)  # today's: the adaptation alone
    today = np.abs(adapted.duration_means.sum(axis=1) - own)
    assert (today > 1.0).all()  # the average's prior holds a style of 6 steps a label back by over a frame
    kept = own_durations(adapted, take, data_weight(12, 4.0), [0, 1])
    error = np.abs(kept.duration_means.sum(axis=1) - own)
    assert (error < 0.5 * today).all()
    exact = own_durations(adapted, take, 1.0, [0, 1])
    np.testing.assert_allclose(exact.duration_means.sum(axis=1), own)
    # the states keep the adaptation's proportions, the variances scale with the means
    ratio = exact.duration_means / adapted.duration_means
    np.testing.assert_allclose(ratio, ratio[:, :1] * np.ones_like(ratio))
    np.testing.assert_allclose(exact.duration_variances, adapted.duration_variances * ratio**2)
    np.testing.assert_array_equal(exact.means, adapted.means)


def test_no_weight_leaves_the_adaptation_as_it_was(average):
    take = slow_take(6, 5)
    adapted = adapt(average, take, FLOORS, DEFAULT)
    same = own_durations(adapted, take, 0.0, [0, 1])
    np.testing.assert_array_equal(same.duration_means, adapted.duration_means)
    untouched = own_durations(adapted, [take[0], []], 1.0, [0, 1])  # a label without steps keeps its durations
    np.testing.assert_array_equal(untouched.duration_means[1], adapted.duration_means[1])


def test_a_styles_range_factors_are_pulled_toward_the_averages():
    own, average = np.log([2.0, 0.5, 1.0]), np.log([1.2, 1.0, 1.0])
    np.testing.assert_allclose(pulled_factors(own, average, 1.0), own)
    np.testing.assert_allclose(pulled_factors(own, average, 0.0), average)
    np.testing.assert_allclose(pulled_factors(own, average, 0.25), 0.25 * own + 0.75 * average)


@pytest.mark.parametrize("arguments, message", [
    (["--taus", "today,fast"], "--taus: 'fast' is neither 'today' nor a number of steps"),
    (["--taus", "-3"], "--taus: '-3' must be a finite number of steps, 0 or more"),
    (["--taus", "4,,16"], "--taus: expected 'today' or numbers of steps"),
    (["--taus", "nan"], "--taus: 'nan' must be a finite number of steps"),
    (["--take", "0"], "--take must be 1 or more"),
    (["--seconds", "1"], "--seconds must be 2 to 600"),
    (["--take", "99"], "walking takes: --take 99 needs that one and another to hold out"),
    (["--styles", "moonwalk"], "--styles: no walking takes of style 'moonwalk'"),
])
def test_bad_settings_are_one_line_errors(arguments, message):
    data = Path(__file__).parent / "data" / "cmu-131"
    done = subprocess.run([sys.executable, str(SCRIPT), str(data), *arguments], capture_output=True, text=True, timeout=300)
    assert done.returncode == 1
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("little_data.py: error: ") and message in lines[0], done.stderr


def test_a_missing_folder_is_a_one_line_error(tmp_path):
    done = subprocess.run([sys.executable, str(SCRIPT), str(tmp_path / "nowhere")], capture_output=True, text=True, timeout=300)
    assert done.returncode == 1 and done.stderr.strip() == f"little_data.py: error: {tmp_path / 'nowhere'}: no such file or folder"


def test_a_shorter_step_keeps_every_state_above_the_floor(average):
    take = slow_take(6, 7)
    adapted = adapt(average, take, FLOORS, DEFAULT)
    short = [[s[: len(s) // 2 + 2] for s in label] for label in take]  # own steps far shorter than the model's
    floor = np.full_like(adapted.duration_means, 2.0)
    scaled = own_durations(adapted, short, 1.0, [0, 1])
    assert scaled.duration_means.min() < 2.0  # scaling alone takes a state under the floor
    kept = own_durations(adapted, short, 1.0, [0, 1], floor)
    assert kept.duration_means.min() >= 2.0 - 1e-12
    own = np.array([np.mean([len(s) for s in label]) for label in short])
    np.testing.assert_allclose(kept.duration_means.sum(axis=1), own)  # the frames come from the other states
