"""The body follows its stance foot (synthesis/follow.py): the rule on small arrays, then on the shipped model."""

import numpy as np
import pytest

from instrument.motion.bvh import Motion
from instrument.motion.kinematics import channels_from_local, world_positions
from instrument.motion.limbs import centimetres_per_unit
from instrument.motion.quality import walk_figures
from instrument.synthesis.posing import PoseStream
from instrument.synthesis.contact import contact_space
from instrument.synthesis.footlock import FootLock
from instrument.synthesis.follow import STRENGTH, STRENGTH_OFF_DATA, RootFollow, strength
from instrument.synthesis.interpolation import style_space
from instrument.synthesis.engine import default_controls, render
from walks import features, step


def test_the_body_takes_its_share_of_a_planted_foots_slide_and_characters_stay_apart():
    follow = RootFollow(characters=3)
    pivots = np.zeros((3, 2, 3))
    blend = np.array([[1.0, 0.0], [0.0, 0.0], [1.0, 1.0]])  # left planted / none / both
    strengths = np.array([0.2, 0.2, 0.5])
    np.testing.assert_array_equal(follow.step(pivots, blend, strengths), 0.0)  # the first frame has no slide
    pivots[:, 0] += [3.0, 7.0, 2.0]  # the left foot slides forward 3 units (x), 7 up (y, ignored), 2 sideways (z)
    pivots[:, 1, 0] += 1.0  # the right one 1 unit forward
    offset = follow.step(pivots, blend, strengths)
    np.testing.assert_allclose(offset[0], [-0.2 * 3.0, 0.0, -0.2 * 2.0])  # only the planted foot's horizontal slide
    np.testing.assert_array_equal(offset[1], 0.0)  # no foot planted: the body goes as generated
    np.testing.assert_allclose(offset[2], [-0.5 * (3.0 + 1.0) / 2, 0.0, -0.5 * 2.0 / 2])  # both: their mean
    again = follow.step(pivots, blend, strengths)  # the feet stood still: the offset stays
    np.testing.assert_allclose(again, offset)
    half = RootFollow()
    half.step(np.zeros((1, 2, 3)), np.array([[0.5, 0.0]]), np.array([1.0]))
    moved = half.step(np.full((1, 2, 3), 1.0), np.array([[0.5, 0.0]]), np.array([1.0]))
    assert moved[0, 0] == pytest.approx(-0.5)  # a lock half blended in, eased (smoothstep(0.5) = 0.5)


def test_the_body_takes_more_outside_the_data():
    assert strength(np.zeros(7)) == STRENGTH
    assert strength(np.eye(7)[2]) == STRENGTH
    assert strength(np.array([0.5, 0.5, 0, 0, 0, 0, 0])) == STRENGTH
    assert strength(np.eye(7)[2] * 2.0) == STRENGTH_OFF_DATA
    assert strength(-np.eye(7)[2]) == STRENGTH_OFF_DATA
    assert strength(np.eye(7)[2] * 1.5) == pytest.approx((STRENGTH + STRENGTH_OFF_DATA) / 2)
    assert STRENGTH < STRENGTH_OFF_DATA <= 1.0


def _figures(model, style: str, weight: float, follow: float | None, frames: int = 420) -> dict:
    """walk_figures of a walk with its feet planted, the body taking `follow` of the slide."""
    contact = contact_space(model)
    controls = default_controls(model, {style: weight})
    static, ids = features(model, controls, frames)
    poses = PoseStream(model.layout, model.fps, FootLock(model.layout, contact.clearance, model.fps))
    shares = contact.shares(controls.weights)[0][ids]
    out = [poses.next(row, share, follow) for row, share in zip(static, shares)]
    skeleton = model.layout.skeleton
    channels = channels_from_local(skeleton, np.stack([p.rotations for p in out]), np.stack([p.translations for p in out]))
    motion = Motion(skeleton, channels[30:], model.fps)
    limbs = poses.crowd.lock.limbs
    cm = centimetres_per_unit(model.layout, world_positions(Motion(skeleton, np.asarray(model.layout.template)[None], model.fps))[0])
    return walk_figures(motion, model.layout, limbs, contact.clearance, cm)


