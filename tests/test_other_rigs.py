"""Other skeletons, names, rates, units and rest poses (issue 30): what is learnt from a walk does
not depend on how its rig is built, and models trained on re-rigged walks keep the issue's figures;
and the motion vocabulary (issue 25: walk, run, turns, stand) trained on another rig stands, runs,
turns and stops as it does on the Bandai skeleton.

The sets are built by examples/other_rigs.py (`rerig`) from the public CMU takes in
tests/data/cmu-131 and, where they are here, the shared Bandai walks."""

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from instrument.motion.bvh import Motion, read_bvh, write_bvh
from instrument.motion.kinematics import channels_from_local, forward_kinematics, local_transforms, world_positions
from instrument.motion.features import ROOT_FEATURES, FeatureLayout, choose_layout, extract, heading_angle, resample
from instrument.motion.limbs import Leg, Limbs, find_limbs, foot_tip, hip_height, units_to_metres
from instrument.motion.quality import limb_ranges
from instrument.motion.gestures import gesture_phases
from instrument.motion.standing import still_frames
from instrument.motion.steps import segment_steps
from instrument.motion.upright import TO_Y_UP, up_axis, upright
from instrument.models.modelfile import load_model
from instrument.synthesis.footlock import FootLock
from instrument.training.corpus import read_motions
from instrument.training.units import gesture_from_name

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "examples"))
from other_rigs import SETS, Rig, build_set, build_unit_set, chosen_takes, rerig, rest_turns, unit_takes  # noqa: E402
import bvh_independent  # noqa: E402

CMU = Path(__file__).parent / "data" / "cmu-131"
MOTIONS = Path(__file__).resolve().parents[2] / "shared" / "data" / "bandai-motions"
needs_motions = pytest.mark.skipif(not MOTIONS.is_dir(), reason=f"runs, turns and standing takes not found in {MOTIONS}")


@pytest.fixture(scope="module")
def cmu_take():
    return read_bvh(CMU / "cmu131_jackson_01.bvh")


def test_the_public_takes_are_what_their_source_says(cmu_take):
    """120 fps, 31 joints, CMU's units (hips about 17 units up, a unit about 5.7 cm)."""
    assert cmu_take.fps == 120.0 and len(cmu_take.skeleton.joints) == 31 and cmu_take.frames == 530
    assert sum(p.stat().st_size for p in CMU.glob("*.bvh")) < 2_000_000


def test_both_arms_of_a_cmu_skeleton_are_upper_arm_and_forearm(cmu_take):
    """CMU's left collar bone (3.39 units) is longer than its forearm (3.28): the two longest
    consecutive bones were the collar and the upper arm on that side, the right side's were
    right, so one shoulder swing was measured on the collar bone."""
    names = cmu_take.skeleton.names
    limbs = find_limbs(cmu_take.skeleton, 0, cmu_take.channels[0])
    assert [(names[s], names[e]) for s, e in limbs.arms] == [("LeftShoulder", "LeftElbow"), ("RightShoulder", "RightElbow")]
    assert [(names[leg.hip], names[leg.knee], names[leg.ankle]) for leg in limbs.legs] == [
        ("LeftHip", "LeftKnee", "LeftAnkle"), ("RightHip", "RightKnee", "RightAnkle")]


