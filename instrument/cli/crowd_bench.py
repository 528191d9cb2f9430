"""`instrument bench`'s crowd figures: what one character of a live crowd costs, and the largest
crowd whose live loop keeps time on this machine (docs/crowds.md)."""

from __future__ import annotations

import socket
import time
from typing import Callable

import numpy as np

from ..models.modelfile import Model

CROWD_FPS = 30.0
TRIAL_SECONDS = 3.0  # of realtime live loop per crowd size tried
TRIALS = 2  # a crowd size fails when this many trials in a row fail
DEMO_FIRST_RAMP_S = 4.0  # where the demo score's first ramp starts (examples/demo/demo.toml)
LATENESS_P99_MS = 1.0  # a crowd keeps time when no frame is dropped and the p99 lateness stays under this
SEARCH_BUDGET = 50.0  # seconds the search may take; past it the largest crowd found so far is reported
COST_CROWD = 100  # characters in the crowd whose per-character cost is measured
COST_FRAMES = 30


# the engine's stages in the order it first runs them (`Engine.stage_seconds`: a restyle's tables, range
# and contact before the turns; range, gestures and contact run again later in the frame), then the
# pose and the output's
ENGINE_STAGES = ("cast", "interpolation", "durations", "range", "contact", "turns", "units", "stream", "drive", "gestures", "between")
STAGES = ENGINE_STAGES + ("posing", "finite", "encoding", "sending")


def live_path(model: Model, count: int, spread: float = 0.5):
    """A frame of the live crowd path without the clock: the engine (its stages timed), the check
    that every pose is finite (runtime/finite.py), the flat profile's datagrams for `count` characters written and sent to a local UDP socket, with
    the demo's controls moving from its first ramp on (the weights change every frame). Returns
    the frame function, the seconds per stage (added up over the frames made) and a closer."""
    from ..control.hub import ControlHub
    from ..control.score import ScorePlayer, load_demo
    from ..control.state import ControlState
    from ..output.osc import OscTarget, UdpOut
    from ..output.outputs import make_profile
    from ..runtime.finite import FinitePoses
    from ..terminal import Console
    from ..synthesis.engine import Engine

    engine = Engine(model, count, CROWD_FPS)
    engine.stage_seconds = seconds = {}
    profile = make_profile("flat", model, characters=count)
    state = ControlState(model.style_names, model.states)
    state.set("spread", spread)
    demo = ScorePlayer(load_demo(model, state), state, start=-DEMO_FIRST_RAMP_S)
    console = Console(quiet=True)
    apply = ControlHub([], console=console).apply  # as the live loop applies a score's events
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    out = UdpOut(OscTarget("127.0.0.1", sink.getsockname()[1], "flat"), console)
    finite = FinitePoses()  # as the live loop, a pose that is not a number is held, not sent

    def frame(index: int) -> None:
        now = index / CROWD_FPS
        for event in demo.due(now):
            apply(state, event)
        state.advance(now)
        crowd = engine.frame(now, state.snapshot(), state.spread)
        started = time.perf_counter()
        crowd = finite(crowd)[0]
        checked = time.perf_counter()
        seconds["finite"] = seconds.get("finite", 0.0) + checked - started
        datagrams = profile.encode(crowd, state.echo())
        encoded = time.perf_counter()
        out.send(datagrams)
        seconds["encoding"] = seconds.get("encoding", 0.0) + encoded - checked
        seconds["sending"] = seconds.get("sending", 0.0) + time.perf_counter() - encoded
        drain(sink)

    def close() -> None:
        out.close()
        sink.close()

    return frame, seconds, close


def drain(sink: socket.socket) -> None:
    """Reads away what the sink holds (so the next frame's datagrams are not dropped unsent)."""
    sink.setblocking(False)
    try:
        while sink.recv(65536):
            pass
    except BlockingIOError:
        pass


def measure_cost(model: Model, yardstick: Callable[[], object], solves: int) -> dict:
    """Microseconds per character per frame of the live crowd path and of each of its stages,
    each also as a ratio to the bare solve of one window: `yardstick` runs `solves` of them and
    is timed after every frame, so frames and solves see the same machine (`against_yardstick`)."""
    frame, seconds, close = live_path(model, COST_CROWD)
    solving = 0.0
    try:
        frame(0)  # compiles and loads
        yardstick()  # so does the solve's first call (`bench --crowd` times no solve before this)
        seconds.clear()
        for index in range(1, COST_FRAMES + 1):
            frame(index)
            started = time.perf_counter()
            yardstick()
            solving += time.perf_counter() - started
    finally:
        close()
    window_solve_us = solving * 1e6 / COST_FRAMES / solves
    per_character = {stage: seconds.get(stage, 0.0) * 1e6 / COST_FRAMES / COST_CROWD for stage in STAGES}
    total = sum(per_character.values())
    figures = {"crowd_size_for_cost": COST_CROWD, "stream_us_per_character": total,
               "crowd_engine_us_per_character": sum(per_character[s] for s in ENGINE_STAGES),
               "crowd_pose_us_per_character": per_character["posing"],
               "crowd_flat_us_per_character": per_character["encoding"] + per_character["sending"],
               "crowd_window_solve_us": window_solve_us,
               "stream_per_character_to_window_solve": total / window_solve_us}
    for stage, cost in per_character.items():
        figures[f"crowd_{stage}_us_per_character"] = cost
        figures[f"crowd_{stage}_to_window_solve"] = cost / window_solve_us
    return figures


