"""The compiled, batched pose path (CrowdPoses, the foot lock's kernels) against the plain-Python
path it replaced (tests/reference_lock.py), on walks the shipped model makes."""

import numpy as np
import pytest

import reference_lock as reference
from instrument.synthesis.posing import CrowdPoses, PoseStream
from instrument.models.modelfile import load_model
from instrument.synthesis.contact import contact_space
from instrument.synthesis import footlock
from instrument.synthesis.footlock import FootLock
from instrument.synthesis.interpolation import GROUPS, style_space
from instrument.synthesis.engine import drive
from instrument.synthesis.stream import Controls, Crowd
from walks import step

FIELDS = ("rotations", "translations", "world_rotations", "world_positions")


def _performance(model, frames: int, variant: int) -> list[Controls]:
    """Controls per frame: styles changing every 40 frames, exaggerated (x2), inverted (-1),
    blended, per body part, with steering; `variant` shifts which style comes when."""
    styles = len(model.style_names)
    out = []
    for i in range(frames):
        block = i // 40 + variant
        weights = np.zeros(styles)
        weights[block % styles] = (1.0, 2.0, -1.0, 0.5)[block % 4]
        weights[(block + 3) % styles] += 0.5 if block % 3 == 0 else 0.0
        parts = None
        if block % 5 == 2:  # the legs in another style than the rest
            parts = np.full((styles, len(GROUPS)), np.nan)
            parts[:, GROUPS.index("legs")] = np.eye(styles)[(block + 1) % styles] * 2.0
        out.append(Controls(weights, parts, turn=0.3 * np.sin(i / 50.0) * (variant % 2)))
    return out


def _features(model, space, performances: list[list[Controls]]):
    """Static features (frames, N, D) and contact shares (frames, N, 2) of N live walks."""
    contact = contact_space(model)
    walker = Crowd(space, len(performances), seeds=list(range(len(performances))))
    statics, shares = [], []
    for controls in zip(*performances):
        frame = step(walker, list(controls))
        statics.append(np.empty(frame.shape))
        drive(frame, walker.cadence, np.ones(len(controls)), np.array([c.turn for c in controls]), statics[-1])
        shares.append(np.stack([contact.shares(c.weights, c.part_weights)[0, walker.history_ids[n, 1]]
                                for n, c in enumerate(controls)]))
    return np.array(statics), np.array(shares)


def _reference_run(model, static, shares, position=None, heading=0.0, locked=True, fps=None):
    contact, fps = contact_space(model), fps or model.fps
    lock = reference.FootLock(model.layout, contact.clearance, fps, contact.tip_clearance) if locked else None
    stream = reference.PoseStream(model.layout, fps, lock)
    if position is not None:
        stream.position, stream.heading = np.asarray(position, dtype=float), heading
    return [stream.next(row, s if locked else None) for row, s in zip(static, shares)]


def _locked_run(model, static, shares, fps=None, lock=None, watch=()) -> tuple[list, dict[str, np.ndarray]]:
    """One character's poses from the compiled pose stream (its foot lock `lock`, or the model's
    without tips), and each frame's copy of the lock state's fields named in `watch` (frames, ...)."""
    fps = fps or model.fps
    lock = lock or FootLock(model.layout, contact_space(model).clearance, fps)
    stream = PoseStream(model.layout, fps, lock)
    poses, seen = [], {name: [] for name in watch}
    for row, s in zip(static, shares):
        poses.append(stream.next(row, s))
        for name in watch:
            seen[name].append(getattr(stream.crowd.lock_state, name)[0].copy())
    return poses, {name: np.array(values) for name, values in seen.items()}


def _assert_same_pose(got, want) -> None:
    for field in FIELDS:
        np.testing.assert_allclose(getattr(got, field), getattr(want, field), rtol=0, atol=1e-9)


