"""A sequence of controls rendered as one motion, and the per-frame figures a transition is judged by.

`render_sequence` is `engine.render` with the controls changing part-way (the gait from walk to
stand, say): the same engine, frame by frame, the same ChannelStream, so what it measures is what
`synth` and a live run play. It also keeps the unit each frame was made of, so a figure can count
the steps taken after a change.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.kinematics import ChannelStream
from ..synthesis.engine import Engine
from ..synthesis.stream import Controls


@dataclass
class Sequence:
    motion: Motion
    labels: np.ndarray  # (frames,) the label (2 * unit + foot) each frame was made of
    changes: list[int]  # the frame at which each segment after the first began (its controls first used)


def render_sequence(model: Model, segments: list[tuple[Controls, int]]) -> Sequence:
    """The motion of `segments` ((controls, frames) one after another) from rest, at the origin."""
    engine = Engine(model)
    channels = ChannelStream(model.layout.skeleton)
    rows, labels, changes = [], [], []
    k = 0
    for number, (controls, frames) in enumerate(segments):
        if number:
            changes.append(k)
        for _ in range(frames):
            pose = engine.frame(k / engine.fps, controls)
            rows.append(channels.next(pose.rotations[0], pose.translations[0]))
            labels.append(int(engine.frame_ids[0]) // model.states)
            k += 1
    return Sequence(Motion(model.layout.skeleton, np.array(rows), model.fps), np.array(labels), changes)


def velocity_jumps(positions: np.ndarray, per_joint: bool = False) -> np.ndarray:
    """(frames,) the largest joint velocity jump at each frame: max over joints of |v(t) - v(t-1)|,
    v the joint's frame-to-frame world displacement (units per frame^2; 0 for the first two
    frames); with `per_joint`, (frames, joints) before the max. A pop (a joint snapping to a new
    place) is a jump far above what the motion's own accelerations give."""
    jumps = np.zeros(positions.shape[:2])
    if len(positions) > 2:
        jumps[2:] = np.linalg.norm(np.diff(positions, 2, axis=0), axis=-1)
    return jumps if per_joint else jumps.max(axis=1)


def horizontal_speed(track: np.ndarray, fps: float, window: int = 1) -> np.ndarray:
    """(frames,) the horizontal speed of a point (frames, 3), over a centred window of `window`
    frames either side (ends use what there is)."""
    frames = len(track)
    k = np.arange(frames)
    after, before = np.minimum(k + window, frames - 1), np.maximum(k - window, 0)
    span = np.maximum(after - before, 1)
    return np.linalg.norm((track[after] - track[before])[:, [0, 2]], axis=1) / span * fps
