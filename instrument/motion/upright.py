"""Which way is up in a capture, and the capture turned so that Y is up.

Everything after reading (features, steps, feet, the lock) takes Y as up, as most BVH files do;
a capture exported from a Z-up scene (Blender's, 3ds Max's, some suits' tools) has its body
lying along Y. What is up is found from the motion, not the file: over the take's frames, the
body's extent (its joints' spread along an axis) is largest along the vertical for a walker
(standing height against a stride or a shoulder width), and of the two ends of that axis the
floor is where the legs hang: the joint furthest from the body's middle along the axis is a foot
(a standing body's feet are further below its middle joint than its head is above it). That
holds for a walk, a stand and a walk in place alike; which end stays still does not (on a
treadmill or in an exporter's "in place" walk the planted foot moves backwards while the head
stays, so "the still end is the floor" turned such takes upside down).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..errors import UserError
from .bvh import Motion, Skeleton
from .kinematics import channels_from_local, forward_kinematics, local_transforms
from .rotations import axis_angle_matrix

# the turn that brings each up axis to +Y (right-handed; +Z up -> +Y keeps +X and sends +Y to -Z,
# as Blender's BVH exporter and importer convert)
TO_Y_UP = {
    "+Y": np.eye(3),
    "-Y": axis_angle_matrix("x", np.pi),
    "+Z": axis_angle_matrix("x", -np.pi / 2),
    "-Z": axis_angle_matrix("x", np.pi / 2),
    "+X": axis_angle_matrix("z", np.pi / 2),
    "-X": axis_angle_matrix("z", -np.pi / 2),
}
SAMPLED_FRAMES = 64  # frames the up axis is judged on (evenly spread over the take)


def up_axis(motion: Motion) -> str:
    """'+Y', '+Z', '-Y', ... : the axis the body stands along, with its sign (see the module's text)."""
    if motion.frames < 1 or len(motion.skeleton.joints) < 3:
        return "+Y"
    sampled = np.unique(np.linspace(0, motion.frames - 1, min(SAMPLED_FRAMES, motion.frames)).astype(int))
    picked = Motion(motion.skeleton, motion.channels[sampled], motion.fps)
    now = forward_kinematics(picked.skeleton, *local_transforms(picked))[1]
    body = _body(now)
    top, bottom = np.where(body[..., None], now, -np.inf).max(axis=1), np.where(body[..., None], now, np.inf).min(axis=1)
    extent = np.median(top - bottom, axis=0)
    axis = int(np.argmax(extent))
    height = np.where(body, now[..., axis], np.nan)
    kept = height[:, ~np.isnan(height).all(axis=0)]
    relative = np.nanmedian(kept - np.nanmedian(kept, axis=1, keepdims=True), axis=0)  # each joint from the middle
    up = -1.0 if relative[np.nanargmax(np.abs(relative))] > 0 else 1.0  # the furthest is a foot: below
    return ("+" if up > 0 else "-") + "XYZ"[axis]


def _body(positions: np.ndarray) -> np.ndarray:
    """(frames, joints) True for the joints of the body: not a floor or scene joint standing apart
    (a static root at the origin while the walker is metres away), i.e. within four times the
    joints' median distance from their median point."""
    centre = np.median(positions, axis=1, keepdims=True)
    distance = np.linalg.norm(positions - centre, axis=2)
    return distance <= 4.0 * np.median(distance, axis=1, keepdims=True) + 1e-12


def upright(motion: Motion) -> tuple[Motion, str]:
    """The motion turned so that Y is up (its root's rotation and position turned; every other
    joint as it was), and the up axis it had. A Y-up motion comes back unchanged."""
    axis = up_axis(motion)
    if axis == "+Y":
        return motion, axis
    turn = TO_Y_UP[axis]
    rotations, translations = local_transforms(motion)
    roots = [j for j, joint in enumerate(motion.skeleton.joints) if joint.parent < 0]
    rotations[:, roots] = turn @ rotations[:, roots]
    translations[:, roots] = translations[:, roots] @ turn.T
    joints = list(motion.skeleton.joints)
    for j in roots:
        if not joints[j].rotation_order:
            raise UserError(f"{motion.source or 'the take'}: {axis[1]} is up in this capture ({axis}), and its root "
                            f"{joints[j].name!r} has no rotation channels to turn it Y up: export it with Y up")
        if not joints[j].position_axes:  # the root's place is its offset: turned with it
            joints[j] = replace(joints[j], offset=tuple(float(v) for v in turn @ np.asarray(joints[j].offset)))
    skeleton = Skeleton(tuple(joints))
    return Motion(skeleton, channels_from_local(skeleton, rotations, translations), motion.fps, motion.source), axis


def upright_take(motion: Motion) -> tuple[Motion, str]:
    """`upright` for a take of more than one frame, as `convert` and `render` show it (glTF is Y up;
    a Z-up capture lay on its back); a one-frame pose (a T-pose rest, whose arms may span as far
    as it stands tall) is left as it is, its up axis taken as +Y."""
    return upright(motion) if motion.frames > 1 else (motion, "+Y")
