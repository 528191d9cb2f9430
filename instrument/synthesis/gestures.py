"""The engine's gesture stage: a wave or a raise of the hands layered on the gait's upper body.

A gesture is a second label stream for one body part, not a second pipeline: a second `Crowd`
(stream.py) over the same lambda* tables as the gait (the gesture's labels are rows of the same
model arrays, models/gestures.py, so the style weights, exaggeration, inversion and the crowd's
spread shape a wave as they shape the walk), planned through the gesture's phases:

    raise -> repeat-a -> repeat-b -> (repeat-a -> repeat-b ...) -> lower -> the stand's rest

The planner moves from a label to the other foot's label of the unit in `counters[:, UNIT]`
(label = 2 * unit + foot); a gesture's four labels are two such pairs, (lower, raise) and
(repeat-a, repeat-b), so choosing the unit from the label under way strings the phases: with the
repeat's unit, the raise goes on to repeat-a, and a and b follow each other for as long as the
unit stays (the look-ahead the window solves sees the loop as it will be played); the other
pair's unit takes repeat-b to the lower, and the stand's takes the lower to rest. The
repeat loops while the gesture's target is held; let go during the raise (a tap), it repeats as
many half cycles as its takes hold (it plays as the actors did); let go later, it lowers at the
end of the half cycle under way.

The gesture's stream starts from the two frames the character has just shown (its window's fixed
frames), so the arms leave the walk's swing without a jump; its upper-body features (the `upper`
group: spine, neck, head, arms) then replace the gait's with a weight that eases in over EASE_IN
seconds and out over EASE_OUT once the lower has ended (times: they were 6 and 12 frames, a
quarter as long at 120 fps as at 30), the legs and the root staying the gait's:
the feet keep their plan and the foot lock, the walk its speed and heading. The gesture's stream
solves only those dimensions (the range of static dimensions holding the `upper` group, read in
place from the gait's tables: each dimension's solve is independent of the others, so the upper
body comes out as a full solve would make it). While the gesture has every character's whole
upper body (weight 1, before the lower), the frame shows nothing of the gait's upper body, so the
gait's own solve makes the gesture's instead (`begin` plans the gesture's window and hands its
rows to the gait's stream, `Crowd.guest`; `after` moves the gesture's stream on by the frame the
gait made): one solve a frame, not two. At the lower the gait's upper body is solved again, from
the gesture's frames (its fixed past), unseen until the ease out, so the arms are back in the
walk's swing when they are handed back (docs/mlpg.md, "A gesture's frame"). While no gesture
plays the stage only keeps the last two frames' upper body.
"""

from __future__ import annotations

from collections.abc import Collection

import numpy as np
from numba import njit
from numba.types import Array, float64, int64

from ..models.gestures import gesture_labels, gesture_repeats
from ..models.modelfile import Model
from ..motion.features import REFERENCE_FPS
from .direct import entry_point
from .interpolation import StyleSpace, body_groups
from .parameters import GROUPS
from .stream import FOLLOWER, LABEL, UNIT, Crowd, _commit, _plan_window, _short_of_draws

EASE_IN = 6 / REFERENCE_FPS  # seconds the gesture's upper body takes to come in (its stream starts where the gait is)
EASE_OUT = 12 / REFERENCE_FPS  # seconds it takes to hand the arms back to the gait after the lower


