import numpy as np
import pytest

from instrument.motion.bvh import parse_bvh, read_bvh
from instrument.motion.features import ROOT_FEATURES, choose_layout, extract, resample, restore, with_deltas
from instrument.motion.limbs import find_limbs
from instrument.motion.kinematics import forward_kinematics, local_transforms, world_positions
from instrument.motion.rotations import rotation_angle_between
from conftest import needs_walks
from samples import cmu_style_walk


@pytest.fixture(scope="module")
def walks(real_walks):
    return [read_bvh(p) for p in real_walks]


def test_every_shared_walk_comes_back_exactly(walks):
    layout = choose_layout(walks)
    names = layout.skeleton.names
    assert names[layout.root] == "Hips"
    assert "joint_Root" in layout.to_dict()["left_out"]
    worst_rotation, worst_path = 0.0, 0.0
    for motion in walks:
        features, start, heading = extract(motion, layout)
        assert features.shape == (motion.frames, layout.dimension)
        assert np.isfinite(features).all()
        again = restore(features, layout, motion.fps, start, heading)
        rot_a, trans_a = local_transforms(motion)
        rot_b, trans_b = local_transforms(again)
        worst_rotation = max(worst_rotation, rotation_angle_between(rot_a, rot_b).max())
        path_a = forward_kinematics(motion.skeleton, rot_a, trans_a)[1][:, layout.root]
        path_b = forward_kinematics(again.skeleton, rot_b, trans_b)[1][:, layout.root]
        worst_path = max(worst_path, np.abs(path_a - path_b).max())
    assert worst_rotation < 1e-6
    assert worst_path < 1.0  # centimetres, over the whole take


def test_features_do_not_depend_on_where_the_walk_starts_or_faces(walks):
    motion = walks[0]
    layout = choose_layout([motion])
    moved = parse_bvh(
        # turn and shift the whole take through the static top joint (joint_Root)
        "\n".join(_retarget_top(motion, yaw_degrees=40.0, shift=(100.0, 0.0, -50.0)))
    )
    a, _, heading_a = extract(motion, layout)
    b, _, heading_b = extract(moved, layout)
    np.testing.assert_allclose(a, b, atol=1e-7)
    assert heading_b - heading_a == pytest.approx(np.deg2rad(40.0), abs=1e-9)


def _retarget_top(motion, yaw_degrees, shift):
    from instrument.motion.bvh import bvh_text

    text = bvh_text(motion).splitlines()
    start = text.index("MOTION") + 3
    out = text[:start]
    for line in text[start:]:
        values = line.split()
        values[0:3] = [f"{shift[0]:.6f}", f"{shift[1]:.6f}", f"{shift[2]:.6f}"]
        values[5] = f"{yaw_degrees:.6f}"  # joint_Root's Yrotation (order Z X Y)
        out.append(" ".join(values))
    return out


def test_still_joints_are_left_out_and_restored():
    text, _ = cmu_style_walk(fps=30)
    motion = parse_bvh(text)
    layout = choose_layout([motion])
    modelled = {layout.skeleton.names[j] for j in layout.joints}
    assert {"LeftUpLeg", "RightUpLeg", "LeftArm", "RightArm"} <= modelled
    assert "Neck" not in modelled and "LHipJoint" not in modelled
    assert layout.dimension == len(ROOT_FEATURES) + 3 * len(modelled)
    features, start, heading = extract(motion, layout)
    again = restore(features, layout, motion.fps, start, heading)
    np.testing.assert_allclose(world_positions(again), world_positions(motion), atol=1e-6)


def test_resampling_120_to_30_matches_a_take_made_at_30():
    fast, _ = cmu_style_walk(fps=120, seconds=4.4)
    slow, _ = cmu_style_walk(fps=30, seconds=4.4)
    resampled = resample(parse_bvh(fast), 30.0)
    direct = parse_bvh(slow)
    assert resampled.fps == 30.0
    assert resampled.frames == direct.frames
    np.testing.assert_allclose(world_positions(resampled), world_positions(direct), atol=1e-3)


def test_upsampling_keeps_a_walks_accelerations():
    """A walk made at 30 fps and upsampled to 120 has the accelerations of the same walk made at
    120, and a real take at 30 fps upsampled keeps the jitter `evaluate` measures. Upsampled
    linearly, a take moved at constant speed between its own frames and turned at each: its
    second differences were 0 and spikes in turn (3 times the true ones here), Bandai's walks at
    60 fps had 5.4 times the jitter of the same walks at 30, and a model trained at 60 fps learnt
    that alternation
    (docs/evaluate.md, "Walks trained at another rate than their capture's")."""
    fast, _ = cmu_style_walk(fps=120, seconds=2.0)
    slow, _ = cmu_style_walk(fps=30, seconds=2.0)
    direct = world_positions(parse_bvh(fast))
    upsampled = world_positions(resample(parse_bvh(slow), 120.0))
    inner = slice(8, len(upsampled) - 8)  # the spline's ends know nothing beyond the take
    scale = np.abs(np.diff(direct, 2, axis=0)[inner]).max()
    assert np.abs(np.diff(upsampled, 2, axis=0)[inner] - np.diff(direct[: len(upsampled)], 2, axis=0)[inner]).max() < 0.1 * scale


@needs_walks
@pytest.mark.parametrize("fps", [60.0, 120.0])
def test_upsampled_takes_keep_their_jitter(real_walks, fps):
    take = read_bvh(real_walks[0])
    layout = choose_layout([take])
    limbs = find_limbs(take.skeleton, layout.root, np.asarray(layout.template))

    def jitter(motion):
        body = world_positions(motion)[:, [j for leg in limbs.legs for j in (leg.hip, leg.knee, leg.ankle)]]
        return np.linalg.norm(np.diff(body, 3, axis=0), axis=2).mean() * motion.fps**3

    assert jitter(resample(take, fps)) < 2.0 * jitter(take)  # cubic: 1.4x at 60, 1.5x at 120; linear: 5.6x, 11x


def test_resampling_turns_the_short_way():
    text, _ = cmu_style_walk(fps=60, seconds=1.0)
    motion = parse_bvh(text)
    # the hips yaw passes through values written both as +179 and -179 degrees
    half = resample(motion, 30.0)
    rot_a = local_transforms(motion)[0][::2]
    rot_b = local_transforms(half)[0]
    assert rotation_angle_between(rot_a, rot_b).max() < 1e-6


def test_deltas_use_the_hts_windows():
    t = np.arange(10.0)[:, None]
    static = np.hstack([3 * t**2, t])
    dynamic = with_deltas(static)
    assert dynamic.shape == (10, 6)
    np.testing.assert_allclose(dynamic[1:-1, 2], 6 * t[1:-1, 0])  # (f(t+1) - f(t-1)) / 2
    np.testing.assert_allclose(dynamic[1:-1, 4], 6.0)  # f(t+1) - 2 f(t) + f(t-1)
    np.testing.assert_allclose(dynamic[0, 2], 0.5 * (static[1, 0] - static[0, 0]))  # edge repeats