@pytest.mark.parametrize("fps", [120.0, 24.0])
def test_at_another_rate_the_lock_makes_the_reference_poses(model, space, fps):
    """Posed at another rate than 30 fps (the same frames: a walk slower or faster, but the lock's
    rule is what is compared), the lock's blend, the body's drop, the swing lift and the hold on
    the floor move by their share of a time a frame (features.REFERENCE_FPS), not by a 30 fps
    frame's: the compiled lock and the reference make the same poses, and at 120 fps a foot's
    hold passes through values between 0 and 1."""
    static, shares = _features(model, space, [_performance(model, 200, 1)])
    poses, state = _locked_run(model, static[:, 0], shares[:, 0], fps=fps, watch=("held",))
    held = state["held"]
    for got, want in zip(poses, _reference_run(model, static[:, 0], shares[:, 0], fps=fps)):
        _assert_same_pose(got, want)
    between = ((held > 0.0) & (held < 1.0)).any()
    assert between == (fps > 30.0)


def test_one_character_makes_the_reference_poses_through_style_changes_and_extrapolation(model, space):
    static, shares = _features(model, space, [_performance(model, 400, 0)])
    poses, state = _locked_run(model, static[:, 0], shares[:, 0], watch=("drop",))
    drops = state["drop"]
    expected = _reference_run(model, static[:, 0], shares[:, 0])
    for got, want in zip(poses, expected):
        assert (got.index, got.time) == (want.index, want.time)
        _assert_same_pose(got, want)
    # the lock did something on this walk, the body's drop included (so the comparison covers it)
    assert max(drops) > 1e-3
    plain = _reference_run(model, static[:, 0], shares[:, 0], locked=False)
    moved = [np.abs(a.world_positions - b.world_positions).max() for a, b in zip(poses, plain)]
    assert max(moved) > 1e-2 and np.mean(np.array(moved) > 1e-6) > 0.5


def test_a_quick_walks_feet_land_again_while_their_release_runs_as_the_reference_has_it(model, space):
    """At 2.5 times the pace a walk's foot lands again before the joint-space release of its last
    stance has run out (RELEASE_FRAMES is longer than such a swing): the release runs on as the new
    lock comes in from where the foot is shown, and the compiled lock and the reference make the
    same poses through it (with the pull's ease-out in and smoothstep out, `footlock.pull_step`).
    Dropped at once at such a landing, a release gave back up to a third of its lock's correction
    in one frame (docs/evaluate.md, "A landing foot's hold, eased out")."""
    weights = np.eye(len(model.style_names))[model.style_names.index("active")]
    static, shares = _features(model, space, [[Controls(weights, speed=2.5)] * 240])
    poses, state = _locked_run(model, static[:, 0], shares[:, 0], watch=("weights", "releasing"))
    before = np.vstack([np.zeros((1, 2)), state["weights"][:-1]])
    landings = int(((before == 0.0) & (state["weights"] > 0.0) & (state["releasing"] > 0.0)).sum())
    assert landings >= 5
    for got, want in zip(poses, _reference_run(model, static[:, 0], shares[:, 0])):
        _assert_same_pose(got, want)


