"""The live loop: control events -> control state -> engine -> pose -> outputs, once per frame.

Performance time is the frame index divided by the frame rate. Events are applied at frame
boundaries by that time, so a replayed log gives the same frames whether it runs in realtime
or as fast as the CPU allows. The engine works at the model's frame rate; other output rates
sample a cubic curve through its frames (synthesis/between.py). A pose that is not a number is
held, not sent (finite.py).
"""

from __future__ import annotations

import gc
import time
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Callable, Iterable, Protocol, Sequence

import numpy as np

from ..control.events import ControlEvent, LogReplay
from ..control.hub import ControlHub
from ..control.state import ControlState
from ..models.modelfile import Model
from ..synthesis.engine import Engine, rehearse
from ..synthesis.parameters import DEFAULT_SPACING, GAITS
from ..control.values import all_values
from ..synthesis.footfalls import Footfalls, pacing
from ..synthesis.posing import Frame
from ..synthesis.stream import gait_index
from .clock import IDLE_UNTIL, FrameClock
from .finite import FinitePoses
from ..terminal import Console
from .stopping import StopFlag
from .tempo import BeatLock, locked_speed, snap_ratio, step_seconds

STATUS_EVERY = 0.5  # seconds of wall time
LEAD_MARGIN = 0.0005  # seconds added to the expected work of a frame when waking before its deadline
LEAD_SPREAD = 1.25  # ... after scaling it by this: a crowd's work varies by milliseconds (style changes)
# the earliest a frame's work starts, in frames before its deadline: a single character's work
# takes a millisecond or two, so this only binds for a crowd, whose work can fill most of a frame
# (the rest is for the OS and live input); a frame whose work takes longer is late
MAX_LEAD_FRAMES = 0.9
INPUT_BUDGET = IDLE_UNTIL  # seconds of input handling per look: what is left waits for the next look


class Sink(Protocol):
    """An output of the show (OSC targets, the BVH recorder, MIDI and HID feedback, the console).
    Made in two halves so the work is done before the deadline and only sending at it: `prepare`
    turns the frame (every pose and every control value: a sink never reads the control state)
    into what `send` sends, or None for nothing this frame. A failure in either is counted and
    said on the console; the show goes on. A sink that sends one character of a crowd says which
    in `character` (checked against the crowd at the start)."""

    name: str

    def prepare(self, frame: Frame) -> object: ...

    def send(self, prepared: object) -> None: ...

    def close(self) -> None: ...


@dataclass
class Summary:
    frames: int = 0
    late: int = 0
    dropped: int = 0
    output_errors: dict[str, int] = field(default_factory=dict)
    input_errors: dict[str, int] = field(default_factory=dict)  # a device's poll or an event's apply that raised
    held: int = 0  # character frames whose pose was not finite: each held its last one (finite.py)
    seconds: float = 0.0


def close_all(things, console: Console) -> None:
    """Close each of `things` in turn; one that cannot close is said on the console and leaves the
    others to close."""
    for thing in things:
        try:
            thing.close()
        except Exception as error:
            name = getattr(thing, "name", type(thing).__name__)
            console.warn(f"close {name}", f"{name} did not close cleanly: {error}")


@dataclass
class Show:
    """One performance, assembled and checked once: `run` builds it from the command line and a
    show file, `bench` and the crowd bench from their own choices, a test from its own; `perform`
    plays it.

    `sinks` get every frame (their `character` must be in the crowd); `sources` are polled for
    live control events between and at the start of frames (a device's `poll`); `replay` is a
    controller log or a score played by performance time; `apply` puts one event into `state`
    (the hub's, so events are checked and counted as a show's are; default: a hub of no device);
    `describe_sources` names the live sources on the status line."""

    model: Model
    sinks: list[Sink]
    fps: float = 30.0
    seconds: float | None = None  # of performance time; None: until the replay ends, or Ctrl-C
    fast: bool = False  # no realtime pacing: as fast as the CPU allows
    characters: int = 1
    spacing: float = DEFAULT_SPACING  # metres between a crowd's characters
    lookahead: int | None = None  # the stream's, in the model's frames (None: its rate's default, parameters.py)
    state: ControlState | None = None  # default: the model's, at rest
    replay: LogReplay | None = None
    sources: list[Callable[[float], list[ControlEvent]]] = field(default_factory=list)
    apply: Callable[[ControlState, ControlEvent], bool] | None = None
    describe_sources: Callable[[], str] = lambda: ""
    beat_lock: BeatLock | None = None  # steps locked to a tempo source's beats (runtime/tempo.py; realtime only)

    def __post_init__(self):
        # `run` refuses these for the user with one line; here they are a caller's mistake
        if (not self.fps > 0 or self.characters < 1 or (self.lookahead is not None and self.lookahead < 1)
                or (self.seconds is not None and self.seconds < 0)):
            raise ValueError(f"Show: fps {self.fps}, characters {self.characters}, lookahead {self.lookahead}, "
                             f"seconds {self.seconds}")
        wanted = [getattr(sink, "character", 0) for sink in self.sinks]
        if any(not 0 <= k < self.characters for k in wanted):
            raise ValueError(f"a sink asks for a character outside the crowd of {self.characters}: {wanted}")
        if self.beat_lock is not None and self.fast:
            raise ValueError("Show: a tempo source needs realtime pacing")
        if self.state is None:
            self.state = ControlState(self.model.style_names, self.model.states)


