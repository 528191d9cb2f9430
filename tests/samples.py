"""BVH files in other conventions than the shared walks, written as plain text by the tests.

These are deliberately written without the project's own writer, so the reader is checked
against an independent author.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

# A CMU-style skeleton (31 joints, names as in the CMU conversions, 3 rotation channels below
# the root, rotation order ZYX), in centimetres, facing +Z with +X to the character's left.
CMU_JOINTS = [
    # name, parent, offset
    ("Hips", None, (0, 0, 0)),
    ("LHipJoint", "Hips", (0, 0, 0)),
    ("LeftUpLeg", "LHipJoint", (9, -5, 0)),
    ("LeftLeg", "LeftUpLeg", (0, -42, 0)),
    ("LeftFoot", "LeftLeg", (0, -40, 0)),
    ("LeftToeBase", "LeftFoot", (0, -5, 12)),
    ("RHipJoint", "Hips", (0, 0, 0)),
    ("RightUpLeg", "RHipJoint", (-9, -5, 0)),
    ("RightLeg", "RightUpLeg", (0, -42, 0)),
    ("RightFoot", "RightLeg", (0, -40, 0)),
    ("RightToeBase", "RightFoot", (0, -5, 12)),
    ("LowerBack", "Hips", (0, 5, 0)),
    ("Spine", "LowerBack", (0, 12, 0)),
    ("Spine1", "Spine", (0, 12, 0)),
    ("Neck", "Spine1", (0, 10, 0)),
    ("Neck1", "Neck", (0, 5, 0)),
    ("Head", "Neck1", (0, 8, 0)),
    ("LeftShoulder", "Spine1", (4, 8, 0)),
    ("LeftArm", "LeftShoulder", (14, 0, 0)),
    ("LeftForeArm", "LeftArm", (0, -28, 0)),
    ("LeftHand", "LeftForeArm", (0, -25, 0)),
    ("LeftFingerBase", "LeftHand", (0, -5, 0)),
    ("LeftHandIndex1", "LeftFingerBase", (0, -3, 0)),
    ("LThumb", "LeftHand", (1, -2, 2)),
    ("RightShoulder", "Spine1", (-4, 8, 0)),
    ("RightArm", "RightShoulder", (-14, 0, 0)),
    ("RightForeArm", "RightArm", (0, -28, 0)),
    ("RightHand", "RightForeArm", (0, -25, 0)),
    ("RightFingerBase", "RightHand", (0, -5, 0)),
    ("RightHandIndex1", "RightFingerBase", (0, -3, 0)),
    ("RThumb", "RightHand", (-1, -2, 2)),
]

STRIDE_SECONDS = 1.1  # one left and one right step


def cmu_style_walk(fps: float = 120.0, seconds: float = 4.4, order: str = "ZYX", newline: str = "\n") -> tuple[str, np.ndarray]:
    """A procedural walk on the CMU-style skeleton; returns the text and the frames at which the
    left foot is furthest ahead (where right steps begin)."""
    t = np.arange(int(round(seconds * fps))) / fps
    phase = 2 * np.pi * t / STRIDE_SECONDS
    names = [j[0] for j in CMU_JOINTS]
    euler = {name: np.zeros((len(t), 3)) for name in names}  # degrees about X, Y, Z
    swing = 25 * np.sin(phase)
    euler["LeftUpLeg"][:, 0] = -swing  # negative X rotation carries the left foot forward (+Z)
    euler["RightUpLeg"][:, 0] = swing
    euler["LeftLeg"][:, 0] = 10.0
    euler["RightLeg"][:, 0] = 10.0
    euler["LeftArm"][:, 0] = swing * 0.6
    euler["RightArm"][:, 0] = -swing * 0.6
    euler["Hips"][:, 1] = 4 * np.sin(phase)  # a little pelvis yaw
    hips = np.stack([np.zeros_like(t), 88 + 2 * np.cos(2 * phase), 120.0 * t], axis=1)

    def angles(name: str) -> np.ndarray:
        rotation = Rotation.from_euler("XYZ", euler[name], degrees=True)
        return rotation.as_euler(order, degrees=True)

    rot_channels = " ".join(f"{axis}rotation" for axis in order)
    out = ["HIERARCHY"]

    def write(index: int, depth: int) -> None:
        name, parent, offset = CMU_JOINTS[index]
        pad = "  " * depth
        out.append(f"{pad}{'ROOT' if parent is None else 'JOINT'} {name}")
        out.append(f"{pad}{{")
        out.append(f"{pad}  OFFSET {offset[0]:.5f} {offset[1]:.5f} {offset[2]:.5f}")
        if parent is None:
            out.append(f"{pad}  CHANNELS 6 Xposition Yposition Zposition {rot_channels}")
        else:
            out.append(f"{pad}  CHANNELS 3 {rot_channels}")
        children = [k for k, j in enumerate(CMU_JOINTS) if j[1] == name]
        for child in children:
            write(child, depth + 1)
        if not children:
            out.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET 0.00000 -2.00000 0.00000", f"{pad}  }}"])
        out.append(f"{pad}}}")

    write(0, 0)
    out.extend(["MOTION", f"Frames: {len(t)}", f"Frame Time: {1 / fps:.8f}"])
    columns = [hips] + [angles(name) for name in names]
    frames = np.hstack(columns)
    out.extend(" ".join(f"{v:.6f}" for v in row) for row in frames)
    # the left foot is furthest ahead where sin(phase) peaks
    left_ahead = (STRIDE_SECONDS / 4 + STRIDE_SECONDS * np.arange(10)) * fps
    return newline.join(out) + newline, left_ahead[left_ahead < len(t)]


def reorder_bvh(text: str, order: str, drop_joint_positions: bool = False) -> str:
    """The same motion with every joint's rotation channels in another Euler order (and, when
    asked, the position channels of non-root joints removed, as in 3-channel files)."""
    lines = text.splitlines()
    motion_at = next(i for i, line in enumerate(lines) if line.strip() == "MOTION")
    header, frames_lines = lines[:motion_at], lines[motion_at + 3 :]
    values = np.array([[float(v) for v in line.split()] for line in frames_lines])
    new_header, columns, position = [], [], 0
    is_root = True
    for line in header:
        tokens = line.split()
        if tokens and tokens[0] == "CHANNELS":
            names = tokens[2:]
            block = values[:, position : position + len(names)]
            position += len(names)
            rot = [n[0] for n in names if n.endswith("rotation")]
            rot_values = block[:, [k for k, n in enumerate(names) if n.endswith("rotation")]]
            pos_names = [n for n in names if n.endswith("position")]
            pos_values = block[:, [k for k, n in enumerate(names) if n.endswith("position")]]
            keep_positions = pos_names and (is_root or not drop_joint_positions)
            new_rot = Rotation.from_euler("".join(rot), rot_values, degrees=True).as_euler(order, degrees=True)
            new_names = (pos_names if keep_positions else []) + [f"{a}rotation" for a in order]
            columns += ([pos_values] if keep_positions else []) + [new_rot]
            indent = line[: len(line) - len(line.lstrip())]
            new_header.append(f"{indent}CHANNELS {len(new_names)} {' '.join(new_names)}")
            is_root = False
        else:
            new_header.append(line)
    data = np.hstack(columns)
    body = [" ".join(f"{v:.6f}" for v in row) for row in data]
    return "\n".join(new_header + lines[motion_at : motion_at + 3] + body) + "\n"


BANDAI_TO_CMU = {
    "Chest": "Spine1", "Neck": "Neck1", "Shoulder_L": "LeftShoulder", "UpperArm_L": "LeftArm", "LowerArm_L": "LeftForeArm",
    "Hand_L": "LeftHand", "Shoulder_R": "RightShoulder", "UpperArm_R": "RightArm", "LowerArm_R": "RightForeArm",
    "Hand_R": "RightHand", "UpperLeg_L": "LeftUpLeg", "LowerLeg_L": "LeftLeg", "Foot_L": "LeftFoot",
    "Toes_L": "LeftToeBase", "UpperLeg_R": "RightUpLeg", "LowerLeg_R": "RightLeg", "Foot_R": "RightFoot",
    "Toes_R": "RightToeBase",
}
# The CMU joints the shared walks have no counterpart for, each inserted at zero offset above
# (or, for the hands' joints, below) a renamed joint, as in the CMU conversions, never rotated.
CMU_INSERTED_ABOVE = {"LeftUpLeg": "LHipJoint", "RightUpLeg": "RHipJoint", "Spine": "LowerBack", "Neck1": "Neck"}
CMU_HAND = {"LeftHand": ("LeftFingerBase", "LeftHandIndex1", "LThumb"),
            "RightHand": ("RightFingerBase", "RightHandIndex1", "RThumb")}
CMU_HIPS_CHILDREN = ("LHipJoint", "RHipJoint", "LowerBack")  # the CMU files' order: legs first


def cmu_named_walk(path) -> str:
    """A shared walk as a file in the CMU conversions' 31-joint layout: joints renamed as there,
    re-rooted at Hips (the static `joint_Root` above it removed), the CMU joints the walks lack
    inserted unrotated at zero offset (LHipJoint, RHipJoint, LowerBack, Neck, and per hand a
    FingerBase, HandIndex1 and thumb made from the hand's end site), 3 rotation channels per
    joint in ZYX order. The body moves exactly as in the walk."""
    from instrument.motion.bvh import Joint, Motion, Skeleton, bvh_text, read_bvh

    motion = read_bvh(path)
    top = motion.skeleton.joints[0]
    width = len(top.channels)
    assert top.name == "joint_Root" and not np.any(motion.channels[:, :width]), "re-rooting assumes a static identity root"
    rotation = ("Zrotation", "Yrotation", "Xrotation")
    columns, at = {}, width  # joint name -> its columns in the walk
    nodes = {}  # name -> [parent, offset, channels, end site, children]
    for joint in motion.skeleton.joints[1:]:
        name = BANDAI_TO_CMU.get(joint.name, joint.name)
        columns[name] = (at, at + len(joint.channels))
        at += len(joint.channels)
        parent = motion.skeleton.joints[joint.parent].name
        nodes[name] = [None if parent == "joint_Root" else BANDAI_TO_CMU.get(parent, parent), joint.offset,
                       joint.channels, joint.end_site, []]
    for below, name in CMU_INSERTED_ABOVE.items():
        nodes[name] = [nodes[below][0], (0.0, 0.0, 0.0), rotation, None, []]
        nodes[below][0] = name
    for hand, (base, index, thumb) in CMU_HAND.items():
        along = np.array(nodes[hand][1]) / np.linalg.norm(nodes[hand][1])  # the forearm's way (the walks' hands end at once)
        nodes[hand][3] = None
        nodes[base] = [hand, (0.0, 0.0, 0.0), rotation, None, []]
        nodes[index] = [base, tuple(5.0 * along), rotation, tuple(4.0 * along), []]
        nodes[thumb] = [hand, (0.0, 0.0, 0.0), rotation, tuple(3.0 * along + (0.0, 0.0, 3.0)), []]  # and ahead
    for name, node in nodes.items():
        if node[0] is not None:
            nodes[node[0]][4].append(name)
    nodes["Hips"][4] = [*CMU_HIPS_CHILDREN, *(c for c in nodes["Hips"][4] if c not in CMU_HIPS_CHILDREN)]
    joints, blocks = [], []

    def add(name: str, parent: int) -> None:
        _, offset, channels, end_site, children = nodes[name]
        joints.append(Joint(name, parent, tuple(float(v) for v in offset), tuple(channels),
                            None if end_site is None else tuple(float(v) for v in end_site)))
        if name in columns:
            blocks.append(motion.channels[:, slice(*columns[name])])
        else:
            blocks.append(np.zeros((motion.frames, len(channels))))
        here = len(joints) - 1
        for child in children:
            add(child, here)

    add("Hips", -1)
    assert len(joints) == 31, [j.name for j in joints]
    text = bvh_text(Motion(Skeleton(tuple(joints)), np.hstack(blocks), motion.fps))
    return reorder_bvh(text, "ZYX", drop_joint_positions=True)


def z_up(motion):
    """The same take as exported from a Z-up scene (Blender's, 3ds Max's): its root turned so
    that +Z is up (the inverse of what `upright` undoes)."""
    from instrument.motion.bvh import Motion
    from instrument.motion.kinematics import channels_from_local, local_transforms
    from instrument.motion.upright import TO_Y_UP

    rotations, translations = local_transforms(motion)
    to_z_up = TO_Y_UP["+Z"].T
    rotations[:, 0] = to_z_up @ rotations[:, 0]
    translations[:, 0] = translations[:, 0] @ to_z_up.T
    return Motion(motion.skeleton, channels_from_local(motion.skeleton, rotations, translations), motion.fps)
