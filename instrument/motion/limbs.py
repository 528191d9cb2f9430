"""Legs and arms of any skeleton, found from the joint tree and the template pose (not from names).

A leg is a subtree under the root that reaches near the ground; its thigh and shin are the two
longest consecutive bones on the way from the root to its lowest joint, so hip, knee and ankle
are where those bones start and end, and the foot is the ankle and what hangs below it. The
foot's pivot, the joint that is locked where it lands and that a heel rises about, is the foot's
front-most joint (its toes; a toe-tip joint such as Mixamo's Toe_End where there is one): not
the last joint listed, which may be a heel marker behind the ankle. The ball of the foot (Mixamo's
ToeBase) was tried: the toe tip then slid 1.5-8 times as much (`instrument evaluate`). A foot
that is its ankle alone rolls about its End Site, where that reaches forward (`foot_tip`). The
arms are the two longest branches of the upper body that do not hold one another (the neck
branches off with them but reaches a third as far); the upper arm and forearm are the last two
consecutive long bones on an arm's longest way down (a collar bone may be longer than the
forearm, a hand's bones are short), so the shoulder joint is where the upper arm starts and the
elbow where it ends.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .bvh import Motion, Skeleton
from .features import ROOT_FEATURES, FeatureLayout, heading_angle
from .kinematics import forward_kinematics, local_transforms

UP = np.array([0.0, 1.0, 0.0])


@dataclass(frozen=True)
class Leg:
    hip: int  # the joint whose rotation swings the thigh
    knee: int
    ankle: int
    foot: tuple[int, ...]  # the ankle and every joint below it (toes, end joints)
    pivot: int  # the foot's front-most joint: locked where it lands, a heel rises about it; the ankle if none (then its End Site: foot_tip)
    thigh: float  # bone lengths in the skeleton's units
    shin: float


@dataclass(frozen=True)
class Limbs:
    root: int
    legs: tuple[Leg, ...]  # two legs, in joint order
    arms: tuple[tuple[int, int], ...]  # (shoulder joint that swings the upper arm, elbow) per arm
    leg_length: float  # hip to ankle, fully stretched

    @property
    def feet(self) -> tuple[tuple[int, ...], ...]:
        return tuple(leg.foot for leg in self.legs)


def _chain(parents: np.ndarray, joint: int, top: int) -> list[int]:
    """Joints from `top` (excluded) down to `joint` (included)."""
    out = []
    while joint >= 0 and joint != top:
        out.append(joint)
        joint = int(parents[joint])
    return out[::-1]


def descendants(parents: np.ndarray, joint: int) -> list[int]:
    """`joint` and every joint below it (a BVH lists a parent before its children)."""
    out = [joint]
    for j in range(joint + 1, len(parents)):  # a BVH lists parents before children
        if parents[j] in out:
            out.append(j)
    return out


def _two_longest(chain: list[int], lengths: np.ndarray) -> tuple[int, int, int]:
    """(start, middle, end) joints of the two consecutive non-zero bones with the largest total
    length; bone k of a chain ends at chain[k] and starts at its parent in the chain."""
    bones = [(chain[k - 1], chain[k]) for k in range(1, len(chain)) if lengths[chain[k]] > 1e-6]
    if len(bones) < 2:
        raise ValueError("limb with fewer than two bones")
    best = max(range(len(bones) - 1), key=lambda k: lengths[bones[k][1]] + lengths[bones[k + 1][1]])
    return bones[best][0], bones[best][1], bones[best + 1][1]


def _front(positions: np.ndarray, ankle: int, foot: list[int]) -> int:
    """The foot's pivot (see the module's text): of the template pose's foot joints, the one
    furthest from the ankle along the floor."""
    forward = np.hypot(*(positions[foot] - positions[ankle])[:, [0, 2]].T)
    return foot[int(np.argmax(forward))] if forward.max() > 1e-9 else ankle


def _reach(parents: np.ndarray, lengths: np.ndarray, joint: int) -> tuple[float, list[int]]:
    """The longest way down from `joint` by bone length: (its length, its joints from `joint` on)."""
    children = [c for c in range(joint + 1, len(parents)) if parents[c] == joint]
    if not children:
        return 0.0, [joint]
    length, path = max(((lengths[c] + _reach(parents, lengths, c)[0], c) for c in children), key=lambda lc: lc[0])
    return float(length), [joint] + _reach(parents, lengths, path)[1]


def _arm_branches(parents: np.ndarray, lengths: np.ndarray, root: int, in_legs: set[int]) -> list[int]:
    """The first joints of the two arms, in joint order: of the upper body's branches (a joint
    whose parent has another child there), the two longest (by the longest way down from the
    branch's parent) that do not hold one another. The neck and head branch off where the arms
    do but reach a third as far; fingers and thumbs branch off within an arm. Found by the tree,
    not by where the hands are in the template pose: a hand swung across the body put the head
    further out on its side than the hand, and the neck was taken for that arm."""
    upper = [j for j in range(len(parents)) if j != root and j not in in_legs and root in _chain(parents, j, -1)[:-1]]
    branches = [j for j in upper if sum(1 for k in upper if parents[k] == parents[j]) >= 2]
    reach = {j: lengths[j] + _reach(parents, lengths, j)[0] for j in branches}
    chosen: list[int] = []
    for j in sorted(branches, key=lambda b: -reach[b]):
        if all(j not in descendants(parents, c) and c not in descendants(parents, j) for c in chosen):
            chosen.append(j)
        if len(chosen) == 2:
            break
    return sorted(chosen) if len(chosen) == 2 else []


LONG_BONE = 0.6  # an arm's upper arm and forearm are each at least this share of its longest bone


def _arm(parents: np.ndarray, lengths: np.ndarray, branch: int) -> tuple[int, int] | None:
    """(shoulder, elbow) of the arm that starts at `branch`: where the last two consecutive long
    bones (each at least LONG_BONE of the longest) on its longest way down (from the joint it
    hangs from) start and meet; None for an arm of fewer than two bones. Not the two longest:
    a CMU rig's collar bone (3.39 units) is longer than its forearm (3.28), so the collar and
    upper arm were taken for one side's arm and its shoulder swing measured on the collar bone."""
    chain = [int(parents[branch])] + _reach(parents, lengths, branch)[1]
    bones = [(chain[k - 1], chain[k]) for k in range(1, len(chain)) if lengths[chain[k]] > 1e-6]
    if len(bones) < 2:
        return None
    longest = max(lengths[end] for _, end in bones)
    pairs = [k for k in range(len(bones) - 1)
             if min(lengths[bones[k][1]], lengths[bones[k + 1][1]]) >= LONG_BONE * longest]
    if not pairs:  # no two long bones in a row: the two longest consecutive ones
        shoulder, elbow, _ = _two_longest(chain, lengths)
        return shoulder, elbow
    return bones[pairs[-1]][0], bones[pairs[-1]][1]


def leg_columns(layout: FeatureLayout) -> np.ndarray:
    """(2, D) bool: the features of each leg's joints (its hip and every joint below), in the
    legs' order (the contact tables' feet); none for a skeleton without two legs."""
    out = np.zeros((2, layout.dimension), dtype=bool)
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    if limbs is None:
        return out
    first = len(ROOT_FEATURES)  # the joints' features follow the root's
    for f, leg in enumerate(limbs.legs):
        below = set(descendants(layout.skeleton.parents, leg.hip))
        for k, joint in enumerate(layout.joints):
            out[f, first + 3 * k:first + 3 * k + 3] = joint in below
    return out


def find_limbs(skeleton: Skeleton, root: int, template: np.ndarray) -> Limbs | None:
    """Legs and arms from one frame of channel values (the template pose); None when the
    skeleton has no two legs below the root (then nothing about feet can be measured or fixed)."""
    return _find_limbs(skeleton, root, tuple(float(v) for v in template))


@lru_cache(maxsize=8)
def _find_limbs(skeleton: Skeleton, root: int, template: tuple[float, ...]) -> Limbs | None:
    rotations, translations = local_transforms(Motion(skeleton, np.asarray(template)[None], 30.0))
    positions = forward_kinematics(skeleton, rotations, translations)[1][0]
    parents = skeleton.parents
    lengths = np.linalg.norm(translations[0], axis=1)
    height = positions[:, 1] - positions[:, 1].min()
    legs = []
    for child in [j for j in range(len(parents)) if parents[j] == root]:
        below = descendants(parents, child)
        lowest = below[int(np.argmin(height[below]))]
        if height[lowest] >= height[root] / 3.0:
            continue
        try:
            hip, knee, ankle = _two_longest([root] + _chain(parents, lowest, root), lengths)
        except ValueError:
            continue
        foot = descendants(parents, ankle)
        legs.append(Leg(hip, knee, ankle, tuple(foot), _front(positions, ankle, foot), float(lengths[knee]),
                        float(lengths[ankle])))
    if len(legs) != 2:
        return None
    in_legs = {j for leg in legs for j in descendants(parents, _chain(parents, leg.hip, root)[0])}
    arms = [arm for branch in _arm_branches(parents, lengths, root, in_legs) if (arm := _arm(parents, lengths, branch))]
    leg_length = float(np.mean([leg.thigh + leg.shin for leg in legs]))
    return Limbs(root, tuple(legs), tuple(arms), leg_length)


def units_to_metres(hip_height: float) -> float:
    """Guess the data's unit from the hips' height: centimetres, metres, inches or millimetres
    (Vicon's and other optical systems' exports; read as an unknown unit, hips of 0.87 m came out
    0.95 m, and every figure in cm, the glTF and the VMC scale with them, 9% off)."""
    for scale in (0.01, 1.0, 0.0254, 0.001):
        if 0.5 <= hip_height * scale <= 1.5:
            return scale
    return 0.95 / hip_height if hip_height > 0 else 1.0


def hip_height(world_pose: np.ndarray, root: int) -> float:
    """How high the hips stand in a pose (J, 3), for guessing the unit: above the floor at height
    0, or above the lowest joint where a joint is lower than that (a capture whose floor is below
    the origin: hips at the origin, or at 0.2 m in metres, which was guessed as 4.75 m a unit)."""
    return float(world_pose[root, 1] - min(0.0, float(world_pose[:, 1].min())))


def centimetres_per_unit(layout: FeatureLayout, world_template: np.ndarray) -> float:
    return 100.0 * units_to_metres(hip_height(world_template, layout.root))


def clearance(positions: list[np.ndarray], limbs: Limbs) -> np.ndarray:
    """(2, foot joints) ground clearance of each foot joint: its 1st-percentile height over
    the takes, shared by both feet (the lower of the two), so a foot that never quite lands in
    the data does not move the floor."""
    heights = np.vstack([p[:, list(foot), 1] for p in positions for foot in limbs.feet])
    per_joint = np.percentile(heights, 1.0, axis=0)
    return np.broadcast_to(per_joint, (2, len(per_joint))).copy()


TIP_REACH = 0.25  # an End Site is a toe tip where it reaches this share of its length forward (`foot_tip`)


def foot_tip(layout: FeatureLayout, leg: Leg) -> np.ndarray | None:
    """(3,) where the toes end, in the ankle's frame, for a foot that is its ankle alone (no toe
    joint: the pivot is the ankle) and ends in an End Site reaching forward, the way the takes
    travel (many CMU conversions and some suits put it at the toe tip); None otherwise. The lock
    rolls such a heel up about this point as it would about a toe joint: about the ankle alone
    it could not, and a planted leg that could not reach stretched, swinging the hips 25-37%
    wider than the takes (docs/evaluate.md, "No toes"). Decided once per layout (`_foot_tips`):
    training, calibration, evaluate and the lock ask for every take and every character."""
    return _foot_tips(layout).get(leg.ankle)


@lru_cache(maxsize=8)
def _foot_tips(layout: FeatureLayout) -> dict[int, np.ndarray]:
    """Each toe-less foot's End Site (read-only, by its ankle) where the End Sites are toe tips;
    empty where they are not, or no foot is toe-less.

    Both feet are decided together, by the foot whose ankle stands lower in the template pose:
    the more nearly flat of the two (a walk's planted foot), whose End Site reaches TIP_REACH of
    its length forward when it is a toe tip. The template is one frame (the first take's first),
    and its other foot may be pitched 80 degrees down: judged each by itself, the shared walks'
    toe-less re-rig lost one foot's tip in 3 of their 12 takes' first frames (forward by 0.05-0.18
    of its length) and in 34% of all their frames, the lock rolling one heel about its toe tip and
    the other about its ankle; the lower foot reached at least 0.45 forward in every frame. A sole
    marker straight below the ankle reaches nowhere and a heel marker behind it reaches back; no
    heel rolls about either (one rolled about a point behind the ankle would swing the foot the
    wrong way).

    Forward is the heading frame's +Z in the template pose (`FeatureLayout.heading_reference`:
    where the takes travel, whatever the rig's axes). A model from before issue 30 (no
    `root_reference`) reads its heading from the root's own axes, which need not face the way the
    takes travel (hips whose rest faces X): there the End Site need only reach along the floor,
    which a heel marker passes too."""
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    joints = layout.skeleton.joints
    ends = {leg.ankle: np.asarray(joints[leg.ankle].end_site, dtype=np.float64) for leg in (limbs.legs if limbs else ())
            if leg.pivot == leg.ankle and joints[leg.ankle].end_site is not None
            and np.linalg.norm(joints[leg.ankle].end_site) >= 1e-9}
    if not ends:
        return {}
    world_rot, world_pos = (a[0] for a in forward_kinematics(layout.skeleton, layout.template_pose[0][None],
                                                              layout.template_pose[1][None]))
    judge = min(ends, key=lambda ankle: world_pos[ankle, 1])
    reach = world_rot[judge] @ ends[judge]
    if layout.root_reference is None:
        ahead = float(np.hypot(reach[0], reach[2]))
    else:
        yaw = heading_angle(world_rot[layout.root][None], layout.heading_reference)[0]
        ahead = float(reach @ np.array([np.sin(yaw), 0.0, np.cos(yaw)]))
    if ahead < TIP_REACH * np.linalg.norm(reach):
        return {}
    for end in ends.values():
        end.flags.writeable = False  # shared by every caller
    return ends


def tip_positions(world_rot: np.ndarray, world_pos: np.ndarray, limbs: Limbs, layout: FeatureLayout) -> np.ndarray | None:
    """(T, tips, 3) where the toe-less feet's tips (`foot_tip`) are in world transforms (T, J, 3, 3),
    (T, J, 3), in the legs' order; None when neither foot has a tip."""
    tips = [(leg.ankle, tip) for leg in limbs.legs if (tip := foot_tip(layout, leg)) is not None]
    if not tips:
        return None
    return np.stack([world_pos[:, a] + world_rot[:, a] @ tip for a, tip in tips], axis=1)


def tip_heights(world_rot: np.ndarray, world_pos: np.ndarray, limbs: Limbs, layout: FeatureLayout) -> np.ndarray | None:
    """(T * feet,) the toe tips' (`tip_positions`) heights over one take's frames; None when
    neither foot has a tip. Taken a take at a time, so training keeps the heights, not every
    take's rotations (a corpus of 400 takes: some 200 MB more)."""
    tips = tip_positions(world_rot, world_pos, limbs, layout)
    return None if tips is None else tips[:, :, 1].T.ravel()


def tip_clearance(heights: list[np.ndarray], frames: list[int]) -> float:
    """The toe tips' ground clearance, as `clearance` takes each joint's: the 1st percentile of
    a take's tip heights (`tip_heights`), their mean over the takes weighted by frames (as the
    lock's floor, `quality.take_floors`, is)."""
    return float(np.average([np.percentile(h, 1.0) for h in heights], weights=frames))


def sole_clearance(positions: list[np.ndarray], limbs: Limbs) -> float:
    """The height of a foot's lowest point when it stands on the floor: the 1st percentile, over
    the takes and both feet, of the lowest foot joint's height in each frame (ankle or toes,
    whichever is lower then). Stricter than `clearance` for floating: a flat foot whose ankle is
    2.3 cm above the ankle's clearance and toes 3.8 cm above theirs is 2.3 cm up by `clearance`
    but its toes' 3.8 cm (or more) above the sole's floor by this."""
    lowest = np.concatenate([p[:, list(foot), 1].min(axis=1) for p in positions for foot in limbs.feet])
    return float(np.percentile(lowest, 1.0))
