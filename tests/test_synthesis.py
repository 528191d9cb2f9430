"""MLPG, streaming generation, interpolation and durations on the shipped default model."""

import numpy as np
import pytest

from instrument.synthesis.durations import state_durations, whole_frames
from instrument.synthesis.interpolation import GROUPS, interpolate
from instrument.synthesis.mlpg import mlpg, mlpg_continued
from instrument.synthesis.engine import Engine, default_controls
from instrument.synthesis.stream import DEFAULT_LOOKAHEAD, Controls, Crowd
from walks import features, finer, step, tune

WINDOWS = [(0, 0, np.array([1.0])), (1, 1, np.array([-0.5, 0.0, 0.5])), (1, 1, np.array([1.0, -2.0, 1.0]))]


@pytest.mark.parametrize("frames", [1, 2, 3, 4, 7, 50, 1000])
def test_mlpg_agrees_with_nnmnkwii(frames):
    paramgen = pytest.importorskip("nnmnkwii.paramgen", reason="nnmnkwii (the test oracle) is not installed")
    rng = np.random.default_rng(frames)
    means = rng.normal(size=(frames, 3 * 9))
    variances = rng.uniform(0.01, 3.0, size=(frames, 3 * 9))
    np.testing.assert_allclose(mlpg(means, variances), paramgen.mlpg(means, variances, WINDOWS), atol=1e-8, rtol=0)


def test_continuing_from_fixed_frames_of_the_exact_solution_changes_nothing():
    rng = np.random.default_rng(1)
    means, variances = rng.normal(size=(60, 12)), rng.uniform(0.1, 2.0, size=(60, 12))
    full = mlpg(means, variances)
    for count in (1, 2):
        rest = mlpg_continued(means[None], 1 / variances[None], full[None, :count])[0]
        np.testing.assert_allclose(rest, full[count:], atol=1e-10)


def test_interpolation_identities(model, space):
    styles = len(model.style_names)
    zero = interpolate(space, np.zeros(styles))
    np.testing.assert_allclose(zero.means, model.average.means.reshape(zero.means.shape), atol=1e-12)
    np.testing.assert_allclose(1 / zero.precisions, model.average.variances.reshape(zero.means.shape), rtol=1e-10)
    np.testing.assert_allclose(zero.duration_means, model.average.duration_means, atol=1e-12)
    for k, name in enumerate(model.style_names):
        one = interpolate(space, np.eye(styles)[k])
        style = model.style(name)
        np.testing.assert_allclose(one.means, style.means.reshape(one.means.shape), atol=1e-10)
        np.testing.assert_allclose(1 / one.precisions, style.variances.reshape(one.means.shape), rtol=1e-10)
        np.testing.assert_allclose(one.duration_means, style.duration_means, atol=1e-10)
        np.testing.assert_allclose(one.duration_variances, style.duration_variances, rtol=1e-10)


def test_half_weight_lies_between_and_inversion_mirrors(model, space):
    k = model.style_names.index("elderly")
    w = np.zeros(len(model.style_names))
    base, full = interpolate(space, w).means, interpolate(space, np.eye(len(w))[k]).means
    half = interpolate(space, 0.5 * np.eye(len(w))[k]).means
    inverse = interpolate(space, -1.0 * np.eye(len(w))[k]).means
    np.testing.assert_allclose(half, (base + full) / 2, atol=1e-12)
    np.testing.assert_allclose(inverse - base, base - full, atol=1e-12)