def test_inside_the_data_the_body_keeps_its_pace_and_the_heel_takes_the_slide(model):
    """Active, whose generated legs sweep least of the ground the body travels (the body taking
    half the slide makes it 2.8% slower; feminine's was least before training calibrated the
    hips on the played walk, and is now 0.3%): inside the data the body takes none of the
    planted foot's slide (it would slow the walk: the foot lock's heel rise takes it,
    tests/test_quality.py checks the ranges that leaves)."""
    assert STRENGTH == 0.0
    held = _figures(model, "active", 1.0, 0.0)
    followed = _figures(model, "active", 1.0, None)  # the default, STRENGTH
    np.testing.assert_equal(followed, held)
    taking = _figures(model, "active", 1.0, 0.5)
    assert taking["speed_cm_s"] < held["speed_cm_s"] * 0.99  # what the body takes it no longer travels


def test_an_exaggerated_walk_keeps_its_feet_planted(model):
    """Feminine x2 skated at 29 cm/s with the lock alone (25 with a fifth of the slide followed)."""
    figures = _figures(model, "feminine", 2.0, strength(np.eye(len(model.style_names))[model.style_names.index("feminine")] * 2))
    assert figures["skate_cm_s"] < 12.0
    assert figures["under_frac"] == 0.0 and figures["air_frac"] <= 0.02


def test_synth_follows_as_the_live_path_does(model):
    """The engine (synth, evaluate) passes the weights' strength, as the live engine does."""
    controls = default_controls(model, {"youthful": 2.0})
    motion = render(model, controls, 120)
    contact = contact_space(model)
    static, ids = features(model, controls, 120)
    poses = PoseStream(model.layout, model.fps, FootLock(model.layout, contact.clearance, model.fps))
    shares = contact.shares(controls.weights)[0][ids]
    out = [poses.next(row, share, STRENGTH_OFF_DATA) for row, share in zip(static, shares)]
    skeleton = model.layout.skeleton
    again = channels_from_local(skeleton, np.stack([p.rotations for p in out]), np.stack([p.translations for p in out]))
    np.testing.assert_allclose(motion.channels, again, atol=1e-9)


def test_a_jump_out_of_the_data_changes_the_follow_without_a_jump_in_the_pose(model):
    """Live, the strength follows the weights frame by frame (none -> half here): the body's
    offset changes its rate, never its value, so the joints move no faster across the change
    than the unplanted walk itself does (plus 20%, as the lock's own continuity test allows)."""
    from instrument.synthesis.stream import Controls, Crowd

    space, contact = style_space(model), contact_space(model)
    names = model.style_names
    calm, bold = np.zeros(len(names)), np.eye(len(names))[names.index("feminine")] * 2.0
    walker = Crowd(space)
    poses = PoseStream(model.layout, model.fps, FootLock(model.layout, contact.clearance, model.fps))
    plain = PoseStream(model.layout, model.fps)
    planted, raw = [], []
    for weights in [calm] * 60 + [bold] * 30:
        controls = Controls(weights)
        frame = step(walker, [controls])[0]
        shares = contact.shares(controls.weights)[0, walker.history_ids[0, 1]]
        planted.append(poses.next(frame, shares, strength(contact.leg_weights(controls.weights))).world_positions)
        raw.append(plain.next(frame).world_positions)
    planted, raw = np.array(planted), np.array(raw)
    assert strength(calm) < strength(bold)
    moves = np.linalg.norm(np.diff(planted[55:75], axis=0), axis=2).max()
    assert moves < 1.2 * np.linalg.norm(np.diff(raw[55:75], axis=0), axis=2).max()
