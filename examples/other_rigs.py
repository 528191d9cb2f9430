"""Test sets of other skeletons, names, rates, units and rest poses, built from walks you have,
and the figures a model trained on each gets (issue 30).

    python examples/other_rigs.py ../shared/data/bandai-walk [--out /tmp/rigs] [--sets mixamo-60,cmu31-120]
                                  [--styles elderly,active,feminine] [--takes 6] [--seconds 12]
                                  [--public tests/data/cmu-131] [--curving N [--turns DIR]]
                                  [--units N [--manifest]]

Every set is the same takes re-rigged (`rerig`): joints renamed to another convention (Mixamo's
"mixamorig:Hips"..., CMU's 31 joints with its zero-length hip, lower-back and finger joints),
re-rooted at the hips, rotation channels in another Euler order, resampled to another rate
(slerp), scaled to other units and, for `rest-posed`, every joint's rest orientation turned by a
fixed rotation of its own (the bones' offsets point elsewhere and every local rotation differs;
the body moves exactly as before). For each set it trains a model (`instrument train`), measures
it (`instrument evaluate --real SET --variants one --json`) and prints, per style, the issue's
targets: synthesized walks recognised at >= 0.9x the rate of the real takes (cross-validated over
whole takes), knee, hip and shoulder ranges within 10% of the takes', skate at weight 1 no more
than 1.2x the takes', both feet off the floor (float, the stricter way) in no more frames than the
takes. `--public DIR` adds a set of public captures as they are (no re-rig).
`--curving N` adds N left and N right turning walks of each style to every set, named as walks:
a capture whose walks curve, as an actor's do walking round a room.
`--units N [--manifest]` builds the motion vocabulary instead (issue 25: N walks, runs, turns each
way and standing takes of each style, `unit_takes`), under their own names or neutral names and
a manifest (`build_unit_set`), trains it and prints, per set, how many of `instrument evaluate
--units`'s target rows pass.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from instrument.errors import UserError, run_script
from instrument.motion.bvh import Joint, Motion, Skeleton, read_bvh, write_bvh
from instrument.motion.features import resample
from instrument.motion.kinematics import channels_from_local, forward_kinematics, local_transforms
from instrument.motion.rotations import expmap_to_matrix, matrix_to_expmap
from instrument.training.corpus import TakeFile, styled_takes
from instrument.training.units import take_gesture

SIDES = {"_L": "Left", "_R": "Right"}
BANDAI_BODY = ("Hips", "Spine", "Chest", "Neck", "Head")


def mixamo_name(name: str) -> str:
    """The Bandai walks' joint as Mixamo names it: Hips -> mixamorig:Hips, UpperLeg_L -> mixamorig:LeftUpLeg."""
    parts = {"Spine": "Spine", "Chest": "Spine1", "UpperLeg": "UpLeg", "LowerLeg": "Leg", "Foot": "Foot", "Toes": "ToeBase",
             "Shoulder": "Shoulder", "UpperArm": "Arm", "LowerArm": "ForeArm", "Hand": "Hand"}
    if name[-2:] in SIDES:
        return f"mixamorig:{SIDES[name[-2:]]}{parts[name[:-2]]}"
    return f"mixamorig:{parts.get(name, name)}"


def cmu_name(name: str) -> str:
    """The Bandai walks' joint as the CMU conversions name it (Chest -> Spine1, UpperLeg_L -> LeftUpLeg)."""
    parts = {"UpperLeg": "UpLeg", "LowerLeg": "Leg", "Foot": "Foot", "Toes": "ToeBase", "Shoulder": "Shoulder",
             "UpperArm": "Arm", "LowerArm": "ForeArm", "Hand": "Hand"}
    if name[-2:] in SIDES:
        return SIDES[name[-2:]] + parts[name[:-2]]
    return {"Chest": "Spine1", "Neck": "Neck1"}.get(name, name)


