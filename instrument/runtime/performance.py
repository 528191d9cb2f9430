"""The live loop: control events -> control state -> engine -> pose -> outputs, once per frame.

Performance time is the frame index divided by the frame rate. Events are applied at frame
boundaries by that time, so a replayed log gives the same frames whether it runs in realtime
or as fast as the CPU allows. The engine works at the model's frame rate; other output rates
are interpolated from its frames.
"""

from __future__ import annotations

import gc
import signal
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Protocol

import numpy as np

from ..control.events import ControlEvent, LogReplay
from ..control.state import ControlState
from ..models.modelfile import Model
from ..synthesis.interpolation import style_space
from ..synthesis.offline import drive
from ..synthesis.stream import DEFAULT_LOOKAHEAD, Walker, step
from .clock import FrameClock
from .console import Console
from .pose import Pose, PoseStream

STATUS_EVERY = 0.5  # seconds of wall time
LEAD_MARGIN = 0.0005  # seconds added to the expected work of a frame when waking before its deadline


class Output(Protocol):
    """Made in two halves so the work is done before the deadline and only sending at it."""

    name: str

    def prepare(self, pose: Pose, echo: dict[str, float]) -> object: ...

    def send(self, prepared: object) -> None: ...

    def close(self) -> None: ...


class Engine:
    """The walk at the model's rate, sampled at any output rate by interpolating features."""

    def __init__(self, model: Model, lookahead: int = DEFAULT_LOOKAHEAD, seed: int = 0):
        self.model = model
        self.space = style_space(model)
        self.walker = Walker(model.layout.dimension, lookahead=lookahead, seed=seed)
        self.frames: list[np.ndarray] = []  # the last two model frames, driven
        self.made = 0  # model frames made

    def sample(self, time_s: float, controls) -> np.ndarray:
        """Static features at performance time `time_s`, making model frames as needed.

        At the model's own rate this is exactly its newest frame (no added latency); between
        model frames it interpolates the two around `time_s`.
        """
        position = time_s * self.model.fps
        newest = int(np.ceil(position - 1e-9))
        while self.made <= newest:
            frame = step(self.space, [self.walker], [controls])[0]
            self.frames = (self.frames + [drive(frame, self.walker.cadence, controls.turn)])[-2:]
            self.made += 1
        fraction = position - (newest - 1)
        if fraction >= 1.0 - 1e-9 or len(self.frames) == 1:
            return self.frames[-1]
        return self.frames[0] + (self.frames[1] - self.frames[0]) * fraction


@dataclass
class Summary:
    frames: int = 0
    late: int = 0
    dropped: int = 0
    output_errors: dict[str, int] = field(default_factory=dict)
    seconds: float = 0.0


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
    on_frame: Callable[[int, FrameClock, Summary], None] | None = None,
) -> Summary:
    """Run until `seconds` of performance time, the end of a non-looping replay, or Ctrl-C.

    `timing`, when given, receives each frame's send time minus its deadline (seconds).
    `on_frame`, when given, is called after each frame is sent (health, the systemd watchdog)."""
    state = state or ControlState(model.style_names, model.states)
    apply = apply or (lambda s, e: s.set(e.control, e.value))
    engine = Engine(model, lookahead)
    poses = PoseStream(model.layout, fps)
    clock = FrameClock(fps, realtime=not fast)
    summary = Summary()
    stop = {"now": False}
    previous = signal.signal(signal.SIGTERM, lambda *_: stop.__setitem__("now", True))
    last_status = 0.0
    started = time.monotonic()
    work_times: deque[float] = deque(maxlen=300)  # how long making a frame took, recently

    def take_live(now: float) -> None:
        for source in live_sources:
            for event in source(now):
                apply(state, event)

    try:
        while not stop["now"]:
            index = clock.frame
            now = index / fps
            if seconds is not None and now >= seconds:
                break
            work_started = time.monotonic()  # from here on, the frame's work: events, engine, outputs
            if replay is not None:
                if replay.finished and seconds is None:
                    break
                for event in replay.due(now):
                    if not apply(state, event):
                        console.warn(f"unknown {event.control}", f"ignored an event for unknown control {event.control!r}")
            take_live(now)  # what came since the last look, while the loop waited
            state.advance(now)
            controls = state.snapshot()
            pose = poses.next(engine.sample(now, controls))
            echo = state.echo()
            prepared = [_attempt(console, summary, output, output.prepare, pose, echo) for output in outputs]
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
            clock.advance(lead=min(expected + LEAD_MARGIN, 0.5 / fps),
                          idle=(lambda: take_live(upcoming)) if live_sources else None)
    except KeyboardInterrupt:
        pass
    finally:
        signal.signal(signal.SIGTERM, previous)
        for output in outputs:
            try:
                output.close()
            except Exception as error:
                console.warn(f"close {output.name}", f"output {output.name} did not close cleanly: {error}")
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


def _status(index: int, fps: float, clock: FrameClock, state: ControlState, sources: str) -> str:
    weights = " ".join(f"{n[:4]} {w:+.2f}" for n, w in zip(state.style_names, state.weights) if w != 0.0) or "average"
    return (f"frame {index:7d}  {fps:g} fps  late {clock.late}  speed {state.speed:.2f}  turn {state.turn:+.2f}  "
            f"{weights}" + (f"  | {sources}" if sources else ""))
