"""Streaming generation of an endless walk (ST-MLPG, one frame at a time).

Each output frame re-solves MLPG over a short window: the two frames already sent (fixed, so
the new frame joins them exactly), the frame being made, and a look-ahead planned from the
current lambda* and durations. Controls are read every frame, so any change shows in the very
next frame; the fixed past and a rate limit at the pace of the recorded data keep it from
jumping.

A `Crowd` is the running state of N characters held in arrays: where each is in its step, what
it has sent, its random draws. One compiled call per frame plans every character's look-ahead,
gathers its window, solves all windows, limits the rate and commits the frame; Python only
swaps a character's lambda* and duration tables when its controls change. One character is a
crowd of one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from .durations import MIN_FRAMES, whole_frames
from .interpolation import CrowdLambda, StyleSpace
from .cores import LEAST_PER_LIGHT_PART, over_cores, parts
from .direct import DirectCall
from .mlpg import _part, _prefetch_row, _solve
from .parameters import DEFAULT_LOOKAHEAD, GAITS, MAX_SPEED, MIN_SPEED


class StreamTables(NamedTuple):
    """What the compiled frame step reads and writes, row n for character n: one record, not a
    score of positional arrays."""

    mean_own: np.ndarray  # (N, labels * states, 3D) lambda* means: each character's own term (CrowdLambda)
    mean_shared: np.ndarray  # (labels * states, 3D) plus the term all share
    precision_own: np.ndarray  # (N, labels * states, 3D) precisions: each character's own factor
    precision_shared: np.ndarray  # (labels * states, 3D) times the factor all share
    plain: np.ndarray  # (N,) bool: the character's lambda* is the shared one (own term 0, factor 1)
    base: np.ndarray  # (N, labels, states) frames per state before liveliness
    sigma: np.ndarray  # (N, labels, states) duration sd times liveliness
    counters: np.ndarray  # (N, 9) int: where each plan is (LABEL ... NEXT below)
    carry: np.ndarray  # (N, labels) the fraction of a frame each label's steps carry on
    pool: np.ndarray  # (N, draws) liveliness draws
    history: np.ndarray  # (N, 2, D) the last two frames sent
    history_ids: np.ndarray  # (N, 2) int: their states
    ratios: np.ndarray  # (N,) rate limit, times the data's largest change (0: none)
    max_step: np.ndarray  # (D,) the data's largest frame-to-frame change
    lo: int  # the first of the tables' static dimensions the stream makes (D of them from there)
    guest: np.ndarray  # (2,) int: [a, b) of its D dimensions solved on `guest_rows` (a = b: none)
    guest_rows: np.ndarray  # (N, window) int: another stream's window rows (a gesture's, synthesis/gestures.py)
    pair_keys: np.ndarray  # (S + 3,) int: the (row, guest row) pair each slot holds (-1: none), then the slots
    # used and the guest range [a, b) they were made for (S = 0: no cache)
    pair_rows: np.ndarray  # (2, 1, S, 3D) a plain character's hosted rows: means, precisions (`_gather_pairs`)
    clip_change: np.ndarray  # (labels * states, 3D) where `limit` > 0: precisions made row by row (CrowdLambda)
    clip_base: np.ndarray  # (labels * states, 3D)
    limit: float  # 0: the precisions are two factors

    def part(self, start: int, stop: int) -> StreamTables:
        """Characters start to stop (views), for a part of the crowd on a core of its own."""
        shared = {"mean_shared", "precision_shared", "max_step", "lo", "guest", "clip_change", "clip_base", "limit"}
        pairs = {"pair_keys", "pair_rows"}  # not shared among cores that run at once: none
        return StreamTables(*(_NO_PAIRS[name] if name in pairs else t if name in shared else t[start:stop]
                              for name, t in zip(self._fields, self)))


# the pair cache of a part of a crowd on a core of its own: none (parts run at once)
_NO_PAIRS = {"pair_keys": np.zeros(3, dtype=np.int64), "pair_rows": np.zeros((2, 1, 0, 0))}
# slots of the cache of a hosted window's rows, at most half of them used (then emptied): a held wave
# or raise over the shipped model's walk passes through about 105 pairs of states; another model's
# more pairs only empty it more often
PAIR_SLOTS = 512
AHEAD = 2  # the provisional frames after the one sent that a step keeps (`Crowd.ahead`: the tangent's, between.py)
DRAWS_PAST_FRAMES = 3  # a plan over F frames takes at most F + 1 draws; two more kept in hand (`_short_of_draws`)


class WindowWork(NamedTuple):
    """The frame step's scratch arrays for one window length, kept between frames."""

    rows: np.ndarray  # (N, window) int: each window's rows of the lambda* tables
    work1: np.ndarray  # (window, D) solver work
    work2: np.ndarray  # (window, D)
    ids: np.ndarray  # (N, lookahead + 1) int: planned states
    counts: np.ndarray  # (N, lookahead + 3) int: frames of each state instance planned
    carries: np.ndarray  # (N, lookahead + 3) and their carries

    def part(self, start: int, stop: int, work: tuple[np.ndarray, np.ndarray] | None = None) -> WindowWork:
        """Characters start to stop (views), with solver work of their own (`work`) when given."""
        work1, work2 = (self.work1, self.work2) if work is None else work
        return WindowWork(self.rows[start:stop], work1, work2, self.ids[start:stop],
                          self.counts[start:stop], self.carries[start:stop])