def asf_name(name: str) -> str:
    """The Bandai walks' joint as CMU's ASF skeletons name it (Hips -> hip, UpperArm_L -> lhumerus)."""
    parts = {"UpperLeg": "femur", "LowerLeg": "tibia", "Foot": "foot", "Toes": "toes", "Shoulder": "clavicle",
             "UpperArm": "humerus", "LowerArm": "radius", "Hand": "wrist"}
    if name[-2:] in SIDES:
        return name[-1].lower() + parts[name[:-2]]
    return {"Hips": "hip", "Spine": "lowerback", "Chest": "thorax", "Neck": "lowerneck", "Head": "head"}.get(name, name)


def blender_name(name: str) -> str:
    """The Bandai walks' joint as Blender's Rigify names it (UpperLeg_L -> thigh.L, Hand_R -> hand.R)."""
    parts = {"UpperLeg": "thigh", "LowerLeg": "shin", "Foot": "foot", "Toes": "toe", "Shoulder": "shoulder",
             "UpperArm": "upper_arm", "LowerArm": "forearm", "Hand": "hand"}
    if name[-2:] in SIDES:
        return f"{parts[name[:-2]]}.{name[-1]}"
    return name.lower()


def suit_name(name: str) -> str:
    """The Bandai walks' joint as a 23-joint inertial suit's BVH names it (Hips, Chest to Chest4, Neck,
    Head, and per side Collar, Shoulder, Elbow, Wrist, Hip, Knee, Ankle, Toe); the walks' Chest is
    split in three (`split_joint`: Chest, Chest.1, Chest.2)."""
    parts = {"UpperLeg": "Hip", "LowerLeg": "Knee", "Foot": "Ankle", "Toes": "Toe", "Shoulder": "Collar",
             "UpperArm": "Shoulder", "LowerArm": "Elbow", "Hand": "Wrist"}
    if name[-2:] in SIDES:
        return SIDES[name[-2:]] + parts[name[:-2]]
    return {"Spine": "Chest", "Chest": "Chest2", "Chest.1": "Chest3", "Chest.2": "Chest4"}.get(name, name)


def humanik_name(name: str) -> str:
    """The Bandai walks' joint as MotionBuilder's HumanIK names it: CMU's names behind the
    character's prefix (UpperArm_L -> Character1_LeftArm, LowerLeg_L -> Character1_LeftLeg)."""
    return "Character1_" + cmu_name(name)


RENAMES = {"mixamo": mixamo_name, "cmu": cmu_name, "asf": asf_name, "blender": blender_name, "suit": suit_name,
           "humanik": humanik_name}


def split_joint(motion: Motion, name: str, pieces: int) -> Motion:
    """`name`'s bone (to its first child) cut into `pieces` joints named name.1, name.2, ..., its
    rotation shared among them (each turns by 1/pieces of it, so the last turns as `name` did)
    and its other children hung from the last: a spine of more joints that bends along its length.
    The joints beyond move by less than a centimetre against the take's."""
    skeleton = motion.skeleton
    rotations, translations = local_transforms(motion)
    j = skeleton.index(name)
    children = skeleton.children(j)
    step = np.asarray(skeleton.joints[children[0]].offset) / pieces
    piece = expmap_to_matrix(matrix_to_expmap(rotations[:, j]) / pieces)
    order = list(range(j + 1)) + [-k for k in range(1, pieces)] + list(range(j + 1, len(skeleton.joints)))
    position = {old: new for new, old in enumerate(order)}
    joints, rot, trans = [], [], []
    for new, old in enumerate(order):
        if old < 0:  # an inserted piece
            source = skeleton.joints[j]
            joints.append(Joint(f"{name}.{-old}", new - 1, tuple(step), tuple(c for c in source.channels if c.endswith("rotation"))))
            rot.append(piece)
            trans.append(np.broadcast_to(step, (motion.frames, 3)))
            continue
        joint = skeleton.joints[old]
        parent = position[joint.parent] if joint.parent >= 0 else -1
        offset, moved = np.asarray(joint.offset), translations[:, old]
        if joint.parent == j:  # hangs from the last piece, where `name`'s bone now ends
            parent = position[j] + pieces - 1
            offset, moved = offset - (pieces - 1) * step, moved - (pieces - 1) * step
        joints.append(Joint(joint.name, parent, tuple(float(v) for v in offset), joint.channels, joint.end_site))
        rot.append(piece if old == j else rotations[:, old])
        trans.append(moved)
    skeleton = Skeleton(tuple(joints))
    return Motion(skeleton, channels_from_local(skeleton, np.stack(rot, 1), np.stack(trans, 1)), motion.fps, motion.source)