def test_an_arm_held_out_sideways_is_not_a_swing(cmu_take):
    """The shoulder's swing is measured in the vertical plane of travel, where the upper arm lies
    nearer that plane than across it: the take's right arm, held out sideways in 6 of its frames
    (30 fps), read +135 and -146 degrees there and its range 270-odd degrees (the takes' shoulder
    figure 93.6 where the arms swing through 66). Made up: an arm swinging +-30 degrees that is
    held out sideways in 10 frames (a centimetre off the side) swings 60 degrees; one that swings
    +-30 degrees about straight up (overhead) 60 too, not 300 (no wrap at 180)."""
    motion = resample(cmu_take, 30.0)
    layout = choose_layout([motion])
    limbs = find_limbs(motion.skeleton, layout.root, np.asarray(layout.template))
    world_rot, positions = forward_kinematics(motion.skeleton, *local_transforms(motion))
    yaw = heading_angle(world_rot[:, layout.root], layout.heading_reference)
    right = limb_ranges(positions, yaw, replace(limbs, arms=limbs.arms[1:]), layout.root)["shoulder_deg"]
    assert 100.0 < right < 180.0  # 150 degrees (was 271)

    frames = 200
    swing = np.radians(30.0) * np.sin(np.linspace(0.0, 8.0 * np.pi, frames))
    leg = Leg(hip=3, knee=4, ankle=5, foot=(5,), pivot=5, thigh=1.0, shin=1.0)
    made_up = Limbs(0, (leg, leg), ((1, 2),), 2.0)

    def shoulder(bone: np.ndarray) -> float:
        """The shoulder's range of an arm `bone` (frames, 3) on a body walking along +z."""
        pose = np.zeros((frames, 6, 3))
        pose[:, :, 2] = np.arange(frames)[:, None] * 0.05
        pose[:, 1, 1], pose[:, 3, 1], pose[:, 4, 1], pose[:, 5, 1] = 1.5, 1.0, 0.5, 0.0
        pose[:, 2] = pose[:, 1] + bone
        return limb_ranges(pose, np.zeros(frames), made_up, 0)["shoulder_deg"]

    hanging = np.stack([np.zeros(frames), -np.cos(swing), np.sin(swing)], axis=1)
    sideways = hanging.copy()
    sideways[::20] = [[1.0, 0.01, -0.01], [-1.0, 0.01, 0.01]] * 5
    assert shoulder(hanging) == pytest.approx(60.0, abs=1.0)
    assert shoulder(sideways) == pytest.approx(60.0, abs=1.0)
    assert shoulder(-hanging) == pytest.approx(60.0, abs=1.0)


def _features(motion):
    layout = choose_layout([motion])
    return extract(motion, layout)[0], segment_steps(motion, layout).steps, layout


ORDERS = ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"]
_BASE: dict[float, tuple] = {}


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(turn=st.floats(0.0, 90.0), scale=st.sampled_from([1.0, 0.01 * 5.65, 1 / 2.54, 10.0]),
       order=st.sampled_from(ORDERS), fps=st.sampled_from([24.0, 30.0, 60.0]), up=st.sampled_from(["Y", "Z"]),
       positions=st.booleans())
def test_what_is_learnt_does_not_depend_on_the_rig(cmu_take, turn, scale, order, fps, up, positions):
    """The same capture with every joint's rest orientation turned (by up to 90 degrees, a
    rotation of its own), in other units and Euler orders, with Z up or Y up, with position
    channels on every joint or only where needed, read as training reads it (turned Y up): the
    steps are cut at the same frames, the root's height and speeds are the same (in the new
    units), its turning and tilt the same, and every joint turns by the same angle. With the
    heading read from the root's own axes, a turned root changed the heading, the tilt and the
    steps; a Z-up capture failed training with a numpy traceback."""
    if fps not in _BASE:
        _BASE[fps] = _features(resample(cmu_take, fps))
    base, base_steps, base_layout = _BASE[fps]
    motion = rerig(cmu_take, Rig(fps, scale, order, rest_turn_deg=turn, keep_root=False, up=up, positions=positions))
    motion, found = upright(motion)
    assert found == "+" + up
    features, steps, layout = _features(motion)
    assert layout.joints == base_layout.joints and layout.root == base_layout.root
    assert [(s.label, s.start, s.end) for s in steps] == [(s.label, s.start, s.end) for s in base_steps]
    np.testing.assert_allclose(features[:, :3] / scale, base[:, :3], atol=1e-5 * np.abs(base[:, :3]).max())
    np.testing.assert_allclose(features[:, 3:len(ROOT_FEATURES)], base[:, 3:len(ROOT_FEATURES)], atol=1e-6)
    joints = features[:, len(ROOT_FEATURES):].reshape(motion.frames, -1, 3)
    base_joints = base[:, len(ROOT_FEATURES):].reshape(motion.frames, -1, 3)
    np.testing.assert_allclose(np.linalg.norm(joints, axis=2), np.linalg.norm(base_joints, axis=2), atol=1e-6)


