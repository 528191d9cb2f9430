"""Straight when told: at turn = 0 a walk keeps its heading, even when trained on takes whose
right and left steps turn unequally; and the drift figure of `instrument evaluate` measures it.

The training case curves real walks from the shared takes (their right steps turn 6 deg/s
more than their left ones), trains on them as `instrument train` does, and walks the model
with steps a fractional number of frames long (x.5: the case where the odd frame alternates)."""

from __future__ import annotations

import dataclasses
import numpy as np
import pytest

from instrument.training.build import build_model
from instrument.models.modelfile import default_model_path, load_model
from instrument.motion.bvh import Motion, read_bvh, write_bvh
from instrument.motion.features import choose_layout, extract, heading_angle, restore
from instrument.motion.kinematics import forward_kinematics, local_transforms
from instrument.motion.quality import heading_drift
from instrument.motion.steps import segment_steps
from instrument.synthesis.durations import state_durations
from instrument.synthesis.interpolation import interpolate, style_space
from instrument.synthesis.engine import default_controls, render
import walks
from instrument.synthesis.stream import Crowd

RIGHT_STEP_TURN = np.radians(6.0)  # rad/s added to the yaw rate of every right step of the takes


def _drift(motion: Motion, root: int, layout=None) -> float:
    """The drift figure, the heading and the steps read as `layout` reads them (default: the
    motion's own layout's steps, the heading from the root's own axes)."""
    reference = None if layout is None else layout.heading_reference
    yaw = heading_angle(forward_kinematics(motion.skeleton, *local_transforms(motion))[0][:, root], reference)
    return heading_drift(yaw, segment_steps(motion, layout).steps, motion.fps)


def _curved(motion: Motion, layout) -> Motion:
    """The take with every right step turning RIGHT_STEP_TURN faster (left steps as they were)."""
    features, start, heading = extract(motion, layout)
    for step in segment_steps(motion, layout).steps:
        if step.label == "right":
            features[step.start : step.end, 3] += RIGHT_STEP_TURN
    return restore(features, layout, motion.fps, start, heading)


@pytest.fixture(scope="module")
def curved_model(real_walks, tmp_path_factory):
    """A model of one style trained on three real takes made asymmetric, and those takes."""
    folder = tmp_path_factory.mktemp("curved")
    chosen = [p for p in real_walks if "_normal_" in p.name][:3]
    motions = [read_bvh(p) for p in chosen]
    layout = choose_layout(motions)
    pairs = []
    for path, motion in zip(chosen, motions):
        out = folder / path.name
        write_bvh(out, _curved(motion, layout))
        pairs.append((out, "normal"))
    model, _, _ = build_model(pairs)
    return model, [read_bvh(p) for p, _ in pairs]


def test_the_curved_takes_do_curve(curved_model):
    """The training data is what the test says: its heading turns by about half the extra rate
    of the right steps (which are half the walk), where the takes as recorded barely turn."""
    model, takes = curved_model
    root = model.layout.root
    assert min(_drift(m, root) for m in takes) > 0.3 * np.degrees(RIGHT_STEP_TURN)


def test_a_model_of_asymmetric_steps_walks_straight_at_turn_0(curved_model):
    model, _ = curved_model
    space = style_space(model)
    right, left = model.style("normal").means  # labels
    np.testing.assert_allclose(right[:, 3], -left[:, 3], atol=1e-12)  # mirror-image yaw rates
    lam = interpolate(space, np.array([1.0]))
    step = state_durations(lam.duration_means, lam.duration_variances)[0].sum()
    for frames_per_step in (np.floor(step) + 0.5, np.floor(step) + 1.0, np.floor(step) + 1.3):
        controls = default_controls(model, {"normal": 1.0}, speed=step / frames_per_step)
        static, ids = walks.features(model, controls, 600, widen=False)
        label = ids // model.states
        starts = np.flatnonzero(np.diff(label) == -1) + 1  # each stride from a right step's first frame
        yaw = np.degrees(np.concatenate([[0.0], np.cumsum(static[:, 3]) / model.fps]))
        per_stride = np.diff(yaw[starts])
        assert len(per_stride) >= 15
        # one carry across labels turned this walk 0.17 degrees every stride at x.5 frames a step
        assert abs(per_stride[2:].mean()) < 0.02, (frames_per_step, per_stride)
        assert np.abs(per_stride[2:]).max() < 0.1, (frames_per_step, per_stride)


def test_the_walk_with_its_feet_planted_keeps_its_heading(curved_model):
    """The whole pose path (widen, foot lock, root integration) as `instrument evaluate` sees it."""
    model, _ = curved_model
    motion = render(model, default_controls(model, {"normal": 1.0}), 15 + 360)
    motion = Motion(motion.skeleton, motion.channels[15:], motion.fps)
    assert _drift(motion, model.layout.root) < 0.1  # deg/s (one carry across labels: 0.25)