# CMU's joints the walks lack: (name, the renamed joint it is inserted above, at zero offset, unrotated)
CMU_ABOVE = (("LHipJoint", "LeftUpLeg"), ("RHipJoint", "RightUpLeg"), ("LowerBack", "Spine"), ("Neck", "Neck1"))
# and below each hand: (name, parent, offset as a share of a quarter of the forearm, along it)
CMU_BELOW = (("LeftFingerBase", "LeftHand", 0.0), ("LeftHandIndex1", "LeftFingerBase", 1.0), ("LThumb", "LeftHand", 0.5),
             ("RightFingerBase", "RightHand", 0.0), ("RightHandIndex1", "RightFingerBase", 1.0), ("RThumb", "RightHand", 0.5))


# the bones a twist joint is inserted half way down (`Rig.twist`): (the bone's joint, the joint it ends at), per side
TWIST_BONES = (("UpperLeg", "LowerLeg"), ("UpperArm", "LowerArm"), ("LowerArm", "Hand"))


def _depth_first(rows: list[tuple], reverse: bool) -> list[tuple]:
    """`rows` (name, ..., parent name, ...) in the order a BVH file writes them: each joint before
    its children, the children in their order among `rows` (or the reverse)."""
    out = []

    def visit(parent: str | None) -> None:
        children = [r for r in rows if r[2] == parent]
        for row in reversed(children) if reverse else children:
            out.append(row)
            visit(row[0])

    visit(None)
    return out


@dataclass(frozen=True)
class Rig:
    """How a set differs from the takes it is made of."""

    fps: float
    scale: float = 1.0  # units: 0.01 turns centimetres into metres
    order: str = "ZXY"  # Euler order of every rotation channel
    rename: str = ""  # "", "mixamo", "cmu" (CMU's 31 joints), "asf", "blender", "suit" or "humanik"
    rest_turn_deg: float = 0.0  # each joint's rest orientation turned by up to this much (a fixed seed)
    keep_root: bool = True  # keep a static floor joint above the hips (else re-root at the hips)
    up: str = "Y"  # "Z": the world turned so that Z is up (as Blender's and 3ds Max's scenes are)
    positions: bool = False  # position channels on every joint (a joint's offset then moves nothing)
    drop: tuple[str, ...] = ()  # the take's joints left out (leaves: the toes; the foot then ends the leg)
    split: tuple[str, int] | None = None  # a joint whose bone is cut into this many (`split_joint`)
    rest_pose: bool = False  # every joint's rest orientation that of the first take's first frame (world axes)
    frames: int = 0  # keep only this many frames of each take (0: all)
    lift: float = 0.0  # the whole take raised by this much (the take's units; negative: the floor below the origin)
    reorder: bool = False  # siblings written in reverse order (legs before the spine, right before left)
    twist: bool = False  # a leaf twist joint half way down each thigh, upper arm and forearm (as Unreal's rigs have)
    eyes: bool = False  # two leaf joints in the head, 8 cm above its joint and 3 cm to either side (as VRoid's rigs have)


