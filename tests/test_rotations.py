import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from instrument.motion import rotations as rot

rng = np.random.default_rng(7)


def elementary(axis: str, degrees: np.ndarray) -> np.ndarray:
    a = np.deg2rad(degrees)
    c, s = np.cos(a), np.sin(a)
    m = np.zeros(a.shape + (3, 3))
    i = "XYZ".index(axis)
    j, k = (i + 1) % 3, (i + 2) % 3  # cyclic, so Y gets its +s at [0, 2]
    m[..., i, i] = 1
    m[..., j, j], m[..., j, k], m[..., k, j], m[..., k, k] = c, -s, s, c
    return m


@pytest.mark.parametrize("order", ["XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX"])
def test_euler_is_the_product_of_channel_rotations_in_file_order(order):
    angles = rng.uniform(-180, 180, size=(5, 4, 3))
    expected = elementary(order[0], angles[..., 0]) @ elementary(order[1], angles[..., 1]) @ elementary(order[2], angles[..., 2])
    matrix = rot.euler_to_matrix(angles, order)
    assert matrix.shape == (5, 4, 3, 3)
    np.testing.assert_allclose(matrix, expected, atol=1e-12)
    back = rot.euler_to_matrix(rot.matrix_to_euler(matrix, order), order)
    np.testing.assert_allclose(back, matrix, atol=1e-10)


def test_quaternion_and_expmap_round_trips():
    matrix = Rotation.random(50, random_state=1).as_matrix().reshape(5, 10, 3, 3)
    np.testing.assert_allclose(rot.quat_to_matrix(rot.matrix_to_quat(matrix)), matrix, atol=1e-12)
    np.testing.assert_allclose(rot.expmap_to_matrix(rot.matrix_to_expmap(matrix)), matrix, atol=1e-12)
    q = rot.matrix_to_quat(matrix)
    np.testing.assert_allclose(np.abs(np.sum(rot.expmap_to_quat(rot.quat_to_expmap(q)) * q, -1)), 1, atol=1e-12)


def test_axis_angle_matrix_matches_elementary():
    a = rng.uniform(-3, 3, 10)
    for axis in "xyz":
        np.testing.assert_allclose(rot.axis_angle_matrix(axis, a), elementary(axis.upper(), np.rad2deg(a)), atol=1e-12)


def test_quaternions_keep_one_sign():
    angle = np.linspace(0, 4 * np.pi, 200)  # two full turns about one axis
    q = Rotation.from_rotvec(np.outer(angle, [0, 1, 0])).as_quat()
    q[::3] *= -1  # sign flips, as a converter may produce
    smooth = rot.continuous_quaternions(q)
    assert np.all(np.sum(smooth[1:] * smooth[:-1], -1) > 0)
    np.testing.assert_allclose(Rotation.from_quat(smooth).as_matrix(), Rotation.from_quat(q).as_matrix(), atol=1e-12)


def test_expmaps_never_jump_by_two_pi():
    angle = np.linspace(0, 3 * np.pi, 300)  # past pi, where the principal rotation vector flips
    axis = np.array([0.3, 0.9, 0.1]) / np.linalg.norm([0.3, 0.9, 0.1])
    principal = Rotation.from_rotvec(np.outer(angle, axis)).as_rotvec()
    assert np.max(np.linalg.norm(np.diff(principal, axis=0), axis=-1)) > np.pi  # the jump is real
    smooth = rot.continuous_expmap(principal)
    assert np.max(np.linalg.norm(np.diff(smooth, axis=0), axis=-1)) < 0.05
    np.testing.assert_allclose(smooth, np.outer(angle, axis), atol=1e-9)
    np.testing.assert_allclose(rot.expmap_to_matrix(smooth), rot.expmap_to_matrix(principal), atol=1e-12)


def test_slerp_halfway_and_ends():
    q0 = Rotation.from_rotvec([0, 0, 0]).as_quat()
    q1 = Rotation.from_rotvec([0, 0, 1.0]).as_quat()
    mid = rot.slerp(q0, q1, 0.5)
    np.testing.assert_allclose(Rotation.from_quat(mid).as_rotvec(), [0, 0, 0.5], atol=1e-12)
    np.testing.assert_allclose(rot.slerp(q0, -q1, 1.0) * np.sign(rot.slerp(q0, -q1, 1.0)[3]), q1, atol=1e-12)


def test_angle_between_is_geodesic():
    a = Rotation.random(20, random_state=3)
    delta = rng.uniform(1e-8, 3.0, 20)
    b = a * Rotation.from_rotvec(np.outer(delta, [1, 0, 0]))
    np.testing.assert_allclose(rot.rotation_angle_between(a.as_matrix(), b.as_matrix()), delta, rtol=1e-6, atol=1e-12)
