"""Our skeleton in the T-pose of a Unity-normalised humanoid: the reference the VMC profile sends from.

A normalised humanoid (a VRM avatar, Unity's Humanoid after normalisation) has identity
rotations in its T-pose: spine, neck and head upright, arms out sideways with the palms down,
hands along the forearms, legs straight down, feet flat on the floor with the toes straight
ahead. A VMC receiver (EVMC4U and the apps built like it) writes each received local rotation
straight into such bones. So each mapped joint needs its world rotation in that same T-pose (its
"reference"); a frame's world rotation times the reference's inverse is then the avatar bone's
world rotation.

The references are found in the source frame (right-handed, Y up, the walk heading -Z):
- torso (Hips, Spine, Chest, UpperChest, Neck, Head): the template pose's joint turned so the
  bone points up and the hip line (the shoulder line above the spine) runs across;
- Shoulder, UpperArm, UpperLeg: the template's joint swung by the smallest rotation onto the
  T-pose direction, then turned about it so the hinge below (elbow, knee), as bent in the
  template, turns about its T-pose axis: the vertical for an elbow (palms down), the left-right
  axis for a knee;
- LowerArm, Hand, LowerLeg: the parent's reference carried on at the skeleton's rest (identity
  local rotations, the straight limb of every BVH convention) and swung onto the T-pose
  direction, so forearm twist and wrist bend read as they do in the data;
- Foot, Toes: the foot flat on the floor, from the flattest stance available (of the poses
  given, the one with that ankle lowest), turned so the toes point straight ahead.
An end bone whose End Site has no length (the shipped skeleton's hands, head and toes) points
where its own offset points: along its parent bone at rest.
"""

from __future__ import annotations

import numpy as np

from ..motion.bvh import Skeleton

UP, DOWN, FORWARD = np.array([0.0, 1.0, 0.0]), np.array([0.0, -1.0, 0.0]), np.array([0.0, 0.0, -1.0])
LEFT, RIGHT = np.array([-1.0, 0.0, 0.0]), np.array([1.0, 0.0, 0.0])  # the character's, facing -Z
DIRECTIONS = {
    "Hips": UP, "Spine": UP, "Chest": UP, "UpperChest": UP, "Neck": UP, "Head": UP,
    "LeftShoulder": LEFT, "LeftUpperArm": LEFT, "LeftLowerArm": LEFT, "LeftHand": LEFT,
    "RightShoulder": RIGHT, "RightUpperArm": RIGHT, "RightLowerArm": RIGHT, "RightHand": RIGHT,
    "LeftUpperLeg": DOWN, "LeftLowerLeg": DOWN, "RightUpperLeg": DOWN, "RightLowerLeg": DOWN,
    "LeftFoot": FORWARD, "LeftToes": FORWARD, "RightFoot": FORWARD, "RightToes": FORWARD,
}
TORSO = ("Hips", "Spine", "Chest", "UpperChest", "Neck", "Head")
CARRIED = ("LowerArm", "Hand", "LowerLeg")  # after the side prefix
CHAIN_NEXT = {"Hips": ("Spine",), "Spine": ("Chest", "UpperChest", "Neck"), "Chest": ("UpperChest", "Neck"),
              "UpperChest": ("Neck",), "Neck": ("Head",)}
TIP = {"LeftHand", "RightHand", "Head", "LeftToes", "RightToes"}  # point along their own offset
# a limb's root, the hinge below it, and the axis that hinge turns about in the T-pose: an elbow
# bends the forearm forward (palms down: about the vertical), a knee the shin back (across)
HINGES = {"LeftUpperArm": ("LeftLowerArm", UP), "RightUpperArm": ("RightLowerArm", UP),
          "LeftUpperLeg": ("LeftLowerLeg", RIGHT), "RightUpperLeg": ("RightLowerLeg", RIGHT)}
MIN_HINGE_BEND = np.radians(8.0)  # a straighter limb in the template tells nothing about its hinge


def swing(source: np.ndarray, target: np.ndarray) -> np.ndarray:
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


def square(direction: np.ndarray, across: np.ndarray, target: np.ndarray, target_across: np.ndarray) -> np.ndarray:
    """The rotation taking `direction` onto `target` and `across` (made perpendicular) onto `target_across`."""
    def frame(d, c):
        d = d / np.linalg.norm(d)
        c = c - d * np.dot(c, d)
        c = c / np.linalg.norm(c)
        return np.stack([d, c, np.cross(d, c)], axis=1)
    return frame(target, target_across) @ frame(direction, across).T