def perform(show: Show, console: Console, stop: StopFlag | None = None,
            on_frame: Callable[[int, FrameClock, Summary], None] | None = None,
            timing: list[float] | None = None, compiled: bool = False) -> Summary:
    """Play the show until its `seconds` of performance time, the end of a non-looping replay, or
    Ctrl-C.

    Every kernel the show can reach is compiled before its first frame (`rehearse`), unless
    `compiled` says the caller did it already with `compile_kernels` for this model, crowd and
    rate (`run` does, before it opens anything: a second rehearsal only cost start-up time).

    `stop` is the flag Ctrl-C and SIGTERM set (installed here unless the caller did, so that a
    stop during its start-up is kept too). `on_frame`, when given, is called after each frame is
    sent (health, the systemd watchdog). `timing`, when given, receives each frame's send time
    minus its deadline (seconds). Every sink gets the whole frame and takes the pose it sends
    from it."""
    model, outputs, state, fps, seconds, replay = show.model, show.sinks, show.state, show.fps, show.seconds, show.replay
    live_sources, describe_sources = show.sources, show.describe_sources
    apply = show.apply or ControlHub([], console=console).apply  # checked, counted and warned as a show's events are
    if not compiled:  # every kernel compiled now, not at the show's first run, stand or wave
        rehearse(model, show.characters, fps, show.lookahead)
    engine = Engine(model, show.characters, fps, show.lookahead, spacing=show.spacing)
    clock = FrameClock(fps, realtime=not show.fast)
    feet = Footfalls(engine.poses)
    finite = FinitePoses()  # a pose that is not a number is not sent
    beat_lock = show.beat_lock
    landed: dict[int, float] = {}  # when each character's foot landed in the frame before (the beat lock's cue)
    for output in outputs:
        if hasattr(output, "watch"):  # an output that shows late frames (the console)
            output.watch(clock)
    summary = Summary()
    own_stop = stop is None
    stop = StopFlag().install() if own_stop else stop
    last_status = 0.0
    started = time.monotonic()
    work_times: deque[float] = deque(maxlen=300)  # how long making a frame took, recently
    backlog: deque[ControlEvent] = deque()  # taken from devices, not yet applied (over the budget)
    collecting = False  # the collector was on, and is kept off the frames' work (turned back on at the end)

    def guarded_apply(event: ControlEvent) -> bool:
        try:
            return apply(state, event)
        except Exception as error:  # a bad event never stops the show
            _count(console, summary.input_errors, f"apply {event.source.kind}", error)
            return False

    prepared_revision = -1  # the control state's revision the engine's tables were last made ahead for

    def between_frames(upcoming: float, wake: float, expected: float) -> None:
        """While waiting for the frame at `upcoming` (its work starts at `wake`, clock time; a frame's
        work recently took `expected`, which stands for a retune's cost until one was timed): take
        live events, and make the engine's tables for what they changed (`Engine.retune`), so a
        control taken while waiting costs its frame no retune, which would otherwise set every
        frame's lead (the recent p99 of the work is a style change's retune). Only where the
        frame will take the same controls (no beat lock deciding speeds, no morph moving them) and
        where there is time left before waking; otherwise the frame retunes as it did."""
        nonlocal prepared_revision
        take_live(upcoming)
        if state.revision == prepared_revision or beat_lock is not None or state.morph is not None:
            return
        # only a frame that makes a model frame retunes (the frames between read nothing a retune
        # makes): tables made for one between would be made again, or for nothing
        if not engine.makes_model_frame(upcoming):
            return
        # the dearest work it may do (restyling every table) must end before waking, on the clock:
        # the engine times its restyles, ahead or in a frame (a turn or a gait retunes nothing, a
        # speed only the pace), so one a stall made slow ages out rather than keep the later ones out
        if wake - clock.now() < IDLE_UNTIL + max(engine.restyle_seconds, default=expected):
            return
        revision = state.revision
        engine.retune(state.snapshot(), state.spread)  # the frame finds them made (same controls)
        prepared_revision = revision

    def take_live(now: float) -> None:
        """Apply what devices sent, for at most INPUT_BUDGET seconds but at least one event (so a
        machine too busy for the budget still moves on); the rest waits its turn (stamped with the
        time it is applied at, so a replay of the record hits the same frame)."""
        until = time.monotonic() + INPUT_BUDGET
        if not backlog:
            for source in live_sources:
                try:
                    backlog.extend(source(now))
                except Exception as error:  # a device that fails is reported; the walk goes on
                    _count(console, summary.input_errors, f"poll {getattr(source, '__qualname__', 'device')}", error)
        first = True
        while backlog and (first or time.monotonic() < until):
            first = False
            event = backlog.popleft()
            guarded_apply(event if event.time == now else ControlEvent(now, event.source, event.control, event.value))

    try:
        while not stop:
            index = clock.frame
            now = index / fps
            if seconds is not None and now >= seconds:
                break
            work_started = time.monotonic()  # from here on, the frame's work: events, engine, outputs
            if replay is not None:
                if replay.finished and seconds is None:
                    break
                for event in replay.due(now):
                    guarded_apply(event)
            take_live(now)  # what came since the last look, while the loop waited
            state.advance(now)
            controls = state.snapshot()
            synced = state.sync >= 0.5  # the `sync` control's on (its nearest choice)
            if beat_lock is not None and synced:  # its decisions are events: recorded, replayed
                for event in beat_lock.decide(now, controls.speed, lambda k: step_seconds(engine, controls, k), landed,
                                              state.lock_speeds, show.characters, snap_ratio(state.steps_per_beat)):
                    guarded_apply(event)
            if not synced:
                state.lock_speeds.clear()  # turned on again, the lock starts afresh
            elif state.lock_speeds:  # the lock's (live, or a replayed log's)
                controls = replace(controls, speed=locked_speed(state.lock_speeds, controls.speed, show.characters))
            crowd, held = finite(engine.frame(now, controls, state.spread))  # its retune, if any, timed by the engine
            if len(held):
                summary.held += len(held)
                console.warn("pose", f"frame {index}: the engine made a pose that is not a number for character"
                             f"{'s' if len(held) > 1 else ''} {', '.join(map(str, held[:8]))}{' ...' if len(held) > 8 else ''}; "
                             "held the last pose (the walk goes on)")
            if GAITS[controls.gait] in engine.units.missing:  # said, not refused: the walk goes on
                console.warn(f"gait {GAITS[controls.gait]}", f"gait {GAITS[controls.gait]}: this model has no "
                             f"{GAITS[controls.gait]} unit (it has {', '.join(engine.model.units)}); it walks")
            missing_turn = engine.units.unsteered(controls.gait, controls.turn)
            if missing_turn:  # said once, not refused: the walk is steered without turning steps
                console.warn(f"turn {missing_turn}", f"turn: this model has no {missing_turn} unit (it has "
                             f"{', '.join(engine.model.units)}); its walk is steered without turning steps")
            for name in controls.gestures:  # said once, not refused: the walk goes on without it
                if name not in engine.gestures.labels:
                    console.warn(f"gesture {name}", f"gesture {name}: this model has no {name} gesture "
                                 f"({'it has ' + ', '.join(engine.gestures.names) if engine.gestures.names else 'none'}); "
                                 "the walk goes on")
            footfalls = feet.after(crowd)
            landed = {f.character: clock.deadline(index) for f in pacing(footfalls) if index > 0}
            frame = Frame(index, now, crowd, all_values(state), state.echo(), footfalls)
            prepared = [_attempt(console, summary, output, output.prepare, frame) for output in outputs]
            if index > 0:
                work_times.append(time.monotonic() - work_started)
            else:  # the first frame compiled and loaded things: not what a frame takes
                # everything loaded so far lives for the whole show: keep the collector off it, so
                # a full collection during the performance walks only what the performance made
                gc.collect()
                gc.freeze()
                collecting = gc.isenabled()
                gc.disable()  # from now on the collector runs after a frame is sent (`collect_between_frames`)
                clock.restart()  # the first frame paid for warming up: the schedule starts now
            clock.hold()
            sent_at = time.monotonic()
            for output, payload in zip(outputs, prepared):
                if payload is not None:
                    _attempt(console, summary, output, output.send, payload)
            if timing is not None:
                timing.append(sent_at - clock.deadline())
            summary.frames += 1
            if on_frame is not None:
                on_frame(index, clock, summary)
            if not show.fast and sent_at - last_status >= STATUS_EVERY:
                last_status = sent_at
                console.status(_status(index, fps, clock, state, describe_sources()))
            if collecting:
                collect_between_frames()
            # wake early enough for what a frame has recently taken, and at once after a jump;
            # meanwhile take live events as they come (stamped with the coming frame's time, as
            # if taken at its start), so a flood of them is handled while waiting, not at the frame
            expected, lead = frame_lead(work_times, engine.restyle_seconds, fps)
            upcoming = (index + 1) / fps
            clock.advance(lead=lead,
                          idle=(lambda: between_frames(upcoming, clock.deadline() - lead, expected)) if live_sources else None)
    except KeyboardInterrupt:  # a caller that kept Python's own SIGINT handler
        pass
    finally:
        if collecting:
            gc.enable()
        if own_stop:
            stop.restore()
        # files (listed last) first: a device library that crashes closing its port takes nothing written with it
        close_all(reversed(outputs), console)
    summary.late, summary.dropped = clock.late, clock.dropped
    summary.seconds = time.monotonic() - started
    return summary


