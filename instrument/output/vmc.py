"""The VMC profile: the de facto OSC stream for humanoid avatars (VSeeFace, Warudo, EVMC4U, VMC4B...).

Receivers set each humanoid bone's local rotation on a normalised avatar, whose bones all have
identity rotations in a T-pose facing +Z (Unity: left-handed, Y up, metres). So rotations are
sent relative to a T-pose of our own skeleton: each bone's world rotation is compared with its
world rotation in that T-pose, and the comparison is expressed in the frame of its humanoid
parent. Our T-pose is the model's template pose, turned so the walk heads forward, with every
bone swung to the T-pose direction (spine up, legs down, arms out sideways, feet forward).

Per frame, in bundles of at most 1,400 bytes:
    /VMC/Ext/Root/Pos  s"root" fff ffff    the avatar's origin (identity: the hips carry the walk)
    /VMC/Ext/Bone/Pos  s<HumanBone> fff ffff   local position and rotation of each mapped bone
    /VMC/Ext/OK i1, /VMC/Ext/T f<seconds>
"""

from __future__ import annotations

import numpy as np

from ..motion.bvh import Motion
from ..motion.features import FeatureLayout, extract, restore_local
from ..motion.kinematics import forward_kinematics
from ..motion.rotations import axis_angle_matrix
from ..runtime.pose import Pose, quaternions
from .osc import bundles, float_messages, float_prefix, message

UP, DOWN, FORWARD = np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, -1.0])
LEFT, RIGHT = np.array([-1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])  # in the source frame, facing -Z
DIRECTIONS = {
    "Hips": UP, "Spine": UP, "Chest": UP, "UpperChest": UP, "Neck": UP, "Head": UP,
    "LeftShoulder": LEFT, "LeftUpperArm": LEFT, "LeftLowerArm": LEFT, "LeftHand": LEFT,
    "RightShoulder": RIGHT, "RightUpperArm": RIGHT, "RightLowerArm": RIGHT, "RightHand": RIGHT,
    "LeftUpperLeg": DOWN, "LeftLowerLeg": DOWN, "RightUpperLeg": DOWN, "RightLowerLeg": DOWN,
    "LeftFoot": FORWARD, "LeftToes": FORWARD, "RightFoot": FORWARD, "RightToes": FORWARD,
}
CHAIN_NEXT = {"Hips": ("Spine",), "Spine": ("Chest", "UpperChest", "Neck"), "Chest": ("UpperChest", "Neck"),
              "UpperChest": ("Neck",), "Neck": ("Head",)}
UNITY = np.array([-1.0, -1.0, 1.0, 1.0])  # right-handed (x, y, z, w) -> Unity's left-handed, Z flipped


def units_to_metres(hip_height: float) -> float:
    """Guess the data's unit from the hips' height: centimetres, metres or inches."""
    for scale in (0.01, 1.0, 0.0254):
        if 0.5 <= hip_height * scale <= 1.5:
            return scale
    return 0.95 / hip_height if hip_height > 0 else 1.0


def _template_world(layout: FeatureLayout) -> tuple[np.ndarray, np.ndarray]:
    """World rotations and positions of the template pose, turned to heading 0."""
    template = Motion(layout.skeleton, np.asarray(layout.template)[None], 30.0)
    features, _, _ = extract(template, layout)
    features[:, 1:4] = 0.0
    rotations, translations, _ = restore_local(features, layout, 30.0)
    world_rot, world_pos = forward_kinematics(layout.skeleton, rotations, translations)
    return world_rot[0], world_pos[0]


