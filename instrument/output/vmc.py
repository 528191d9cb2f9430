"""The VMC profile: the de facto OSC stream for humanoid avatars (EVMC4U, VMC4UE, VMC4B, VSeeFace, Warudo, VNyan...).

Receivers set each humanoid bone's local rotation on a normalised avatar, whose bones all have
identity rotations in a T-pose facing +Z (Unity: left-handed, Y up, metres). So each bone's
rotation is sent relative to our skeleton's own pose in that T-pose (see tpose.py): its world
rotation times its T-pose rotation's inverse, expressed in the frame of its humanoid parent.

Per frame, in bundles of at most 1,400 bytes (a target given as HOST:PORT/vmc-unbundled gets the
same messages one per datagram, see osc.py), in the order of the VMC specification's receivers:
    /VMC/Ext/Root/Pos  s"root" fff ffff    the avatar's origin: identity with root="hips"
                                           (the hips carry the walk, as VirtualMotionCapture's
                                           tracked body does); the path on the floor and the
                                           heading with root="path"
    /VMC/Ext/Bone/Pos  s<HumanBone> fff ffff   local position and rotation of each mapped bone,
                                           then of the finger bones (a relaxed hand) unless off
    /VMC/Ext/OK i1, /VMC/Ext/T f<seconds>
"""

from __future__ import annotations

import numpy as np

from ..motion.bvh import Motion
from ..motion.features import FeatureLayout, extract, restore_local
from ..motion.kinematics import forward_kinematics
from ..motion.limbs import hip_height, units_to_metres
from ..motion.rotations import axis_angle_matrix
from ..synthesis.posing import Pose, quaternions
from .osc import bundles, float_messages, float_prefix, message
from .tpose import TPose

UNITY = np.array([-1.0, -1.0, 1.0, 1.0])  # right-handed (x, y, z, w) -> Unity's left-handed, Z flipped
ROOT_CONVENTIONS = ("hips", "path")
# a relaxed hand: curl (degrees) of the proximal, intermediate and distal bone of each finger
RELAXED_CURL = {"Thumb": (10.0, 10.0, 10.0), "Index": (15.0, 20.0, 10.0), "Middle": (20.0, 25.0, 10.0),
                "Ring": (25.0, 25.0, 10.0), "Little": (30.0, 25.0, 10.0)}
PHALANGES = ("Proximal", "Intermediate", "Distal")