def compile_kernels(model: Model, characters: int, fps: float, profiles: Iterable = ()) -> None:
    """Every kernel a show's frames call, compiled (or loaded from numba's cache): the engine's
    (`rehearse`), the check of a frame's poses and each OSC profile's encoding of a frame. `run`
    calls it before it opens anything, where Ctrl-C ends the process at once: a first run
    compiles for half a minute (in `perform`, with the devices open, a Ctrl-C waited for it);
    `perform(..., compiled=True)` then does not rehearse again. With the cache warm it takes
    about as long as loading the kernels."""
    rehearse(model, characters, fps)
    state = ControlState(model.style_names, model.states)
    crowd, _ = FinitePoses()(Engine(model, characters, fps).frame(0.0, state.snapshot(), state.spread))
    for profile in profiles:
        if hasattr(profile, "encode"):  # the flat profile's compiled encoding, of the poses an output gives it
            profile.encode(crowd if getattr(profile, "whole_crowd", False) else crowd.character(0), state.echo())


def frame_lead(work_times: Sequence[float], restyles: Sequence[float], fps: float) -> tuple[float, float]:
    """(expected, lead): what the coming frame's work may take (seconds), and how long before its
    deadline the loop wakes for it. The recent p99 of the work (or the last frame's, after a jump),
    and, once the engine has timed restyles, at least a typical frame's work plus the dearest of
    them: a style change taken at the frame's start (after the last look while waiting, too late
    to retune ahead) is retuned in the frame's work, and when such frames are under one in a
    hundred the p99 does not hold them, and each was late."""
    if not work_times:
        expected = 0.5 / fps
    else:
        typical, p99 = np.percentile(work_times, (50, 99))
        expected = max(p99, work_times[-1], typical + max(restyles, default=0.0))
    return expected, min(LEAD_SPREAD * expected + LEAD_MARGIN, MAX_LEAD_FRAMES / fps)