def yaw_to_forward(direction: np.ndarray) -> np.ndarray:
    """The rotation about Y turning `direction`'s horizontal part straight ahead (-Z)."""
    angle = np.arctan2(direction[0], direction[2]) - np.arctan2(FORWARD[0], FORWARD[2])
    c, s = np.cos(-angle), np.sin(-angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


class TPose:
    """Per mapped joint, its world rotation when the avatar stands in its normalised T-pose.

    `template_rot`/`template_pos` are the template pose's world rotations and positions, and
    `stance_rot`/`stance_pos` (N poses) candidate flat-footed poses, all already turned so the
    walk heads -Z.
    """

    def __init__(self, skeleton: Skeleton, joints: list[int], bones: list[str],
                 template_rot: np.ndarray, template_pos: np.ndarray, stance_rot: np.ndarray, stance_pos: np.ndarray):
        self.skeleton = skeleton
        self.by_bone = dict(zip(bones, joints))
        self.template_rot, self.template_pos = template_rot, template_pos
        self.stance_rot, self.stance_pos = stance_rot, stance_pos
        self.rotations: dict[str, np.ndarray] = {}
        for joint, bone in sorted(zip(joints, bones)):  # a BVH lists parents first
            self.rotations[bone] = self._reference(joint, bone)

    def local_direction(self, joint: int, bone: str) -> np.ndarray | None:
        """Where the bone points in its own frame (None if it has no length at all)."""
        skeleton = self.skeleton
        target = None
        for successor in CHAIN_NEXT.get(bone, ()):
            if successor in self.by_bone:
                target = self.by_bone[successor]
                break
        children = skeleton.children(joint)
        if target is None and children and bone not in TIP:
            target = children[0]
        if target is not None:
            vector = self.template_rot[joint].T @ (self.template_pos[target] - self.template_pos[joint])
        else:
            vector = skeleton.offsets[joint]  # along the parent bone at rest
            if np.linalg.norm(vector) < 1e-9 and skeleton.joints[joint].end_site is not None:
                vector = np.asarray(skeleton.joints[joint].end_site, dtype=float)
        norm = np.linalg.norm(vector)
        return vector / norm if norm > 1e-9 else None

    def _mapped_parent(self, joint: int) -> str | None:
        parent = self.skeleton.parents[joint]
        while parent >= 0:
            for bone, j in self.by_bone.items():
                if j == parent and bone in self.rotations:
                    return bone
            parent = self.skeleton.parents[parent]
        return None

    def _across(self, bone: str) -> np.ndarray | None:
        """The body's left-pointing line for a torso bone: the hips' or the shoulders'."""
        pairs = [("LeftUpperLeg", "RightUpperLeg"), ("LeftUpperArm", "RightUpperArm"), ("LeftShoulder", "RightShoulder")]
        if bone not in ("Hips", "Spine"):
            pairs = pairs[1:] + pairs[:1]
        for left, right in pairs:  # a line of no length (CMU's collars both start at the neck) is no line
            if left in self.by_bone and right in self.by_bone:
                line = self.template_pos[self.by_bone[left]] - self.template_pos[self.by_bone[right]]
                if np.linalg.norm(line) > 1e-9:
                    return line
        return None

    def _reference(self, joint: int, bone: str) -> np.ndarray:
        direction = self.local_direction(joint, bone)
        target = DIRECTIONS[bone]
        side_free = bone.removeprefix("Left").removeprefix("Right")
        if bone.endswith(("Foot", "Toes")):
            return self._flat_foot(joint, bone)
        parent = self._mapped_parent(joint)
        if side_free in CARRIED and parent is not None:
            carried = self.rotations[parent]  # identity local rotations down to this joint
        else:
            carried = self.template_rot[joint]
        if direction is None:
            return carried
        world_direction = carried @ direction
        across = self._across(bone) if bone in TORSO else None
        if across is not None:
            return square(world_direction, across, target, LEFT) @ carried
        reference = swing(world_direction, target) @ carried
        return self._hinge_roll(joint, bone, reference) @ reference

    def _hinge_roll(self, joint: int, bone: str, reference: np.ndarray) -> np.ndarray:
        """The turn about a limb's T-pose direction that lines up the hinge below it (elbow,
        knee), as bent in the template, with its T-pose axis: the limb's roll, normalised."""
        if bone not in HINGES or HINGES[bone][0] not in self.by_bone:
            return np.eye(3)
        lower_bone, hinge_axis = HINGES[bone]
        lower = self.by_bone[lower_bone]
        direction = self.local_direction(lower, lower_bone)
        if direction is None:
            return np.eye(3)
        upper_vector = self.template_pos[lower] - self.template_pos[joint]
        lower_vector = self.template_rot[lower] @ direction
        hinge = np.cross(upper_vector, lower_vector)
        if np.linalg.norm(hinge) < np.sin(MIN_HINGE_BEND) * np.linalg.norm(upper_vector) * np.linalg.norm(lower_vector):
            return np.eye(3)
        target = DIRECTIONS[bone]
        hinge = reference @ self.template_rot[joint].T @ hinge  # where the hinge lies once the limb is in the T-pose
        hinge -= target * np.dot(hinge, target)
        return swing(hinge, hinge_axis if np.dot(hinge, hinge_axis) >= 0 else -hinge_axis)

    def _flat_foot(self, joint: int, bone: str) -> np.ndarray:
        side = "Left" if bone.startswith("Left") else "Right"
        foot = self.by_bone.get(f"{side}Foot", joint)
        flattest = int(np.argmin(self.stance_pos[:, foot, 1]))
        rotations, positions = self.stance_rot[flattest], self.stance_pos[flattest]
        children = self.skeleton.children(foot)
        toes = self.by_bone.get(f"{side}Toes", children[0] if children else None)
        if toes is not None:
            along = positions[toes] - positions[foot]
        else:
            direction = self.local_direction(foot, f"{side}Foot")
            along = rotations[foot] @ direction if direction is not None else FORWARD
        return yaw_to_forward(along) @ rotations[joint]
