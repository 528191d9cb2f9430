"""Cut a walk into alternating right and left steps.

The signal is how far the left foot is ahead of the right one along the direction of travel,
measured in the root's heading frame. It peaks when the left foot is ahead (the right foot is
about to swing) and dips when the right foot is ahead. A right step runs from a peak to the
next dip, a left step from a dip to the next peak. Pieces before the first and after the last
extremum are partial steps and are dropped, and so are stretches that are not walking.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.ndimage import uniform_filter1d

from .bvh import Motion
from .features import FeatureLayout, choose_layout, heading_angle, travel_direction
from .kinematics import forward_kinematics, local_transforms
from .rotations import axis_angle_matrix

LABELS = ("right", "left")
MIN_STEP_SECONDS = 0.2
MAX_STEP_SECONDS = 2.0
MIN_STRIDE = 0.1  # a step whose feet pass each other by less than this share of leg length is not walking


@dataclass(frozen=True)
class Step:
    label: str  # "right" (the right foot swings forward) or "left"
    start: int  # first frame
    end: int  # one past the last frame

    @property
    def frames(self) -> int:
        return self.end - self.start


@dataclass(frozen=True)
class Segmentation:
    steps: list[Step]
    warnings: list[str]
    feet: tuple[str, str]  # names of the joints taken as left and right foot


def foot_signal(motion: Motion, layout: FeatureLayout | None = None) -> tuple[np.ndarray, tuple[int, int], float, np.ndarray]:
    """Left-ahead-of-right distance per frame, the (left, right) foot joints, leg length, root travel."""
    layout = layout or choose_layout([motion])
    rotations, translations = local_transforms(motion)
    world_rot, world_pos = forward_kinematics(motion.skeleton, rotations, translations)
    root_pos = world_pos[:, layout.root]
    heading = axis_angle_matrix("y", heading_angle(world_rot[:, layout.root], layout.heading_reference))
    velocity = np.gradient(root_pos, axis=0) * motion.fps
    forward = travel_direction(heading, velocity)
    left = np.cross(np.array([0.0, 1.0, 0.0]), forward)
    relative = world_pos - root_pos[:, None]
    side = _branch_sides(motion, layout.root, np.einsum("tjk,tk->j", relative, left) / motion.frames)
    height = relative[..., 1].mean(axis=0)
    below_root = np.array([j != layout.root and is_below(motion, j, layout.root) for j in range(len(side))])
    left_foot = _lowest(height, below_root & (side > 0))
    right_foot = _lowest(height, below_root & (side < 0))
    leg = float(-min(height[left_foot], height[right_foot])) if left_foot >= 0 and right_foot >= 0 else 0.0
    if left_foot < 0 or right_foot < 0:
        return np.zeros(motion.frames), (left_foot, right_foot), 0.0, np.zeros(motion.frames)
    ahead = np.einsum("tk,tk->t", world_pos[:, left_foot] - world_pos[:, right_foot], forward)
    travel = np.einsum("tk,tk->t", velocity, forward) / motion.fps
    return ahead, (left_foot, right_foot), leg, np.cumsum(travel)


def _branch_sides(motion: Motion, root: int, side: np.ndarray) -> np.ndarray:
    """Each joint's side (+ left) as the mean side of its whole branch from the root (a leg: hip,
    knee, ankle, toes). A joint's own mean side is near 0 for a toe that points inwards as the
    body turns: in a take turning left, the left toes came out on the right and both "feet" were
    taken from the left leg (Bandai's dataset-2_walk-turn-left_feminine_001, after the root's
    heading was read against its mean rotation)."""
    parents = motion.skeleton.parents
    branch = np.arange(len(side))
    for j in range(len(side)):
        while parents[branch[j]] >= 0 and parents[branch[j]] != root:
            branch[j] = parents[branch[j]]
    means = {b: side[branch == b].mean() for b in set(branch.tolist())}
    return np.array([means[b] for b in branch])


def is_below(motion: Motion, joint: int, ancestor: int) -> bool:
    """Whether `ancestor` is on the path from `joint` up to the root of the skeleton."""
    parents = motion.skeleton.parents
    p = parents[joint]
    while p >= 0:
        if p == ancestor:
            return True
        p = parents[p]
    return False


def _lowest(height: np.ndarray, allowed: np.ndarray) -> int:
    if not allowed.any():
        return -1
    return int(np.flatnonzero(allowed)[np.argmin(height[allowed])])


def _alternating_extrema(signal: np.ndarray, fps: float, prominence: float) -> list[tuple[int, int]]:
    """(frame, +1 for a peak / -1 for a dip), alternating; of two alike in a row the stronger stays."""
    from scipy.signal import find_peaks  # here, not at the top: scipy.signal takes a second to import

    distance = max(1, int(round(MIN_STEP_SECONDS * fps)))
    peaks, _ = find_peaks(signal, prominence=prominence, distance=distance)
    dips, _ = find_peaks(-signal, prominence=prominence, distance=distance)
    events = sorted([(int(p), 1) for p in peaks] + [(int(d), -1) for d in dips])
    out: list[tuple[int, int]] = []
    for frame, kind in events:
        if out and out[-1][1] == kind:
            if kind * signal[frame] > kind * signal[out[-1][0]]:
                out[-1] = (frame, kind)
        else:
            out.append((frame, kind))
    return out


def segment_steps(motion: Motion, layout: FeatureLayout | None = None) -> Segmentation:
    """Steps of a walk, with warnings about anything dropped or doubtful."""
    if motion.frames < 2 * MIN_STEP_SECONDS * motion.fps:  # a rest pose (one frame) or a moment: no step fits
        return Segmentation([], [f"{motion.frames} frame(s), {motion.duration:.2f} s: too short to hold a step"], ("", ""))
    names = motion.skeleton.names
    signal, (left_foot, right_foot), leg, travel = foot_signal(motion, layout)
    if left_foot < 0 or right_foot < 0:
        return Segmentation([], ["no left and right foot found below the root"], ("", ""))
    feet = (names[left_foot], names[right_foot])
    width = max(1, int(round(0.1 * motion.fps)))
    smooth = uniform_filter1d(signal, width, mode="nearest")
    amplitude = (np.percentile(smooth, 95) - np.percentile(smooth, 5)) / 2.0
    if amplitude < MIN_STRIDE * leg:
        return Segmentation([], ["the feet never pass each other: not a walk"], feet)
    extrema = _alternating_extrema(smooth, motion.fps, prominence=0.5 * amplitude)
    steps, warnings, dropped, on_the_spot = [], [], 0, 0
    for (start, kind), (end, _) in zip(extrema[:-1], extrema[1:]):
        seconds = (end - start) / motion.fps
        stride = abs(smooth[end] - smooth[start])
        moved = travel[end] - travel[start]
        if not (MIN_STEP_SECONDS <= seconds <= MAX_STEP_SECONDS) or stride < 2 * MIN_STRIDE * leg or moved < MIN_STRIDE * leg:
            dropped += 1
            on_the_spot += moved < MIN_STRIDE * leg
            continue
        steps.append(Step("right" if kind > 0 else "left", start, end))
    if dropped:
        warnings.append(f"dropped {dropped} stretch(es) that are not walking steps")
    if not steps and on_the_spot == dropped > 0:  # say why, or a treadmill take is a mystery
        warnings.append("no complete steps found: the feet pass each other but the body does not travel "
                        "(walking on the spot or on a treadmill?); takes must walk across the floor")
    elif not steps:
        warnings.append("no complete steps found")
    return Segmentation(steps, warnings, feet)


def contiguous_runs(steps: list[Step]) -> list[list[Step]]:
    """Steps grouped into runs where each starts where the previous ended."""
    runs: list[list[Step]] = []
    for step in steps:
        if runs and runs[-1][-1].end == step.start:
            runs[-1].append(step)
        else:
            runs.append([step])
    return runs
