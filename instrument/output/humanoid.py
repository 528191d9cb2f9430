"""Which joint of a skeleton is which humanoid bone (Unity's HumanBodyBones names, used by VMC).

`guess_humanoid` reads common naming conventions (the shipped model's `UpperLeg_L`, CMU's
`LeftUpLeg` (or, in the conversions that keep the ASF names, `LeftHip` under `LHipJoint` and
`LeftShoulder` under `LeftCollar`), Mixamo's `mixamorig:LeftUpLeg`, Unreal's `thigh_l` / `ball_l`, Rigify's `thigh.L`,
VRoid's `J_Bip_L_UpperLeg`, 3ds Max Biped's `Bip01 L Thigh`, ...). For anything else, a TOML file
maps joint names to bone names:

    [bones]
    "pelvis" = "Hips"
    "thigh_left" = "LeftUpperLeg"
"""

from __future__ import annotations

import re
from pathlib import Path

from ..errors import UserError
from ..motion.bvh import Skeleton
from ..tomlfile import read_toml

HUMAN_BONES = (
    "Hips", "Spine", "Chest", "UpperChest", "Neck", "Head",
    "LeftShoulder", "LeftUpperArm", "LeftLowerArm", "LeftHand",
    "RightShoulder", "RightUpperArm", "RightLowerArm", "RightHand",
    "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToes",
    "RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToes",
)
SPINE_CHAIN = ("Spine", "Chest", "UpperChest")
# (pattern on the lower-cased name without side markers, bone without side); first match wins
LIMB_PATTERNS = [
    (r"(index|thumb|finger|middle|ring|pinky)", None),
    (r"(shoulder|clavicle|collar)", "Shoulder"),
    (r"(forearm|lowerarm|elbow)", "LowerArm"),
    (r"(upperarm|^arm$|^arm\d*$)", "UpperArm"),
    (r"(hand|wrist)", "Hand"),
    (r"(upleg|upperleg|thigh)", "UpperLeg"),
    (r"(lowerleg|^leg$|shin|knee|calf)", "LowerLeg"),
    (r"(toe|ball)", "Toes"),
    (r"(foot|ankle)", "Foot"),
    (r"(hipjoint)", None),
    (r"^hip\d*$", "UpperLeg"),  # a sided hip is the thigh's joint (CMU's ASF names: LeftHip)
]


def _side(name: str) -> str | None:
    if re.search(r"(^|[_.:\s-])l($|[_.\s-])|left", name, re.IGNORECASE) or re.match(r"^L[A-Z]", name):
        return "Left"
    if re.search(r"(^|[_.:\s-])r($|[_.\s-])|right", name, re.IGNORECASE) or re.match(r"^R[A-Z]", name):
        return "Right"
    return None


def _core(name: str) -> str:
    name = name.split(":")[-1]
    name = re.sub(r"(?i)left|right", "", name)
    name = re.sub(r"(^|[_.\s-])[LRlr]($|[_.\s-])", "", name)
    name = re.sub(r"^[LR](?=[A-Z])", "", name)
    return re.sub(r"[_.\s-]", "", name).lower()


def guess_humanoid(skeleton: Skeleton) -> dict[str, str]:
    """{joint name: human bone} for the joints whose role is clear from their names."""
    mapping: dict[str, str] = {}
    names = skeleton.names
    for name, parent in zip(names, skeleton.parents):
        core, side = _core(name), _side(name)
        if side:
            for pattern, bone in LIMB_PATTERNS:
                if re.search(pattern, core):
                    if bone == "Shoulder" and parent >= 0 and mapping.get(names[parent]) == f"{side}Shoulder":
                        bone = "UpperArm"  # a shoulder under the collar bone is the arm's joint (CMU's ASF names)
                    if bone and f"{side}{bone}" not in mapping.values():
                        mapping[name] = f"{side}{bone}"
                    break
        elif re.search(r"(hips?|pelvis)$", core) and "Hips" not in mapping.values():
            mapping[name] = "Hips"
        elif re.search(r"neck", core) and "Neck" not in mapping.values():
            mapping[name] = "Neck"
        elif re.search(r"head", core) and "Head" not in mapping.values():
            mapping[name] = "Head"
    # the spine: joints between the hips and the neck, the last three as Spine, Chest, UpperChest
    hips = next((n for n, b in mapping.items() if b == "Hips"), None)
    neck = next((n for n, b in mapping.items() if b == "Neck"), None)
    if hips and neck:
        chain, j = [], skeleton.parents[names.index(neck)]
        while j >= 0 and names[j] != hips:
            chain.append(names[j])
            j = skeleton.parents[j]
        chain = [c for c in reversed(chain) if c not in mapping][-3:]
        for joint, bone in zip(chain, SPINE_CHAIN[: len(chain)] if len(chain) < 3 else SPINE_CHAIN):
            mapping[joint] = bone
    return mapping


def read_humanoid(path: str | Path, skeleton: Skeleton) -> dict[str, str]:
    path = Path(path)
    _, data = read_toml(path)
    bones = data.get("bones")
    if not isinstance(bones, dict) or not bones:
        raise UserError(f"{path}: expected a [bones] table of \"joint\" = \"HumanBone\"")
    for joint, bone in bones.items():
        if joint not in skeleton.names:
            raise UserError(f"{path}: [bones] key {joint!r}: the model's skeleton has no such joint (it has "
                            f"{', '.join(skeleton.names[:6])}, ...): this map is for another skeleton")
        if bone not in HUMAN_BONES:
            raise UserError(f"{path}: [bones] {joint!r} = {bone!r}: not a humanoid bone ({', '.join(HUMAN_BONES[:4])}, ...)")
    return dict(bones)