def test_feet_planted_and_lifted_at_random_make_the_reference_poses_and_take_the_lock_in_gradually(model, space):
    """Contact shares flickering at random (each foot on or off for 1 to 6 frames), which no
    shipped walk makes but a hand-made or badly trained model may: a foot lands again while its
    release runs, is released again before it ran out, lands while its hold is still going. The
    compiled lock and the reference make the same poses, and the IK's weight (`LockState.locking`)
    comes in and goes out by at most a landing's pace a frame but where a walk's release sets it to
    none (its correction then given back in joint space): planted again before the release had run
    out, it took `weights`, not yet 0, in one frame (the heading, the flat foot, the hold at once)."""
    weights = np.eye(len(model.style_names))[model.style_names.index("active")]
    static, _ = _features(model, space, [[Controls(weights, speed=1.5)] * 150])
    rng = np.random.default_rng(7)
    pace = footlock.LANDING_PACE / footlock.BLEND_FRAMES + 1e-12
    replanted = 0
    for _ in range(3):
        shares = np.zeros((len(static), 2))
        for f in range(2):
            t, on = 0, bool(rng.integers(2))
            while t < len(shares):
                n = int(rng.integers(1, 7))
                shares[t:t + n, f], t, on = (0.9 if on else 0.0), t + n, not on
        poses, state = _locked_run(model, static[:, 0], shares, watch=("locking", "releasing"))
        locking, releasing = (np.vstack([np.zeros((1, 2)), state[name]]) for name in ("locking", "releasing"))
        released = releasing[1:] > releasing[:-1]  # a release began (or began again) this frame
        moved = np.abs(np.diff(locking, axis=0))
        assert (moved[~released] <= pace).all(), moved[~released].max()
        replanted += int(((np.diff(locking, axis=0) > 0) & (releasing[1:] > 0)).sum())
        for got, want in zip(poses, _reference_run(model, static[:, 0], shares)):
            _assert_same_pose(got, want)
    assert replanted >= 3  # feet took the lock in again while their release ran


def test_a_toe_less_foot_makes_the_reference_poses(toe_less):
    """A rig whose feet are their ankles alone, ending in an End Site at the toe tip (the shared
    walks' toe joints dropped: `toe_less`), its heels rolling up about those tips: the compiled
    lock and the reference make the same poses through style changes and extrapolation, and the
    tips were what the lock held (a heel rose about one; a lock without them makes other poses)."""
    model = load_model(toe_less[1])
    contact = contact_space(model)
    static, shares = _features(model, style_space(model), [_performance(model, 400, 0)])
    lock = FootLock(model.layout, contact.clearance, model.fps, contact.tip_clearance)
    assert lock.tips.any(axis=1).all()
    poses, state = _locked_run(model, static[:, 0], shares[:, 0], lock=lock, watch=("rises",))
    rises = state["rises"]
    for got, want in zip(poses, _reference_run(model, static[:, 0], shares[:, 0])):
        _assert_same_pose(got, want)
    assert np.max(rises) > 0.05  # radians: a heel rose about its tip
    tipless = PoseStream(model.layout, model.fps, FootLock(model.layout, contact.clearance, model.fps))
    moved = [np.abs(tipless.next(row, s).world_positions - got.world_positions).max()
             for row, s, got in zip(static[:, 0], shares[:, 0], poses)]
    assert max(moved) > 1.0  # cm


def test_a_crowd_makes_each_characters_own_poses(model, space):
    """Three characters with different controls, start points and headings, in one call a frame:
    each gets the poses of its own single run."""
    count = 3
    static, shares = _features(model, space, [_performance(model, 240, k) for k in range(count)])
    contact = contact_space(model)
    positions = np.array([[0.0, 0.0, 0.0], [150.0, 0.0, -40.0], [-80.0, 0.0, 300.0]])
    headings = np.array([0.0, 1.2, -2.5])
    crowd = CrowdPoses(model.layout, model.fps, count, FootLock(model.layout, contact.clearance, model.fps),
                       positions, headings)
    frames = [crowd.next(row, s) for row, s in zip(static, shares)]
    for n in range(count):
        expected = _reference_run(model, static[:, n], shares[:, n], positions[n], headings[n])
        for frame, want in zip(frames, expected):
            got = frame.character(n)
            _assert_same_pose(got, want)
    # the characters really differ (different controls and places)
    last = frames[-1].world_positions
    assert np.abs(last[0] - last[1]).max() > 1.0 and np.abs(last[1] - last[2]).max() > 1.0


