"""The live loop: control events -> control state -> engine -> pose -> outputs, once per frame.

Performance time is the frame index divided by the frame rate. Events are applied at frame
boundaries by that time, so a replayed log gives the same frames whether it runs in realtime
or as fast as the CPU allows. The engine works at the model's frame rate; other output rates
are interpolated from its frames.
"""

from __future__ import annotations

import gc
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from ..control.events import ControlEvent, LogReplay
from ..control.hub import ControlHub
from ..control.state import ControlState
from ..models.modelfile import Model
from ..synthesis.engine import Engine
from ..synthesis.parameters import DEFAULT_LOOKAHEAD, DEFAULT_SPACING
from ..synthesis.posing import Pose
from .clock import IDLE_UNTIL, FrameClock
from ..terminal import Console
from .stopping import StopFlag

STATUS_EVERY = 0.5  # seconds of wall time
LEAD_MARGIN = 0.0005  # seconds added to the expected work of a frame when waking before its deadline
LEAD_SPREAD = 1.25  # ... after scaling it by this: a crowd's work varies by milliseconds (style changes)
# the earliest a frame's work starts, in frames before its deadline: a single character's work
# takes a millisecond or two, so this only binds for a crowd, whose work can fill most of a frame
# (the rest is for the OS and live input); a frame whose work takes longer is late
MAX_LEAD_FRAMES = 0.9
INPUT_BUDGET = IDLE_UNTIL  # seconds of input handling per look: what is left waits for the next look


class Output(Protocol):
    """Made in two halves so the work is done before the deadline and only sending at it."""

    name: str

    def prepare(self, pose: Pose, echo: dict[str, float]) -> object: ...

    def send(self, prepared: object) -> None: ...

    def close(self) -> None: ...


@dataclass
class Summary:
    frames: int = 0
    late: int = 0
    dropped: int = 0
    output_errors: dict[str, int] = field(default_factory=dict)
    input_errors: dict[str, int] = field(default_factory=dict)  # a device's poll or an event's apply that raised
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


def perform(
    model: Model,
    outputs: list[Output],
    console: Console,
    fps: float = 30.0,
    seconds: float | None = None,
    replay: LogReplay | None = None,
    live_sources: list[Callable[[float], list[ControlEvent]]] = (),
    fast: bool = False,
    apply: Callable[[ControlState, ControlEvent], bool] | None = None,
    describe_sources: Callable[[], str] = lambda: "",
    lookahead: int = DEFAULT_LOOKAHEAD,
    timing: list[float] | None = None,
    state: ControlState | None = None,
    stop: StopFlag | None = None,
    on_frame: Callable[[int, FrameClock, Summary], None] | None = None,
    characters: int = 1,
    spacing: float = DEFAULT_SPACING,
) -> Summary:
    """Run until `seconds` of performance time, the end of a non-looping replay, or Ctrl-C.

    `timing`, when given, receives each frame's send time minus its deadline (seconds).
    `stop` is the flag Ctrl-C and SIGTERM set (installed here unless the caller did, so that a
    stop during its start-up is kept too).
    `on_frame`, when given, is called after each frame is sent (health, the systemd watchdog).
    `characters` walk at once, `spacing` metres apart (synthesis/engine.py); an output gets the
    pose of its `character` (0 unless it says), or the whole CrowdPose if it says `whole_crowd`."""
    state = state or ControlState(model.style_names, model.states)
    apply = apply or ControlHub([], console=console).apply  # checked, counted and warned as a show's events are
    engine = Engine(model, characters, fps, lookahead, spacing=spacing)
    wanted = [None if getattr(output, "whole_crowd", False) else getattr(output, "character", 0) for output in outputs]
    if any(k is not None and not 0 <= k < characters for k in wanted):  # `run` checks this for the user
        raise ValueError(f"an output asks for a character outside the crowd of {characters}: {wanted}")
    clock = FrameClock(fps, realtime=not fast)
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

    def guarded_apply(event: ControlEvent) -> bool:
        try:
            return apply(state, event)
        except Exception as error:  # a bad event never stops the show
            _count(console, summary.input_errors, f"apply {event.source.split(':')[0]}", error)
            return False

    def take_live(now: float) -> None:
        """Apply what devices sent, for at most INPUT_BUDGET seconds; the rest waits its turn
        (stamped with the time it is applied at, so a replay of the record hits the same frame)."""
        until = time.monotonic() + INPUT_BUDGET
        if not backlog:
            for source in live_sources:
                try:
                    backlog.extend(source(now))
                except Exception as error:  # a device that fails is reported; the walk goes on
                    _count(console, summary.input_errors, f"poll {getattr(source, '__qualname__', 'device')}", error)
        while backlog and time.monotonic() < until:
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
            crowd = engine.frame(now, controls, state.spread)
            echo = state.echo()
            prepared = [_attempt(console, summary, output, output.prepare, crowd if k is None else crowd.character(k), echo)
                        for output, k in zip(outputs, wanted)]
            if index > 0:
                work_times.append(time.monotonic() - work_started)
            else:  # the first frame compiled and loaded things: not what a frame takes
                # everything loaded so far lives for the whole show: keep the collector off it, so
                # a full collection during the performance walks only what the performance made
                gc.collect()
                gc.freeze()
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
            if not fast and sent_at - last_status >= STATUS_EVERY:
                last_status = sent_at
                console.status(_status(index, fps, clock, state, describe_sources()))
            # wake early enough for what a frame has recently taken, and at once after a jump;
            # meanwhile take live events as they come (stamped with the coming frame's time, as
            # if taken at its start), so a flood of them is handled while waiting, not at the frame
            expected = max(np.percentile(work_times, 99), work_times[-1]) if work_times else 0.5 / fps
            upcoming = (index + 1) / fps
            clock.advance(lead=min(LEAD_SPREAD * expected + LEAD_MARGIN, MAX_LEAD_FRAMES / fps),
                          idle=(lambda: take_live(upcoming)) if live_sources else None)
    except KeyboardInterrupt:  # a caller that kept Python's own SIGINT handler
        pass
    finally:
        if own_stop:
            stop.restore()
        # files (listed last) first: a device library that crashes closing its port takes nothing written with it
        close_all(reversed(outputs), console)
    summary.late, summary.dropped = clock.late, clock.dropped
    summary.seconds = time.monotonic() - started
    return summary


def _attempt(console: Console, summary: Summary, output: Output, method, *args):
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
    return (f"frame {index:7d}  {fps:g} fps  late {clock.late}  speed {state.speed:.2f}  turn {state.turn:+.2f}  "
            f"{weights}" + (f"  | {sources}" if sources else ""))