SETS = {
    "suit23-60": Rig(60.0, 1.0, "ZXY", "suit", keep_root=False, split=("Chest", 3), rest_pose=True),
    "mixamo-60": Rig(60.0, 1.0, "ZXY", "mixamo", keep_root=False),
    "cmu31-120": Rig(120.0, 0.01, "ZYX", "cmu", keep_root=False),
    "bandai-24-m": Rig(24.0, 0.01, "ZXY"),
    "rest-posed-30-in": Rig(30.0, 1 / 2.54, "XYZ", rest_turn_deg=40.0, keep_root=False),
    "twist-60-mm": Rig(60.0, 10.0, "XZY", "mixamo", keep_root=False, reorder=True, twist=True, eyes=True),
}


Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # Y up -> Z up (+90 degrees about X)


def rest_turns(motion: Motion, rig: Rig) -> np.ndarray:
    """For `rig.rest_pose`: each source joint's world rotation in the take's first frame, inverted:
    the set's joints then rest in that pose, their rotations all zero there."""
    if rig.split:
        motion = split_joint(motion, *rig.split)
    world_rot, _ = forward_kinematics(motion.skeleton, *local_transforms(motion))
    return np.swapaxes((Z_UP if rig.up == "Z" else np.eye(3)) @ world_rot[0], -1, -2)