def test_a_character_placed_mid_walk_walks_on_as_if_it_had_started_there(model, space):
    static, shares = _features(model, space, [_performance(model, 120, k) for k in range(2)])
    contact = contact_space(model)
    crowd = CrowdPoses(model.layout, model.fps, 2, FootLock(model.layout, contact.clearance, model.fps))
    for row, s in zip(static[:60], shares[:60]):
        crowd.next(row, s)
    crowd.place(1, np.array([500.0, 0.0, 500.0]), 2.0)
    frames = [crowd.next(row, s) for row, s in zip(static[60:], shares[60:])]
    expected = _reference_run(model, static[60:, 1], shares[60:, 1], [500.0, 0.0, 500.0], 2.0)
    for frame, want in zip(frames, expected):
        _assert_same_pose(frame.character(1), want)
    # the other character walked on undisturbed
    unmoved = _reference_run(model, static[:, 0], shares[:, 0])[60:]
    np.testing.assert_allclose(frames[-1].world_positions[0], unmoved[-1].world_positions, rtol=0, atol=1e-9)


def test_without_a_lock_or_shares_the_feet_are_left_as_made(model, space):
    static, shares = _features(model, space, [_performance(model, 60, 1)])
    contact = contact_space(model)
    expected = _reference_run(model, static[:, 0], shares[:, 0], locked=False)
    unlocked = PoseStream(model.layout, model.fps)
    no_shares = PoseStream(model.layout, model.fps, FootLock(model.layout, contact.clearance, model.fps))
    for row, want in zip(static[:, 0], expected):
        for stream in (unlocked, no_shares):
            got = stream.next(row)
            _assert_same_pose(got, want)


def test_a_wrong_shape_is_refused_not_read_past(model):
    crowd = CrowdPoses(model.layout, model.fps, 2)
    with pytest.raises(ValueError, match="2 characters"):
        crowd.next(np.zeros((2, model.layout.dimension - 3)))
    with pytest.raises(ValueError, match="shares"):
        crowd.next(np.zeros((2, model.layout.dimension)), np.zeros((1, 2)))


def test_each_frame_owns_its_arrays(model, space):
    """An output may keep a pose (a recorder, the console): the next frame must not overwrite it."""
    static, shares = _features(model, space, [_performance(model, 3, 0)])
    stream = PoseStream(model.layout, model.fps)
    first = stream.next(static[0, 0])
    kept = first.world_positions.copy()
    stream.next(static[1, 0])
    np.testing.assert_array_equal(first.world_positions, kept)


def _leg_swings(hip, knee, ankle, target, toes):
    """The compiled leg IK's thigh and shin turns (the kernel writes them into arrays it is given)."""
    thigh, shin = np.empty((3, 3)), np.empty((3, 3))
    footlock.leg_swings(hip, knee, ankle, target, toes, thigh, shin, np.empty((2, 3, 3)))
    return thigh, shin


def test_the_compiled_leg_ik_turns_as_the_reference_does():
    """Reachable and unreachable targets, straight legs, knees bent a little backwards."""
    rng = np.random.default_rng(5)
    for case in range(300):
        hip = rng.normal(size=3)
        knee = hip + np.array([0.0, -4.0, 0.3]) + 0.3 * rng.normal(size=3)
        ankle = knee + np.array([0.0, -4.0, -0.3]) + 0.3 * rng.normal(size=3)
        if case % 3 == 0:  # straight, or nearly: the hinge comes from the toes
            ankle = knee + (knee - hip) * (1.0 + 0.01 * rng.normal()) + 1e-4 * rng.normal(size=3) * (case % 2)
        target = hip + rng.normal(size=3) * rng.uniform(1.0, 12.0)
        toes = rng.normal(size=3)
        got = _leg_swings(hip, knee, ankle, target, toes)
        want = reference._leg_swings(hip, knee, ankle, target, toes)
        for a, b in zip(got, want):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_a_degenerate_leg_gives_numbers_not_an_exception():
    """Compiled division follows numpy (a live show must not stop on a zero length): a target at
    the hip has no direction, and the turns come back NaN as numpy's would, not as ZeroDivisionError."""
    hip, knee, ankle = np.zeros(3), np.array([0.0, -4.0, 0.0]), np.array([0.0, -8.0, 0.1])
    thigh, shin = _leg_swings(hip, knee, ankle, hip.copy(), np.array([0.0, 0.0, 1.0]))
    assert thigh.shape == shin.shape == (3, 3)


