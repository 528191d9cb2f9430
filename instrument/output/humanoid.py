"""Which joint of a skeleton is which humanoid bone (Unity's HumanBodyBones names, used by VMC).

`guess_humanoid` reads common naming conventions (the shipped model's `UpperLeg_L`, CMU's
`LeftUpLeg`, Mixamo's `mixamorig:LeftUpLeg`, Unreal's `thigh_l` / `ball_l`, Rigify's `thigh.L`,
VRoid's `J_Bip_L_UpperLeg`, 3ds Max Biped's `Bip01 L Thigh`, HumanIK's `Character1_LeftUpLeg`
(a prefix every joint shares is read past), an inertial suit's and the CMU conversions'
`LeftHip` / `LeftCollar` / `LeftShoulder` (the upper arm), CMU's ASF `lfemur` / `lhumerus`,
...). For anything else, a TOML file
maps joint names to bone names:

    [bones]
    "pelvis" = "Hips"
    "thigh_left" = "LeftUpperLeg"
"""

from __future__ import annotations

import difflib
import re
from collections.abc import Sequence
from pathlib import Path

from ..errors import quoted
from ..motion.bvh import Skeleton
from ..tomlfile import Field, TomlFile

HUMAN_BONES = (
    "Hips", "Spine", "Chest", "UpperChest", "Neck", "Head",
    "LeftShoulder", "LeftUpperArm", "LeftLowerArm", "LeftHand",
    "RightShoulder", "RightUpperArm", "RightLowerArm", "RightHand",
    "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToes",
    "RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToes",
)
SPINE_CHAIN = ("Spine", "Chest", "UpperChest")
THIGH_NAMES = r"(upleg|upperleg|thigh|femur)"
# (pattern on the lower-cased name without side markers, bone without side); first match wins
LIMB_PATTERNS = [
    (r"(index|thumb|finger|middle|ring|pinky)", None),
    (r"(shoulder|clavicle|collar)", "Shoulder"),  # the upper arm where a collar came before it (`_limb`)
    (r"(forearm|lowerarm|elbow|radius)", "LowerArm"),
    (r"(upperarm|^arm$|^arm\d*$|humerus)", "UpperArm"),
    (r"(hand|wrist)", "Hand"),
    (THIGH_NAMES, "UpperLeg"),
    (r"(lowerleg|^leg$|shin|knee|calf|tibia)", "LowerLeg"),
    (r"(toe|ball)", "Toes"),
    (r"(foot|ankle)", "Foot"),
    (r"(hipjoint)", None),
    (r"^hips?$", "UpperLeg"),  # a sided hip (LeftHip, then LeftKnee, LeftAnkle) is the thigh's joint (`_limb`)
]

# CMU's ASF names: a lower-case side letter before the bone's name (lfemur, rhumerus, lclavicle)
ASF_LIMB = r"^[lr](?=(hipjoint|femur|tibia|foot|toes|clavicle|humerus|radius|wrist|hand|fingers|thumb)$)"


def _side(name: str) -> str | None:
    if re.match(ASF_LIMB, name):
        return "Left" if name[0] == "l" else "Right"
    if re.search(r"(^|[_.:\s-])l($|[_.\s-])|left", name, re.IGNORECASE) or re.match(r"^L[A-Z]", name):
        return "Left"
    if re.search(r"(^|[_.:\s-])r($|[_.\s-])|right", name, re.IGNORECASE) or re.match(r"^R[A-Z]", name):
        return "Right"
    return None


def _core(name: str) -> str:
    name = name.split(":")[-1]
    name = re.sub(ASF_LIMB, "", name)
    name = re.sub(r"(?i)left|right", "", name)
    name = re.sub(r"(^|[_.\s-])[LRlr]($|[_.\s-])", "", name)
    name = re.sub(r"^[LR](?=[A-Z])", "", name)
    return re.sub(r"[_.\s-]", "", name).lower()


def _limb(core: str, side: str, taken: set[str], thighs: set[str]) -> str | None:
    """The sided bone a joint's name says (None: none, or one already taken). A shoulder after a
    collar on its side is the upper arm (a suit's and the CMU conversions' LeftCollar,
    LeftShoulder, LeftElbow, LeftWrist), as Mixamo's LeftShoulder, LeftArm is the collar first.
    A sided hip is the thigh only on a side (`thighs`) with no joint named as a thigh (a rig with
    LeftHip above LeftUpLeg has a stub there)."""
    for pattern, bone in LIMB_PATTERNS:
        if re.search(pattern, core):
            if bone == "Shoulder" and f"{side}Shoulder" in taken:
                bone = "UpperArm"
            if bone == "UpperLeg" and not re.search(THIGH_NAMES, core) and side in thighs:
                return None
            return f"{side}{bone}" if bone and f"{side}{bone}" not in taken else None
    return None


