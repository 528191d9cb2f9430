"""Full range: the range-scaling post-filter, on the shipped model (which holds range statistics)."""

import numpy as np
import pytest

from instrument.synthesis.posing import PoseStream
from instrument.synthesis.engine import Engine, default_controls
from instrument.synthesis.stream import Controls, Crowd
from instrument.synthesis.widen import KEPT, RangeFilter, ease_per_frame, range_space, stride_means, without_range
from instrument.training.widen import TRAINING_SECONDS, _generated_range, _made_walk, _spread, settle_frames
from walks import features, finer, step


def _widened(model, space, weights_per_frame):
    """The engine's frames (range stage on) at these weights, one set a frame, and the engine."""
    engine = Engine(model)
    out = [engine.next_features(Controls(np.asarray(weights, dtype=float)))[0] for weights in weights_per_frame]
    return np.array(out), engine


def test_a_widened_walk_has_the_range_training_learnt_from_the_data(model, space):
    names = model.style_names
    rng = range_space(model)
    for style in ("masculine", "normal", "elderly"):
        weights = np.eye(len(names))[names.index(style)]
        factor = rng.factors(weights)[0]
        made = _generated_range(model, weights)  # as training measured it
        frames, engine = _widened(model, space, [weights] * int(round(TRAINING_SECONDS * model.fps)))
        widened = _spread(frames[settle_frames(model.fps):] - stride_means(engine.stream.base, engine.stream.means)[0])
        moving = made > 1e-3 * made.max()  # features that swing (a few are nearly still)
        np.testing.assert_allclose(widened[moving], (made * factor)[moving], rtol=0.02)
        assert np.abs(np.log(factor[moving])).max() > 0.05  # the filter did something
        np.testing.assert_array_equal(factor[list(KEPT)], 1.0)


@pytest.mark.parametrize("style, weight", [("feminine", 2.0), ("masculine", -1.0), ("elderly", 1.0), ("active", 1.0)])
def test_a_style_change_shows_in_the_next_frame_without_a_jump(model, space, style, weight):
    names = model.style_names
    calm = np.zeros(len(names))
    bold = np.eye(len(names))[names.index(style)] * weight
    steady, _ = _widened(model, space, [calm] * 90)
    changed, _ = _widened(model, space, [calm] * 60 + [bold] * 30)
    np.testing.assert_array_equal(steady[:60], changed[:60])
    assert np.abs(steady[60] - changed[60]).max() > 1e-3
    # joints move across the change no further in a frame than the unwidened walk's do across it
    # (plus 20%; measured 0.98-1.14x over every style at 1, 2 and -1)
    walker = Crowd(space)
    raw = [step(walker, [Controls(w)])[0] for w in [calm] * 60 + [bold] * 30]

    def largest_move(frames):
        poses = PoseStream(model.layout, model.fps)
        positions = np.array([poses.next(f).world_positions for f in frames])
        return np.linalg.norm(np.diff(positions[55:75], axis=0), axis=2).max()

    assert largest_move(changed) < 1.2 * largest_move(raw)


def test_a_model_without_range_statistics_walks_as_before(model, space):
    bare = without_range(model)
    assert range_space(bare) is None and Engine(bare).range_filter is None
    assert range_space(model) is not None  # the model handed in keeps its statistics
    controls = default_controls(model, {"normal": 1.0})
    plain, _ = features(bare, controls, 60)
    walker = Crowd(space)
    np.testing.assert_array_equal(plain[:, 4:], np.array([step(walker, [controls])[0] for _ in range(60)])[:, 4:])
    widened, _ = features(model, controls, 60)
    assert np.abs(widened - plain).max() > 1e-3
    np.testing.assert_array_equal(widened[:, list(KEPT)], plain[:, list(KEPT)])  # path and speed as made


def test_blends_are_widened_and_extrapolations_walk_as_made(model):
    rng = range_space(model)
    names = model.style_names
    one = np.eye(len(names))
    pair = 0.5 * (one[0] + one[1])
    factors = lambda *args: rng.factors(*args)[0]  # noqa: E731 (one character)
    np.testing.assert_allclose(np.log(factors(pair)), 0.5 * np.log(factors(one[0]) * factors(one[1])))
    for outside in (2.0 * one[0], -one[0], one[0] + one[1]):
        np.testing.assert_array_equal(factors(outside), 1.0)
    halfway = np.log(factors(-0.5 * one[0]))  # fading out, continuously
    np.testing.assert_allclose(halfway, 0.5 * np.log(factors(np.zeros(len(names)))))
    parts = np.full((len(names), 3), np.nan)
    parts[0, 1] = 2.0  # the legs of style 0 doubled: legs as made, the rest widened as at weight 1
    legs = rng.group_masks[1] > 0
    legged = factors(one[0], parts)
    np.testing.assert_array_equal(legged[legs], 1.0)
    np.testing.assert_allclose(legged[~legs], factors(one[0])[~legs])


