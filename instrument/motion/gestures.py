"""A gesture take's phases: the hands going up, their repeat (a wave's sway, a raise's hold) and
their going down, found from the joint tree alone (as standing.py finds rest).

The hands' height (the higher hand's, above the hips, in leg lengths) rises from rest to a high
band, stays in it and comes down. Between the take's lowest and highest (its 90th percentile)
heights, a frame is high above HIGH of the way, at rest below LOW of it: the raise runs from the
last rest frame before the first high one to where the hands stop rising (by under MOVING of the
way in a 30 fps frame's time), the lower from where they start falling, before the last high frame, to the first
rest frame after it, the repeat is the stretch between. (Ended at the first high frame, an active
raise, whose hands reach the band in 4 frames and settle for 6 more, was too short for its
states and left out, and its settling became a half of the repeat, played after its hold.)

The repeat is cut into half cycles, so it can loop as long as a pad is held: a wave's hands sway
across the body and back, and each sway one way is a "repeat-a", back a "repeat-b" (the turning
points of the hands' horizontal position along its main direction, with hysteresis); hands held
up without a sway (less than SWING leg lengths) are cut into pieces of about PIECE_SECONDS,
labelled a and b in turn, as the stand's pieces are, and into two at least when they last two
pieces' worth of states (so a short hold trains its style's b too). The planner (synthesis/gestures.py) plays
raise -> a -> b -> a ... -> b -> lower, the a/b pair looping while the gesture is held. Some
takes begin with the hands already up (no raise) or end before they are down: the phase missing
is simply not there, the others still count.

Every length above is a time, stated in frames at 30 fps (features.REFERENCE_FPS) and as long at
any rate, so that a take at 60, 100 or 120 fps is cut where it is at 30, within a frame's time:
the rise and fall are measured over a 30 fps frame's time, the raise begins and the lower ends
with a 30 fps frame of rest, the sway is smoothed over 0.1 s, a phase is kept when it lasts a
30 fps frame per state (and has a frame per state), a hold is cut by its length in 30 fps frames.
Counted in the take's own frames, 7 of the 56 Bandai gesture takes resampled to 120 fps had other
phases than at 30 (a 0.04 s wobble a half cycle, a hold one piece short) and 19 more had a cut over a
30 fps frame away (docs/evaluate.md, "Gesture phases at any frame rate").
"""

from __future__ import annotations

import numpy as np

from .bvh import Motion
from .features import REFERENCE_FPS, FeatureLayout
from .kinematics import forward_kinematics, local_transforms
from .limbs import find_limbs
from .standing import hand_joints
from .steps import Step

# a gesture's labels, in the model's order: two of the planner's pairs (label = 2 * unit + foot),
# (lower, raise) and (repeat-a, repeat-b), so that one unit loops the repeat (synthesis/gestures.py)
PHASES = ("lower", "raise", "repeat-a", "repeat-b")
HIGH = 0.6  # share of the way from the lowest to the highest hand height: the hands are up
LOW = 0.15  # share of the way: the hands are down (a raise starts here, a lower ends here)
SWING = 0.08  # leg lengths: a repeat whose hands sway less than this across is a hold
TURN = 0.3  # share of the sway's range the hands must come back to make a turning point
PIECE_SECONDS = 0.4  # a held repeat's piece
MOVING = 0.02  # share of the way in a 30 fps frame's time: the hands still rising into the repeat, or already falling
SMOOTH_SECONDS = 3 / REFERENCE_FPS  # the sway's moving average: over 3 frames at 30 fps


def hand_tracks(motion: Motion, layout: FeatureLayout) -> tuple[np.ndarray, np.ndarray, float] | None:
    """(heights (frames,), hands' horizontal positions relative to the root (frames, 2), leg
    length) of a take, heights and positions in leg lengths; None for a skeleton without hands."""
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    if limbs is None or motion.frames < 2:
        return None
    positions = forward_kinematics(motion.skeleton, *local_transforms(motion))[1]
    hands = hand_joints(motion.skeleton.parents, limbs, positions[0])
    if not hands:
        return None
    leg = max(limbs.leg_length, 1e-9)
    root = positions[:, limbs.root]
    heights = (positions[:, hands, 1].max(axis=1) - root[:, 1]) / leg
    across = (positions[:, hands][..., [0, 2]].mean(axis=1) - root[:, [0, 2]]) / leg
    return heights, across, leg


def turning_points(signal: np.ndarray, delta: float, start: int = 1) -> list[int]:
    """Indices of the signal's alternate highs and lows: a high is confirmed once the signal has
    come down `delta` from it, a low once it has gone up `delta` (a zigzag filter). A high or low
    in the first `start` frames is the signal's start, no turn."""
    points: list[int] = []
    high = low = 0  # the highest and lowest since the last turning point
    direction = 0  # +1 going up (looking for a high), -1 going down, 0 not yet known
    for k in range(1, len(signal)):
        if signal[k] > signal[high]:
            high = k
        if signal[k] < signal[low]:
            low = k
        if direction >= 0 and signal[high] - signal[k] > delta:
            points += [high] if high >= start else []
            direction, low = -1, k
        elif direction <= 0 and signal[k] - signal[low] > delta:
            points += [low] if low >= start else []
            direction, high = 1, k
    return points


