"""In time with the music: a tempo source's beats, and the walk's steps locked to them.

`TempoFollower` turns MIDI clock (24 ticks per quarter note; start, stop, continue and song
position) with the arrival time of each tick into a smoothed beat period and phase: a straight
line fitted to the last beat of ticks (a real clock over JACK or USB jitters by a millisecond or
more, the fit averages it out; one beat of ticks follows a tempo change within a beat). Each
tick is numbered by its nearest place on that line, not counted, so a tick lost on the way does
not slip the beat.
`LinkTempo` (runtime/link.py) answers the same questions from an Ableton Link session.

`BeatLock` makes the walk step on those beats. It chooses a whole ratio of steps per beat (2, 1
or 1/2) nearest the style's own cadence at the performer's speed, or the one the performer
forces (`steps-per-beat`), and sets each character's speed (so the durations stage stretches
the HSMM state durations as `speed` does, and a style keeps its rhythm within the step) once
per footfall of that character: the step period the ratio asks for, less the footfall's
distance from the nearest beat of that grid, so the next footfall lands on it (the whole error
corrected in one step, within MAX_CORRECTION of the period, so a lock never stumbles). The
speed changes only at footfalls, so the engine retunes once a step of each character. When the
clock stops, the last speed stays (no jump); when it starts, the next two footfalls bring the
lock in. The lock's decisions are control events (`TEMPO`), so a recorded show replays exactly.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Callable, Protocol

import numpy as np

from ..control.events import RawEvent, Source
from ..control.state import LockSpeeds
from ..synthesis.durations import state_durations
from ..synthesis.engine import Engine
from ..synthesis.parameters import MAX_SPEED, MIN_SPEED
from ..synthesis.stream import LABEL, Controls

TICKS_PER_BEAT = 24  # MIDI clock
TICKS_PER_SIXTEENTH = 6  # song position counts sixteenth notes
FIT_TICKS = 24  # ticks in the line fit: one beat (follows a tempo change within a beat)
MIN_TICKS = 6  # before this many ticks since a start there is no tempo yet (a quarter of a beat)
RATIOS = (0.5, 1.0, 2.0)  # steps per beat the lock chooses from
SWITCH_MARGIN = 1.15  # another ratio must fit the style's cadence this much better to be chosen instead
MAX_CORRECTION = 0.3  # of the step period: the most one step is lengthened or shortened to reach the beat
SKIPS_IN_A_ROW = 3  # ticks in a row each numbered past the count: a slower tempo, not lost ticks
AHEAD = 0.3  # ticks: a tick this near the place after the count's, or past it, is numbered by its place
MIN_BPM, MAX_BPM = 20.0, 400.0  # a fitted tempo outside these is a broken clock, not music


class Tempo(Protocol):
    """A tempo source as the beat lock reads it (times in `time.monotonic()` seconds)."""

    def period(self) -> float | None:
        """Seconds per beat, or None before the source has a tempo."""

    def beat_at(self, moment: float) -> float | None:
        """Beats (fractional) at `moment`; whole numbers are the beats. None before a tempo."""

    @property
    def running(self) -> bool:
        """The music is playing (a stopped clock keeps its last tempo, but no phase to lock to)."""


class TempoFollower:
    """MIDI clock to beats. Feed it every clock message (`message`) with its arrival time."""

    def __init__(self, fit_ticks: int = FIT_TICKS):
        self.ticks: deque[tuple[int, float]] = deque(maxlen=fit_ticks)  # (tick number, arrival time)
        self.position = 0  # the number the next tick gets (song position: ticks from the song's start)
        # ticks before any start, stop or continue (a source already playing, or one that always
        # sends its clock) count: the tempo is right at once, the beat from the first tick seen
        self.running = True
        self._fit: tuple[float, float] | None = None  # time = a + b * tick
        self._skipped = 0  # ticks in a row numbered past the count (ticks were lost)
        self._stale = False  # ticks came since the line was fitted (fitted when next asked: once a footfall)
        self.received = 0

    def message(self, kind: str, moment: float, value: int = 0) -> None:
        """One clock message: `kind` is mido's name (clock, start, stop, continue, songpos);
        `value` the song position in sixteenth notes."""
        self.received += 1
        if kind == "clock":
            if self.running:
                number = self._number(moment)
                self.ticks.append((number, moment))
                self.position = number + 1
                self._stale = True
        elif kind == "start":  # the next tick is the song's first
            self.running, self.position = True, 0
            self.ticks.clear()
            self._skipped = 0
        elif kind == "continue":  # from the song position; the line is fitted anew (the time jumped)
            self.running = True
            self.ticks.clear()
            self._skipped = 0
        elif kind == "stop":
            self.running = False
        elif kind == "songpos":
            self.position = int(value) * TICKS_PER_SIXTEENTH
            self.ticks.clear()
            self._skipped = 0

    def _number(self, moment: float) -> int:
        """The number of a tick arriving at `moment`: its nearest place on the fitted line, so a
        tick lost on the way (over JACK a client that misses a cycle of a busy server loses that
        cycle's MIDI) does not slip the beat; counted on (the last tick's number plus one) where
        the place is no further ahead than a tick's jitter.

        A place at least 1 - AHEAD past the count skips the ticks lost. Right after a skip, a
        tick nearer the skipped-to place than the next takes the skip back: the skipped one was
        late (the two share a place, the line fit averages them). SKIPS_IN_A_ROW skips are no
        losses but a slower tempo: the line starts anew from the count (a faster tempo never
        skips, its ticks come early, and is simply counted)."""
        counted = self.position
        if len(self.ticks) < MIN_TICKS:
            return counted
        self._refit()
        if self._fit is None:
            return counted
        a, b = self._fit
        place = (moment - a) / b
        skipped, self._skipped = self._skipped, 0
        if skipped and place < counted - 0.5:
            return counted - 1
        if place < counted + 1 - AHEAD:
            return counted
        if skipped + 1 >= SKIPS_IN_A_ROW:  # the tempo slowed down: fit it from the count
            self._restart(keep=2)
            return counted
        self._skipped = skipped + 1
        return max(int(round(place)), counted + 1)

    def _restart(self, keep: int) -> None:
        """Forget all but the newest `keep` ticks (their tempo kept until MIN_TICKS come)."""
        while len(self.ticks) > keep:
            self.ticks.popleft()
        self._stale = True

    def _refit(self) -> None:
        if not self._stale:
            return
        self._stale = False
        if len(self.ticks) < MIN_TICKS and self._fit is None:
            return
        if len(self.ticks) < 2:
            return
        data = np.array(self.ticks, dtype=np.float64)
        tick, moment = data[:, 0] - data[-1, 0], data[:, 1]  # about the newest tick: well conditioned
        x, y = tick - tick.mean(), moment - moment.mean()
        slope = float(x @ y / (x @ x)) if x @ x > 0 else 0.0
        intercept = float(moment.mean() - slope * tick.mean())
        if len(self.ticks) < MIN_TICKS:  # a restart: keep the last tempo, move the phase to the newest tick
            slope = self._fit[1]
            intercept = moment[-1]
        bpm = 60.0 / (slope * TICKS_PER_BEAT) if slope > 0 else 0.0
        if MIN_BPM <= bpm <= MAX_BPM:
            self._fit = (intercept - slope * data[-1, 0], slope)

    def period(self) -> float | None:
        self._refit()
        return None if self._fit is None else self._fit[1] * TICKS_PER_BEAT

    def beat_at(self, moment: float) -> float | None:
        self._refit()
        if self._fit is None:
            return None
        a, b = self._fit
        return (moment - a) / b / TICKS_PER_BEAT


def choose_ratio(natural_step: float, beat: float, current: float | None) -> float:
    """Steps per beat (RATIOS) whose step period, beat / ratio, is nearest (by ratio) the walk's
    own `natural_step` (seconds); the `current` one stays unless another fits SWITCH_MARGIN better."""
    def misfit(ratio: float) -> float:
        return abs(math.log(beat / ratio / natural_step))

    best = min(RATIOS, key=misfit)
    if current is not None and math.exp(misfit(current)) <= SWITCH_MARGIN * math.exp(misfit(best)):
        return current
    return best


@dataclass
class LockReport:
    """What the lock is doing, for the status line and the benchmark."""

    ratio: float | None = None  # steps per beat
    speed: float | None = None  # the speed it sets
    offset: float | None = None  # seconds from the last footfall to its nearest grid beat (+ late)


TEMPO = Source.of("tempo")  # the source of the lock's events (control/kinds.py reads them back)


class BeatLock:
    """Sets each character's speed so its footfalls land on the beats of `tempo`.

    Its decisions are events (`tempo` `speed/K`), applied through the hub like a device's: a
    `--record` log keeps them, and a replay of the log plays them back without a tempo source,
    so the synced performance is replayed exactly (control/kinds.py `TempoDecoder`)."""

    def __init__(self, tempo: Tempo):
        self.tempo = tempo
        self.report = LockReport()
        self._held: float | None = None  # the step period set last while the music played (kept while it is stopped)

    def decide(self, now: float, performed: float, step_at_1: Callable[[int], float], landed: dict[int, float],
               speeds: dict[int, float], characters: int = 1, steps_per_beat: float = 0.0) -> list[RawEvent]:
        """This frame's `speed/K` events (performance time `now`): for each character K whose foot
        landed in the frame before (at `landed[K]`, `time.monotonic()`), and each that has no
        speed yet (`speeds`, the state's lock_speeds). `performed`: the performer's speed;
        `step_at_1(K)`: a step's length at speed 1 of character K (asked only for those);
        `steps_per_beat`: 0 for the lock's choice, else the ratio forced (one of RATIOS).

        The ratio is chosen for character 0 (the performance) and the crowd walks it: every
        character's footfalls on the same grid of beats, each with its own foot and its own
        style's rhythm within the step (docs/tempo.md)."""
        beat = self.tempo.period()
        if beat is None:  # no tempo yet: the performer's speed
            return []
        # those that landed and those without a speed yet (all of them at the start, none once the lock has run)
        unset = [k for k in range(characters) if k not in speeds] if len(speeds) < characters else []
        due = sorted(set(landed).union(unset)) if unset else sorted(landed)
        if not due:
            return []
        running = self.tempo.running
        if running or self._held is None:
            ratio = steps_per_beat if steps_per_beat > 0 else choose_ratio(step_at_1(0) / performed, beat, self.report.ratio)
            self.report.ratio = ratio
            self._held = period = beat / ratio
        else:  # stopped: the step period played last, without a correction (a Link tempo changed meanwhile waits)
            period = self._held
        steps = np.atleast_1d(step_at_1(np.array(due)))  # every due character's step at once
        events = []
        for k, step in zip(due, steps):
            target = period
            if k in landed and running:
                position = self.tempo.beat_at(landed[k]) * ratio  # in steps of the grid
                offset = (position - round(position)) * period  # + late
                target = period - max(-MAX_CORRECTION * period, min(MAX_CORRECTION * period, offset))
                if k == 0:
                    self.report.offset = offset
            speed = min(max(float(step) / target, MIN_SPEED), MAX_SPEED)
            if k == 0:
                self.report.speed = speed
            events.append(RawEvent(now, TEMPO, f"speed/{k}", speed))
        return events

    def describe(self) -> str:
        """For the status line: the tempo, the steps per beat chosen and the last footfall's offset."""
        beat, report = self.tempo.period(), self.report
        if beat is None:
            return "sync: no tempo yet"
        text = f"sync {60.0 / beat:.1f} bpm" + ("" if self.tempo.running else " (stopped)")
        if report.ratio is not None:
            text += f", {report.ratio:g} steps/beat"
        if report.offset is not None:
            text += f", footfall {1000.0 * report.offset:+.0f} ms"
        return text


def locked_speed(speeds: dict[int, float], performed: float, characters: int) -> float | np.ndarray:
    """The speed the engine walks with under the lock: character 0's for one character, else
    one a character (the performer's for a character the lock has not set yet). From the state's
    `LockSpeeds`, only the characters set since the last frame are read."""
    if characters == 1:
        return speeds.get(0, performed)
    if not isinstance(speeds, LockSpeeds):
        return np.array([speeds.get(k, performed) for k in range(characters)])
    return speeds.per_character(characters, performed)


def step_seconds(engine: Engine, controls: Controls, character: int | np.ndarray = 0) -> float | np.ndarray:
    """Seconds a step of `character` takes at speed 1 with these controls' style and phase
    stretch (its duration pdfs through the durations stage's formula), the mean of its current
    unit's two labels (a run's steps are shorter than a walk's); for an array of characters, an
    array (one numpy pass for all the characters whose feet landed in a frame).
    The pdfs do not move with the speed: those of the last retune serve (the style of the frame
    before), so the lock costs no retune of its own."""
    interpolation = engine.features[0]
    if interpolation.duration_means is None:  # before the first frame
        engine.retune(controls)
    frames = state_durations(interpolation.duration_means[character], interpolation.duration_variances[character], 1.0,
                             controls.state_scale)  # (..., labels, states)
    unit = engine.stream.counters[character, LABEL] // 2
    steps = frames.sum(axis=-1)  # (..., labels)
    if np.ndim(character) == 0:
        return float(steps[2 * int(unit):2 * int(unit) + 2].mean()) / engine.model.fps
    rows = np.arange(len(steps))
    return (steps[rows, 2 * unit] + steps[rows, 2 * unit + 1]) / 2.0 / engine.model.fps


def snap_ratio(value: float) -> float:
    """The `steps-per-beat` control's value as the lock takes it: below 0.25, 0 (the lock
    chooses); else the nearest of RATIOS."""
    return 0.0 if value < 0.25 else min(RATIOS, key=lambda r: abs(r - value))
