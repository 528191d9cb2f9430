"""A sequence of controls rendered as one motion, and the per-frame figures a transition is judged by.

`render_sequence` is `engine.render` with the controls changing part-way (the gait from walk to
stand, say): the same engine, frame by frame, the same ChannelStream, so what it measures is what
`synth` and a live run play. It also keeps the unit each frame was made of, so a figure can count
the steps taken after a change.
"""

from __future__ import annotations

import copy
import types
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
    return render_forks(model, segments, [])[0]


def render_forks(model: Model, segments: list[tuple[Controls, int]],
                 forks: list[tuple[int, Controls, int]]) -> tuple[Sequence, list[Sequence]]:
    """`render_sequence` of `segments`, and for each fork (frame, controls, frames) the same
    sequence up to that frame, then `controls` for `frames` frames: the engine (and the channels'
    unwrapping) copied as it stood before that frame, so the frames before it are made once
    however many forks leave from there (a sweep of when a second command comes costs only the
    frames after it)."""
    engine = Engine(model)
    channels = ChannelStream(model.layout.skeleton)
    rows: list[np.ndarray] = []
    labels: list[int] = []
    changes: list[int] = []
    leaving = sorted(range(len(forks)), key=lambda n: forks[n][0])
    gone = 0  # forks made (of `leaving`, in its order)
    out: dict[int, Sequence] = {}  # fork number -> its sequence

    def play(engine: Engine, channels: ChannelStream, controls: Controls, frames: int, rows: list, labels: list) -> None:
        for _ in range(frames):
            pose = engine.frame(len(rows) / engine.fps, controls)
            rows.append(channels.next(pose.rotations[0], pose.translations[0]))
            labels.append(int(engine.frame_ids[0]) // model.states)

    def fork_at(frame: int) -> None:
        nonlocal gone
        while gone < len(leaving) and forks[leaving[gone]][0] == frame:
            n = leaving[gone]
            gone += 1
            _, controls, frames = forks[n]
            # the model and skeleton are shared, not copied: only the engine's state is
            twin, twin_channels = twin_of((engine, channels), [model, model.layout.skeleton])
            more_rows, more_labels = list(rows), list(labels)
            play(twin, twin_channels, controls, frames, more_rows, more_labels)
            out[n] = Sequence(Motion(model.layout.skeleton, np.array(more_rows), model.fps), np.array(more_labels),
                              changes + [frame])

    for number, (controls, frames) in enumerate(segments):
        if number:
            changes.append(len(rows))
        for _ in range(frames):
            fork_at(len(rows))
            play(engine, channels, controls, 1, rows, labels)
    fork_at(len(rows))
    if gone < len(leaving):
        raise ValueError(f"render_forks: a fork at frame {forks[leaving[gone]][0]}, past the sequence's {len(rows)} frames")
    main = Sequence(Motion(model.layout.skeleton, np.array(rows), model.fps), np.array(labels), changes)
    return main, [out[n] for n in range(len(forks))]


def twin_of(objects: object, shared: list[object]) -> object:
    """A deep copy of `objects` that keeps each of `shared` itself (not copied) and every numpy
    view reached a view of the same copy: deepcopy on its own copies a view into an array of its
    own, so arrays one state shares (an engine's frame ids are a column of its stream's history,
    its contact shares rows of its contact table) would part in the copy. Each array viewed is
    copied once and its views made again on the copy, in deepcopy's memo."""
    memo: dict[int, object] = {id(s): s for s in shared}
    twins: dict[int, np.ndarray] = {}  # id(array viewed) -> its copy
    for view in _views(objects, set(memo)):
        base = view
        while isinstance(base.base, np.ndarray):
            base = base.base
        if id(base) not in twins:
            twin = np.copy(base, order="K")
            if twin.strides != base.strides:  # (an array whose memory is not laid out as any order's)
                continue
            twins[id(base)] = memo[id(base)] = twin
        made = np.ndarray(view.shape, view.dtype, buffer=twins[id(base)], offset=view.ctypes.data - base.ctypes.data,
                          strides=view.strides)
        made.flags.writeable = view.flags.writeable
        memo[id(view)] = made
    return copy.deepcopy(objects, memo)


def _views(root: object, skip: set[int]) -> list[np.ndarray]:
    """The numpy arrays reachable from `root` as deepcopy reaches them (through attributes, dicts,
    lists, tuples and sets; not through the objects whose ids are in `skip`) that view another
    array's memory."""
    found: list[np.ndarray] = []
    seen = set(skip)
    todo = [root]
    while todo:
        item = todo.pop()
        if id(item) in seen or isinstance(item, (str, bytes, int, float, bool, type(None), type, types.ModuleType,
                                                 types.FunctionType, types.BuiltinFunctionType, types.MethodType)):
            continue
        seen.add(id(item))
        if isinstance(item, np.ndarray):
            if isinstance(item.base, np.ndarray):
                found.append(item)
        elif isinstance(item, dict):
            todo.extend(item.values())
        elif isinstance(item, (list, tuple, set, frozenset)):
            todo.extend(item)
        elif _plain(type(item)):  # (one deepcopy copies by its own means, e.g. a compiled function, is not entered)
            attributes = getattr(item, "__dict__", None)
            if isinstance(attributes, dict):
                todo.extend(attributes.values())
            for kind in type(item).__mro__:
                slots = getattr(kind, "__slots__", ())
                todo.extend(getattr(item, name) for name in ((slots,) if isinstance(slots, str) else slots)
                            if hasattr(item, name))
    return found


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


def _plain(kind: type) -> bool:
    """Whether deepcopy copies an object of `kind` attribute by attribute (no copy or reduction of its own)."""
    return (not hasattr(kind, "__deepcopy__") and kind.__reduce_ex__ is object.__reduce_ex__
            and kind.__reduce__ is object.__reduce__)