@pytest.mark.parametrize("axis", sorted(TO_Y_UP))
def test_up_is_found_in_a_walk_and_in_a_still_stand(cmu_take, axis):
    """The take turned so that each axis is up (both signs): found from where its legs hang, walking,
    still (its first frame held for a second) and walking in place."""
    turned = Motion(cmu_take.skeleton, cmu_take.channels.copy(), cmu_take.fps)
    rotations, translations = local_transforms(turned)
    back = TO_Y_UP[axis].T  # Y up -> `axis` up
    rotations[:, 0], translations[:, 0] = back @ rotations[:, 0], translations[:, 0] @ back.T
    turned = Motion(turned.skeleton, channels_from_local(turned.skeleton, rotations, translations), turned.fps)
    assert up_axis(turned) == axis
    still = Motion(turned.skeleton, turned.channels[[0] * 120], turned.fps)
    assert up_axis(still) == axis
    # in place (a treadmill, an exporter's "in place" walk): the root's travel taken out, so the
    # planted foot moves backwards and the head stays; the legs still hang below
    rotations, translations = local_transforms(cmu_take)
    travel = translations[:, 0] - translations[:1, 0]
    translations[:, 0] -= travel * np.array([1.0, 0.0, 1.0])
    in_place = channels_from_local(cmu_take.skeleton, rotations, translations)
    rotations, translations = local_transforms(Motion(cmu_take.skeleton, in_place, cmu_take.fps))
    rotations[:, 0], translations[:, 0] = back @ rotations[:, 0], translations[:, 0] @ back.T
    assert up_axis(Motion(cmu_take.skeleton, channels_from_local(cmu_take.skeleton, rotations, translations),
                          cmu_take.fps)) == axis
    upright_again = world_positions(upright(turned)[0])
    np.testing.assert_allclose(upright_again, world_positions(cmu_take), atol=1e-6 * np.abs(upright_again).max())


@pytest.mark.parametrize("lift", [0.0, -0.7, -0.9, 0.3])
def test_the_unit_is_guessed_wherever_the_floor_is(cmu_take, lift):
    """The take in metres (CMU's unit is about 5.64 cm) with the floor at the origin, 0.7 or 0.9 m
    below it (the hips near the origin, as some exporters place them) or 0.3 m above: always
    metres. Guessed from the hips' height above the origin alone, the floor 0.7 m down read the
    hips' 0.2 m as a unit of 4.75 m: skate and floating measured 10 times over (skate 45.5
    against 8.0 cm/s on the same takes, float 43%)."""
    motion = rerig(cmu_take, Rig(30.0, 0.0564, "ZXY", keep_root=False, lift=lift / 0.0564))
    pose = world_positions(Motion(motion.skeleton, motion.channels[:1], motion.fps))[0]
    assert units_to_metres(hip_height(pose, 0)) == 1.0


@given(st.floats(0.55, 1.25), st.sampled_from([("m", 1.0), ("cm", 0.01), ("in", 0.0254), ("mm", 0.001)]))
@settings(max_examples=80, deadline=None)
def test_the_unit_is_each_one_a_capture_comes_in(hips_m, unit):
    """Hips from 0.55 to 1.25 m high (a child to a tall adult; inches above 50 read as cm) in
    metres, centimetres, inches or millimetres give back that unit: millimetres (Vicon's exports)
    fell to the unknown unit's guess, the hips made 0.95 m whatever their height."""
    _, metres_per_unit = unit
    assert units_to_metres(hips_m / metres_per_unit) == metres_per_unit


def test_training_reads_a_z_up_capture_y_up(cmu_take, tmp_path):
    """A take written Z up (as from a Z-up scene) is read for training and evaluation (read_motions)
    as the same take Y up: every joint where it was. It failed training with a numpy traceback."""
    path = tmp_path / "cmu131_jackson_01.bvh"
    write_bvh(path, rerig(cmu_take, Rig(120.0, 1.0, "ZXY", keep_root=False, up="Z")))
    (motion,) = read_motions([(path, "jackson")], 30.0)
    np.testing.assert_allclose(world_positions(motion), world_positions(resample(cmu_take, 30.0)), atol=1e-4)


def test_the_suit_set_is_the_issues_23_joints_and_moves_as_the_take(real_walks):
    """suit23-60: Hips, Chest to Chest4, Neck, Head and per side collar, shoulder, elbow, wrist,
    hip, knee, ankle and toe, 60 fps, every rotation zero in the rest pose; the legs' and feet's
    world positions those of the take (the spine cut in four moves the joints above it by less
    than a centimetre)."""
    take = read_bvh(real_walks[0])
    rig = SETS["suit23-60"]
    suit = rerig(take, rig, rest_turns(take, rig))
    names = suit.skeleton.names
    assert len(names) == 23 and names[:7] == ["Hips", "Chest", "Chest2", "Chest3", "Chest4", "Neck", "Head"]
    assert {"LeftCollar", "RightWrist", "LeftHip", "RightKnee", "LeftAnkle", "RightToe"} <= set(names)
    assert suit.fps == 60.0
    source = world_positions(resample(take, 60.0))
    mine = world_positions(suit)
    frames = min(len(source), len(mine))
    old = take.skeleton.names
    for name, new in (("Toes_L", "LeftToe"), ("Foot_R", "RightAnkle"), ("LowerLeg_L", "LeftKnee")):
        np.testing.assert_allclose(mine[:frames, names.index(new)], source[:frames, old.index(name)], atol=1e-3)
    assert np.abs(mine[:frames, names.index("Head")] - source[:frames, old.index("Head")]).max() < 1.0