def _swing(source: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction `source` onto `target`."""
    a, b = source / np.linalg.norm(source), target / np.linalg.norm(target)
    axis, cos = np.cross(a, b), float(np.dot(a, b))
    if np.linalg.norm(axis) < 1e-9:
        if cos > 0:
            return np.eye(3)
        perpendicular = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
        axis, cos = perpendicular / np.linalg.norm(perpendicular), -1.0
    skew = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + skew + skew @ skew / (1.0 + cos)


class VmcProfile:
    def __init__(self, layout: FeatureLayout, mapping: dict[str, str], forward: np.ndarray, scale: float | None = None):
        skeleton = layout.skeleton
        names = skeleton.names
        self.joints = [names.index(j) for j in mapping]
        self.bones = [mapping[names[j]] for j in self.joints]
        self.bone_prefixes = [float_prefix("/VMC/Ext/Bone/Pos", 7, bone) for bone in self.bones]
        # turn the walk so it heads to -Z here, which is +Z (the avatar's front) after the Z flip
        phi = float(np.arctan2(forward[0], forward[2]))
        self.turn = axis_angle_matrix("y", np.pi - phi)
        world_rot, world_pos = _template_world(layout)
        self.scale = units_to_metres(float(world_pos[layout.root][1])) if scale is None else scale
        by_bone = {mapping[names[j]]: j for j in self.joints}
        rest = []
        for j, bone in zip(self.joints, self.bones):
            target = self._direction_child(skeleton, j, bone, by_bone)
            direction = None
            if target is not None:
                direction = world_pos[target] - world_pos[j]
            elif skeleton.joints[j].end_site is not None:
                direction = world_rot[j] @ np.asarray(skeleton.joints[j].end_site)
            turned = self.turn @ world_rot[j]
            if direction is not None and np.linalg.norm(direction) > 1e-9:
                turned = _swing(self.turn @ direction, DIRECTIONS[bone]) @ turned
            rest.append(turned)
        self.rest_inverse = np.transpose(np.array(rest), (0, 2, 1))
        self.parents = np.array([self._mapped_parent(skeleton, j) for j in self.joints])
        self.has_parent = self.parents >= 0
        self.parent_rows = np.where(self.has_parent, self.parents, np.arange(len(self.joints)))

    @staticmethod
    def _direction_child(skeleton, joint: int, bone: str, by_bone: dict[str, int]) -> int | None:
        for successor in CHAIN_NEXT.get(bone, ()):
            if successor in by_bone:
                return by_bone[successor]
        children = skeleton.children(joint)
        return children[0] if children else None

    def _mapped_parent(self, skeleton, joint: int) -> int:
        """Index into self.joints of the nearest mapped ancestor, -1 for none."""
        p = skeleton.parents[joint]
        while p >= 0:
            if p in self.joints:
                return self.joints.index(p)
            p = skeleton.parents[p]
        return -1

    def bone_transforms(self, pose: Pose) -> tuple[np.ndarray, np.ndarray]:
        """Per mapped bone: Unity quaternion (x, y, z, w) and Unity local position (metres)."""
        normalised = self.turn @ pose.world_rotations[self.joints] @ self.rest_inverse  # world deltas from the T-pose
        # in the frame of the humanoid parent; a bone without one (the hips) stays in world space
        parent_frames = np.where(self.has_parent[:, None, None], normalised[self.parent_rows], np.eye(3))
        local = np.transpose(parent_frames, (0, 2, 1)) @ normalised
        world = pose.world_positions[self.joints] @ self.turn.T
        offsets = world - np.where(self.has_parent[:, None], world[self.parent_rows], 0.0)
        positions = np.einsum("kji,kj->ki", parent_frames, offsets) * self.scale * np.array([1.0, 1.0, -1.0])
        return quaternions(local) * UNITY, positions

    def datagrams(self, pose: Pose, echo: dict[str, float]) -> list[bytes]:
        quats, positions = self.bone_transforms(pose)
        messages = [message("/VMC/Ext/Root/Pos", "root", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)]
        messages += float_messages(self.bone_prefixes, np.hstack([positions, quats]))
        messages += [message("/VMC/Ext/OK", 1), message("/VMC/Ext/T", float(pose.time))]
        return bundles(messages)


def forward_direction(average_static_means: np.ndarray) -> np.ndarray:
    """The direction of travel in the heading frame, from the model's mean root speeds."""
    vx, vz = average_static_means[..., 1].mean(), average_static_means[..., 2].mean()
    return np.array([vx, 0.0, vz])