def _standing_world(layout: FeatureLayout, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rotations and positions (N, J, ...) of poses given as static features, each at heading 0."""
    features = np.array(features, dtype=np.float64)
    features[:, 1:4] = 0.0
    rotations, translations, _ = restore_local(features, layout, 30.0)
    return forward_kinematics(layout.skeleton, rotations, translations)


def _template_features(layout: FeatureLayout) -> np.ndarray:
    template = Motion(layout.skeleton, np.asarray(layout.template)[None], 30.0)
    return extract(template, layout)[0]


def relaxed_hand() -> dict[str, np.ndarray]:
    """Local rotations (source frame) of the finger bones of a relaxed hand: fingers curled
    towards the palm, which faces down in the T-pose."""
    out = {}
    for side, axis_sign in (("Left", 1.0), ("Right", -1.0)):  # curling takes the fingertips down
        for finger, curls in RELAXED_CURL.items():
            for phalanx, degrees in zip(PHALANGES, curls):
                out[f"{side}{finger}{phalanx}"] = axis_angle_matrix("z", axis_sign * np.radians(degrees))
    return out


class VmcProfile:
    def __init__(self, layout: FeatureLayout, mapping: dict[str, str], forward: np.ndarray, scale: float | None = None,
                 stance: np.ndarray | None = None, root: str = "hips", fingers: bool = True):
        """`stance`: static features of poses among which the flattest footed is found (the
        model's state means); `root`: "hips" or "path" (see the module docstring)."""
        skeleton = layout.skeleton
        names = skeleton.names
        self.root_joint, self.root_convention = layout.root, root
        self.joints = [names.index(j) for j in mapping]
        self.bones = [mapping[names[j]] for j in self.joints]
        self.bone_prefixes = [float_prefix("/VMC/Ext/Bone/Pos", 7, bone) for bone in self.bones]
        # turn the walk so it heads to -Z here, which is +Z (the avatar's front) after the Z flip
        phi = float(np.arctan2(forward[0], forward[2]))
        self.turn = axis_angle_matrix("y", np.pi - phi)
        template_features = _template_features(layout)
        template_rot, template_pos = _standing_world(layout, template_features)
        world_rot, world_pos = self.turn @ template_rot[0], template_pos[0] @ self.turn.T
        stance_rot, stance_pos = _standing_world(layout, template_features if stance is None else stance)
        self.scale = units_to_metres(hip_height(world_pos, layout.root)) if scale is None else scale
        tpose = TPose(skeleton, self.joints, self.bones, world_rot, world_pos, self.turn @ stance_rot, stance_pos @ self.turn.T)
        self.tpose = tpose
        self.rest_inverse = np.transpose(np.array([tpose.rotations[b] for b in self.bones]), (0, 2, 1))
        self.parents = np.array([self._mapped_parent(skeleton, j) for j in self.joints])
        self.has_parent = self.parents >= 0
        self.parent_rows = np.where(self.has_parent, self.parents, np.arange(len(self.joints)))
        self.finger_messages = []
        if fingers:
            curls = relaxed_hand()
            values = np.hstack([np.zeros((len(curls), 3)), quaternions(np.array(list(curls.values()))) * UNITY])
            self.finger_messages = float_messages([float_prefix("/VMC/Ext/Bone/Pos", 7, b) for b in curls], values)

    def _mapped_parent(self, skeleton, joint: int) -> int:
        """Index into self.joints of the nearest mapped ancestor, -1 for none."""
        p = skeleton.parents[joint]
        while p >= 0:
            if p in self.joints:
                return self.joints.index(p)
            p = skeleton.parents[p]
        return -1

    def root_transform(self, pose: Pose) -> tuple[float, np.ndarray]:
        """The avatar origin's heading (radians about Y) and position in the turned source frame
        (model units): the identity, or the root joint's heading and its path on the floor."""
        if self.root_convention == "hips":
            return 0.0, np.zeros(3)
        r = pose.world_rotations[self.root_joint]
        yaw = 2.0 * np.arctan2(r[0, 2] - r[2, 0], 1.0 + r[0, 0] + r[1, 1] + r[2, 2])  # its twist about Y
        position = self.turn @ pose.world_positions[self.root_joint]
        return float(yaw), position * np.array([1.0, 0.0, 1.0])  # turning about Y commutes with the turn

    def bone_transforms(self, pose: Pose, root: tuple[float, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Per mapped bone: Unity quaternion (x, y, z, w) and Unity local position (metres)."""
        yaw, root_pos = self.root_transform(pose) if root is None else root
        root_rot = axis_angle_matrix("y", yaw)
        normalised = self.turn @ pose.world_rotations[self.joints] @ self.rest_inverse  # world deltas from the T-pose
        # in the frame of the humanoid parent; a bone without one (the hips) in the avatar origin's
        parent_frames = np.where(self.has_parent[:, None, None], normalised[self.parent_rows], root_rot)
        local = np.transpose(parent_frames, (0, 2, 1)) @ normalised
        world = pose.world_positions[self.joints] @ self.turn.T
        offsets = world - np.where(self.has_parent[:, None], world[self.parent_rows], root_pos)
        positions = np.einsum("kji,kj->ki", parent_frames, offsets) * self.scale * np.array([1.0, 1.0, -1.0])
        return quaternions(local) * UNITY, positions

    def root_message(self, root: tuple[float, np.ndarray]) -> bytes:
        yaw, root_pos = root
        position = root_pos * self.scale * np.array([1.0, 1.0, -1.0])
        quat = np.array([0.0, np.sin(yaw / 2.0), 0.0, np.cos(yaw / 2.0)]) * UNITY  # w >= 0: |yaw| <= pi
        return message("/VMC/Ext/Root/Pos", "root", *position.tolist(), *quat.tolist())

    def datagrams(self, pose: Pose, echo: dict[str, float]) -> list[bytes]:
        root = self.root_transform(pose)
        quats, positions = self.bone_transforms(pose, root)
        messages = [self.root_message(root)]
        messages += float_messages(self.bone_prefixes, np.hstack([positions, quats]))
        messages += self.finger_messages
        messages += [message("/VMC/Ext/OK", 1), message("/VMC/Ext/T", float(pose.time))]
        return bundles(messages)