def test_the_steps_are_the_same_at_every_rate(cmu_take):
    """Steps cut from the take at 24, 30, 60 and 120 fps start and end at the same moments (within
    a frame at 24 fps) and are the same steps."""
    cut = {}
    for fps in (24.0, 30.0, 60.0, 120.0):
        steps = segment_steps(resample(cmu_take, fps)).steps
        cut[fps] = [(s.label, s.start / fps, s.end / fps) for s in steps]
    for fps, steps in cut.items():
        assert [s[0] for s in steps] == [s[0] for s in cut[120.0]], fps
        assert np.abs(np.array([s[1:] for s in steps]) - np.array([s[1:] for s in cut[120.0]])).max() <= 1 / 24 + 1e-9


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "instrument", *args], capture_output=True, text=True, timeout=900)


@pytest.mark.parametrize("name", ["rest-posed-30-in", "cmu31-120", "suit23-60"])
def test_a_model_of_a_re_rigged_set_keeps_the_issues_figures(real_walks, tmp_path, name):
    """Two styles of the shared walks, three takes each, re-rigged (`SETS`: joints turned at rest
    and inches; CMU's 31 joints and names, 120 fps and metres; issue 30's 23-joint suit, its
    spine in four, 60 fps, resting in a captured pose), trained and measured by
    `instrument evaluate --real`. At weight 1, each style's walk is recognised at least 0.9x as
    often as its real takes (cross-validated), its knee, hip and shoulder ranges are within 10%
    of the takes' and it skates no more than 1.2x as much (issue 30's targets). On the turned
    rest before the root's heading was read from its untwisted rest: hips 27% short of the
    takes', skate 2.7-3.8x."""
    shared = real_walks[0].parent
    folder = tmp_path / name
    rig = SETS[name]
    files = build_set(chosen_takes(shared, ["active", "feminine"], 3), rig, folder)
    assert read_bvh(files[0]).fps == rig.fps
    figures = _trained_and_evaluated(folder, tmp_path)
    for style in ("active", "feminine"):
        real, made = figures["real"][style], figures["synth"][style]
        assert made["recognised"] >= 0.9 * real["recognised"], (style, made["recognised"], real["recognised"])
        for key in ("knee_deg", "hip_deg", "shoulder_deg"):
            assert abs(made[key] / real[key] - 1.0) <= 0.10, (style, key, made[key], real[key])
        assert made["skate_cm_s"] <= 1.2 * real["skate_cm_s"], (style, made["skate_cm_s"], real["skate_cm_s"])


def _trained_and_evaluated(folder: Path, tmp_path: Path) -> dict:
    """`instrument train` on `folder`, then `evaluate --real` of that model against the same takes
    (one variant, 8 s): its JSON figures."""
    model = tmp_path / "model.npz"
    trained = cli("train", str(folder), "--out", str(model), "--quiet")
    assert trained.returncode == 0, trained.stderr
    result = cli("evaluate", str(model), "--real", str(folder), "--variants", "one", "--seconds", "8", "--json")
    assert result.returncode == 0, result.stderr
    return json.loads(result.stdout)


def _hip_swing(path: Path, skip_s: float = 0.0) -> float:
    """A walk's hip swing as read from its file by an independent reader (tests/bvh_independent.py):
    each thigh's (hip to knee) angle from straight down in the vertical plane of the hips' travel
    (over the second about each frame), its 1st to 99th percentile range, the mean of both legs;
    from `skip_s` seconds on."""
    names, positions, fps = bvh_independent.world_positions(path)
    positions = positions[int(round(skip_s * fps)):]
    hips = positions[:, names.index("Hips")]
    frames, half = np.arange(len(hips)), int(round(fps / 2))
    travel = hips[np.minimum(frames + half, len(hips) - 1)] - hips[np.maximum(frames - half, 0)]
    travel[:, 1] = 0.0
    forward = travel / np.linalg.norm(travel, axis=1, keepdims=True)
    ranges = []
    for side in ("L", "R"):
        thigh = positions[:, names.index(f"LowerLeg_{side}")] - positions[:, names.index(f"UpperLeg_{side}")]
        angle = np.degrees(np.arctan2(np.einsum("ti,ti->t", thigh, forward), -thigh[:, 1]))
        ranges.append(np.ptp(np.percentile(angle, [1.0, 99.0])))
    return float(np.mean(ranges))