def _scaled(skeleton, template, scale: float):
    """The same skeleton and template in other units (scale 0.01: centimetres to metres)."""
    from instrument.motion.bvh import Joint, Skeleton

    joints = tuple(Joint(j.name, j.parent, tuple(np.array(j.offset) * scale), j.channels,
                         None if j.end_site is None else tuple(np.array(j.end_site) * scale)) for j in skeleton.joints)
    template = np.array(template, dtype=float)
    template[:3] *= scale  # the root's position channels
    return Skeleton(joints), template


def _feet_rig(heel_last: bool, scale: float):
    """A skeleton with a ball, a toe tip and (heel_last) a heel marker per foot, in `scale` units:
    the skeleton, its layout, the rest pose's rotations and translations, its legs and each
    foot joint's height on the floor at rest (what the lock plants to)."""
    from test_contact import _feet_skeleton

    from instrument.motion.features import FeatureLayout
    from instrument.motion.kinematics import forward_kinematics
    from instrument.motion.limbs import find_limbs

    skeleton, template = _scaled(*_feet_skeleton(heel_last), scale)
    layout = FeatureLayout(skeleton, 0, tuple(range(len(skeleton.joints))), tuple(template))
    rest_rot, rest_tr = layout.template_pose[0], layout.template_pose[1]
    _, rest_pos = forward_kinematics(skeleton, rest_rot[None], rest_tr[None])
    legs = find_limbs(skeleton, 0, np.asarray(template)).legs
    ground = np.array([[rest_pos[0, j, 1] for j in leg.foot] for leg in legs])
    return skeleton, layout, rest_rot, rest_tr, legs, ground


@pytest.mark.parametrize("heel_last", [True, False])
@pytest.mark.parametrize("scale", [1.0, 0.01])
def test_a_foot_with_a_heel_joint_is_locked_as_the_reference_does_in_any_units(heel_last, scale):
    """Another skeleton than the shipped one: feet with a ball, a toe tip and (heel_last) a heel
    marker listed after them, in centimetres and in metres; a left foot landing toes up (laid
    flat) while the hips move on (heel rise, and its pace as the lock lets go)."""
    from instrument.motion.kinematics import forward_kinematics

    skeleton, layout, rest_rot, rest_tr, legs, ground = _feet_rig(heel_last, scale)
    compiled, oracle = FootLock(layout, ground, 30.0), reference.FootLock(layout, ground, 30.0)
    state = compiled.start(1)

    def pitch(angle: float) -> np.ndarray:
        c, s = np.cos(angle), np.sin(angle)
        return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])

    risen = flattened = 0
    for i in range(60):
        t = i / 30.0
        rot, tr = rest_rot.copy(), rest_tr.copy()
        tr[0, 2] = 30.0 * scale * t  # the hips walk on over the planted left foot
        tr[0, 1] += 3.0 * scale * np.sin(6.0 * t)
        rot[legs[0].ankle] = pitch(-np.radians(20.0) * max(0.0, 1.0 - t)) @ rot[legs[0].ankle]  # toes up, then down
        rot[legs[1].hip] = pitch(-0.6) @ rot[legs[1].hip]  # the right leg swings forward
        shares = np.array([1.0, 0.0]) if i < 40 else np.array([0.0, 1.0])
        expected = oracle.apply(rot, tr, shares)
        world_rot, world_pos = forward_kinematics(skeleton, rot[None], tr[None])
        rotations, translations = rot[None].copy(), tr[None].copy()
        compiled.apply(state, rotations, translations, shares[None], world_rot.copy(), world_pos.copy())
        _, positions = forward_kinematics(skeleton, rotations, translations)
        assert np.isfinite(positions).all()
        np.testing.assert_allclose(positions[0] / scale, expected[3] / scale, atol=1e-8)
        np.testing.assert_allclose(rotations[0], expected[0], atol=1e-9)
        risen += state.rises[0, 0] > 0.0
        flattened += not np.allclose(rotations[0, legs[0].ankle], rot[legs[0].ankle]) and i < 10
    assert risen > 10 and flattened > 5  # the heel rose, the foot was laid flat: both were compared


