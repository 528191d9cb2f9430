"""Rotation conversions, vectorised over any leading shape, plus continuity over time.

Conversions delegate to scipy's Rotation (well tested, any Euler order). Quaternions are
(x, y, z, w), scipy's and Unity's order. Exponential maps are rotation vectors (axis * angle,
radians). BVH Euler channels are intrinsic rotations in file order: 'Zrotation Xrotation
Yrotation' means R = Rz @ Rx @ Ry, which scipy spells as the upper-case order 'ZXY'.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

TWO_PI = 2.0 * np.pi


def _flat(x: np.ndarray, tail: int) -> tuple[np.ndarray, tuple[int, ...]]:
    x = np.asarray(x, dtype=np.float64)
    return x.reshape((-1,) + x.shape[x.ndim - tail :]), x.shape[: x.ndim - tail]


def euler_to_matrix(angles_deg: np.ndarray, order: str) -> np.ndarray:
    flat, lead = _flat(angles_deg, 1)
    return Rotation.from_euler(order.upper(), flat, degrees=True).as_matrix().reshape(lead + (3, 3))


def matrix_to_euler(matrix: np.ndarray, order: str) -> np.ndarray:
    """Euler angles in degrees; along axis 0 (time) they are unwrapped so curves never jump 360."""
    flat, lead = _flat(matrix, 2)
    angles = Rotation.from_matrix(flat).as_euler(order.upper(), degrees=True).reshape(lead + (3,))
    if angles.ndim > 1 and angles.shape[0] > 1:
        angles = np.rad2deg(np.unwrap(np.deg2rad(angles), axis=0))
    return angles


def matrix_to_quat(matrix: np.ndarray) -> np.ndarray:
    """Quaternions of proper rotation matrices (every matrix here is a product of rotations, so
    scipy's orthogonalisation, 5x the cost of the conversion, is skipped)."""
    flat, lead = _flat(matrix, 2)
    return Rotation.from_matrix(flat, assume_valid=True).as_quat().reshape(lead + (4,))


def quat_to_matrix(quat: np.ndarray) -> np.ndarray:
    flat, lead = _flat(quat, 1)
    return Rotation.from_quat(flat).as_matrix().reshape(lead + (3, 3))


def expmap_to_matrix(expmap: np.ndarray) -> np.ndarray:
    flat, lead = _flat(expmap, 1)
    return Rotation.from_rotvec(flat).as_matrix().reshape(lead + (3, 3))


def matrix_to_expmap(matrix: np.ndarray) -> np.ndarray:
    """Rotation vectors with angle in [0, pi]; see `continuous_expmap` for curves over time."""
    flat, lead = _flat(matrix, 2)
    return Rotation.from_matrix(flat).as_rotvec().reshape(lead + (3,))


def expmap_to_quat(expmap: np.ndarray) -> np.ndarray:
    flat, lead = _flat(expmap, 1)
    return Rotation.from_rotvec(flat).as_quat().reshape(lead + (4,))


def quat_to_expmap(quat: np.ndarray) -> np.ndarray:
    flat, lead = _flat(quat, 1)
    return Rotation.from_quat(flat).as_rotvec().reshape(lead + (3,))


def axis_angle_matrix(axis: str, angle: np.ndarray) -> np.ndarray:
    """Rotation matrices about one coordinate axis ('x', 'y' or 'z') by angles in radians."""
    angle = np.asarray(angle, dtype=np.float64)
    c, s = np.cos(angle), np.sin(angle)
    i = "xyz".index(axis.lower())
    j, k = (i + 1) % 3, (i + 2) % 3  # the plane the rotation turns, in right-handed order
    out = np.zeros(angle.shape + (3, 3))
    out[..., i, i] = 1.0
    out[..., j, j] = out[..., k, k] = c
    out[..., j, k], out[..., k, j] = -s, s
    return out


def continuous_quaternions(quat: np.ndarray) -> np.ndarray:
    """Flip signs along axis 0 so consecutive quaternions have a non-negative dot product."""
    quat = np.array(quat, dtype=np.float64)
    if quat.shape[0] < 2:
        return quat
    dots = np.sum(quat[1:] * quat[:-1], axis=-1)
    flips = np.cumprod(np.where(dots < 0, -1.0, 1.0), axis=0)
    quat[1:] *= flips[..., None]
    return quat


def continuous_expmap(expmap: np.ndarray, reference: np.ndarray | None = None) -> np.ndarray:
    """Along axis 0, replace each rotation vector by the equivalent nearest the previous one.

    The equivalents of axis*angle are axis*(angle + 2*pi*k); the best k is the one whose length
    along the axis is nearest the previous vector's projection. `reference` (one frame) seeds
    the first frame, so a continued curve joins the curve before it.
    """
    expmap = np.array(expmap, dtype=np.float64)
    angle = np.linalg.norm(expmap, axis=-1)
    safe = np.where(angle > 1e-12, angle, 1.0)
    axis = expmap / safe[..., None]
    previous = None if reference is None else np.asarray(reference, dtype=np.float64)
    for t in range(expmap.shape[0]):
        if previous is not None:
            along = np.sum(previous * axis[t], axis=-1)
            k = np.round((along - angle[t]) / TWO_PI)
            expmap[t] = axis[t] * (angle[t] + TWO_PI * k)[..., None]
        previous = expmap[t]
    return expmap


def slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Spherical interpolation between unit quaternions, elementwise; takes the short way round."""
    q0 = np.asarray(q0, dtype=np.float64)
    q1 = np.asarray(q1, dtype=np.float64)
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_theta = np.sin(theta)
    near = sin_theta < 1e-9
    w0 = np.where(near, 1.0 - t, np.sin((1.0 - t) * theta) / np.where(near, 1.0, sin_theta))
    w1 = np.where(near, t, np.sin(t * theta) / np.where(near, 1.0, sin_theta))
    out = w0 * q0 + w1 * q1
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def rotation_angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Geodesic angle (radians) between rotation matrices, elementwise."""
    rel = np.einsum("...ji,...jk->...ik", a, b)
    cos = (np.trace(rel, axis1=-2, axis2=-1) - 1.0) / 2.0
    # arccos is ill-conditioned near 0: use the skew part as well
    skew = np.stack([rel[..., 2, 1] - rel[..., 1, 2], rel[..., 0, 2] - rel[..., 2, 0], rel[..., 1, 0] - rel[..., 0, 1]], -1)
    return np.arctan2(np.linalg.norm(skew, axis=-1) / 2.0, cos)