def test_a_toe_less_rig_swings_its_hips_as_its_takes(toe_less, tmp_path):
    """The shared active and elderly walks with their toe joints dropped (`toe_less`): each
    style's 8 s walk, as `instrument synth` writes it and an independent reader reads it back
    (the first half second left out, as evaluate does), swings its hips within 10% of its takes'
    read the same way, and plants its feet: its ankles in their lowest fifth of frames slide no
    faster than 1.5x the takes' and never sink a centimetre under where they stand.

    With the ankle as the foot's only joint the lock could not roll a heel up, a planted leg that
    could not reach stretched and swung the thigh back: active 70.4 deg against the takes' 51.2
    (+37%, by `evaluate --real`); the heel now rises about the End Site (footlock.FootLock.tips).
    Read from the files: active 53.8 against 52.8 (+2%) and elderly 23.9 against 27.5 (-13%)
    before training's range calibration counted a toe-less foot's tip among its feet's points (it
    took the heel's roll about the held tip for skate and kept none of its steps), then elderly
    26.1 (-5%; the toed rig's -3%). With a walk's release in joint space its feet skated 0.13
    cm/s against the takes' 1.8, and calibration, held to that, kept no step: 23.95 again, until a
    step could skate up to half the takes' own (widen.SKATE_ALLOWANCE): 26.8 (-2.6%)."""
    takes, model = toe_less
    real = {style: [p for p in sorted(takes.glob("*.bvh")) if f"_{style}_" in p.name] for style in ("active", "elderly")}
    feet = ["Foot_L", "Foot_R"]
    for style, files in real.items():
        made = tmp_path / f"{style}.bvh"
        result = cli("synth", "--model", str(model), "--style", f"{style}=1", "--seconds", "8", "--out", str(made))
        assert result.returncode == 0, result.stderr
        swing, takes_swing = _hip_swing(made, 0.5), float(np.mean([_hip_swing(p) for p in files]))
        assert abs(swing / takes_swing - 1.0) <= 0.10, (style, swing, takes_swing)
        skate, under = bvh_independent.foot_skate(made, feet)
        takes_skate = float(np.mean([bvh_independent.foot_skate(p, feet)[0] for p in files]))
        assert skate <= 1.5 * takes_skate and under == 0.0, (style, skate, takes_skate, under)


def _toe_less(take: Path, folder: Path) -> tuple[Motion, FeatureLayout, tuple[Leg, ...]]:
    """One shared walk with its toe joints dropped (each foot ends in an End Site at the toe tip),
    its layout as training chooses it, and its legs."""
    motion = read_bvh(build_set([take], Rig(30.0, 1.0, "ZXY", keep_root=False, drop=("Toes_L", "Toes_R")), folder)[0])
    layout = choose_layout([motion])
    return motion, layout, find_limbs(motion.skeleton, layout.root, np.asarray(layout.template)).legs


def test_a_toe_less_foot_rolls_about_an_end_site_ahead_not_one_below_or_behind(real_walks, tmp_path):
    """A toe-less foot's End Site is its heel's pivot only where it reaches forward, the way the
    takes travel (a toe tip): one straight below the ankle (a sole marker) or as far behind it as
    the toe tip was ahead (a heel marker) is no toe, and the foot stays its ankle alone, as
    before the End Site was read; the lock then holds no tip. Reaching along the floor by a
    quarter of its length, as was asked before, took the heel marker for a toe tip."""
    motion, layout, legs = _toe_less(chosen_takes(real_walks[0].parent, ["active"], 1)[0], tmp_path)
    assert all(leg.pivot == leg.ankle and foot_tip(layout, leg) is not None for leg in legs)  # the toe tips
    ankles = forward_kinematics(motion.skeleton, *local_transforms(Motion(motion.skeleton, np.asarray(layout.template)[None],
                                                                           30.0)))[0][0]

    def moved(where) -> FeatureLayout:
        """The layout with each foot's End Site moved to `where(its world reach)` in the template pose."""
        joints = list(motion.skeleton.joints)
        for leg in legs:
            world = ankles[leg.ankle]
            joints[leg.ankle] = replace(joints[leg.ankle], end_site=tuple(world.T @ where(world @ np.asarray(joints[leg.ankle].end_site))))
        return replace(layout, skeleton=replace(motion.skeleton, joints=tuple(joints)))

    below = moved(lambda reach: np.array([0.0, -np.linalg.norm(reach), 0.0]))
    behind = moved(lambda reach: reach * np.array([-1.0, 1.0, -1.0]))  # turned half round about the vertical
    for odd in (below, behind):
        assert all(foot_tip(odd, leg) is None for leg in legs)
        lock = FootLock(odd, np.zeros((2, 1)), 30.0, tip_clearance=4.0)
        assert not lock.tips.any()