def test_the_range_training_measures_as_long_a_walk_at_any_rate(model):
    """The walk whose range training measures, made by the shipped model and by its twin at 120
    fps (every state four times as many frames: the same walk in seconds), lasts as long and
    holds as many steps, counted from as long after its start. Counted in frames (600, the
    first 60 left out) the 120 fps walk was 4.5 s from 0.5 s on, a quarter of the strides."""
    fine = finer(model, 4)
    weights = np.eye(len(model.style_names))[model.style_names.index("normal")]
    measured = []
    for m in (model, fine):
        frames, ids, _ = _made_walk(m, weights)
        steps = np.count_nonzero(np.diff(ids // m.states) != 0)
        measured.append((len(frames) / m.fps, settle_frames(m.fps) / m.fps, steps))
    assert measured[1] == measured[0]
    assert measured[0][2] > 20  # some ten strides or more: the range's 1st-99th percentile over many


def _range_filter_in_numpy(frames, means, factors, fps=30.0):
    """The range stage restated in numpy's elementwise form (what it was before it was compiled):
    mean and factor eased `ease_per_frame` of the way a frame (a quarter at 30 fps), the swing
    about the mean scaled, the kept features as made."""
    ease = ease_per_frame(fps)
    mean, factor, out = None, None, []
    for frame, target_mean, target_factor in zip(frames, means, factors):
        if mean is None:
            mean, factor = target_mean, target_factor
        else:
            mean = mean + (target_mean - mean) * ease
            factor = factor + (target_factor - factor) * ease
        made = mean + factor * (frame - mean)
        made[:, list(KEPT)] = frame[:, list(KEPT)]
        out.append(made)
    return out


@pytest.mark.parametrize("characters,fps", [(1, 30.0), (5, 30.0), (2, 120.0)])
def test_the_compiled_range_filter_makes_numpys_numbers_to_the_bit(characters, fps):
    rng = np.random.default_rng(characters)
    dimension, frames = 66, 40
    made = rng.normal(0.0, 3.0, (frames, characters, dimension))
    # the targets stay a while, then jump (a style change), as the engine's do
    means = np.repeat(rng.normal(0.0, 1.0, (4, characters, dimension)), frames // 4, axis=0)
    factors = np.repeat(np.exp(rng.normal(0.0, 0.3, (4, characters, dimension))), frames // 4, axis=0)
    scale = RangeFilter(fps)
    compiled = [scale(frame, mean, factor) for frame, mean, factor in zip(made, means, factors)]
    for ours, theirs in zip(compiled, _range_filter_in_numpy(made, means, factors, fps)):
        np.testing.assert_array_equal(ours, theirs)
    np.testing.assert_array_equal(means[-1], means[-2])  # the targets as they were handed over (not eased in place)


def test_a_style_change_eases_in_over_the_same_time_at_any_rate():
    """A stride mean's target moving by 1 reaches as far in 0.1 s (and in 0.4 s) at 120 fps as at
    30: a quarter of the way a frame at 30 fps (within 1/e in 0.12 s). Counted in frames, at 120
    fps it had all but arrived (99%) by 0.1 s where at 30 it was 58% of the way."""
    reached = {}
    for fps in (30.0, 120.0):
        scale, frames = RangeFilter(fps), int(round(0.4 * fps))
        half = np.full((1, 66), 0.5)  # out = mean + 0.5 (0 - mean): the eased mean, halved
        scale(np.zeros((1, 66)), np.zeros((1, 66)), half)
        out = [scale(np.zeros((1, 66)), np.ones((1, 66)), half)[0, 0] for _ in range(frames)]
        reached[fps] = 2.0 * np.array([out[int(round(t * fps)) - 1] for t in (0.1, 0.4)])
    np.testing.assert_allclose(reached[120.0], reached[30.0], rtol=1e-9)
    np.testing.assert_allclose(reached[30.0], 1.0 - 0.75 ** np.array([3, 12]))


def test_the_range_filter_refuses_frames_of_another_crowd():
    scale = RangeFilter()
    scale(np.zeros((2, 66)), np.zeros((2, 66)), np.ones((2, 66)))
    with pytest.raises(ValueError, match="RangeFilter"):
        scale(np.zeros((3, 66)), np.zeros((3, 66)), np.ones((3, 66)))