def gesture_phases(motion: Motion, layout: FeatureLayout, states: int = 5) -> list[Step]:
    """The take's phases as Steps labelled with PHASES (see the module's text); [] when the hands
    never go up."""
    tracks = hand_tracks(motion, layout)
    if tracks is None:
        return []
    heights, across, _ = tracks
    bottom, top = float(heights.min()), float(np.percentile(heights, 90))
    if top - bottom < 0.2:  # the hands hardly move up: no gesture in this take
        return []
    high = np.flatnonzero(heights >= bottom + HIGH * (top - bottom))
    rest = heights <= bottom + LOW * (top - bottom)
    first, last = int(high[0]), int(high[-1])
    # the raise goes on while the hands still rise, the lower begins where they start falling: an
    # active raise's hands reach the high band in 4 frames and settle for 6 more, which, cut as the
    # repeat's first half, was played after its hold
    span = motion.fps / REFERENCE_FPS  # a 30 fps frame, in this take's frames
    frames = np.arange(motion.frames)
    rise = np.interp(frames + span, frames, heights) - heights  # over the next 30 fps frame's time
    fall = np.interp(frames - span, frames, heights) - heights  # since the last one
    moving = MOVING * (top - bottom)
    while first < last and rise[first] > moving:
        first += 1
    while last > first and fall[last] > moving:
        last -= 1
    before = np.flatnonzero(rest[:first])
    after = np.flatnonzero(rest[last:])
    margin = max(1, round(span))  # the rest the raise begins with and the lower ends with: a 30 fps frame
    start = max(0, int(before[-1]) + 1 - margin) if len(before) else 0
    end = min(motion.frames, last + int(after[0]) + margin) if len(after) else motion.frames
    steps: list[Step] = []
    if _long_enough(first - start, motion.fps, states):
        steps.append(Step("raise", start, first))
    steps += _repeats(across[first:last + 1], first, motion.fps, states)
    if _long_enough(end - (last + 1), motion.fps, states):
        steps.append(Step("lower", last + 1, end))
    return steps


def _reference_frames(frames: int, fps: float) -> int:
    """How many 30 fps frames a stretch of `frames` at `fps` lasts, to the nearest (`frames` at 30 fps)."""
    return int(np.floor(frames * REFERENCE_FPS / fps + 0.5))


def _long_enough(frames: int, fps: float, states: int) -> bool:
    """Whether a phase of `frames` is kept: it lasts a 30 fps frame for each of the `states`, and
    has a frame for each at this rate (a label's states take a frame each, at any rate)."""
    return frames >= states and _reference_frames(frames, fps) >= states


def _smoothed(signal: np.ndarray, fps: float) -> np.ndarray:
    """A moving average over SMOOTH_SECONDS at `fps`: at 30 fps the mean of 3 frames; at other
    rates the end frames weigh what part of their frame's time falls within the window."""
    half = SMOOTH_SECONDS * fps / 2  # in frames
    reach = np.arange(-int(np.ceil(half)), int(np.ceil(half)) + 1)
    weights = np.clip(half + 0.5 - np.abs(reach), 0.0, 1.0)
    weights = weights[weights > 0]
    return np.convolve(signal, weights / weights.sum(), mode="same")


def _repeats(across: np.ndarray, offset: int, fps: float, states: int) -> list[Step]:
    """The repeat stretch's half cycles (a sway one way "repeat-a", back "repeat-b"), or a hold's
    pieces; those too short for their `states` are left out (_long_enough)."""
    centred = across - across.mean(axis=0)
    direction = np.linalg.svd(centred, full_matrices=False)[2][0] if len(across) > 2 else np.array([1.0, 0.0])
    signal = _smoothed(centred @ direction, fps)
    spread = float(np.percentile(signal, 95) - np.percentile(signal, 5)) if len(signal) else 0.0
    steps: list[Step] = []
    if spread >= SWING:
        # the start: the frames nearer the first than the second 30 fps frame (the first frame at 30 fps)
        start = max(1, int(np.ceil(fps / REFERENCE_FPS / 2)))
        bounds = [0] + turning_points(signal, TURN * spread, start) + [len(signal)]
        for a, b in zip(bounds[:-1], bounds[1:]):
            if _long_enough(b - a, fps, states):
                rising = signal[min(b, len(signal) - 1)] > signal[a]
                steps.append(Step("repeat-a" if rising else "repeat-b", offset + a, offset + b))
        return steps
    # counted in 30 fps frames, so the hold has as many pieces at any rate
    length, piece = _reference_frames(len(across), fps), max(states, int(round(PIECE_SECONDS * REFERENCE_FPS)))
    # at least two pieces when it holds them (an a and a b: only a b goes on to the lower, so a hold
    # cut into one piece leaves its style's b to the other styles' takes)
    count = max(1, min(2, length // states), length // piece)
    bounds = np.linspace(0, len(across), count + 1).round().astype(int)
    return [Step(("repeat-a", "repeat-b")[k % 2], offset + int(a), offset + int(b))
            for k, (a, b) in enumerate(zip(bounds[:-1], bounds[1:])) if _long_enough(b - a, fps, states)]