@pytest.mark.parametrize("style, index", [("active", 1), ("feminine", 0)])
def test_both_toe_less_feet_roll_about_their_tips_whatever_the_first_frame(real_walks, tmp_path, style, index):
    """The template (the first take's first frame) of these takes has one foot pitched far down:
    its End Site reaches 0.18 (active's 2nd take, the right foot) and 0.06 (feminine's 1st, the
    left) of its length forward. Judged each by itself, that foot lost its tip and the lock rolled
    one heel about its toe tip and the other about its ankle; the foot standing lower, the more
    nearly flat, now judges for both."""
    _, layout, legs = _toe_less(chosen_takes(real_walks[0].parent, [style], index + 1)[index], tmp_path)
    assert all(leg.pivot == leg.ankle and foot_tip(layout, leg) is not None for leg in legs)
    assert FootLock(layout, np.zeros((2, 1)), 30.0, tip_clearance=4.0).tips.any(axis=1).all()


def test_a_model_from_before_issue_30_finds_the_toe_tips_of_hips_facing_sideways(real_walks, tmp_path):
    """A model without `root_reference` reads its heading from the root's own axes: with the hips'
    rest turned a quarter round (the body's pose unchanged), their +Z points across the way the
    takes travel, and a toe tip asked to reach along it was refused. There the End Site need
    only reach along the floor, as it did before issue 30's heading reference was read."""
    motion, layout, legs = _toe_less(chosen_takes(real_walks[0].parent, ["active"], 1)[0], tmp_path)
    skeleton, root = motion.skeleton, layout.root
    turn = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # a quarter round about the vertical
    rotations, translations = (a.copy() for a in layout.template_pose[:2])
    rotations[root] = rotations[root] @ turn
    joints = list(skeleton.joints)
    for child in skeleton.children(root):  # turned back below the hips: every other joint's world pose kept
        rotations[child] = turn.T @ rotations[child]
        translations[child] = turn.T @ translations[child]
        joints[child] = replace(joints[child], offset=tuple(turn.T @ np.asarray(joints[child].offset)))
    turned = replace(skeleton, joints=tuple(joints))
    template = channels_from_local(turned, rotations[None], translations[None])[0]
    old = replace(layout, skeleton=turned, template=tuple(float(v) for v in template), root_reference=None)
    kept = world_positions(Motion(turned, template[None], 30.0))[0]
    assert np.allclose(kept, world_positions(Motion(skeleton, np.asarray(layout.template)[None], 30.0))[0], atol=1e-9)
    assert all(foot_tip(old, leg) is not None for leg in legs)


def test_a_rig_with_toes_on_one_foot_only_is_one_line_before_training(real_walks, tmp_path):
    """The foot lock holds each foot by its own joints side by side: a skeleton with toes on one
    foot only trained all the way and then ended in a traceback (numpy's vstack of uneven feet).
    It is refused at once, naming both feet."""
    folder = tmp_path / "one-toe"
    build_set(chosen_takes(real_walks[0].parent, ["active"], 1), Rig(30.0, 1.0, "ZXY", keep_root=False, drop=("Toes_L",)),
              folder)
    result = cli("train", str(folder), "--out", str(tmp_path / "model.npz"), "--quiet")
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "the feet have different joints (Foot_L against Foot_R, Toes_R)" in result.stderr
    assert not (tmp_path / "model.npz").exists()


@needs_motions
@pytest.mark.parametrize("name", ["dataset-2_wave-both-hands_elderly_001", "dataset-2_raise-up-both-hands_active_002"])
def test_a_rig_with_twist_joints_stands_and_gestures_as_its_take(name):
    """A standing take on a rig with a twist joint half way down each upper arm, forearm and
    thigh (as Unreal's rigs have) and two eyes in the head (as VRoid's have; Mixamo's names,
    millimetres, siblings in reverse order) stands still in the same frames and cuts the same
    gesture phases as the take itself. The twist joints and the eyes end branches of the upper
    body and were taken for hands: a hanging upper arm's "hand" stood above the hips, no frame of
    any standing take was still, and a model trained on such a rig had no stand unit (its gait
    played the walk)."""
    take = read_bvh(MOTIONS / f"{name}.bvh")
    twisted = rerig(take, replace(SETS["twist-60-mm"], fps=take.fps))
    assert sum(n.endswith("Twist") for n in twisted.skeleton.names) == 6
    assert {"mixamorig:LeftEye", "mixamorig:RightEye"} <= set(twisted.skeleton.names)
    found = []
    for motion in (take, twisted):
        layout = choose_layout([motion])
        found.append((still_frames(motion, layout), [(p.label, p.start, p.end) for p in gesture_phases(motion, layout)]))
    (still, phases), (twisted_still, twisted_phases) = found
    assert still.sum() >= 5 and np.array_equal(twisted_still, still)
    assert phases and twisted_phases == phases