def rerig(motion: Motion, rig: Rig, rest: np.ndarray | None = None) -> Motion:
    """The same body motion on another rig (see the module's text): world positions of every
    kept joint are those of the take, times `rig.scale` (turned to Z up for `rig.up`). `rest`
    (`rest_turns` of the set's first take) sets every joint's rest orientation for `rig.rest_pose`."""
    if rig.split:
        motion = split_joint(motion, *rig.split)
    if rig.frames:
        motion = Motion(motion.skeleton, motion.channels[:rig.frames], motion.fps, motion.source)
    source = motion.skeleton
    rotations, translations = local_transforms(motion)
    world_rot, world_pos = forward_kinematics(source, rotations, translations)
    world_pos = world_pos + np.array([0.0, rig.lift, 0.0])
    if rig.up == "Z":
        world_rot, world_pos = Z_UP @ world_rot, world_pos @ Z_UP.T
    names = [j.name for j in source.joints]
    rename = RENAMES.get(rig.rename, lambda n: n)
    first = 0 if rig.keep_root else names.index("Hips")
    # the new tree: (name, source joint or -1, parent name or None, offset share of the hand's end site)
    rows: list[tuple[str, int, str | None, float]] = []
    for j, joint in enumerate(source.joints):
        if j < first or joint.name in rig.drop:
            continue
        parent = None if j == first else rename(names[joint.parent])
        rows.append((rename(joint.name), j, parent, 0.0))
    if rig.rename == "cmu":
        for name, below in CMU_ABOVE:
            k = next(i for i, r in enumerate(rows) if r[0] == below)
            rows.insert(k, (name, -1, rows[k][2], 0.0))
            rows[k + 1] = (below, rows[k + 1][1], name, 0.0)
        for name, parent, share in CMU_BELOW:
            k = max(i for i, r in enumerate(rows) if r[0] == parent or r[2] == parent)
            rows.insert(k + 1, (name, -1, parent, share))
    twists = {}  # an inserted twist joint: (the source joint whose bone it is on, that bone's end)
    if rig.twist:
        for bone, end in TWIST_BONES:
            for side in SIDES:
                if bone + side in names:
                    twists[rename(bone + side) + "Twist"] = (names.index(bone + side), names.index(end + side))
                    rows.append((rename(bone + side) + "Twist", -1, rename(bone + side), 0.5))
    eyes = {}  # an inserted eye: where it sits from the head, in the head's frame (the take's units)
    if rig.eyes:
        head = names.index("Head")
        for side, across in (("Left", 3.0), ("Right", -3.0)):
            eyes[rename("Head").replace("Head", f"{side}Eye")] = world_rot[0, head].T @ np.array([across, 8.0, 0.0])
            rows.append((rename("Head").replace("Head", f"{side}Eye"), -1, rename("Head"), 0.0))
    rows = _depth_first(rows, rig.reorder)
    new_names = [r[0] for r in rows]
    frames, count = motion.frames, len(rows)
    turns = np.random.default_rng(30).normal(size=(count, 3))
    turns *= math.radians(rig.rest_turn_deg) / np.maximum(np.linalg.norm(turns, axis=1, keepdims=True), 1e-9)
    turn = expmap_to_matrix(turns) if rig.rest_turn_deg else np.broadcast_to(np.eye(3), (count, 3, 3))
    if rig.rest_pose:
        turn = np.stack([rest[r[1]] if r[1] >= 0 else np.eye(3) for r in rows]) if rest is not None else world_rot[0, [r[1] for r in rows]].swapaxes(-1, -2)
    w_rot = np.empty((frames, count, 3, 3))
    w_pos = np.empty((frames, count, 3))
    end_sites: list[tuple | None] = []
    for k, (name, j, parent, share) in enumerate(rows):
        if j >= 0:
            w_rot[:, k] = world_rot[:, j] @ turn[k]
            w_pos[:, k] = world_pos[:, j] * rig.scale
            end = source.joints[j].end_site
            dropped = [c for c in source.children(j) if source.joints[c].name in rig.drop]
            if dropped:  # the dropped joint's place becomes this joint's end site
                end = source.joints[dropped[0]].offset
            has_children = any(r[2] == name for r in rows)
            end_sites.append(None if end is None or has_children else tuple(turn[k].T @ np.asarray(end) * rig.scale))
        elif name in twists:  # half way down its bone, turning with it
            bone, end = twists[name]
            p = new_names.index(parent)
            w_rot[:, k] = w_rot[:, p]
            w_pos[:, k] = w_pos[:, p] + share * (world_pos[:, end] - world_pos[:, bone]) * rig.scale
            end_sites.append(tuple(0.1 * turn[p].T @ np.asarray(source.joints[end].offset) * rig.scale))
        elif name in eyes:  # fixed in the head
            p = new_names.index(parent)
            w_rot[:, k] = w_rot[:, p]
            w_pos[:, k] = w_pos[:, p] + world_rot[:, names.index("Head")] @ eyes[name] * rig.scale
            end_sites.append(tuple(turn[p].T @ eyes[name] * 0.1 * rig.scale))
        else:  # an inserted joint sits on its parent (a finger: further along the forearm's line) unrotated
            p = new_names.index(parent)
            hand = rows[p][1] if rows[p][1] >= 0 else rows[new_names.index(rows[p][2])][1]
            tip = 0.25 * np.asarray(source.joints[hand].offset) * rig.scale  # a quarter of the forearm, on along it
            along = world_rot[:, hand] @ tip
            w_rot[:, k] = w_rot[:, p]
            w_pos[:, k] = w_pos[:, p] + share * along
            leaf = not any(r[2] == name for r in rows)
            end_sites.append(tuple(turn[k].T @ tip * 0.3) if leaf else None)
    parents = [new_names.index(r[2]) if r[2] else -1 for r in rows]
    local_rot = np.empty_like(w_rot)
    local_pos = np.empty_like(w_pos)
    for k, p in enumerate(parents):
        if p < 0:
            local_rot[:, k], local_pos[:, k] = w_rot[:, k], w_pos[:, k]
        else:
            local_rot[:, k] = np.swapaxes(w_rot[:, p], -1, -2) @ w_rot[:, k]
            local_pos[:, k] = np.einsum("tji,tj->ti", w_rot[:, p], w_pos[:, k] - w_pos[:, p])
    rotation = tuple(f"{axis}rotation" for axis in rig.order)
    offsets = np.median(local_pos, axis=0)
    moves = np.abs(local_pos - offsets).max(axis=0).max(axis=1) > 1e-6 * np.abs(offsets).max()  # the root, or hips under a floor joint
    joints = tuple(Joint(name, p, tuple(float(v) for v in offsets[k]) if p >= 0 else (0.0, 0.0, 0.0),
                         (("Xposition", "Yposition", "Zposition") if p < 0 or moves[k] or rig.positions else ()) + rotation, end)
                   for k, (name, p, end) in enumerate(zip(new_names, parents, end_sites)))
    skeleton = Skeleton(joints)
    return resample(Motion(skeleton, channels_from_local(skeleton, local_rot, local_pos), motion.fps), rig.fps)