def test_extrapolated_variances_stay_within_the_models_span_and_blends_move_freely(model, space):
    """Past the styles (x2, -1) each variance stays between the least and the largest of lambda
    0's and the styles' for its state and dimension (its log-linear extrapolation has nothing in
    the data behind it: an inverted run's root speed sd reached 4 m/s), while a blend inside the
    styles is the log-linear mix, untouched."""
    styles = len(model.style_names)
    own = np.log(np.concatenate([model.average.variances[None], model.styles.variances]))  # (1 + styles, labels, states, 3D)
    low, high = own.min(axis=0).reshape(-1, own.shape[-1]), own.max(axis=0).reshape(-1, own.shape[-1])
    for weights in (-1.0 * np.eye(styles)[model.style_names.index("normal")], 2.0 * np.eye(styles)[0],
                    np.full(styles, -3.0)):
        logs = -np.log(interpolate(space, weights).precisions)
        assert (logs >= low - 1e-9).all() and (logs <= high + 1e-9).all()
    unbounded = np.log(model.average.variances) - 1.0 * (np.log(model.style("normal").variances) - np.log(model.average.variances))
    assert (unbounded.reshape(low.shape) > high + 1.0).any()  # the bound does bind at -1
    a, b = model.style_names.index("elderly"), model.style_names.index("active")
    blend = -np.log(interpolate(space, 0.5 * (np.eye(styles)[a] + np.eye(styles)[b])).precisions)
    mixed = 0.5 * (np.log(model.style("elderly").variances) + np.log(model.style("active").variances))
    np.testing.assert_allclose(blend, mixed.reshape(blend.shape), atol=1e-9)


@pytest.mark.parametrize("weight", [-10.0, -3.0, 5.0, 25.0])
def test_variances_stay_positive_for_extreme_weights(model, space, weight):
    weights = np.full(len(model.style_names), weight)
    lam = interpolate(space, weights)
    assert np.isfinite(lam.precisions).all() and (lam.precisions > 0).all()
    assert (lam.duration_variances > 0).all()
    walker = Crowd(space)
    frames = np.vstack([step(walker, [Controls(weights)]) for _ in range(40)])
    assert np.isfinite(frames).all()


def test_body_part_weights(model, space):
    names = model.style_names
    masks = space.group_masks
    assert GROUPS == ("root", "legs", "upper")
    legs_joints = {model.layout.names[i].split(".")[0] for i in np.flatnonzero(masks[1, : model.layout.dimension])}
    assert legs_joints == {"UpperLeg_L", "LowerLeg_L", "Foot_L", "Toes_L", "UpperLeg_R", "LowerLeg_R", "Foot_R", "Toes_R"}
    parts = np.full((len(names), len(GROUPS)), np.nan)
    parts[names.index("youthful")] = [0.0, 1.0, 0.0]  # youthful legs only
    parts[names.index("elderly")] = [0.0, 0.0, 1.0]  # elderly upper body only
    mixed = interpolate(space, np.zeros(len(names)), parts)
    youthful = interpolate(space, np.eye(len(names))[names.index("youthful")])
    elderly = interpolate(space, np.eye(len(names))[names.index("elderly")])
    average = interpolate(space, np.zeros(len(names)))
    np.testing.assert_allclose(mixed.means[:, masks[1]], youthful.means[:, masks[1]], atol=1e-12)
    np.testing.assert_allclose(mixed.means[:, masks[2]], elderly.means[:, masks[2]], atol=1e-12)
    np.testing.assert_allclose(mixed.means[:, masks[0]], average.means[:, masks[0]], atol=1e-12)


def test_speed_and_phase_stretch():
    means, variances = np.array([3.0, 2.0, 4.0, 3.0, 3.0]), np.array([1.0, 0.5, 2.0, 1.0, 0.5])
    natural = state_durations(means, variances)
    np.testing.assert_allclose(natural, means)
    faster = state_durations(means, variances, speed=1.5)
    assert faster.sum() == pytest.approx(means.sum() / 1.5)
    assert np.argmax(means - faster) == 2  # the most variable state gives most
    assert state_durations(means, variances, speed=100.0).sum() >= state_durations(means, variances, speed=4.0).sum() - 1e-9
    assert (state_durations(means, variances, speed=4.0) >= 1.0).all()
    stretched = state_durations(means, variances, state_scale=np.array([1, 1, 3.0, 1, 1]))
    np.testing.assert_allclose(stretched, means * [1, 1, 3, 1, 1])