# rows of Crowd.counters
# per character: where the plan is, its draws in the pool, which foot's steps follow the other's
# (0 right, 1 left) and the unit its next steps are of (the engine's units stage sets it: a label
# is 2 * unit + foot, and a step's next label is the other foot's in that unit); NEXT, when not
# 0, is 1 + the unit of the one step right after the current, UNIT's steps coming after it (a
# change the body was told too late to bend into, synthesis/units.py, waits a step)
LABEL, STATE, ELAPSED, HEAD, TAIL, FILLED, FOLLOWER, UNIT, NEXT = range(9)


@dataclass
class Controls:
    """Everything a performer can move, as plain numbers (one snapshot per frame)."""

    weights: np.ndarray  # (styles,): 0 absent, 1 the style, >1 exaggerated, <0 inverted
    part_weights: np.ndarray | None = None  # (styles, groups); NaN follows `weights`
    speed: float | np.ndarray = 1.0  # step rate relative to the model's, clamped to [0.25, 4]; (N,): each character's (the beat lock's)
    state_scale: np.ndarray | None = None  # (states,): stretch single phases of the step
    liveliness: float = 0.0  # 0: mean durations; 1: durations drawn from the pdfs
    turn: float = 0.0  # steering, radians per second: turning steps where the model has them, else added yaw
    gait: int = 1  # index into parameters.GAITS: stand, walk, run (taken at the next step boundary)
    gestures: tuple[str, ...] = ()  # the gesture targets held (synthesis/gestures.py: a press starts one)

    def key(self) -> tuple:
        """What lambda* and the durations depend on (the turn, the gait and the gestures do not: they choose labels)."""
        parts = None if self.part_weights is None else np.asarray(self.part_weights, dtype=np.float64).tobytes()
        scale = None if self.state_scale is None else np.asarray(self.state_scale, dtype=np.float64).tobytes()
        return (np.asarray(self.weights, dtype=np.float64).tobytes(), parts, np.asarray(self.speed, dtype=np.float64).tobytes(), scale,
                float(self.liveliness))


def gait_index(value: float) -> int:
    """The gait a value chooses: the nearest whole value, within the gaits (a fader's zones)."""
    return int(min(max(np.floor(float(value) + 0.5), 0), len(GAITS) - 1))


