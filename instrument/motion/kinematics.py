"""Local joint transforms from BVH channels, and forward kinematics to world space."""

from __future__ import annotations

import numpy as np
from numba import njit

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


class ChannelStream:
    """BVH channel values of one frame at a time, each Euler angle unwrapped against the frame
    before (the multiple of 360 degrees that brings it nearest), so a recording's curves never
    jump a turn, as `channels_from_local` keeps a whole walk's. A recording and `synth` both
    write through one, so the same poses give the same lines."""

    def __init__(self, skeleton: Skeleton):
        self.skeleton = skeleton
        self.angles = np.array([c.endswith("rotation") for joint in skeleton.joints for c in joint.channels])
        self.previous: np.ndarray | None = None

    def next(self, rotations: np.ndarray, translations: np.ndarray) -> np.ndarray:
        """Channel values (C,) of a frame's local rotations (J, 3, 3) and translations (J, 3)."""
        out = channels_from_local(self.skeleton, rotations[None], translations[None])[0]
        if self.previous is not None:
            turns = np.round((out[self.angles] - self.previous[self.angles]) / 360.0)
            out[self.angles] -= 360.0 * turns
        self.previous = out
        return out


def forward_kinematics(
    skeleton: Skeleton, rotations: np.ndarray, translations: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (T, J, 3, 3) and world positions (T, J, 3) of every joint."""
    rotations = np.ascontiguousarray(rotations, dtype=np.float64)
    translations = np.ascontiguousarray(translations, dtype=np.float64)
    world_rot = np.empty_like(rotations)
    world_pos = np.empty_like(translations)
    _compose(skeleton.parents, rotations, translations, world_rot, world_pos)
    return world_rot, world_pos


@njit(cache=True, nogil=True)
def _compose(parents, rotations, translations, world_rot, world_pos):  # pragma: no cover - compiled
    """Each joint's world transform from its parent's (a BVH lists parents before children).

    A recurrence down the tree: numpy would need one call per joint (or per depth), ~100 us for
    a live frame; compiled, it is a few microseconds."""
    for t in range(rotations.shape[0]):
        rot, trans, wrot, wpos = rotations[t], translations[t], world_rot[t], world_pos[t]
        for j in range(parents.shape[0]):
            compose_joint(parents, rot, trans, wrot, wpos, j)


@njit(cache=True, nogil=True, inline="always")
def compose_joint(parents, rotations, translations, world_rot, world_pos, j):  # pragma: no cover - compiled
    """Joint j's world transform from its parent's, in one frame's arrays (J, 3, 3) and (J, 3):
    `_compose`'s step, which the foot lock also takes for the joints of a leg it turns."""
    p = parents[j]
    if p < 0:
        for a in range(3):
            for b in range(3):
                world_rot[j, a, b] = rotations[j, a, b]
            world_pos[j, a] = translations[j, a]
        return
    for a in range(3):
        for b in range(3):
            world_rot[j, a, b] = (world_rot[p, a, 0] * rotations[j, 0, b] + world_rot[p, a, 1] * rotations[j, 1, b]
                                  + world_rot[p, a, 2] * rotations[j, 2, b])
        world_pos[j, a] = world_pos[p, a] + (world_rot[p, a, 0] * translations[j, 0] + world_rot[p, a, 1] * translations[j, 1]
                                             + world_rot[p, a, 2] * translations[j, 2])


def world_positions(motion: Motion) -> np.ndarray:
    return forward_kinematics(motion.skeleton, *local_transforms(motion))[1]
