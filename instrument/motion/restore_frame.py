"""`features.restore_local` for one frame of N characters at once, compiled.

A live frame restores one row of features per character, each continuing its own root path
(position and heading). Done with numpy, that is some forty small array operations a frame
whatever N is; compiled, one loop over characters and joints (the rotations as scipy's
`Rotation.from_rotvec(...).as_matrix()` computes them: through the unit quaternion).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from .features import ROOT_FEATURES, FeatureLayout


class FrameRestorer:
    """The layout's constant arrays, laid out for the kernel."""

    def __init__(self, layout: FeatureLayout, fps: float):
        template_rot, template_trans, parent_rot, parent_pos = layout.template_pose
        self.template_rot = np.ascontiguousarray(template_rot)
        self.template_trans = np.ascontiguousarray(template_trans)
        self.parent_rot = np.ascontiguousarray(parent_rot)
        self.parent_pos = np.ascontiguousarray(parent_pos, dtype=np.float64)
        self.root = int(layout.root)
        self.joints = np.asarray(layout.joints, dtype=np.int64)
        self.reference = np.ascontiguousarray(layout.reference)
        self.root_reference = np.ascontiguousarray(layout.heading_reference)
        self.fps = float(fps)

    def next(self, static: np.ndarray, positions: np.ndarray, headings: np.ndarray,
             rotations: np.ndarray, translations: np.ndarray) -> None:
        """Local rotations (N, J, 3, 3) and translations (N, J, 3) written from features (N, D);
        each character's root `positions` (N, 3) and `headings` (N,) move on one frame."""
        restore_next(np.ascontiguousarray(static, dtype=np.float64), positions, headings, self.template_rot,
                     self.template_trans, self.parent_rot, self.parent_pos, self.root, self.joints, self.reference,
                     self.root_reference, self.fps, rotations, translations)


@njit(cache=True, error_model="numpy")
def expmap_matrix(x: float, y: float, z: float, out) -> None:  # pragma: no cover - compiled
    """Rotation matrix of the rotation vector (x, y, z), written into `out` (3, 3)."""
    angle = np.sqrt(x * x + y * y + z * z)
    if angle <= 1e-3:  # scipy's Taylor series of sin(angle / 2) / angle
        angle2 = angle * angle
        scale = 0.5 - angle2 / 48.0 + angle2 * angle2 / 3840.0
    else:
        scale = np.sin(angle / 2.0) / angle
    qx, qy, qz, qw = scale * x, scale * y, scale * z, np.cos(angle / 2.0)
    x2, y2, z2, w2 = qx * qx, qy * qy, qz * qz, qw * qw
    xy, zw, xz, yw, yz, xw = qx * qy, qz * qw, qx * qz, qy * qw, qy * qz, qx * qw
    out[0, 0], out[0, 1], out[0, 2] = x2 - y2 - z2 + w2, 2.0 * (xy - zw), 2.0 * (xz + yw)
    out[1, 0], out[1, 1], out[1, 2] = 2.0 * (xy + zw), -x2 + y2 - z2 + w2, 2.0 * (yz - xw)
    out[2, 0], out[2, 1], out[2, 2] = 2.0 * (xz - yw), 2.0 * (yz + xw), -x2 - y2 + z2 + w2


@njit(cache=True, error_model="numpy")
def _multiply(a, b, out) -> None:  # pragma: no cover - compiled
    """out = a @ b for 3x3 matrices (no BLAS call for so small a product)."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@njit(cache=True, nogil=True, error_model="numpy")
def restore_next(static, positions, headings, template_rot, template_trans, parent_rot, parent_pos, root, joints,
                 reference, root_reference, fps, rotations, translations):  # pragma: no cover - compiled
    """See `FrameRestorer.next`; the arithmetic of `features.restore_local` for one frame."""
    first = len(ROOT_FEATURES)
    tilt = np.empty((3, 3))
    heading = np.zeros((3, 3))
    root_rot = np.empty((3, 3))
    swing = np.empty((3, 3))
    local = np.empty((3, 3))
    for n in range(static.shape[0]):
        row = static[n]
        c, s = np.cos(headings[n]), np.sin(headings[n])  # the heading: a turn about Y
        heading[0, 0], heading[0, 2], heading[1, 1], heading[2, 0], heading[2, 2] = c, s, 1.0, -s, c
        rotations[n] = template_rot
        translations[n] = template_trans
        expmap_matrix(row[4], 0.0, row[5], tilt)
        _multiply(heading, tilt, swing)
        _multiply(swing, root_reference, root_rot)  # the root's rest as the layout reads it (features.FeatureLayout.heading_reference)
        for a in range(3):
            for b in range(3):
                rotations[n, root, a, b] = (parent_rot[0, a] * root_rot[0, b] + parent_rot[1, a] * root_rot[1, b]
                                            + parent_rot[2, a] * root_rot[2, b])  # parent_rot.T @ root_rot
        root_pos = positions[n].copy()
        root_pos[1] = row[0]
        for b in range(3):
            translations[n, root, b] = ((root_pos[0] - parent_pos[0]) * parent_rot[0, b]
                                        + (root_pos[1] - parent_pos[1]) * parent_rot[1, b]
                                        + (root_pos[2] - parent_pos[2]) * parent_rot[2, b])
        for k in range(joints.shape[0]):
            at = first + 3 * k
            expmap_matrix(row[at], row[at + 1], row[at + 2], local)
            _multiply(reference[k], local, rotations[n, joints[k]])
        vx, vz = row[1], row[2]
        positions[n, 0] += (c * vx + s * vz) / fps  # heading @ (vx, 0, vz) / fps
        positions[n, 2] += (-s * vx + c * vz) / fps
        headings[n] += row[3] / fps