class Crowd:
    """N characters walking, each with its own controls, seed and random draws.

    Liveliness draws come from each character's own generator in a fixed order, pre-drawn into
    a pool (`pool[n, head:tail]` are the draws of the current and coming states, the `states`
    before `head` those of the states just left, which a following step uses again (`_plan`); the
    numbers after `tail` are drawn but not yet used), so the same seed gives the same walk
    however the pool is refilled.
    """

    def __init__(self, space: StyleSpace, count: int = 1, lookahead: int = DEFAULT_LOOKAHEAD,
                 seeds: list[int] | None = None, max_step_ratio: float | np.ndarray = 1.0, columns: slice | None = None):
        seeds = list(range(count)) if seeds is None else list(seeds)
        if len(seeds) != count:
            raise ValueError("one seed per character")
        self.space = space
        self.count = count
        self.lookahead = lookahead
        labels_states, width = space.base.shape[1], space.base.shape[2]
        # the static dimensions it makes: all, or a range of them (a gesture's stream: the upper body's),
        # read from the full lambda* tables in place (each dimension's solve is independent of the others)
        self.columns = slice(*(columns or slice(None)).indices(width // 3)[:2])
        dimension = self.columns.stop - self.columns.start
        self.max_step = np.ascontiguousarray(space.max_step[self.columns])
        self.sent = 0
        self.counters = np.zeros((count, 9), dtype=np.int64)
        self.counters[:, FOLLOWER] = 1  # a walk begins on a right step (label 0), which the left one follows
        self.carry = np.zeros((count, space.labels))  # the fraction of a frame each label's steps carry on
        self.history = np.zeros((count, 2, dimension))
        self.history_ids = np.zeros((count, 2), dtype=np.int64)
        # a frame's change is limited to this times the data's largest (0: no limit)
        self.max_step_ratio = np.broadcast_to(np.asarray(max_step_ratio, dtype=np.float64), (count,)).copy()
        self.tables = CrowdLambda(np.zeros((count, labels_states, width)), np.zeros((labels_states, width)),
                                  np.ones((count, labels_states, width)), np.ones((labels_states, width)),
                                  np.ones(count, dtype=bool))
        self.base = np.ones((count, space.labels, space.states))  # frames per state before liveliness
        self.sigma = np.zeros((count, space.labels, space.states))  # duration sd times liveliness
        self.cadence = np.ones(count)  # model step length / planned step length (scales root speeds)
        self.rngs = [np.random.default_rng(seed) for seed in seeds]
        self.pool = np.zeros((count, 4 * (lookahead + 8)))
        # dimensions [a, b) solved on another stream's window rows, `guest_rows` (a = b: none): the upper
        # body of a gesture that has all of it, in the gait's solve (synthesis/gestures.py sets both)
        self.guest = np.zeros(2, dtype=np.int64)
        self.guest_rows = np.zeros((count, lookahead + 3), dtype=np.int64)
        self._pairs = tuple(_NO_PAIRS.values())  # the hosted rows' cache, made at the first `host`
        self._buffers: dict[int, tuple] = {}
        self._made: tuple | None = None  # (what it was made from, the StreamTables record): `_record`
        self._advance = DirectCall(_advance)  # one core's frame: no dispatch a call (direct.py)
        self._parts_work: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}  # (fixed, k): part k's solver work
        # (N, AHEAD, D) each character's provisional next frames: the rows after the first of the window
        # the last step solved (its look-ahead's first frames, before the rate limit; fewer with a
        # shorter look-ahead). What the engine reads the newest frame's tangent from (between.py), at no solve of its own
        self.ahead = np.zeros((count, min(AHEAD, lookahead), dimension))

    def start_at(self, phases: np.ndarray) -> None:
        """Each character begins at its own (label, state) of the step cycle, before its first
        frame. The label it begins on leads and the other follows: a following step takes the
        frames and draws of the leading step before it, so the pair's turns cancel (`_plan`). The
        phase's label is a foot (0 right, 1 left) of the walk; `begin_in` moves it to another unit. One
        that begins mid-step is given, at its first frame (when its durations are known), the
        fraction of a frame that step would have carried to there at mean durations, so the
        first following step matches it: begun with none, its labels' carries stayed apart and
        a crowd's walkers curved up to 16 degrees a minute."""
        phases = np.asarray(phases, dtype=np.int64)
        self.counters[:, LABEL], self.counters[:, STATE] = phases[:, 0], phases[:, 1]
        self.counters[:, FOLLOWER] = 1 - phases[:, 0]

    def begin_in(self, units: np.ndarray) -> None:
        """Before the first frame: each character's first step is of its unit (a show that starts
        standing stands from its first frame), on the foot its phase gave."""
        if self.sent == 0:
            self.counters[:, LABEL] = 2 * np.asarray(units, dtype=np.int64) + self.counters[:, LABEL] % 2

    def _carry_to_phase(self) -> None:
        """Before the first frame: a character beginning at state s > 0 carries what states 0 to
        s - 1 of its step would have (from none, at mean durations), as if it had walked them."""
        for n in np.flatnonzero(self.counters[:, STATE] > 0):
            label, carry = self.counters[n, LABEL], 0.0
            for state in range(self.counters[n, STATE]):
                carry = whole_frames(self.base[n, label, state], carry)[1]
            self.carry[n, label] = carry

    def tune(self, duration_means: np.ndarray, duration_variances: np.ndarray, speed: float | np.ndarray,
             state_scale: np.ndarray | None, liveliness: float, rows: np.ndarray | None = None) -> None:
        """The engine's durations stage: every character's frames per state (N, labels, states)
        from its duration pdfs and the performed speed, phase stretch and liveliness, and the
        cadence that scales its root speeds. (Its lambda* tables, `tables`, are set by the
        interpolation stage.) `rows`: only these characters' (the others' pace has not changed)."""
        scale = np.ones(self.space.states) if state_scale is None else np.asarray(state_scale, dtype=np.float64)
        speeds = np.broadcast_to(np.asarray(speed, dtype=np.float64), (self.count,))  # one a character: the beat lock's
        rows = np.arange(self.count) if rows is None else np.asarray(rows, dtype=np.int64)
        means = np.ascontiguousarray(duration_means, dtype=np.float64)
        variances = np.ascontiguousarray(duration_variances, dtype=np.float64)
        speeds, liveliness = np.ascontiguousarray(speeds), float(liveliness)
        # a crowd's rows part by part over the cores (each row written by its own part only)
        over_cores(_tune, [(means, variances, speeds, scale, liveliness, rows[a:b], self.base, self.sigma, self.cadence)
                           for a, b in parts(len(rows), LEAST_PER_LIGHT_PART)])

    def _draws_for(self, frames: int) -> None:
        """Make sure every character has draws for a plan over `frames` frames (`_short_of_draws`)."""
        counters = self.counters
        if not _short_of_draws(counters, frames):
            return
        need = frames + DRAWS_PAST_FRAMES  # (as `_short_of_draws` asks: the pool is made twice that and a step long)
        states = self.space.states
        if self.pool.shape[1] < 2 * need + states:
            grown = np.zeros((self.count, 2 * need + states + self.pool.shape[1]))
            grown[:, : self.pool.shape[1]] = self.pool
            self.pool = grown
        for n, rng in enumerate(self.rngs):
            head, filled = counters[n, HEAD], counters[n, FILLED]
            if not _short_of_draws(counters[n:n + 1], frames):
                continue
            first = max(head - states, 0)  # the states just left stay: a following step draws again what its leader drew
            kept = filled - first  # draws kept, in order
            self.pool[n, :kept] = self.pool[n, first:filled]
            self.pool[n, kept:] = rng.standard_normal(self.pool.shape[1] - kept)
            counters[n, HEAD] -= first
            counters[n, TAIL] -= first
            counters[n, FILLED] = self.pool.shape[1]

    @property
    def means(self) -> np.ndarray:
        """(N, labels * states, 3D) every character's lambda* means, put together."""
        return self.tables.means

    @property
    def precisions(self) -> np.ndarray:
        return self.tables.precisions

    def _window_buffers(self, fixed: int) -> WindowWork:
        if fixed not in self._buffers:
            window = fixed + self.lookahead + 1
            dimension = self.history.shape[2]
            self._buffers[fixed] = WindowWork(
                np.zeros((self.count, window), dtype=np.int64),  # each window's rows of the lambda* tables
                np.zeros((window, dimension)), np.zeros((window, dimension)),  # solver work
                np.zeros((self.count, self.lookahead + 1), dtype=np.int64),  # planned ids
                np.zeros((self.count, self.lookahead + 3), dtype=np.int64),  # state instances: frames
                np.zeros((self.count, self.lookahead + 3)),  # and carries
            )
        return self._buffers[fixed]

    def _record(self) -> StreamTables:
        """The record the compiled step reads, made again only when the interpolation stage has
        handed over new lambda* tables or the draws' pool has grown (the other arrays are written
        in place): a record a frame cost a one-character frame about 1 us."""
        made = self._made
        if made is None or made[0][0] is not self.tables or made[0][1] is not self.pool or made[0][2] is not self.max_step_ratio:
            key = (self.tables, self.pool, self.max_step_ratio)  # (compared one by one: a generator's any() cost a frame 0.4 us)
            if len(self._pairs[0]) > 3:  # the hosted rows' cache held rows of the tables before
                self._pairs[0][:-3] = -1
                self._pairs[0][-3] = 0
            lam = self.tables
            self._made = key, StreamTables(lam.mean_own, lam.mean_shared, lam.precision_own, lam.precision_shared,
                                           lam.plain, self.base, self.sigma, self.counters, self.carry, self.pool,
                                           self.history, self.history_ids, self.max_step_ratio, self.max_step,
                                           self.columns.start, self.guest, self.guest_rows, *self._pairs,
                                           lam.precision_shared if lam.clip_change is None else lam.clip_change,
                                           lam.precision_shared if lam.clip_base is None else lam.clip_base,
                                           float(lam.limit))
        return self._made[1]

    def host(self, a: int, b: int) -> None:
        """Solve static dimensions [a, b) on `guest_rows` from the next frame (a = b: none), the
        hosted rows kept in a cache of their own while the tables are (`_gather_pairs`)."""
        self.guest[:] = a, b
        if a < b and len(self._pairs[0]) == 3:
            keys = np.full(PAIR_SLOTS + 3, -1, dtype=np.int64)
            keys[-3:] = 0
            self._pairs = keys, np.zeros((2, 1, PAIR_SLOTS, self.tables.mean_shared.shape[1]))
            self._made = None

    def step(self) -> np.ndarray:
        """One frame for each character, (N, D), from the tables the engine's stages set."""
        if self.sent == 0:
            self._carry_to_phase()
        fixed = min(self.sent, 2)
        frames = np.empty((self.count, self.history.shape[2]))
        buffers = self._window_buffers(fixed)
        ratios = self.max_step_ratio
        # the whole crowd's, so a part limits as the crowd does (one character: a plain number)
        limited = bool(ratios[0] > 0) if self.count == 1 else bool((ratios > 0).any())
        cut = parts(self.count)
        if len(cut) == 1:  # one core's worth (one character): no parts to cut
            tables = self._record()
            # its draws checked in the compiled step (0.4 us a frame in Python), topped up when short
            while self._advance((tables, buffers), tables, buffers, fixed, frames, self.ahead, limited):
                self._draws_for(self.lookahead + 1)
                tables = self._record()  # (its pool may be a new one)
            self.sent += 1
            return frames
        self._draws_for(self.lookahead + 1)
        tables = self._record()
        for k in range(1, len(cut)):  # each part's own solver work (the first's is the buffers')
            if (fixed, k) not in self._parts_work:
                self._parts_work[fixed, k] = np.zeros_like(buffers.work1), np.zeros_like(buffers.work2)
        over_cores(_advance, [(tables.part(start, stop), buffers.part(start, stop, self._parts_work.get((fixed, k))),
                               fixed, frames[start:stop], self.ahead[start:stop], limited)
                              for k, (start, stop) in enumerate(cut)])
        self.sent += 1
        return frames

    def state_plan(self, frames: int) -> np.ndarray:
        """The state indices character 0 would pass through over `frames` frames with its
        tables as they are, without generating anything (the plan full-sequence MLPG uses)."""
        if self.sent == 0:
            self._carry_to_phase()
        self._draws_for(frames)
        ids = np.zeros(frames, dtype=np.int64)
        counts = np.zeros(frames + 3, dtype=np.int64)
        carries = np.zeros(frames + 3)
        tail = _plan(self.base[0], self.sigma[0], self.counters[0], self.carry[0], self.pool[0], ids, counts, carries)[1]
        self.counters[0, TAIL] = tail  # the draws the plan made stay the character's (as if drawn now)
        return ids


@njit(cache=True, nogil=True)
def _plan(base, sigma, counter, carry, pool, ids, counts, carries):  # pragma: no cover - compiled
    """Fill ids (label * states + state) for len(ids) frames and the frames and carry-out of each
    state instance the plan passes through, from the current one; returns (instances, tail).

    Durations are real-valued: each instance takes floor(duration + carry) frames (at least
    one) and carries the rest on to the next state of the same label (from a step's last state
    to the first of the label's next step), so a long performance never drifts in time, every
    step stays within a frame of its real length, and a right step and the left step after it
    get the same frames state by state. Their models are mirror images, so that keeps the walk
    straight at turn = 0 (one carry passed on across labels gives the odd frame of a step 16.5
    frames long always to the same label: the walk curves). With liveliness, a following step's
    state (`FOLLOWER`'s label: the left one, unless `Crowd.start_at` began the walk on a left
    step or the unit was entered on one, `_enter`) takes the draw of the same state of the leading step before it (the one `states`
    instances back, kept in the pool), so the two steps of a stride still match and the walk goes
    straight while its strides vary (each step drawing its own turned it 38 degrees a minute,
    one way or the other); the states of the first following step that no leading step came
    before keep their mean durations, as `Crowd.start_at` assumed for the leader's."""
    states = base.shape[1]
    label, state, elapsed = counter[LABEL], counter[STATE], counter[ELAPSED]
    head, tail = counter[HEAD], counter[TAIL]
    frames = ids.shape[0]
    filled, k = 0, 0
    first_boundary = True
    remainders = carry.copy()  # (labels,), as the plan moves on
    follower = counter[FOLLOWER]
    while filled < frames:
        duration = base[label, state]
        spread = sigma[label, state]
        if spread != 0.0:
            if head + k >= tail:
                tail = head + k + 1
            draw = pool[head + k]
            if label % 2 == follower:  # the leading step's draw; none before the first leading step
                draw = pool[head + k - states] if head + k >= states else 0.0
            duration = max(MIN_FRAMES, duration + spread * draw)
        count = max(1, int(np.floor(duration + remainders[label])))
        remainders[label] += duration - count
        counts[k], carries[k] = count, remainders[label]
        for _ in range(max(count - elapsed, 0)):
            if filled < frames:
                ids[filled] = label * states + state
                filled += 1
        elapsed, k = 0, k + 1
        state += 1
        if state == states:  # the other foot's step, of the unit the engine chose
            left = label // 2
            state, label = 0, 2 * (_next_unit(counter) if first_boundary else counter[UNIT]) + 1 - label % 2
            first_boundary = False
            if label // 2 != left:
                follower = _enter(remainders, label)
    return k, tail


@njit(cache=True, nogil=True)
def numpy_sum(values):  # pragma: no cover - compiled
    """The sum of a 1-D array as numpy adds it (its pairwise summation: eight running sums from
    eight values up, one block of 128 at most here), so a compiled stage gives numpy's numbers to
    the bit."""
    count = values.shape[0]
    if count < 8:
        total = 0.0
        for k in range(count):
            total += values[k]
        return total
    assert count <= 128  # numpy splits longer arrays in halves first
    r0, r1, r2, r3, r4, r5, r6, r7 = values[0], values[1], values[2], values[3], values[4], values[5], values[6], values[7]
    k = 8
    while k < count - count % 8:
        r0 += values[k]
        r1 += values[k + 1]
        r2 += values[k + 2]
        r3 += values[k + 3]
        r4 += values[k + 4]
        r5 += values[k + 5]
        r6 += values[k + 6]
        r7 += values[k + 7]
        k += 8
    total = ((r0 + r1) + (r2 + r3)) + ((r4 + r5) + (r6 + r7))
    while k < count:
        total += values[k]
        k += 1
    return total


@njit(cache=True, nogil=True)
def _tune(means, variances, speeds, scale, liveliness, rows, base, sigma, cadence):  # pragma: no cover - compiled
    """`Crowd.tune` for every character in one pass: base = durations.state_durations(means,
    variances, speed, scale), sigma = liveliness sqrt(variances) scale, cadence = the sum of
    max(means, MIN_FRAMES) over the sum of base; the same operations in the same order as those
    numpy forms (tests/walks.py and the reference stream use them), so the same numbers to the bit
    (numpy took a dozen passes over the crowd's tables: 3 us a character a retune); for the
    characters `rows` only."""
    labels, states = means.shape[1], means.shape[2]
    floored = np.empty(labels * states)
    made = np.empty(labels * states)
    for n in rows:
        speed = min(max(speeds[n], MIN_SPEED), MAX_SPEED)
        for label in range(labels):
            total, spread = 0.0, 0.0
            for state in range(states):
                floored[label * states + state] = max(means[n, label, state], MIN_FRAMES)
                total += floored[label * states + state]
                spread += variances[n, label, state]
            rho = (total / speed - total) / spread
            for state in range(states):
                made[label * states + state] = max((floored[label * states + state] + rho * variances[n, label, state])
                                                   * scale[state], MIN_FRAMES)
                base[n, label, state] = made[label * states + state]
                sigma[n, label, state] = liveliness * np.sqrt(variances[n, label, state]) * scale[state]
        cadence[n] = numpy_sum(floored) / numpy_sum(made)


@njit(cache=True, nogil=True)
def _next_unit(counter):  # pragma: no cover - compiled
    """The unit of the step after the current one: NEXT's when one waits, else UNIT's."""
    return counter[NEXT] - 1 if counter[NEXT] > 0 else counter[UNIT]


@njit(cache=True, nogil=True)
def _enter(carry, label):  # pragma: no cover - compiled
    """A unit entered on `label` (the first step after another unit's): that step leads a pair, as
    a walk's first step from rest does. The other foot's label of the unit takes the carry this
    one begins with, so the two steps get the same frames state by state, and the follower's
    draws are this step's; returns the following foot (`FOLLOWER`). Each label kept its own
    carry while the unit was left, and a gait left after an odd number of steps came back with
    its two feet a fraction of a frame apart for good: active x2's run, stopped and set off again,
    went on at 14 and 15 frames a step, the walk curved 4 degrees a minute. A gesture's stream
    passes through it too (raise -> its repeat's a, b -> lower): a repeat's b takes its a's carry
    and follows its draws, so the two halves of a wave's swing get the same frames state by state
    (a wave moved by up to 0.0066 rad from its lower on)."""
    carry[label ^ 1] = carry[label]
    return 1 - label % 2


@njit(cache=True, nogil=True)
def _finish(counter, carry, n, carry_out, states):  # pragma: no cover - compiled
    carry[n, counter[LABEL]] = carry_out
    counter[ELAPSED] = 0
    if counter[TAIL] > counter[HEAD]:
        counter[HEAD] += 1
    counter[STATE] += 1
    if counter[STATE] == states:
        left = counter[LABEL] // 2
        counter[STATE], counter[LABEL] = 0, 2 * _next_unit(counter) + 1 - counter[LABEL] % 2
        counter[NEXT] = 0
        if counter[LABEL] // 2 != left:
            counter[FOLLOWER] = _enter(carry[n], counter[LABEL])


@njit(cache=True, nogil=True)
def _short_of_draws(counters, frames):  # pragma: no cover - compiled
    """Whether a character of `counters` (rows of `Crowd.counters`) has fewer draws left in its
    pool (FILLED - TAIL) than `frames` + DRAWS_PAST_FRAMES (3). A plan over `frames` frames
    (`_plan`) passes through at most `frames` + 1 state instances (one a frame, and the one under
    way, whose frames may all have been played: a state shortened below what it had), the k-th
    taking the draw at HEAD + k, and HEAD never passes TAIL: it takes at most `frames` + 1 draws
    past TAIL; two more are kept in hand. A step's window is planned over lookahead + 1 frames
    (its `ids`), so it asks for lookahead + 4. The one check of the stream's step (`_advance`), a
    gesture's plan (`gestures._plan_guest`) and the refill (`Crowd._draws_for`)."""
    need = frames + DRAWS_PAST_FRAMES
    for n in range(counters.shape[0]):
        if counters[n, FILLED] - counters[n, TAIL] < need:
            return True
    return False


@njit(cache=True, nogil=True)
def _advance(tables, work, fixed, frames, ahead, limit_any):  # pragma: no cover - compiled
    """Plan, solve, rate-limit and commit one frame for every character of `tables` (a crowd or a
    part of one), in place. The solver reads each window's means and precisions from the
    character's lambda* tables (`rows`). `limit_any`: whether any character of the crowd has a
    rate limit (then every frame goes through the limit's arithmetic). `ahead` (N, A, D) takes each
    window's provisional next A frames (`Crowd.ahead`). Returns whether a character has fewer
    draws left in its pool than a plan over the window may take (then it has done nothing: the
    caller tops the pools up, `Crowd._draws_for`, and calls again)."""
    mean_own, mean_shared, precision_own, precision_shared = (tables.mean_own, tables.mean_shared, tables.precision_own,
                                                              tables.precision_shared)
    base, sigma, counters, carry, pool = tables.base, tables.sigma, tables.counters, tables.carry, tables.pool
    history, history_ids, ratios, max_step, lo = tables.history, tables.history_ids, tables.ratios, tables.max_step, tables.lo
    a, b = tables.guest[0], tables.guest[1]  # (only with the window's two fixed frames: the guest's are two)
    rows, work1, work2, ids, counts, carries = work.rows, work.work1, work.work2, work.ids, work.counts, work.carries
    count, states = mean_own.shape[0], base.shape[2]
    if _short_of_draws(counters, ids.shape[1]):  # (a plan over the window's frames)
        return True
    dimension = history.shape[2]
    known = np.ascontiguousarray(history[:, 2 - fixed:]) if fixed else np.zeros((count, 1, dimension))
    work1[:] = 0.0
    work2[:] = 0.0
    # one window's solution at a time, kept in the cache (the frame sent is its first row, copied to
    # `frames`): a crowd's windows side by side were 17 MB zeroed and written a frame for 1,000 characters
    solved = np.zeros((1, rows.shape[1] - fixed, dimension))
    # the rows of the character's lambda* its window reads, put together here, in the cache, as the
    # solver reads them (or the shared tables as they are): a window passes through some ten state
    # instances, and putting together all 90 rows of both tables cost the crowd's stream two thirds of its time
    window, width = rows.shape[1], mean_shared.shape[1]
    means = np.empty((1, window, width))
    precisions = np.empty((1, window, width))
    local = np.empty((1, window), dtype=np.int64)  # each window frame's row of `means` and `precisions`
    shared_means = mean_shared.reshape((1,) + mean_shared.shape)
    shared_precisions = precision_shared.reshape((1,) + precision_shared.shape)
    plain = tables.plain
    guest_rows = tables.guest_rows
    for n in range(count):  # every plan first, so the rows a character's window reads are known before it is solved
        _plan_window(base[n], sigma[n], counters[n], carry[n], pool[n], history_ids[n], fixed, ids[n], counts[n],
                     carries[n], rows[n])
    for n in range(count):
        if n + 1 < count and not plain[n + 1]:  # the next character's rows asked for while this one is solved
            for m in range(window):
                if m == 0 or rows[n + 1, m] != rows[n + 1, m - 1]:
                    _prefetch_row(mean_own[n + 1], rows[n + 1, m], 0, width)
                    _prefetch_row(precision_own[n + 1], rows[n + 1, m], 0, width)
        if plain[n] and a == b:  # 0 + x and 1 x are x: the shared tables are the character's, to the bit
            _solve(shared_means, shared_precisions, rows[n : n + 1], False, known[n : n + 1], fixed, solved, work1, work2,
                   lo)
        elif plain[n] and tables.pair_keys.shape[0] - 3 >= 2 * window:  # hosted, its pairs' rows the shared tables': kept
            _gather_pairs(tables, n, rows[n], guest_rows[n], lo + a, lo + b, local[0])
            pair_rows = tables.pair_rows
            _solve(pair_rows[0], pair_rows[1], local, False, known[n : n + 1], fixed, solved, work1, work2, lo)
        else:  # its window's rows put together, a guest's dimensions from the guest's rows
            _gather(tables, n, rows[n], guest_rows[n], lo + a, lo + b, local[0], means[0], precisions[0])
            _solve(means, precisions, local, False, known[n : n + 1], fixed, solved, work1, work2, lo)
        frames[n] = solved[0, 0]
        for j in range(ahead.shape[1]):
            ahead[n, j] = solved[0, 1 + j]
    for n in range(count):
        for d in range(dimension):
            value = frames[n, d]
            if fixed and limit_any:  # no feature moves further in a frame than the data ever did
                previous = history[n, 1, d]
                bound = ratios[n] * max_step[d] if ratios[n] > 0 else np.inf
                value = previous + min(max(value - previous, -bound), bound)
            frames[n, d] = value
        _commit(history, history_ids, counters, carry, n, frames[n], ids[n, 0], counts[n], carries[n], states)
    return False


@njit(cache=True, nogil=True)
def _commit(history, history_ids, counters, carry, n, frame, state, counts, carries, states):  # pragma: no cover - compiled
    """Character n sent `frame` (of state `state`): its last two frames and their states move on
    by it, and its plan advances by a frame (`_move_on`). The gesture's stream commits this way
    the frame the gait's solve made for it (gestures.py `_move_guest`)."""
    history[n, 0] = history[n, 1]
    history[n, 1] = frame
    history_ids[n, 0] = history_ids[n, 1]
    history_ids[n, 1] = state
    _move_on(counters[n], carry, n, counts, carries, states)


@njit(cache=True, nogil=True)
def _gather(tables, n, rows, guest_rows, a, b, local, means, precisions):  # pragma: no cover - compiled
    """A window's rows of character n's lambda* (the shared tables as they are for a plain
    character, else its own term and the shared one put together, or where a variance is at its
    limit its precisions made from its log offset, as CrowdLambda's `precisions` makes them), each
    state's row once (a state lasts some frames); local[m] is window frame m's row of `means` and
    `precisions`. The tables' static dimensions a to b (each window's: the delta and delta-delta
    columns too) are taken from the rows `guest_rows` (a gesture's, `Crowd.guest`; a = b: none), so
    a window frame's row is of a pair of states and the solve reads one source."""
    mean_own, mean_shared, precision_own, precision_shared = (tables.mean_own[n], tables.mean_shared,
                                                              tables.precision_own[n], tables.precision_shared)
    plain, limit, clip_change, clip_base = tables.plain[n], tables.limit, tables.clip_change, tables.clip_base
    width = means.shape[1]
    dim = width // 3
    used = 0
    for m in range(rows.shape[0]):
        r = rows[m]
        if m > 0 and r == rows[m - 1] and (a == b or guest_rows[m] == guest_rows[m - 1]):
            local[m] = local[m - 1]
            continue
        for k in range(2 if a < b else 1):  # the character's row, then the guest's columns from its row
            r = rows[m] if k == 0 else guest_rows[m]
            for w in range(3 if k else 1):
                start, stop = (w * dim + a, w * dim + b) if k else (0, width)
                length = stop - start
                mean_row, precision_row = _part(means, used, start, length), _part(precisions, used, start, length)
                if plain:
                    _copy_row(_part(mean_shared, r, start, length), mean_row)
                    _copy_row(_part(precision_shared, r, start, length), precision_row)
                    continue
                _sum_row(_part(mean_own, r, start, length), _part(mean_shared, r, start, length), mean_row)
                if limit > 0.0:
                    for c in range(start, stop):
                        value = min(max(precision_own[r, c] + clip_change[r, c], -limit), limit)
                        precisions[used, c] = np.exp(-(value + clip_base[r, c]))
                else:
                    _product_row(_part(precision_own, r, start, length), _part(precision_shared, r, start, length),
                                 precision_row)
        local[m] = used
        used += 1


@njit(cache=True, nogil=True, inline="always")
def _copy_row(a, out):  # pragma: no cover - compiled
    """out = a (a slice's assignment would check the two for overlap and may copy through a new array)."""
    for c in range(out.shape[0]):
        out[c] = a[c]


@njit(cache=True, nogil=True, inline="always")
def _sum_row(a, b, out):  # pragma: no cover - compiled
    """out = a + b, rows as views that own nothing (`mlpg._part`): indexed in the 2-D tables, the
    compiler kept the loop scalar (docs/crowds.md)."""
    for c in range(out.shape[0]):
        out[c] = a[c] + b[c]


@njit(cache=True, nogil=True, inline="always")
def _product_row(a, b, out):  # pragma: no cover - compiled
    """out = a * b, as `_sum_row`."""
    for c in range(out.shape[0]):
        out[c] = a[c] * b[c]


@njit(cache=True, nogil=True)
def _gather_pairs(tables, n, rows, guest_rows, a, b, local):  # pragma: no cover - compiled
    """`_gather` for a plain character (n) whose static dimensions a to b are hosted: its window's
    rows are of (row, guest row) pairs of the shared tables, the same for every plain character,
    so each pair's row is put together once and kept in `tables.pair_rows` (an open table of
    slots keyed by the pair, `pair_keys`) while the tables and the range stay; local[m] is window
    frame m's slot. The slots are emptied before a window that might fill more than half of them
    (the caller's promise: there are at least twice the window's)."""
    slots, labels_states = tables.pair_keys.shape[0] - 3, tables.mean_shared.shape[0]
    keys, state, pair_rows = tables.pair_keys[:slots], tables.pair_keys[slots:], tables.pair_rows
    if state[0] + rows.shape[0] > slots // 2 or state[1] != a or state[2] != b:
        keys[:] = -1
        state[0], state[1], state[2] = 0, a, b
    for m in range(rows.shape[0]):
        if m > 0 and rows[m] == rows[m - 1] and guest_rows[m] == guest_rows[m - 1]:
            local[m] = local[m - 1]
            continue
        key = rows[m] * labels_states + guest_rows[m]
        slot = key % slots
        while keys[slot] != -1 and keys[slot] != key:
            slot = (slot + 1) % slots
        if keys[slot] == -1:  # a pair not seen since the tables came: its row put together as `_gather` does
            _gather(tables, n, rows[m : m + 1], guest_rows[m : m + 1], a, b, local[m : m + 1],
                    pair_rows[0, 0, slot : slot + 1], pair_rows[1, 0, slot : slot + 1])
            keys[slot] = key
            state[0] += 1
        local[m] = slot


@njit(cache=True, nogil=True)
def _plan_window(base, sigma, counter, carry, pool, history_ids, fixed, ids, counts, carries, rows):  # pragma: no cover - compiled
    """One character's plan (`_plan`: ids, its state instances, the draws used) and its window's
    rows of the lambda* tables: the `fixed` frames' states, then the plan's."""
    counter[TAIL] = _plan(base, sigma, counter, carry, pool, ids, counts, carries)[1]
    for m in range(fixed):
        rows[m] = history_ids[2 - fixed + m]
    for m in range(ids.shape[0]):
        rows[fixed + m] = ids[m]


@njit(cache=True, nogil=True)
def _move_on(counter, carry, n, counts, carries, states):  # pragma: no cover - compiled
    """Character n's plan advanced by the frame just sent; the current state may have been
    shortened below what it had."""
    k = 0
    if counter[ELAPSED] >= counts[0]:
        _finish(counter, carry, n, carries[0], states)
        k = 1
    counter[ELAPSED] += 1
    if counter[ELAPSED] >= counts[k]:
        _finish(counter, carry, n, carries[k], states)