# the vocabulary's re-rigged set: Mixamo's names, millimetres, XZY, 60 fps, siblings reversed, twist joints, eyes
VOCABULARY_RIG = "twist-60-mm"
MM_PER_CM = 10.0


@pytest.fixture(scope="module")
def vocabulary(real_walks, tmp_path_factory):
    """(the set's folder, the model): one take of each unit (walk, run, turn each way, a standing
    take) of two styles, re-rigged (`VOCABULARY_RIG`) under names that say nothing and trained
    from a manifest that says each take's style and unit."""
    if not MOTIONS.is_dir():
        pytest.skip(f"runs, turns and standing takes not found in {MOTIONS}")
    folder = tmp_path_factory.mktemp("vocabulary")
    takes = unit_takes([real_walks[0].parent, MOTIONS], ["elderly", "feminine"], 1)
    manifest = build_unit_set(takes, SETS[VOCABULARY_RIG], folder / "set", manifest=True)
    model = folder / "model.npz"
    trained = cli("train", "--manifest", str(manifest), "--out", str(model), "--quiet")
    assert trained.returncode == 0, trained.stderr
    # nothing to warn of but the takes' rate (the rig's, not the model's 30 fps: said, as meant)
    said = [line for line in trained.stderr.splitlines() if "warning" in line and "resampled to the model's" not in line]
    assert not said, trained.stderr
    # the standing takes' gestures, which their names no longer say, from the manifest's fourth column
    said = {gesture_from_name(t.path) for t in takes if t.unit == "stand"} - {None}
    assert said and set(load_model(model).metadata.get("gestures", {})) == said
    return folder / "set", model