def build_set(takes: list[Path], rig: Rig, folder: Path, names: list[str] | None = None) -> list[Path]:
    """Write every take re-rigged into `folder` (same file names, or `names`); returns the files."""
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    rest = rest_turns(read_bvh(takes[0]), rig) if rig.rest_pose else None
    for k, path in enumerate(takes):
        target = folder / (names[k] if names else path.name)
        write_bvh(target, rerig(read_bvh(path), rig, rest))
        out.append(target)
    return out


def chosen_takes(data: Path, styles: list[str], count: int) -> list[Path]:
    """The first `count` walks of each style, in name order."""
    pairs = [p for p in styled_takes([data]) if p.unit == "walk"]
    chosen = []
    for style in styles:
        mine = [p.path for p in pairs if p.style == style][:count]
        if not mine:
            raise UserError(f"{data}: no walks of style {style!r}")
        chosen += mine
    return chosen


UNITS = ("walk", "run", "turn-left", "turn-right", "stand")


def unit_takes(folders: list[Path], styles: list[str], count: int) -> list[TakeFile]:
    """The first `count` takes of each unit (`UNITS`) and style in `folders`, in name order; a
    stand's taken in turn from each kind of standing take (raise, wave), so both gestures train."""
    takes = styled_takes(folders)
    chosen = []
    for style in styles:
        for unit in UNITS:
            mine = [t for t in takes if t.style == style and t.unit == unit]
            kinds: dict[str, list[TakeFile]] = {}
            for take in mine:
                kinds.setdefault(take.path.stem.rsplit("_", 2)[0], []).append(take)
            mine = [t for group in zip(*kinds.values()) for t in group] if unit == "stand" else mine
            if not mine:
                raise UserError(f"{', '.join(map(str, folders))}: no {unit} takes of style {style!r}")
            chosen += mine[:count]
    return chosen


def build_unit_set(takes: list[TakeFile], rig: Rig, folder: Path, manifest: bool = False) -> Path:
    """The takes re-rigged into `folder`: under their own names (their units and styles read from
    them, as `instrument train FOLDER` reads them), or with `manifest` under names that say
    nothing (`take007.bvh`) and a `manifest.csv` (file,style,unit,gesture) that says each
    take's style and unit, and a standing take's gesture. Returns what to train on: the folder or
    the manifest."""
    names = [f"take{k:03d}.bvh" if manifest else take.path.name for k, take in enumerate(takes)]
    build_set([t.path for t in takes], rig, folder, names)
    if not manifest:
        return folder
    rows = ["file,style,unit,gesture"] + [f"{name},{t.style},{t.unit},{take_gesture(t.path, t.unit) or ''}"
                                          for name, t in zip(names, takes)]
    (folder / "manifest.csv").write_text("\n".join(rows) + "\n")
    return folder / "manifest.csv"


def curving_takes(folder: Path, styles: list[str], count: int) -> tuple[list[Path], list[str]]:
    """The first `count` left and right turning walks of each style in `folder`, and the names
    they are written under: as walks (`dataset-2_walk_<style>_turn-left-001.bvh`), so they train
    as a capture of walks that curve (an actor walking round a room) rather than as turns."""
    pairs = [p for p in styled_takes([folder]) if p.unit in ("turn-left", "turn-right")]
    chosen, names = [], []
    for style in styles:
        for unit in ("turn-left", "turn-right"):
            for p in [p for p in pairs if p.style == style and p.unit == unit][:count]:
                chosen.append(p.path)
                names.append(f"dataset-2_walk_{style}_{unit}-{p.path.stem.rsplit('_', 1)[-1]}.bvh")
    return chosen, names


