"""Test oracle: the streaming generator as it was written in plain Python before the per-frame
path was compiled (instrument.synthesis.stream), kept to check that the compiled path makes the
same frames. Streaming generation of an endless walk (ST-MLPG, one frame at a time).

Each output frame re-solves MLPG over a short window: the two frames already sent (fixed, so
the new frame joins them exactly), the frame being made, and a look-ahead planned from the
current lambda* and durations. Controls are read every frame, so any change shows in the very
next frame; the fixed past and a rate limit at the pace of the recorded data keep it from
jumping.

A `Walker` is one character's running state: where it is in its step, what it has sent, its
random draws. `step` advances any number of walkers by one frame in a single batched solve.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from instrument.synthesis.durations import MIN_FRAMES, state_durations, whole_frames
from instrument.synthesis.interpolation import Lambda, StyleSpace, interpolate
from instrument.synthesis.stream import Controls
from instrument.synthesis.mlpg import mlpg_continued

DEFAULT_LOOKAHEAD = 32  # frames: one stride (two steps) at 30 fps; see the README for the trade-off


@dataclass
class Walker:
    """One character's position in the walk and what it has sent."""

    dimension: int
    lookahead: int = DEFAULT_LOOKAHEAD
    seed: int = 0
    max_step_ratio: float = 1.0  # frame-to-frame change limited to this times the data's largest; 0: no limit
    label: int = 0  # 0 right step, 1 left step
    state: int = 0
    elapsed: int = 0  # frames already sent in the current state
    carries: list = field(default_factory=lambda: [0.0, 0.0])  # fractional frames each label's states carry on
    sent: int = 0
    history: np.ndarray = field(default=None)  # (2, D): the last two frames sent, oldest first
    history_ids: list = field(default_factory=lambda: [0, 0])  # their (label, state) indices
    cadence: float = 1.0  # model step length / planned step length (scales root speeds)
    draws: deque = field(default_factory=deque)  # liveliness draws for the current and coming states
    past: deque = field(default_factory=deque)  # the draws of the states left, the latest last
    follower: int = 1  # the label whose steps take the draws of the other's step before them
    rng: np.random.Generator = field(default=None)
    lam: Lambda | None = None
    lam_key: tuple | None = None
    base: list | None = None  # [label][state] durations before liveliness (lists: read per frame)
    sigma: list | None = None  # [label][state] duration standard deviations times liveliness

    def __post_init__(self) -> None:
        if self.history is None:
            self.history = np.zeros((2, self.dimension))
        if self.rng is None:
            self.rng = np.random.default_rng(self.seed)

    def draw(self, k: int) -> float:
        """The liveliness draw of the k-th state from the current one (deterministic per seed)."""
        while len(self.draws) <= k:
            self.draws.append(float(self.rng.standard_normal()))
        return self.draws[k]


def refresh(space: StyleSpace, walker: Walker, controls: Controls) -> None:
    """Recompute lambda* and the durations when the controls they depend on have changed."""
    key = controls.key()
    if key == walker.lam_key:
        return
    lam = interpolate(space, controls.weights, controls.part_weights)
    scale = np.ones(space.states) if controls.state_scale is None else np.asarray(controls.state_scale, dtype=np.float64)
    walker.lam, walker.lam_key = lam, key
    base = state_durations(lam.duration_means, lam.duration_variances, controls.speed, scale)
    walker.base = base.tolist()
    walker.sigma = (controls.liveliness * np.sqrt(lam.duration_variances) * scale).tolist()
    walker.cadence = float(np.maximum(lam.duration_means, MIN_FRAMES).sum() / base.sum())


def _duration(walker: Walker, label: int, state: int, k: int, states: int) -> float:
    """State `state` of `label` k states from the current one; a following step takes the draw
    of the leading step's same state before it (`states` states back), none before there was one."""
    d = walker.base[label][state]
    sigma = walker.sigma[label][state]
    if not sigma:
        return d
    draw = walker.draw(k)  # drawn all the same, so the draws that follow keep their order
    back = k - states
    if label == walker.follower:  # none before the first leading step
        draw = 0.0 if len(walker.past) + back < 0 else walker.draw(back) if back >= 0 else walker.past[back]
    return max(MIN_FRAMES, d + sigma * draw)