def _hips_and_toes(names: list[str], positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The set's hips (frames, 3) and toe joints (frames, 2, 3), in cm."""
    toes = [names.index(f"mixamorig:{side}ToeBase") for side in ("Left", "Right")]
    return positions[:, names.index("mixamorig:Hips")] / MM_PER_CM, positions[:, toes] / MM_PER_CM


def _speed(track: np.ndarray, fps: float) -> np.ndarray:
    """Horizontal speed (cm/s) per frame step of a (frames, ..., 3) track."""
    return np.linalg.norm(np.diff(track[..., [0, 2]], axis=0), axis=-1) * fps


def test_the_vocabulary_on_another_rig_stands_walks_runs_and_turns(vocabulary, tmp_path):
    """`synth --gait stand|walk|run` and `--turn` on the re-rigged model, read back by the
    independent reader: the set's joint names in its order, millimetres, the model's rate, no
    NaN; the stand still (hips under 6 cm/s and feet under 2: issue 25), the run 1.3x the walk's
    speed or more, a turn turning each way (the Bandai skeleton's model turns 52-61 deg/s at
    `--turn 1`), the feet planted in contact (the Bandai model's walks skate 0-0.5 cm/s, its
    runs 0.1-2.4; measured as bvh_independent.foot_skate does)."""
    folder, model = vocabulary
    names_in_set = bvh_independent.world_positions(next(folder.glob("*.bvh")))[0]
    made = {}
    for name, options in (("stand", ["--gait", "stand"]), ("walk", []), ("run", ["--gait", "run"]),
                          ("left", ["--turn", "1.0"]), ("right", ["--turn", "-1.0"])):
        out = tmp_path / f"{name}.bvh"
        done = cli("synth", "--model", str(model), *options, "--style", "feminine=1", "--seconds", "6", "--out", str(out))
        assert done.returncode == 0, done.stderr
        assert "plays the walk" not in done.stderr + done.stdout and "no unit" not in done.stderr + done.stdout
        names, positions, fps = bvh_independent.world_positions(out)
        assert names == names_in_set and abs(fps - 30.0) < 1e-3 and np.isfinite(positions).all()
        hips, toes = _hips_and_toes(names, positions[15:])  # the first half second left out, as evaluate does
        assert 50.0 < hips[:, 1].mean() < 130.0  # hips 0.5 to 1.3 m up: the file is in millimetres
        made[name] = hips, toes, fps
    hips, toes, fps = made["stand"]
    assert _speed(hips, fps).mean() < 6.0 and _speed(toes, fps).mean() < 2.0
    walk, run = (_speed(made[g][0], fps).mean() for g in ("walk", "run"))
    assert run > 1.3 * walk > 1.3 * 50.0
    for name, sign in (("left", 1.0), ("right", -1.0)):
        travel = np.diff(made[name][0][::15, [0, 2]], axis=0)  # over half seconds
        heading = np.unwrap(np.arctan2(travel[:, 0], travel[:, 1]))
        assert sign * np.degrees(heading[-1] - heading[0]) / (len(travel) / 2.0) > 30.0, name
    for name, bound in (("walk", 1.0), ("left", 1.0), ("right", 1.0), ("run", 3.0)):
        _, toes, _ = made[name]
        skate = []
        for k in range(2):
            contact = toes[:, k, 1] <= np.percentile(toes[:, k, 1], 20)
            skate.append(_speed(toes[:, k], fps)[contact[1:] & contact[:-1]])
        assert np.concatenate(skate).mean() <= bound, (name, np.concatenate(skate).mean())


def test_a_score_stands_walks_runs_and_stops_a_crowd_on_another_rig(vocabulary, tmp_path):
    """A score that stands, sets off, breaks into a run and stops, played by `run --score --fast
    --bvh` for a crowd of three at 60 fps on the re-rigged model, one character's file read back:
    at 60 fps, the set's names, finite; still in the stands, the run faster than the walk."""
    folder, model = vocabulary
    (tmp_path / "score.toml").write_text(
        '[[cue]]\nat = 0\nramp = { "style/feminine" = 1.0, gait = "stand" }\n\n'
        '[[cue]]\nat = 1.5\nramp = { gait = "walk" }\n\n'
        '[[cue]]\nat = 4.5\nramp = { gait = "run" }\n\n'
        '[[cue]]\nat = 7.5\nramp = { gait = "stand" }\n')
    done = subprocess.run([sys.executable, "-m", "instrument", "run", "--model", str(model), "--score", "score.toml",
                           "--fast", "--no-osc", "--quiet", "--fps", "60", "--seconds", "10.5", "--characters", "3",
                           "--bvh", "crowd.bvh", "--bvh-character", "1"], capture_output=True, text=True, cwd=tmp_path,
                          timeout=900)
    assert done.returncode == 0, done.stderr
    names, positions, fps = bvh_independent.world_positions(tmp_path / "crowd.bvh")
    assert abs(fps - 60.0) < 1e-3 and names == bvh_independent.world_positions(next(folder.glob("*.bvh")))[0]
    assert np.isfinite(positions).all() and len(positions) == 630
    hips, toes = _hips_and_toes(names, positions)
    speed = _speed(hips, fps)

    def during(a: float, b: float) -> float:
        return float(speed[int(a * fps):int(b * fps)].mean())

    assert during(0.5, 1.5) < 6.0 and during(9.5, 10.5) < 6.0  # stands, and stopped within two seconds
    assert during(6.0, 7.5) > 1.3 * during(3.0, 4.5) > 1.3 * 50.0
    assert _speed(toes, fps)[int(9.5 * fps):].mean() < 2.0


def test_evaluate_units_measures_a_re_rigged_vocabulary(vocabulary):
    """`instrument evaluate --units --json` on the re-rigged model against its own takes: one
    JSON report (a turn's numpy rate made it a traceback), the stand's targets met, every
    stop within two steps."""
    folder, model = vocabulary
    done = cli("evaluate", str(model), "--real", str(folder), "--units", "--variants", "one", "--styles", "feminine",
               "--seconds", "3", "--json")
    assert done.returncode == 0, done.stderr
    targets = json.loads(done.stdout)["units"]["targets"]
    rows = {(t["target"], t["walk"]): t for t in targets}
    assert rows[("stand hips cm/s", "feminine")]["passed"] and rows[("stand feet cm/s", "feminine")]["passed"]
    assert {"feminine left", "feminine right"} <= {t["walk"] for t in targets if t["target"] == "turn mean rate deg/s"}
    stops = [t for t in targets if t["target"] == "stop steps"]
    assert len(stops) == 6 and all(t["passed"] for t in stops), stops