@pytest.mark.parametrize("scale", [1.0, 0.01])
def test_a_stand_closes_up_feet_left_away_from_its_pose_as_the_reference_does(scale):
    """Both feet locked where they stood while the hips moved 15 cm on (a stop leaves the feet
    where its last steps landed them), then a still stand: each foot steps, one at a time and off
    the floor, to where the stand's pose puts it, and stays there; then a foot set off lets go of
    its lock at a step's pace (over BLEND_FRAMES, as any foot: let go at half that pace, a run's
    first stance foot was held through its toe-off); the compiled lock and the reference make
    the same poses. Not standing, the lock holds the feet where they were."""
    from instrument.motion.kinematics import forward_kinematics
    from instrument.synthesis.contact import BLEND_FRAMES

    skeleton, layout, rest_rot, rest_tr, legs, ground = _feet_rig(False, scale)
    compiled, oracle, held = FootLock(layout, ground, 30.0), reference.FootLock(layout, ground, 30.0), FootLock(layout, ground, 30.0)
    state, held_state = compiled.start(1), held.start(1)
    lifted, weights = [], []
    for i in range(86):
        rot, tr = rest_rot.copy(), rest_tr.copy()
        tr[0, 2] = scale * min(i, 15)  # the hips move on 15 cm over the feet, then stand
        standing = 30 <= i < 80
        shares = np.array([1.0, 1.0]) if i < 80 else np.array([1.0, 0.0])  # then the right foot sets off
        expected = oracle.apply(rot, tr, shares, standing)
        world_rot, world_pos = forward_kinematics(skeleton, rot[None], tr[None])
        rotations, translations = rot[None].copy(), tr[None].copy()
        compiled.apply(state, rotations, translations, shares[None], world_rot.copy(), world_pos.copy(), np.array([standing]))
        _, positions = forward_kinematics(skeleton, rotations, translations)
        np.testing.assert_allclose(positions[0] / scale, expected[3] / scale, atol=1e-8)
        np.testing.assert_allclose(rotations[0], expected[0], atol=1e-9)
        lifted.append([(positions[0, list(leg.foot), 1] - ground[f]).min() / scale for f, leg in enumerate(legs)])
        weights.append(state.weights[0, 1])
        if i < 80:  # the same frames, never told it stands
            kept_rot, kept_tr = rot[None].copy(), tr[None].copy()
            held.apply(held_state, kept_rot, kept_tr, shares[None], world_rot.copy(), world_pos.copy())
        if i == 79:  # the stand's last frame: its pose as made has both feet under the standing hips
            kept = forward_kinematics(skeleton, kept_rot, kept_tr)[1][0]
            for leg in legs:
                assert np.hypot(*(positions[0, leg.pivot] - world_pos[0, leg.pivot])[[0, 2]]) / scale < 0.01  # closed up
                assert np.hypot(*(kept[leg.pivot] - world_pos[0, leg.pivot])[[0, 2]]) / scale > 14.0  # held where they were
    lifted = np.array(lifted)
    assert (lifted[:30] < 0.5).all()  # moving on, nothing steps
    up = lifted[30:80] > 1.0
    assert up[:, 0].sum() > 5 and up[:, 1].sum() > 5 and not (up[:, 0] & up[:, 1]).any()  # each foot once, one at a time
    assert weights[80 + BLEND_FRAMES - 2] > 0.0 and weights[80 + BLEND_FRAMES - 1] == 0.0  # let go at a step's pace
