"""A rest skeleton a user can rig: the model's skeleton standing in the normalised T-pose.

`instrument skeleton` writes it as a one-frame BVH whose rest (every rotation zero) is the
T-pose the VMC profile sends from (tpose.py): spine up, arms out palms down, legs down, feet
flat, the character standing at the origin with its feet on the floor, facing +Z with its left
along +X. Blender's BVH importer (Y up -> Z up) turns that into Blender's convention: facing -Y,
left along +X, Z up. Humanoid joints take their Unity/VMC bone names (Hips, LeftUpperArm, ...),
so the Blender add-on's "Humanoid" bone map drives an armature built from it directly. End
bones get a length (hands, head and toes often end in zero-length End Sites), so the importer
makes bones a user can skin to.
"""

from __future__ import annotations

import numpy as np

from ..models.modelfile import Model
from ..motion.bvh import Joint, Motion, Skeleton
from .humanoid import read_humanoid
from .outputs import make_profile
from .tpose import DIRECTIONS

FACING_PLUS_Z = np.diag([-1.0, 1.0, -1.0])  # half a turn about Y: the source frame faces -Z
END_LENGTH = {"Head": 0.2, "LeftHand": 0.09, "RightHand": 0.09, "LeftToes": 0.05, "RightToes": 0.05}  # x hips height
ROTATION_CHANNELS = ("Zrotation", "Xrotation", "Yrotation")
POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")


def joint_names(skeleton: Skeleton, bone_of: dict[int, str]) -> list[str]:
    """Each joint's name in the rest: its humanoid bone's, else its own, renamed NAME_2, NAME_3...
    where a bone took it (CMU's Neck, under the lower neck guessed as the Neck): a BVH whose two
    joints share a name is read as one joint by Blender and most importers."""
    taken = set(bone_of.values())
    names = []
    for j, joint in enumerate(skeleton.joints):
        name = bone_of.get(j)
        if name is None:
            name, k = joint.name, 1
            while name in taken:
                k += 1
                name = f"{joint.name}_{k}"
            taken.add(name)
        names.append(name)
    return names


def tpose_rest(model: Model, humanoid_file: str | None = None) -> Motion:
    """The model's skeleton re-rested in the T-pose, as a one-frame motion at the model's rate."""
    humanoid = read_humanoid(humanoid_file, model.layout.skeleton) if humanoid_file else None
    profile = make_profile("vmc", model, humanoid, fingers=False)
    skeleton = model.layout.skeleton
    bone_of = dict(zip(profile.joints, profile.bones))
    world = []  # T-pose world rotation of every joint: its reference, else carried from its parent
    for j, parent in enumerate(skeleton.parents):
        if j in bone_of:
            world.append(profile.tpose.rotations[bone_of[j]])
        else:
            world.append(world[parent] if parent >= 0 else np.eye(3))
    positions = np.zeros((len(world), 3))
    for j, parent in enumerate(skeleton.parents):
        if parent >= 0:
            positions[j] = positions[parent] + world[parent] @ skeleton.offsets[j]
    positions = positions @ FACING_PLUS_Z.T
    hips = positions[profile.joints[profile.bones.index("Hips")]] if "Hips" in profile.bones else positions[0]
    below_top = np.arange(len(world)) > 0
    floor = positions[below_top, 1].min() if below_top.any() else 0.0
    positions -= np.array([hips[0], floor, hips[2]])
    if 0 not in bone_of:  # a joint above the hips stands on the floor under them
        positions[0] = 0.0
    height = float(positions[profile.joints[profile.bones.index("Hips")], 1]) if "Hips" in profile.bones else 1.0
    names = joint_names(skeleton, bone_of)
    joints = []
    for j, joint in enumerate(skeleton.joints):
        name = names[j]
        offset = positions[j] - (positions[joint.parent] if joint.parent >= 0 else 0.0)
        end = None
        if not skeleton.children(j):
            if name in END_LENGTH:
                end = FACING_PLUS_Z @ DIRECTIONS[name] * END_LENGTH[name] * height
            elif joint.end_site is not None:
                end = FACING_PLUS_Z @ world[j] @ np.asarray(joint.end_site)
        channels = POSITION_CHANNELS + ROTATION_CHANNELS if joint.parent < 0 else ROTATION_CHANNELS
        joints.append(Joint(name, joint.parent, tuple(float(v) for v in offset), channels,
                            None if end is None else tuple(float(v) for v in end)))
    rest = Skeleton(tuple(joints))
    frame = np.zeros((1, rest.channel_count))
    frame[0, :3] = positions[0]
    return Motion(rest, frame, model.fps)