def test_fractional_durations_never_drift():
    carry, total = 0.0, 0
    for k in range(10_000):
        frames, carry = whole_frames(2.3 + 0.01 * (k % 7), carry)
        assert frames >= 1
        total += frames
    exact = sum(2.3 + 0.01 * (k % 7) for k in range(10_000))
    assert abs(total - exact) <= 1.0


@pytest.mark.parametrize("speed", [0.5, 1.0, 2.0])
def test_the_state_plan_follows_the_real_valued_durations(model, space, speed):
    engine = Engine(model)
    engine.retune(default_controls(model, speed=speed))
    plan = engine.stream.state_plan(6000)
    states_entered = np.count_nonzero(np.diff(plan) != 0) + 1
    mean_duration = np.mean(engine.stream.base[0, :2])  # the walk's real-valued frames per state after speed control
    assert 6000 / states_entered == pytest.approx(mean_duration, rel=0.01)
    if speed == 0.5:  # no state is near the one-frame floor: the step takes exactly twice as long
        natural = Engine(model)
        natural.retune(default_controls(model))
        assert np.sum(engine.stream.base[0, :2]) == pytest.approx(2 * np.sum(natural.stream.base[0, :2]))


@pytest.mark.parametrize("style", ["elderly", "youthful", None])
def test_streaming_matches_full_mlpg_within_one_percent(model, space, style):
    controls = default_controls(model, {style: 1.0} if style else {})
    frames = 600
    streamed = features(model, controls, frames, "stream", DEFAULT_LOOKAHEAD, widen=False)[0]
    # the stream never ends, so the full solve runs on past the compared frames (no end effect)
    full = features(model, controls, frames + 150, "full", widen=False)[0][:frames]
    rms = np.sqrt(((streamed - full) ** 2).mean(axis=0))
    assert (rms <= 0.01 * model.static_std).all(), model.layout.names[int(np.argmax(rms / model.static_std))]


def test_the_lookahead_is_a_time_at_any_rate(model):
    """The shipped model and its twin at 120 fps (every state four times as many frames: the same
    walk in seconds) look as far ahead in seconds by default, and the twin's streamed walk stays as
    close to the whole walk's MLPG as the shipped model's. Counted in frames (32), the twin looked
    0.27 s ahead and its worst feature strayed 1.3% of its spread, against 0.75% at 30 fps."""
    errors, ahead = [], []
    for m in (model, finer(model, 4)):
        controls = default_controls(m, {"elderly": 1.0})
        frames = int(10 * m.fps)
        full = features(m, controls, frames + int(5 * m.fps), "full", widen=False)[0][:frames]
        streamed = features(m, controls, frames, widen=False)[0]  # at the engine's default look-ahead
        errors.append(np.max(np.sqrt(((streamed - full) ** 2).mean(0)) / m.static_std))
        ahead.append(Engine(m).stream.lookahead / m.fps)
    assert ahead[1] == ahead[0] == DEFAULT_LOOKAHEAD / model.fps
    assert errors[1] <= errors[0]


def test_short_lookahead_is_measurably_worse(model, space):
    controls = default_controls(model, {"elderly": 1.0})
    full = features(model, controls, 450, "full", widen=False)[0][:300]
    errors = [np.max(np.sqrt(((features(model, controls, 300, "stream", a, widen=False)[0] - full) ** 2).mean(0))
                     / model.static_std) for a in (4, 16, 64)]
    assert errors[0] > errors[1] > errors[2]


@pytest.mark.parametrize("target", [2.0, -1.0])
def test_abrupt_weight_change_stays_within_recorded_pace(model, space, target):
    names = model.style_names
    for name in names:
        walker = Crowd(space)
        frames = []
        for n in range(150):
            weights = np.zeros(len(names))
            if n >= 80:
                weights[names.index(name)] = target
            frames.append(step(walker, [Controls(weights)])[0])
        change = np.abs(np.diff(np.array(frames), axis=0))
        assert (change <= model.static_step_max * (1 + 1e-9)).all(), name


