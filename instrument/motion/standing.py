"""Still standing in a take: what a stand unit learns from, and what `evaluate` measures it against.

No corpus holds long quiet standing (the Bandai standing takes are gestures that begin and end
at rest), so rest is found frame by frame, from the joint tree alone (not from names): a frame
stands when the root barely moves over the floor, the feet stay put and the arms hang (their end
joints no higher than the hips plus a share of the leg): a raised or waving hand is a gesture,
not a posture. (The hands are never quite at rest in those takes, cut tight around the gesture:
the stand unit holds its arms at their mean over these frames, training/units.py.) Stretches of such frames are cut into pieces of about PIECE_SECONDS,
labelled right and left in turn, so a stand unit has "steps" like the walk's and the planner
treats it as one more pair of labels (ST-MLPG joins the pieces into one still stand).
"""

from __future__ import annotations

import numpy as np

from .bvh import Motion
from .features import REFERENCE_FPS, FeatureLayout
from .kinematics import forward_kinematics, local_transforms
from .limbs import descendants, find_limbs
from .steps import LABELS, Segmentation, Step

ROOT_SPEED = 0.07  # leg lengths per second: the root's horizontal speed at rest (about 6 cm/s for a 0.85 m leg)
FOOT_SPEED = 0.06  # leg lengths per second: a planted foot
HAND_HEIGHT = 0.25  # leg lengths above the hips: a hand higher than this is gesturing
PIECE_SECONDS = 0.4  # a stand "step"
STATES = 5  # states of a step model unless told (training's default): a piece has at least a frame each
MIN_STILL_SECONDS = 5 / REFERENCE_FPS  # the shortest still stretch kept (and never fewer frames than states; see standing_steps)


def still_frames(motion: Motion, layout: FeatureLayout) -> np.ndarray:
    """(frames,) bool: whether each frame stands still with the arms down (see the module's text)."""
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    if limbs is None or motion.frames < 2:
        return np.zeros(motion.frames, dtype=bool)
    positions = forward_kinematics(motion.skeleton, *local_transforms(motion))[1]
    leg = max(limbs.leg_length, 1e-9)

    def speed(joints: list[int], axes=(0, 1, 2)) -> np.ndarray:
        moved = np.linalg.norm(np.gradient(positions[:, joints][..., list(axes)], axis=0), axis=-1) * motion.fps
        return moved.max(axis=1) / leg

    hands = hand_joints(motion.skeleton.parents, limbs, positions[0])
    feet = [j for foot in limbs.feet for j in foot]
    still = speed([limbs.root], (0, 2)) < ROOT_SPEED
    still &= speed(feet) < FOOT_SPEED * 10  # feet may shift their weight; a step moves them far faster
    if hands:
        height = positions[:, hands, 1].max(axis=1) - positions[:, limbs.root, 1]
        still &= height < HAND_HEIGHT * leg
    return still


HAND_REACH = 0.75  # share of the farthest end joint's distance below the elbow: an end joint nearer is no hand


def hand_joints(parents: np.ndarray, limbs, pose: np.ndarray) -> list[int]:
    """The arms' end joints: hands, fingers, thumbs. (Limbs.arms names an arm's shoulder and
    elbow, not its end joints.) Per arm, the end joints below its elbow at least HAND_REACH as far
    from it as the farthest in `pose`: a twist joint half way down a rig's upper arm or forearm
    (Unreal's `upperarm_twist_01_l`) ends a branch too, and taken for a hand it stood a hanging
    arm's "hand" above the hips: no frame of a standing take was still. Without arms found, the
    upper body's end joints but the highest one (the head)."""
    ends = {j for j in range(len(parents)) if not (parents == j).any()}
    hands: list[int] = []
    for _, elbow in limbs.arms:
        leaves = [j for j in descendants(parents, elbow) if j in ends]
        reach = np.linalg.norm(pose[leaves] - pose[elbow], axis=1)
        hands += [j for j, r in zip(leaves, reach) if r >= HAND_REACH * reach.max()]
    if hands:
        return sorted(hands)
    legs = {j for foot in limbs.feet for j in foot} | {leg.hip for leg in limbs.legs} | {leg.knee for leg in limbs.legs}
    leaves = [j for j in sorted(ends) if j != limbs.root and j not in legs]
    return sorted(leaves, key=lambda j: pose[j, 1])[:-1] if len(leaves) > 1 else []


def stretches(mask: np.ndarray, shortest: int) -> list[tuple[int, int]]:
    """(start, end) of every run of True at least `shortest` long."""
    padded = np.concatenate([[False], mask, [False]]).astype(np.int8)
    edges = np.flatnonzero(np.diff(padded))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2]) if b - a >= shortest]


def pieces(start: int, end: int, fps: float, states: int = STATES) -> list[tuple[int, int]]:
    """A still stretch [start, end) cut into pieces of about PIECE_SECONDS (at least `states` frames)."""
    piece = max(states, int(round(PIECE_SECONDS * fps)))
    bounds = np.linspace(start, end, max(1, (end - start) // piece) + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]


def standing_steps(motion: Motion, layout: FeatureLayout, states: int = STATES, first: int = 0) -> Segmentation:
    """The still stretches of a take as alternating right and left pieces (see the module's text),
    the first labelled LABELS[first % 2]: training goes on from a style's previous standing take
    (and starts every other style at "left"), since a take often holds one piece (23 of the 56
    Bandai standing takes) and every one began at "right": active's and youthful's stands had no
    left piece, and a corpus of one standing take per style lost its stand unit ("no left step
    long enough").

    A stretch shorter than MIN_STILL_SECONDS is a pause, not a stand. It was 5 frames at any rate:
    at 120 fps the gesture takes' 42-167 ms pauses (32 of 107 stretches) became stand pieces, and
    the stand's pieces averaged 0.31 s where at 30 fps they average 0.39 s. A stretch also needs a
    frame for each of the model's `states` (a count, whatever the rate)."""
    steps: list[Step] = []
    for start, end in stretches(still_frames(motion, layout), max(states, int(round(MIN_STILL_SECONDS * motion.fps)))):
        for a, b in pieces(start, end, motion.fps, states):
            steps.append(Step(LABELS[(first + len(steps)) % 2], a, b))
    warnings = [] if steps else ["no still standing with the arms down found"]
    return Segmentation(steps, warnings, ("", ""))