def cli(*args: str) -> subprocess.CompletedProcess:
    result = subprocess.run([sys.executable, "-m", "instrument", *args], capture_output=True, text=True)
    if result.returncode != 0:
        raise UserError(f"instrument {args[0]}: {result.stderr.strip().splitlines()[-1] if result.stderr.strip() else 'failed'}")
    return result


def targets(figures: dict) -> dict[str, dict]:
    """Per style at weight 1: the issue's figures, the takes' and the walk's, and whether each holds."""
    out = {}
    for style, real in figures["real"].items():
        made = figures["synth"][style]
        row = {}
        for key, name in (("knee_deg", "knee"), ("hip_deg", "hip"), ("shoulder_deg", "shoulder")):
            row[name] = (real[key], made[key], abs(made[key] / real[key] - 1.0) <= 0.10)
        row["skate"] = (real["skate_cm_s"], made["skate_cm_s"], made["skate_cm_s"] <= 1.2 * real["skate_cm_s"])
        row["float"] = (real["float_frac"], made["float_frac"], made["float_frac"] <= real["float_frac"] + 1e-9)
        r, m = real.get("recognised"), made.get("recognised")
        row["recognised"] = (r, m, r is None or m is None or math.isnan(r) or m >= 0.9 * r)
        out[style] = row
    return out


def measure(folder: Path, model: Path, seconds: float) -> dict:
    cli("train", str(folder), "--out", str(model), "--force", "--quiet")
    return json.loads(cli("evaluate", str(model), "--real", str(folder), "--variants", "one", "--seconds", str(seconds),
                          "--json").stdout)


def _cell(real, made, ok: bool, ratio: bool) -> str:
    if real is None or made is None or (isinstance(real, float) and math.isnan(real)):
        return "-"
    change = f"{made / real:.2f}x" if ratio else f"{100 * (made / real - 1):+.0f}%"
    return f"{real:.2f} / {made:.2f} ({change})" + ("" if ok else " **FAIL**")