def collect_between_frames() -> None:
    """What Python's collector would have done during the frame's work (when a generation's
    count passes its threshold, that generation and the younger ones), done once the frame is
    sent: a collection never delays a frame, and the time from a control to its frame does not
    grow by one. The oldest generation walks only what the show made (the rest is frozen)."""
    counts, thresholds = gc.get_count(), gc.get_threshold()
    if counts[0] <= thresholds[0]:
        return
    generation = 0
    while generation < 2 and counts[generation + 1] > thresholds[generation + 1]:
        generation += 1
    gc.collect(generation)


def _attempt(console: Console, summary: Summary, output: Sink, method, *args):
    """Call an output's method; a failure is counted and reported, never raised."""
    try:
        return method(*args)
    except Exception as error:  # an output's failure never stops the clock or the others
        summary.output_errors[output.name] = summary.output_errors.get(output.name, 0) + 1
        console.warn(f"output {output.name}", f"output {output.name} failed: {type(error).__name__}: {error}")
        return None


def _count(console: Console, counts: dict[str, int], key: str, error: Exception) -> None:
    counts[key] = counts.get(key, 0) + 1
    console.warn(key, f"{key} failed: {type(error).__name__}: {str(error)[:200]} (the walk goes on)")


def _status(index: int, fps: float, clock: FrameClock, state: ControlState, sources: str) -> str:
    weights = " ".join(f"{n[:4]} {w:+.2f}" for n, w in zip(state.style_names, state.weights) if w != 0.0) or "average"
    return (f"frame {index:7d}  {fps:g} fps  late {clock.late}  {GAITS[gait_index(state.gait)]}  speed {state.speed:.2f}  "
            f"turn {state.turn:+.2f}  "
            f"{weights}" + (f"  | {sources}" if sources else ""))