def test_the_drift_figure_follows_a_known_turn_and_not_where_the_walk_starts(real_walks):
    """A real take turned at a known rate measures that rate (up to the take's own), and moving
    the start of what is measured by a few frames hardly changes the figure."""
    motion = read_bvh([p for p in real_walks if "_masculine_" in p.name][0])
    layout = choose_layout([motion])
    features, start, heading = extract(motion, layout)
    turns = []
    for sign in (1.0, -1.0):
        turned = features.copy()
        turned[:, 3] += sign * np.radians(4.0)
        turns.append(_drift(restore(turned, layout, motion.fps, start, heading), layout.root))
    assert np.mean(turns) == pytest.approx(4.0, abs=0.05)  # |own + 4| and |own - 4| average to 4
    # as `evaluate` reads the shipped model's walks: its layout reads the root's own axes (a layout
    # with a root_reference, issue 30, moves this take's figure by 0.19 deg/s where the first step
    # drops out at k = 6: 0.50 -> 0.31)
    legacy = dataclasses.replace(layout, root_reference=None)
    figures = [_drift(Motion(motion.skeleton, motion.channels[k:], motion.fps), layout.root, legacy) for k in range(0, 30, 3)]
    assert max(figures) - min(figures) < 0.1


@pytest.mark.parametrize("style, speed", [("normal", 1.0), ("active", 1.0), ("youthful", 0.77), ("masculine", 1.9)])
def test_a_left_step_gets_the_frames_of_the_right_step_before_it(style, speed):
    """The plan on the shipped model: state by state, each left step lasts as long as the right
    step before it; every step stays within a frame of its real-valued length, and the whole
    plan within a frame per label of the sum of those lengths."""
    model = load_model(default_model_path())
    space = style_space(model)
    controls = default_controls(model, {style: 1.0}, speed=speed)
    planner = Crowd(space)
    walks.tune(planner, [controls])
    ids = planner.state_plan(3000)
    change = np.flatnonzero(np.diff(ids)) + 1
    bounds = np.concatenate([[0], change])
    counts = np.diff(np.concatenate([bounds, [len(ids)]]))[: (len(bounds) - 1) // 10 * 10]
    assert ids[0] == 0 and ids[bounds[len(counts)] - 1] == 2 * model.states - 1  # whole strides from a right step
    strides = counts.reshape(-1, 2, model.states)  # (stride, label, state) frames
    np.testing.assert_array_equal(strides[:, 0], strides[:, 1])
    lam = interpolate(space, controls.weights)
    planned = state_durations(lam.duration_means, lam.duration_variances, speed)[0]
    assert np.abs(strides[:, 0].sum(axis=1) - planned.sum()).max() < 1.0
    assert abs(strides.sum() - len(strides) * 2 * planned.sum()) <= 2.0


@pytest.mark.parametrize("phase", [(0, 0), (1, 0), (1, 2), (0, 3)])
@pytest.mark.parametrize("liveliness", [0.0, 1.0])
def test_a_walk_begun_anywhere_in_its_stride_pairs_its_steps_and_keeps_its_heading(phase, liveliness):
    """A crowd's walkers begin at their own phase (label, state). The label a walk begins on
    leads; each following step takes its leader's frames, state by state, and with liveliness
    its draws (drawn apart, the steps turned a walk 38 degrees in a minute at turn
    0; begun mid-step, the labels' carries stayed apart and walkers curved up to 19 degrees a
    minute); the strides still vary with liveliness."""
    model = load_model(default_model_path())
    space = style_space(model)
    states = model.states
    controls = default_controls(model, {"active": 1.0}, liveliness=liveliness)
    walker = Crowd(space, seeds=[5])
    walker.start_at(np.array([phase]))
    static, labels = [], []
    for _ in range(1800):  # a minute
        static.append(walks.step(walker, [controls])[0])
        labels.append(walker.history_ids[0, 1])
    ids = np.array(labels)
    bounds = np.concatenate([[0], np.flatnonzero(np.diff(ids)) + 1])
    counts = np.diff(np.concatenate([bounds, [len(ids)]]))
    skip = 2 * states - phase[1] if phase[1] else 0  # a partial step, and the following step it leads
    leader = phase[0]
    whole = (len(counts) - skip - 1) // (2 * states) * 2 * states
    strides = counts[skip : skip + whole].reshape(-1, 2, states)  # (stride, leading / following step, state)
    assert len(strides) > 20 and ids[bounds[skip]] % states == 0
    np.testing.assert_array_equal(strides[:, 0], strides[:, 1])
    if liveliness:
        assert strides[:, 0].sum(axis=1).std() > 0.5  # the strides vary: liveliness is there
    label = ids // states
    starts = np.flatnonzero((label[1:] == leader) & (label[:-1] != leader)) + 1  # each stride's first frame
    yaw = np.degrees(np.concatenate([[0.0], np.cumsum(np.array(static)[:, 3]) / model.fps]))[starts]
    assert np.ptp(yaw[1:]) < 3.0, yaw  # the heading over a minute, stride by stride