def table(name: str, rows: dict[str, dict]) -> str:
    lines = [f"| {name} | recognised real / made | knee deg | hip deg | shoulder deg | skate cm/s | float % |", "|---" * 7 + "|"]
    for style, row in rows.items():
        cells = [_cell(*row["recognised"], ratio=True)] + [_cell(*row[k], ratio=False) for k in ("knee", "hip", "shoulder")]
        cells.append(_cell(*row["skate"], ratio=True))
        real, made, ok = row["float"]
        cells.append(f"{100 * real:.1f} / {100 * made:.1f}" + ("" if ok else " **FAIL**"))
        lines.append(f"| {style} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def unit_targets(folder: Path, training: Path, model: Path, seconds: float) -> list[dict]:
    """Train on `training` (a folder or a manifest) and return `evaluate --units`'s target rows."""
    cli("train", *(["--manifest"] if training.suffix == ".csv" else []), str(training), "--out", str(model), "--force",
        "--quiet")
    report = json.loads(cli("evaluate", str(model), "--real", str(folder), "--units", "--variants", "one", "--seconds",
                            str(seconds), "--json").stdout)
    return report["units"]["targets"]


def vocabulary(args: argparse.Namespace) -> None:
    """--units: per set, issue 25's targets passed (evaluate --units), one column a set, a row a target."""
    sets = [s.strip() for s in args.sets.split(",") if s.strip()]
    unknown = [s for s in sets if s not in SETS]
    if unknown or not sets:
        raise UserError(f"--sets: no set {unknown[0] if unknown else ''!r} (there are {', '.join(SETS)})")
    motions = Path(args.turns) if args.turns else Path(args.data).parent / "bandai-motions"
    takes = unit_takes([Path(args.data), motions], [s.strip() for s in args.styles.split(",") if s.strip()], args.units)
    out = Path(args.out)
    rows: dict[str, dict[str, list[bool]]] = {}
    for name in sets:
        print(f"{name}: training and measuring", file=sys.stderr)
        training = build_unit_set(takes, SETS[name], out / f"units-{name}", args.manifest)
        for row in unit_targets(out / f"units-{name}", training, out / f"units-{name}.npz", args.seconds):
            rows.setdefault(row["target"], {}).setdefault(name, []).append(row["passed"])
    print("| target | " + " | ".join(sets) + " |\n" + "|---" * (len(sets) + 1) + "|")
    for target, by_set in rows.items():
        print(f"| {target} | " + " | ".join(f"{sum(by_set.get(n, []))}/{len(by_set.get(n, []))}" for n in sets) + " |")
    print("| all | " + " | ".join(f"{sum(sum(r.get(n, [])) for r in rows.values())}/"
                                 f"{sum(len(r.get(n, [])) for r in rows.values())}" for n in sets) + " |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", help="folder of walks to re-rig (named like dataset-2_walk_<style>_NNN.bvh)")
    parser.add_argument("--out", default="/tmp/other-rigs", help="folder for the sets and models (default /tmp/other-rigs)")
    parser.add_argument("--sets", default=",".join(SETS), help=f"comma-separated, of {', '.join(SETS)} (default: all)")
    parser.add_argument("--styles", default="elderly,active,feminine", help="styles to take (default elderly,active,feminine)")
    parser.add_argument("--takes", type=int, default=6, help="walks per style (default 6)")
    parser.add_argument("--seconds", type=float, default=12.0, help="length of each synthesized walk (default 12)")
    parser.add_argument("--curving", type=int, default=0, metavar="N",
                        help="also N left and N right turning walks of each style (from --turns), named as walks")
    parser.add_argument("--turns", default=None, help="folder of turning walks (default: bandai-motions beside DATA)")
    parser.add_argument("--public", action="append", default=[], metavar="DIR",
                        help="also a folder of public captures, trained and measured as they are")
    parser.add_argument("--units", type=int, default=0, metavar="N",
                        help="the motion vocabulary instead: N takes of each unit and style (walks from DATA, the rest "
                             "from --turns), measured by evaluate --units")
    parser.add_argument("--manifest", action="store_true", help="with --units: neutral file names and a manifest")
    args = parser.parse_args()
    if args.units:
        vocabulary(args)
        return
    sets = [s.strip() for s in args.sets.split(",") if s.strip()]
    unknown = [s for s in sets if s not in SETS]
    if unknown or not sets:
        raise UserError(f"--sets: no set {unknown[0] if unknown else ''!r} (there are {', '.join(SETS)})")
    if args.takes < 2 or not 2 <= args.seconds <= 600:
        raise UserError(f"--takes must be at least 2 and --seconds 2 to 600 (got {args.takes}, {args.seconds})")
    out = Path(args.out)
    styles = [s.strip() for s in args.styles.split(",") if s.strip()]
    takes = chosen_takes(Path(args.data), styles, args.takes)
    names = [p.name for p in takes]
    if args.curving:
        turns, turn_names = curving_takes(Path(args.turns) if args.turns else Path(args.data).parent / "bandai-motions",
                                          styles, args.curving)
        takes, names = takes + turns, names + turn_names
    folders = {name: out / name for name in sets} | {Path(p).name: Path(p) for p in args.public}
    report = {}
    for name, folder in folders.items():
        if name in SETS:
            build_set(takes, SETS[name], folder, names)
        print(f"{name}: training and measuring", file=sys.stderr)
        report[name] = targets(measure(folder, out / f"{name}.npz", args.seconds))
        print(table(name, report[name]) + "\n", flush=True)
    failed = [f"{n} {s} {k}" for n, rows in report.items() for s, row in rows.items() for k, v in row.items() if not v[2]]
    print(f"{len(failed)} target(s) missed" + (": " + ", ".join(failed) if failed else ""))


if __name__ == "__main__":
    run_script(main, "other_rigs.py")