def _shared_prefix(names: list[str]) -> int:
    """The length of a prefix every joint's name starts with, up to a separator (HumanIK's
    `Character1_`, Biped's `Bip01 `, a namespace `rig:`), so the names are read without it
    (`Character1_LeftArm` is the upper arm as `LeftArm` is); 0 when there is none."""
    if len(names) < 2:
        return 0
    shared = names[0][: min(len(n) for n in names) - 1]  # never a whole name
    for name in names[1:]:
        while not name.startswith(shared):
            shared = shared[:-1]
    cut = max(shared.rfind(c) for c in "_.: -")
    return cut + 1


def guess_humanoid(skeleton: Skeleton) -> dict[str, str]:
    """{joint name: human bone} for the joints whose role is clear from their names."""
    mapping: dict[str, str] = {}
    names = skeleton.names
    start = _shared_prefix(names)
    thighs = {_side(name[start:]) for name in names if _side(name[start:]) and re.search(THIGH_NAMES, _core(name[start:]))}
    for name in names:
        core, side = _core(name[start:]), _side(name[start:])
        if side:
            bone = _limb(core, side, set(mapping.values()), thighs)
            if bone:
                mapping[name] = bone
        elif re.search(r"(hips?|pelvis)$", core) and "Hips" not in mapping.values():
            mapping[name] = "Hips"
        elif re.search(r"neck", core) and "Neck" not in mapping.values():
            mapping[name] = "Neck"
        elif re.search(r"head", core) and "Head" not in mapping.values():
            mapping[name] = "Head"
    # the spine: joints between the hips and the neck (the head, on a skeleton without a neck
    # joint), the last three as Spine, Chest, UpperChest
    hips = next((n for n, b in mapping.items() if b == "Hips"), None)
    neck = next((n for n, b in mapping.items() if b == "Neck"), None) or next((n for n, b in mapping.items() if b == "Head"), None)
    if hips and neck:
        chain, j = [], skeleton.parents[names.index(neck)]
        while j >= 0 and names[j] != hips:
            chain.append(names[j])
            j = skeleton.parents[j]
        chain = [c for c in reversed(chain) if c not in mapping][-3:]
        for joint, bone in zip(chain, SPINE_CHAIN[: len(chain)] if len(chain) < 3 else SPINE_CHAIN):
            mapping[joint] = bone
    return mapping


SCHEMA = {"bones": Field("table", required='the map: a [bones] table of "joint" = "HumanBone" lines')}


def read_humanoid(path: str | Path, skeleton: Skeleton) -> dict[str, str]:
    """{joint: human bone} of a bone map file (`run --humanoid`, `skeleton --humanoid`), checked
    against `skeleton`: an unknown key or table, a joint the skeleton lacks, a bone that is not a
    humanoid bone, a bone given twice is a one-line UserError naming the file and the line."""
    doc = TomlFile(path)
    bones = doc.check((), doc.data, SCHEMA)["bones"]
    if not bones:
        raise doc.error(("bones",), 'empty: expected "joint" = "HumanBone" lines', "[bones]")
    taken: dict[str, str] = {}
    for joint, bone in bones.items():
        where, shown = ("bones", joint), f"[bones] {joint!r}"
        if joint not in skeleton.names:
            close = _nearest(joint, skeleton.names)
            raise doc.error(where, "the model's skeleton has no such joint (" + (
                f"did you mean {close!r}?)" if close else
                f"it has {', '.join(skeleton.names[:6])}, ...): this map is for another skeleton"), shown)
        if not isinstance(bone, str) or bone not in HUMAN_BONES:
            close = _nearest(bone, HUMAN_BONES)
            raise doc.error(where, f"{quoted(bone)}: not a humanoid bone (" + (
                f"did you mean {close!r}?)" if close else f"{', '.join(HUMAN_BONES[:4])}, ...: Unity's HumanBodyBones)"),
                shown)
        if bone in taken:  # a VMC receiver would get the bone twice a frame, from two joints
            raise doc.error(where, f"{taken[bone]!r} is {bone} already", f"{shown} = {bone!r}")
        taken[bone] = joint
    return dict(bones)


def _nearest(name: object, names: Sequence[str]) -> str | None:
    """The one of `names` that `name` is a typo of, if any."""
    close = difflib.get_close_matches(str(name), names, n=1, cutoff=0.8)
    return close[0] if close else None
