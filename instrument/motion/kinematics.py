"""Local joint transforms from BVH channels, and forward kinematics to world space."""

from __future__ import annotations

import numpy as np

from .bvh import Motion, Skeleton
from .rotations import euler_to_matrix, matrix_to_euler

AXIS_INDEX = {"X": 0, "Y": 1, "Z": 2}


def local_transforms(motion: Motion) -> tuple[np.ndarray, np.ndarray]:
    """Per frame and joint: local rotation matrices (T, J, 3, 3) and translations (T, J, 3).

    Position channels replace the joint's offset (the usual BVH reading); a joint without
    them sits at its offset.
    """
    skeleton, channels = motion.skeleton, motion.channels
    frames, count = motion.frames, len(skeleton.joints)
    rotations = np.broadcast_to(np.eye(3), (frames, count, 3, 3)).copy()
    translations = np.broadcast_to(skeleton.offsets, (frames, count, 3)).copy()
    for j, (joint, start) in enumerate(zip(skeleton.joints, skeleton.channel_start())):
        rot_cols = [start + k for k, c in enumerate(joint.channels) if c.endswith("rotation")]
        if rot_cols:
            rotations[:, j] = euler_to_matrix(channels[:, rot_cols], joint.rotation_order)
        for k, c in enumerate(joint.channels):
            if c.endswith("position"):
                translations[:, j, AXIS_INDEX[c[0]]] = channels[:, start + k]
    return rotations, translations


def channels_from_local(skeleton: Skeleton, rotations: np.ndarray, translations: np.ndarray) -> np.ndarray:
    """The inverse of `local_transforms`: BVH channel values (T, C), Euler angles unwrapped.

    Joints sharing a rotation order are converted in one call (a file usually has one order).
    """
    frames = rotations.shape[0]
    out = np.zeros((frames, skeleton.channel_count))
    starts = skeleton.channel_start()
    orders: dict[str, list[int]] = {}
    for j, joint in enumerate(skeleton.joints):
        if joint.rotation_order:
            orders.setdefault(joint.rotation_order, []).append(j)
        for k, c in enumerate(joint.channels):
            if c.endswith("position"):
                out[:, starts[j] + k] = translations[:, j, AXIS_INDEX[c[0]]]
    for order, joints in orders.items():
        euler = matrix_to_euler(rotations[:, joints], order)  # (T, joints, 3)
        for n, j in enumerate(joints):
            for k, c in enumerate(skeleton.joints[j].channels):
                if c.endswith("rotation"):
                    out[:, starts[j] + k] = euler[:, n, order.index(c[0])]
    return out


def forward_kinematics(
    skeleton: Skeleton, rotations: np.ndarray, translations: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (T, J, 3, 3) and world positions (T, J, 3) of every joint."""
    world_rot = np.empty_like(rotations)
    world_pos = np.empty_like(translations)
    for j, parent in enumerate(skeleton.parents):
        if parent < 0:
            world_rot[:, j] = rotations[:, j]
            world_pos[:, j] = translations[:, j]
        else:
            world_rot[:, j] = world_rot[:, parent] @ rotations[:, j]
            world_pos[:, j] = world_pos[:, parent] + np.einsum("tik,tk->ti", world_rot[:, parent], translations[:, j])
    return world_rot, world_pos


def world_positions(motion: Motion) -> np.ndarray:
    return forward_kinematics(motion.skeleton, *local_transforms(motion))[1]