def test_without_the_rate_limit_an_abrupt_change_can_exceed_the_recorded_pace(model, space):
    names = model.style_names
    worst = 0.0
    for name in ("active", "youthful"):
        walker = Crowd(space, max_step_ratio=0.0)
        frames = [step(walker, [Controls(2.0 * (np.arange(len(names)) == names.index(name)) * (n >= 80))])[0]
                  for n in range(100)]
        worst = max(worst, (np.abs(np.diff(np.array(frames), axis=0)) / model.static_step_max).max())
    assert worst > 1.0  # so the limit in the test above is doing real work


def test_a_control_change_shows_in_the_very_next_frame(model, space):
    names = model.style_names
    steady, changed = Crowd(space), Crowd(space)
    calm = Controls(np.zeros(len(names)))
    for _ in range(45):
        a = step(steady, [calm])
        b = step(changed, [calm])
        np.testing.assert_array_equal(a, b)
    bold = Controls(np.eye(len(names))[names.index("feminine")] * 2.0)
    assert np.abs(step(changed, [bold]) - step(steady, [calm])).max() > 1e-3


def test_liveliness_is_deterministic_per_seed(model, space):
    controls = default_controls(model, {"normal": 1.0}, liveliness=1.0)
    a = features(model, controls, 200, seed=5, widen=False)[0]
    b = features(model, controls, 200, seed=5, widen=False)[0]
    c = features(model, controls, 200, seed=6, widen=False)[0]
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > 1e-3
    plain = features(model, default_controls(model, {"normal": 1.0}), 200, seed=5, widen=False)[0]
    assert np.abs(a - plain).max() > 1e-3


def _performance(names, states, frame):
    """Controls that move every way a performer can: weights in and out of the data, per-part
    weights, speed, phase stretch and liveliness switched on and off mid-walk."""
    weights = np.zeros(len(names))
    weights[frame // 40 % len(names)] = (-1.0, 0.5, 1.0, 2.0)[frame // 25 % 4]
    parts = None
    if 100 <= frame < 160:
        parts = np.full((len(names), len(GROUPS)), np.nan)
        parts[0] = [0.0, 1.5, -0.5]
    scale = np.ones(states)
    scale[frame // 30 % states] = 1.0 + (frame % 90) / 30.0
    return Controls(weights, parts, speed=0.5 + (frame // 50 % 5) * 0.6, state_scale=scale,
                    liveliness=(0.0, 1.0, 0.4)[frame // 70 % 3])


def test_the_compiled_path_makes_the_frames_the_python_path_made(model, space):
    """The per-frame path compiled as one kernel gives the frames (and state plans) of the plain
    Python implementation it replaced (tests/reference_stream.py), for one character and a crowd
    with different seeds, rate limits and controls."""
    import reference_stream as reference

    names, d = model.style_names, model.layout.dimension
    ratios = [1.0, 0.0, 0.5]
    crowd = Crowd(space, 3, seeds=[3, 11, 0], max_step_ratio=np.array(ratios))
    walkers = [reference.Walker(d, seed=s, max_step_ratio=r) for s, r in zip([3, 11, 0], ratios)]
    for frame in range(400):
        controls = [_performance(names, space.states, frame + 17 * n) for n in range(3)]
        new = step(crowd, controls)
        old = reference.step(space, walkers, controls)
        np.testing.assert_allclose(new, old, atol=1e-12, rtol=0, err_msg=f"frame {frame}")
        np.testing.assert_allclose(crowd.cadence, [w.cadence for w in walkers], rtol=1e-15)
    lively = default_controls(model, {"elderly": 1.0}, liveliness=1.0, speed=1.7)
    planner = Crowd(space, seeds=[9])
    tune(planner, [lively])
    np.testing.assert_array_equal(planner.state_plan(3000),
                                  reference.state_plan(space, reference.Walker(d, seed=9), lively, 3000))