class GestureLayer:
    """Per character: which gesture plays, where it is, and how much of the upper body it has."""

    name = "gestures"

    def __init__(self, model: Model, space: StyleSpace, count: int, lookahead: int, seeds: list[int]):
        self.labels = gesture_labels(model.metadata)  # {name: [lower, raise, repeat-a, repeat-b]}
        self.repeats = gesture_repeats(model.metadata)
        units = model.units
        self.rest_unit = units.index("stand") if "stand" in units else 0  # where a lowered gesture goes
        self.columns = np.flatnonzero(body_groups(model.layout)[GROUPS.index("upper")])  # the features a gesture takes
        # the range of static dimensions its stream solves: the upper body's (one range in a skeleton
        # whose upper joints follow one another, as they do in a depth-first joint order)
        self.solved = slice(int(self.columns.min()), int(self.columns.max()) + 1)
        self.crowd = Crowd(space, count, lookahead, seeds=seeds, columns=self.solved) if self.labels else None
        # its plan's work, while the gait's solve makes its frame
        self._work = None if self.crowd is None else self.crowd._window_buffers(2)
        self._next_units = np.zeros((2, 6), dtype=np.int64)  # the unit the plan goes on in, by phase (`_start`)
        self._repeats = 0  # the playing gesture's repeat half cycles, as its takes hold them
        self._holding = False  # whether its target is held
        self.playing: str | None = None
        self.first = 0  # the playing gesture's first label
        self.done = np.zeros(count, dtype=np.int64)  # repeat half cycles finished, per character
        self.tapped = np.ones(count, dtype=bool)  # let go during the raise (or not yet): repeats as the takes do
        self.label = np.zeros(count, dtype=np.int64)  # the label under way at the last frame
        self.ease = np.zeros(count)  # 0..1 along the ease in, then back down along the ease out
        self.weights = np.zeros(count)  # the gesture's share of each character's upper body, this frame
        self.rise, self.fall = 1.0 / (EASE_IN * model.fps), 1.0 / (EASE_OUT * model.fps)  # the ease's move a frame
        self.held: set[str] = set()  # the gesture targets held at the last frame
        self._as_given: Collection[str] = ()  # and as the controls gave them (a held pad: the same each frame)
        width = self.solved.stop - self.solved.start
        self.shown = np.zeros((count, 2, width))  # the last two frames shown, the solved range: where a gesture starts from
        self.shown_ids = np.zeros((count, 2), dtype=np.int64)  # and their states
        self.seen = 0  # frames shown so far (up to 2)
        self.blending = False  # whether this frame has the gesture's upper body in it (`begin`)
        self.gesture = np.zeros((count, width))  # the gesture stream's frame, the solved range
        # its upper body is one range, all the gesture's at weight 1: the gait's solve may make it meanwhile
        self.whole_range = len(self.columns) == width
        self.whole = False  # whether every character's weight was 1 at the last frame (then its ease is 1)
        self.host: Crowd | None = None  # the gait's stream, while its solve makes the gesture's frame (`begin`)
        # `_plan_guest`'s and `_move_guest`'s compiled entry points (direct.py) and the arguments they
        # are called with while the gait hosts, kept from frame to frame: the layer's and the two
        # streams' own arrays and numbers, each made by them of one type, so neither the dispatcher's
        # typing of 16 arrays a call nor the tuple's making is paid a frame (docs/mlpg.md)
        self._plan_call: object = None
        self._plan_arguments: tuple | None = None  # made again at a press or a release, a new pool or another gait
        self._move_call: object = None
        self._move_arguments: tuple = ()  # made when the gait begins to host
        # `_remember`'s, while no gesture plays
        self._remember_call = entry_point(_remember, (self.shown, self.shown_ids, self.solved.start), *_FRAME_TYPES)
        self.started = 0  # gestures begun

    @property
    def names(self) -> list[str]:
        return list(self.labels)

    def rows(self) -> np.ndarray | None:
        """(labels * states,) bool: the rows of lambda* only the gestures' labels have (the
        gait's stream reads none of them but while it makes a gesture's frame, `begin`); None
        without gestures."""
        if self.crowd is None:
            return None
        states = self.crowd.space.states
        rows = np.zeros(self.crowd.space.labels * states, dtype=np.bool_)
        for labels in self.labels.values():
            for label in labels:
                rows[label * states:(label + 1) * states] = True
        return rows

    def retune(self, duration_means: np.ndarray, duration_variances: np.ndarray, stream: Crowd) -> None:
        """The gait's lambda* tables and the gesture's durations at the model's own pace (a walk
        sped up does not hurry the wave)."""
        if self.crowd is not None:
            self.crowd.tables = stream.tables
            self.crowd.tune(duration_means, duration_variances, 1.0, None, 0.0)

    def begin(self, held: Collection[str], gait: Crowd | None) -> None:
        """Before the gait's stream makes the frame: a press or a release of the gesture targets
        `held`, and the gesture's frame. While it has every character's whole upper body (weight
        1) and `gait` is given (the gait's stream; None for a walk solved whole), the gait's own
        solve makes the gesture's upper body (its window's rows for those dimensions are the
        gesture's: `guest`), so the frame pays one solve, not two; `after` takes it from there."""
        if held != self._as_given:  # a press or a release: sets compared only then
            self._as_given = held
            self._plan_arguments = None  # its numbers (held, the gesture, its repeats) may change
            held = set(held)
            pressed = held - self.held
            if self.playing in self.held - held:  # let go: during the raise it was a tap (the takes' repeats), later a hold
                self.tapped = self.label == self.first + 1  # still raising
            self.held = held
            known = sorted(pressed & set(self.labels))  # one the model lacks: `run` says so, the walk goes on
            if known and self.playing is None:
                self._start(known[0])
            self._holding = self.playing in held
        self.blending = self.playing is not None
        guest = False
        if self.blending:
            crowd = self.crowd
            # the gait's solve may make this frame if it made the last or could have (`_progress`: every weight 1, none lowering)
            if self.whole and gait is not None and self.whole_range and gait.sent >= 2 and crowd.sent >= 2:
                guest = self._plan_hosted(crowd, gait)
                if not guest:  # its own stream again (the same plan)
                    self.gesture = crowd.step()
            else:
                _choose_units(crowd.counters, self.label, self.done, self.tapped, self._holding, self._repeats, self.first,
                              self._next_units)
                self.gesture = crowd.step()
                self._progress(crowd.history_ids[:, 1])
        if guest != (self.host is not None) or (guest and gait is not self.host):  # (a call only when it changes)
            self._host(guest, gait)

    def _plan_hosted(self, crowd: Crowd, gait: Crowd) -> bool:
        """The gesture's frame planned for the gait's solve to make (`_plan_guest`, one compiled
        call, its pool of draws topped up first when it runs short); whether every weight is 1."""
        arguments = self._plan_arguments
        if arguments is None or arguments[11] is not crowd.pool or arguments[16] is not gait.guest_rows:
            work = self._work
            arguments = self._plan_arguments = (
                crowd.counters, self.label, self.done, self.tapped, self._holding, self._repeats, self.first,
                self._next_units, crowd.base, crowd.sigma, crowd.carry, crowd.pool, crowd.history_ids, work.ids, work.counts,
                work.carries, gait.guest_rows, crowd.space.states, self.ease, self.weights, self.rise, self.fall)
            if self._plan_call is None:
                self._plan_call = entry_point(_plan_guest, arguments)
        short, playing, whole = self._plan_call(*arguments)
        if short:  # (planned nothing): its draws topped up, as its own step would have
            crowd._draws_for(crowd.lookahead + 1)
            self._plan_arguments = None
            return self._plan_hosted(crowd, gait)
        return self._keep(playing, whole)

    def _progress(self, now: np.ndarray) -> bool:
        """The weights for the frame of states `now`; whether every character's is 1."""
        return self._keep(*_progress(now, self.crowd.space.states, self.first, self.label, self.done, self.ease,
                                     self.weights, self.rise, self.fall))

    def _keep(self, playing: bool, whole: bool) -> bool:
        """`_progress`'s two answers (from either path) kept: the gesture ends when no character
        plays it; returns `whole`."""
        self.whole = whole
        if not playing:
            self.playing = None
        return whole

    def _host(self, guest: bool, gait: Crowd | None) -> None:
        """The gait's solve takes the gesture's upper body (its fixed frames the gesture's), or gives it back."""
        if self.host is not None and (not guest or gait is not self.host):
            self.host.host(0, 0)
            self.host = None
        if guest and self.host is None:
            crowd, work = self.crowd, self._work
            gait.history[:, :, self.solved] = crowd.history
            gait.host(self.solved.start, self.solved.stop)
            self.host = gait
            self._move_arguments = (gait.history, self.solved.start, crowd.history, crowd.history_ids, crowd.counters,
                                    crowd.carry, work.ids, work.counts, work.carries, crowd.space.states, self.weights,
                                    self.columns, self.shown, self.shown_ids)
            self._move_call = entry_point(_move_guest, self._move_arguments, *_FRAME_TYPES)

    def after(self, frames: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """The frame (N, D) with the gesture's upper body layered on at this frame's weights
        (`begin`; in place: the engine's frame is its own), and remembered with its states `ids`
        (where a gesture starts from). When the gait's solve made the gesture's frame (the host's
        last), the gesture's stream moves on by it, in the same compiled call."""
        if type(frames) is not np.ndarray or frames.dtype is not _FLOAT64:
            frames = np.asarray(frames, dtype=np.float64)
        direct = frames.ndim == 2 and type(ids) is np.ndarray and ids.ndim == 1 and ids.dtype is _INT64  # the entry points' types
        if not self.blending:
            if direct:
                self._remember_call(self.shown, self.shown_ids, self.solved.start, frames, ids)
            else:
                _remember(self.shown, self.shown_ids, self.solved.start, frames, ids)
        elif self.host is not None:
            if direct:
                self._move_call(*self._move_arguments, frames, ids)
            else:
                _move_guest(*self._move_arguments, frames, ids)
            self.crowd.sent += 1
        else:
            _blend(self.weights, frames, self.gesture, self.columns, self.solved.start, self.shown, self.shown_ids, ids)
        if self.seen < 2:
            self.seen += 1
        return frames

    def forward(self, forward: np.ndarray) -> None:
        """The frame's forward differences (N, A, D: the provisional next frames' differences from
        the frame, between.py) with the upper body moved each character's weight towards the gesture's,
        as `after` layered the frame (in place; call after it): the gesture stream's provisional next
        frame, its own window's or, while the gait's solve makes its frame, the gait's."""
        if not self.blending:
            return
        crowd, solved = self.crowd, self.solved
        ahead = crowd.ahead if self.host is None else self.host.ahead[:, :, solved]
        gesture = ahead - crowd.history[:, 1:]  # from the gesture's frame as shown: its stream's newest
        columns = self.columns
        forward[:, :, columns] += self.weights[:, None, None] * (gesture[:, :, columns - solved.start] - forward[:, :, columns])

    def _start(self, name: str) -> None:
        crowd = self.crowd
        first = self.labels[name][0]
        self.playing, self.first, self.started = name, first, self.started + 1
        if self.seen == 2:  # the window's fixed past: what the characters have just shown
            crowd.history[:] = self.shown
            crowd.history_ids[:] = self.shown_ids
            crowd.sent = 2
        else:  # at the very first frames: from nothing, as the gait begins
            crowd.sent = 0
        crowd.counters[:] = 0
        crowd.counters[:, LABEL] = first + 1  # the raise
        crowd.counters[:, FOLLOWER] = 1 - (first + 1) % 2
        crowd.carry[:] = 0.0
        self.done[:] = 0
        self.tapped[:] = True  # until let go after the raise
        self.label[:] = first + 1
        self.ease[:] = 0.0
        self.whole = False
        # the unit the plan goes on in, by phase: (before, lower, raise, a, b, after); (lower, raise) is
        # the pair `first // 2`, (a, b) the next: its unit loops a and b, the first pair's ends b in the lower
        ends, repeats, rest = first // 2, first // 2 + 1, self.rest_unit
        self._next_units = np.array([[rest, rest, repeats, repeats, repeats, rest],  # while it repeats
                                     [rest, rest, repeats, repeats, ends, rest]])  # and after
        self._repeats = self.repeats[name]


@njit(cache=True, nogil=True)
def _choose_units(counters, label, done, tapped, held, repeats, first, next_units):  # pragma: no cover - compiled
    """The unit each character's plan goes on in (module text): raise -> a, a -> b, b -> a while
    it repeats, b -> lower, lower -> the rest (`next_units`: by phase, while it repeats and after).
    It repeats while held, or after a tap until the half cycles played, the one under way (a b:
    only a b goes on to the lower) and the `done` before it, make `repeats` (rounded up to a whole
    cycle). Counting only those done, a tap played two half cycles more than its takes hold: an
    active raise, whose takes hold one or two, swayed twice more than it should and its last sway
    no longer looked active (docs/evaluate.md)."""
    for n in range(label.shape[0]):
        going_on = held or (tapped[n] and done[n] + 1 < repeats)
        phase = min(max(label[n] - first, -1), 4) + 1  # 0: before the gesture, 1..4 its labels, 5: after
        counters[n, UNIT] = next_units[0 if going_on else 1, phase]


@njit(cache=True, nogil=True)
def _progress(now, states, first, label, done, ease, weights, rise, fall):  # pragma: no cover - compiled
    """Each character's label under way at the frame of states `now`, the repeat half cycles it
    has finished, its ease (up by `rise` a frame while the gesture plays, down by `fall` after)
    and weight (smoothstep: no kink at either end). Returns whether the
    gesture still has any character, and whether the gait's solve may make the gesture's frame:
    every character's weight 1 and none lowering (from the lower on, the gait's own upper body is
    solved again, unseen until the ease out, so its arms are back in the walk's swing by then)."""
    playing, whole = False, True
    for n in range(label.shape[0]):
        here = now[n] // states
        if here != label[n] and (here == first + 2 or here == first + 3) and label[n] != first + 1:
            done[n] += 1  # a repeat half finished
        label[n] = here
        inside = first <= here <= first + 3
        e = min(max(ease[n] + (rise if inside else -fall), 0.0), 1.0)
        ease[n] = e
        w = e * e * (3.0 - 2.0 * e)
        weights[n] = w
        playing = playing or inside or e > 0.0
        whole = whole and w == 1.0 and here != first
    return playing, whole


@njit(cache=True, nogil=True)
def _plan_guest(counters, label, done, tapped, held, repeats, first, next_units, base, sigma, carry, pool, history_ids, ids,
                counts, carries, rows, states, ease, weights, rise, fall):  # pragma: no cover - compiled
    """The gesture's frame planned for the gait's solve to make, in one call: each character's
    unit (`_choose_units`), its plan and its window's rows into `rows` (the gait's `guest_rows`),
    and its weight at the frame planned (`_progress`). Returns whether a character has fewer draws
    left in its pool than a plan over the window's frames may take (`stream._short_of_draws`; then
    it has done nothing: the caller tops the pool up, `Crowd._draws_for`, and calls again), and
    `_progress`'s two answers."""
    if _short_of_draws(counters, ids.shape[1]):
        return True, False, False
    _choose_units(counters, label, done, tapped, held, repeats, first, next_units)
    for n in range(counters.shape[0]):
        _plan_window(base[n], sigma[n], counters[n], carry[n], pool[n], history_ids[n], 2, ids[n], counts[n], carries[n],
                     rows[n])
    playing, whole = _progress(ids[:, 0], states, first, label, done, ease, weights, rise, fall)
    return False, playing, whole


@njit(cache=True, nogil=True)
def _blend(weights, frames, gesture, columns, lo, shown, shown_ids, ids):  # pragma: no cover - compiled
    """The upper body `columns` of `frames` moved each character's weight towards the gesture's
    (whose column 0 is the frame's `lo`), in place, and remembered as shown (`_remember`: in the
    same call, one dispatch less a frame)."""
    for n in range(frames.shape[0]):
        w = weights[n]
        for c in columns:
            frames[n, c] = frames[n, c] + w * (gesture[n, c - lo] - frames[n, c])
    _remember(shown, shown_ids, lo, frames, ids)


@njit(cache=True, nogil=True)
def _move_guest(gait_history, lo, history, history_ids, counters, carry, ids, counts, carries, states, weights, columns, shown,
                shown_ids, frames, frame_ids):  # pragma: no cover - compiled
    """The gesture's stream moved on by the frame the gait's solve made for it (the gait's last
    frame, from column `lo`), as its own step would have (stream.py `_advance`), and that frame
    blended into `frames` (`_blend`): one call."""
    width = history.shape[2]
    for n in range(history.shape[0]):
        _commit(history, history_ids, counters, carry, n, gait_history[n, 1, lo:lo + width], ids[n, 0], counts[n], carries[n],
                states)
    _blend(weights, frames, history[:, 1], columns, lo, shown, shown_ids, frame_ids)


_FLOAT64, _INT64 = np.dtype(np.float64), np.dtype(np.int64)
# the last two arguments of `_remember` and `_move_guest` as their entry points take them: a frame (N, D) of
# float64 and its states (N,) of int64, each of any layout (the engine's frame is new each frame, its states a
# view of the stream's), the types `GestureLayer.after` checks before it calls them
_FRAME_TYPES = (Array(float64, 2, "A"), Array(int64, 1, "A"))


@njit(cache=True, nogil=True)
def _remember(shown, shown_ids, lo, frames, ids):  # pragma: no cover - compiled
    """The frame just shown (its solved range) and its states, after the one before."""
    for n in range(shown.shape[0]):
        shown_ids[n, 0], shown_ids[n, 1] = shown_ids[n, 1], ids[n]
        for d in range(shown.shape[2]):
            shown[n, 0, d] = shown[n, 1, d]
            shown[n, 1, d] = frames[n, lo + d]