def keeps_time(model: Model, count: int, seconds: float = TRIAL_SECONDS) -> tuple[bool, float, int]:
    """Whether the realtime live loop of `count` characters (the demo, spread 0.5, flat OSC to a
    local UDP socket) keeps time: no frame dropped and p99 lateness under LATENESS_P99_MS. Also
    the p99 lateness (ms) and the late frames (sent over 0.1 ms after their deadline)."""
    from ..control.score import ScorePlayer, load_demo
    from ..control.state import ControlState
    from ..output.osc import OscTarget
    from ..output.outputs import OscOutput, make_profile
    from ..terminal import Console
    from ..runtime.performance import Show, perform

    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    sink.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)  # never read: the kernel drops what overflows
    console = Console(quiet=True)
    output = OscOutput(OscTarget("127.0.0.1", sink.getsockname()[1], "flat"), make_profile("flat", model, characters=count),
                       console)
    state = ControlState(model.style_names, model.states)
    state.set("spread", 0.5)
    # from the demo's first ramp on: weights move every frame, the engine's dearest case (the
    # demo's first seconds stand still, and a crowd that holds them may not hold the rest)
    demo = ScorePlayer(load_demo(model, state), state, start=-DEMO_FIRST_RAMP_S)
    timing: list[float] = []
    try:
        summary = perform(Show(model, [output], CROWD_FPS, seconds, characters=count, state=state, replay=demo), console,
                          timing=timing)
    finally:
        sink.close()
    p99 = float(np.percentile(np.maximum(np.array(timing[1:]), 0.0), 99)) * 1000.0
    return summary.dropped == 0 and p99 < LATENESS_P99_MS, p99, summary.late


def largest_crowd(model: Model, us_per_character: float, budget: float = SEARCH_BUDGET) -> dict:
    """The largest crowd that keeps time at 30 fps: from a guess (half the frame's budget at
    the measured cost per character), halving until one holds, doubling until one fails, then
    bisecting to within a tenth."""
    from ..runtime.priority import realtime_scheduling

    refused = realtime_scheduling()  # as `instrument run` does
    started = time.monotonic()
    tried: dict[int, tuple[float, int, int]] = {}  # crowd size: p99 lateness (ms), late frames, trials taken

    def holds(count: int) -> bool:
        """One trial, and a second when the first fails: on a shared machine another program's
        burst fails a 3 s trial now and then (a crowd of 44 once, of 272 in the run before:
        docs/crowds.md). A size fails when two trials in a row do; the figures kept are the
        last trial's."""
        for trial in range(1, TRIALS + 1):
            ok, p99, late = keeps_time(model, count)
            tried[count] = (p99, late, trial)
            if ok:
                return True
        return False

    guess = max(1, 2 ** int(np.log2(max(1.0, 0.5e6 / CROWD_FPS / us_per_character))))
    low, high = 0, None  # the largest that held, the smallest that failed
    count = guess
    while count >= 1 and time.monotonic() - started < budget:
        if holds(count):
            low = count
            break
        high, count = count, count // 2
    while high is None and low and time.monotonic() - started < budget:
        if holds(2 * low):
            low *= 2
        else:
            high = 2 * low
    while high is not None and high - low > max(1, low // 10) and time.monotonic() - started < budget:
        middle = (low + high) // 2
        if holds(middle):
            low = middle
        else:
            high = middle
    return {"largest_crowd_30fps": low, "largest_crowd_first_failing": high,
            "largest_crowd_p99_ms": tried[low][0] if low else None, "largest_crowd_late_frames": tried[low][1] if low else None,
            "largest_crowd_tried": {str(k): [round(v[0], 3), v[1], v[2]] for k, v in sorted(tried.items())},
            "largest_crowd_search_s": time.monotonic() - started,
            "largest_crowd_scheduling": "realtime" if refused is None else f"normal ({refused})"}