def plan(walker: Walker, states: int, frames: int) -> tuple[list[int], list[tuple[int, float]]]:
    """(label * states + state) for the next `frames` frames, and (frames, carry-out) of the
    state instances the plan passes through, starting with the current one."""
    ids: list[int] = []
    instances: list[tuple[int, float]] = []
    label, state, elapsed, carries, k = walker.label, walker.state, walker.elapsed, list(walker.carries), 0
    while len(ids) < frames:
        count, carries[label] = whole_frames(_duration(walker, label, state, k, states), carries[label])
        instances.append((count, carries[label]))
        ids.extend([label * states + state] * max(count - elapsed, 0))
        elapsed, k = 0, k + 1
        state += 1
        if state == states:
            state, label = 0, 1 - label
    return ids[:frames], instances


def _commit(walker: Walker, states: int, instances: list[tuple[int, float]]) -> None:
    """Advance the walker by the one frame just sent."""
    k = 0
    if walker.elapsed >= instances[0][0]:  # the current state was shortened below what it already had
        _finish(walker, states, instances[0][1])
        k = 1
    walker.elapsed += 1
    if walker.elapsed >= instances[k][0]:
        _finish(walker, states, instances[k][1])


def _finish(walker: Walker, states: int, carry_out: float) -> None:
    walker.carries[walker.label], walker.elapsed = carry_out, 0
    if walker.draws:
        walker.past.append(walker.draws.popleft())
        if len(walker.past) > states:
            walker.past.popleft()
    walker.state += 1
    if walker.state == states:
        walker.state, walker.label = 0, 1 - walker.label


def step(space: StyleSpace, walkers: list[Walker], controls: list[Controls]) -> np.ndarray:
    """One frame for each walker, (N, D), solved together. All walkers share one look-ahead and
    have sent the same number of frames (a crowd starts together)."""
    lookahead = walkers[0].lookahead
    fixed = min(walkers[0].sent, 2)
    width = space.base.shape[2]
    means = np.empty((len(walkers), fixed + lookahead + 1, width))
    precisions = np.empty_like(means)
    plans = []
    for n, (walker, control) in enumerate(zip(walkers, controls)):
        refresh(space, walker, control)
        ids, instances = plan(walker, space.states, lookahead + 1)
        window = walker.history_ids[2 - fixed :] + ids
        means[n] = walker.lam.means[window]
        precisions[n] = walker.lam.precisions[window]
        plans.append((ids[0], instances))
    history = np.stack([w.history[2 - fixed :] for w in walkers])
    frames = mlpg_continued(means, precisions, history)[:, 0]
    if fixed:
        frames = _limit_rate(space, walkers, frames)
    for walker, frame, (sent_id, instances) in zip(walkers, frames, plans):
        walker.history = np.vstack([walker.history[1:], frame])
        walker.history_ids = [walker.history_ids[1], sent_id]
        walker.sent += 1
        _commit(walker, space.states, instances)
    return frames


def _limit_rate(space: StyleSpace, walkers: list[Walker], frames: np.ndarray) -> np.ndarray:
    """No dimension moves further in one frame than the recorded data ever did (times the
    walker's ratio): an abrupt control change becomes a fast but humanly possible transition,
    and the next frames re-plan from where this one really is."""
    ratios = np.array([w.max_step_ratio for w in walkers])
    if not ratios.any():
        return frames
    previous = np.stack([w.history[1] for w in walkers])
    limit = np.where(ratios[:, None] > 0, ratios[:, None] * space.max_step, np.inf)
    return previous + np.clip(frames - previous, -limit, limit)


def state_plan(space: StyleSpace, walker: Walker, controls: Controls, frames: int) -> np.ndarray:
    """The state indices a walker would pass through over `frames` frames with constant
    controls, without generating anything (the plan full-sequence MLPG uses)."""
    refresh(space, walker, controls)
    ids, _ = plan(walker, space.states, frames)
    return np.asarray(ids)
