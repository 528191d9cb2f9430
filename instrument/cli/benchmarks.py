"""The speed figures `instrument bench` reports: parsing, MLPG, streaming, poses and the live loop's pacing,
measured on this machine (`bench_cmd` prints them)."""

from __future__ import annotations

import os
import platform
import sys
import time

import numpy as np

from ..models.modelfile import default_model_path, load_model
from ..motion.bvh import Joint, Motion, Skeleton, bvh_text, parse_bvh
from ..motion.features import choose_layout, extract
from ..synthesis.contact import contact_space
from ..synthesis.engine import Engine
from ..synthesis.footlock import FootLock
from ..synthesis.interpolation import interpolate
from ..synthesis.mlpg import mlpg, mlpg_continued, mlpg_threads
from ..synthesis.posing import CrowdPoses, PoseStream
from ..synthesis.parameters import default_lookahead
from ..synthesis.stream import Controls
from ..synthesis.widen import RangeFilter
from .crowd_bench import largest_crowd, measure_cost

MLPG_FRAMES = 10_000
BATCH = 100
SOLVES = 100  # window solves in one turn of the yardstick


def measure_pacing(model_path: str | None, seconds: float, fps: float, console_address: str | None = None,
                   pages: int = 0) -> dict:
    """Send-time deviation from the schedule of the live loop, with real UDP outputs (and the
    browser console with `pages` pages open, when asked)."""
    import socket

    from ..output.osc import OscTarget
    from ..output.outputs import OscOutput, make_profile
    from ..terminal import Console
    from ..runtime.performance import Show, perform
    from ..runtime.priority import realtime_scheduling
    from ..control.score import ScorePlayer, load_demo
    from ..control.state import ControlState

    model = load_model(model_path or default_model_path())
    sinks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
    for s in sinks:
        s.bind(("127.0.0.1", 0))
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    console = Console(quiet=True)
    outputs = [OscOutput(OscTarget("127.0.0.1", s.getsockname()[1], kind), make_profile(kind, model), console)
               for s, kind in zip(sinks, ("vmc", "flat"))]
    live_sources, link = [], None
    if console_address:
        link = _console_for_pacing(console_address, model, console, outputs, fps, pages)
        live_sources = [link.input.poll]
    timing: list[float] = []
    refused = realtime_scheduling()  # as `instrument run` does
    state = link.output.state if link else ControlState(model.style_names, model.states)
    demo = ScorePlayer(load_demo(model, state), state)
    try:
        summary = perform(Show(model, outputs, fps, seconds, state=state, replay=demo, sources=live_sources), console,
                          timing=timing)
    finally:
        if link:
            open_pages = link.pages
            link.input.close()
    for s in sinks:
        s.close()
    deviation = np.abs(np.array(timing[1:])) * 1000.0
    return {
        "pacing_fps": fps,
        "pacing_seconds": seconds,
        "pacing_frames": summary.frames,
        "pacing_p50_ms": float(np.percentile(deviation, 50)),
        "pacing_p99_ms": float(np.percentile(deviation, 99)),
        "pacing_max_ms": float(deviation.max()),
        "pacing_late_frames": summary.late,
        "pacing_dropped_frames": summary.dropped,
        "pacing_scheduling": "realtime" if refused is None else f"normal ({refused})",
        "pacing_console_pages": open_pages if console_address else None,
    }


def _console_for_pacing(address: str, model, console, outputs: list, fps: float, pages: int):
    """The console beside the measured loop; waits (up to 5 minutes) for `pages` pages to open."""
    from ..console.link import ConsoleLink
    from ..control.state import ControlState
    from ..errors import UserError

    link = ConsoleLink(address, model, ControlState(model.style_names, model.states), {}, console, fps)
    outputs.append(link.output)
    for line in link.announcement():
        print(line, file=sys.stderr, flush=True)
    deadline = time.monotonic() + 300
    while link.pages < pages:
        if time.monotonic() > deadline:
            link.input.close()
            raise UserError(f"--console-pages {pages}: only {link.pages} pages opened in 5 minutes")
        link.input.poll(0.0)  # takes the page count (and says the pages' connections)
        time.sleep(0.1)
    return link


def median_seconds(work, repeat: int) -> float:
    work()  # warm up (and compile)
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def benchmark_walk(frames: int = 500, joints: int = 22) -> str:
    """BVH text of a `frames`-long chain of `joints` 6-channel joints with smooth random motion."""
    channels6 = ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    skeleton = Skeleton(tuple(Joint(f"J{k}", k - 1, (0.0, 10.0, 0.0), channels6) for k in range(joints)))
    rng = np.random.default_rng(0)
    channels = np.cumsum(rng.normal(0, 1.0, (frames, skeleton.channel_count)), axis=0)
    return bvh_text(Motion(skeleton, channels, 30.0))


def _nnmnkwii_mlpg():
    try:
        from nnmnkwii.paramgen import mlpg as reference
    except ImportError:
        return None
    windows = [(0, 0, np.array([1.0])), (1, 1, np.array([-0.5, 0.0, 0.5])), (1, 1, np.array([1.0, -2.0, 1.0]))]
    return lambda means, variances: reference(means, variances, windows)


def machine() -> dict:
    """The machine a figure came from: absolute speeds mean little without it."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as info:
            cpu = next((line.split(":", 1)[1].strip() for line in info if line.startswith("model name")), cpu)
    except OSError:
        pass
    return {"cores": os.cpu_count(), "cpu": cpu, "load_1min": os.getloadavg()[0] if hasattr(os, "getloadavg") else None}


def timed_turns(works, repeat: int) -> np.ndarray:
    """Seconds of each work (repeat, works), timed turn about: a turn runs each once, in order.
    On a shared machine the speed moves within seconds (here a window solve takes 27 us for a
    few seconds, then 44 us, then 27 again, in one process: docs/figures.md), and works timed
    back to back see the same machine where separate runs of medians do not."""
    for work in works:
        work()  # warm up (and compile)
    times = np.empty((repeat, len(works)))
    for k in range(repeat):
        for j, work in enumerate(works):
            start = time.perf_counter()
            work()
            times[k, j] = time.perf_counter() - start
    return times


def turn_about(works, repeat: int) -> tuple[list[float], list[float]]:
    """Median seconds of each work, timed turn about (`timed_turns`), and the median of each
    one's per-turn ratio to the last (last / this: how many times faster than the last it is)."""
    times = timed_turns(works, repeat)
    ratios = times[:, -1:] / times
    return [float(v) for v in np.median(times, axis=0)], [float(v) for v in np.median(ratios, axis=0)]


def against_yardstick(works: dict, yardstick, repeat: int) -> tuple[dict[str, float], dict[str, float], float]:
    """Each named work timed turn about with the yardstick (one window's bare solve, `frames`
    times): median seconds of each, the median of each one's per-turn ratio to the yardstick
    (this / yardstick), and the yardstick's median seconds. A ratio is taken within a turn, so a
    work and its yardstick always see the same machine."""
    times = timed_turns([*works.values(), yardstick], repeat)
    seconds = dict(zip(works, (float(v) for v in np.median(times[:, :-1], axis=0))))
    ratios = dict(zip(works, (float(v) for v in np.median(times[:, :-1] / times[:, -1:], axis=0))))
    return seconds, ratios, float(np.median(times[:, -1]))


def measure(model_path: str | None, repeat: int) -> dict:
    figures: dict = {}
    text = benchmark_walk()
    motion = parse_bvh(text)
    layout = choose_layout([motion])
    figures["bvh_parse_ms_500x22"] = 1000 * median_seconds(lambda: parse_bvh(text), repeat)
    figures["features_ms_500x22"] = 1000 * median_seconds(lambda: extract(motion, layout), repeat)

    model, all_styles, lam, ids = _walk_of_all_styles(model_path)
    dimension = model.layout.dimension
    means, variances = lam.means[ids], 1.0 / lam.precisions[ids]
    figures["dimension"] = dimension
    figures["mlpg_frames"] = MLPG_FRAMES
    figures["machine"] = machine()
    reference = _nnmnkwii_mlpg()
    # `mlpg` shares a long solve among the cores; the one-thread figure is the kernel alone
    ours = [lambda: mlpg(means, variances), lambda: mlpg(means, variances, threads=1)]
    figures["mlpg_threads"] = mlpg_threads(dimension, MLPG_FRAMES)
    if reference:
        seconds, speedups = turn_about([*ours, lambda: reference(means, variances)], repeat)
        figures["nnmnkwii_frames_per_s"] = MLPG_FRAMES / seconds[2]
        figures["mlpg_speedup_over_nnmnkwii"], figures["mlpg_one_thread_speedup_over_nnmnkwii"] = speedups[:2]
    else:
        seconds, _ = turn_about(ours, repeat)
        figures["nnmnkwii_frames_per_s"] = None
        figures["mlpg_speedup_over_nnmnkwii"] = figures["mlpg_one_thread_speedup_over_nnmnkwii"] = None
    figures["mlpg_frames_per_s"], figures["mlpg_one_thread_frames_per_s"] = (MLPG_FRAMES / v for v in seconds[:2])

    # the yardstick of the streaming figures: the bare solve of one window of the same size, `frames`
    # times a block, timed turn about with each figure set against it (`against_yardstick`)
    frames, turns = SOLVES, max(7, repeat)
    solves = window_solves(lam, ids, frames, default_lookahead(model.fps))

    # the engine's stream stage alone (plan, window solve, rate limit), its tables set by the other stages
    walker = Engine(model)
    walker.retune(all_styles)
    crowd = Engine(model, BATCH)
    crowd.retune(all_styles, spread=0.5)  # each character its own mix around the performed one
    batch_frames = 10
    seconds, ratios, solve_seconds = against_yardstick({
        "one": lambda: [walker.stream.step() for _ in range(frames)],
        "batch": lambda: [crowd.stream.step() for _ in range(batch_frames)]}, solves, turns)
    figures["window_solve_us"] = 1e6 / frames * solve_seconds
    figures["stream_us_per_frame"] = 1e6 / frames * seconds["one"]
    figures["stream_us_per_frame_batch"] = 1e6 / batch_frames / BATCH * seconds["batch"]
    figures["stream_to_window_solve"] = ratios["one"]
    figures["stream_batch_to_window_solve"] = ratios["batch"] * frames / (batch_frames * BATCH)
    figures["yardstick_turns"] = turns
    figures["lookahead"] = default_lookahead(model.fps)
    figures |= measure_pose(model, all_styles, turns, solves)
    figures |= measure_gesture(model, all_styles, turns, solves)
    per_character = figures["stream_us_per_frame_batch"]
    figures["characters_at_30fps"] = int(1e6 / 30 / per_character)
    figures["characters_at_60fps"] = int(1e6 / 60 / per_character)
    figures |= measure_cost(model, solves, frames)  # the whole live path of a crowd, per character and stage
    figures |= largest_crowd(model, figures["stream_us_per_character"])
    return figures


def _walk_of_all_styles(model_path: str | None):
    """What the bench's figures are measured on: the model, the controls mixing all its styles
    (1.5 x the even mix), their lambda* and the state ids of a walk of MLPG_FRAMES frames planned
    with them (the window solve, the yardstick, is of its first states)."""
    model = load_model(model_path or default_model_path())
    all_styles = Controls(np.full(len(model.style_names), 1.0 / len(model.style_names)) * 1.5)
    planner = Engine(model)
    planner.retune(all_styles)
    ids = planner.stream.state_plan(MLPG_FRAMES)
    return model, all_styles, interpolate(planner.space, all_styles.weights), ids


def window_solves(lam, ids: np.ndarray, frames: int, lookahead: int):
    """The yardstick: a function making `frames` bare solves of one streaming window looking
    `lookahead` frames ahead (its states the first of `ids`, lambda* `lam`)."""
    window = 2 + lookahead + 1
    window_means, window_precisions = lam.means[ids[None, :window]], lam.precisions[ids[None, :window]]
    known = np.zeros((1, 2, window_means.shape[-1] // 3))

    def solves():
        for _ in range(frames):
            mlpg_continued(window_means, window_precisions, known)

    return solves


def measure_crowd(model_path: str | None) -> dict:
    """`bench --crowd`: only the live crowd's figures (`crowd_bench`: the cost of each stage per
    character against the window solve, and the largest crowd that keeps time), in a minute or
    two, where the whole bench takes several."""
    model, _, lam, ids = _walk_of_all_styles(model_path)
    figures = {"machine": machine()}
    figures |= measure_cost(model, window_solves(lam, ids, SOLVES, default_lookahead(model.fps)), SOLVES)
    figures |= largest_crowd(model, figures["stream_us_per_character"])
    return figures


def measure_pose(model, controls: Controls, turns: int, solves) -> dict:
    """The pose path per frame (features to world pose, the feet planted: one compiled call for
    all characters), for one character and per character in a crowd of BATCH, and the lock on its
    own (what planting the feet adds); the range stage per frame; each timed turn about with
    `solves` (100 bare window solves: `against_yardstick`) and also given as a ratio to one solve.
    The pose figures are None without contact statistics, the range ones without range ones."""
    frames = 100
    figures: dict = {}
    works: dict = {}
    contact = contact_space(model)
    engine = Engine(model)
    static, shares = np.empty((frames, model.layout.dimension)), np.empty((frames, 2))
    for k in range(frames):
        static[k] = engine.next_features(controls)[0]
        if contact is not None:
            shares[k] = engine.contact_shares[0]
    if contact is not None:
        lock = FootLock(model.layout, contact.clearance, model.fps, contact.tip_clearance)

        def poses():
            stream = PoseStream(model.layout, model.fps, lock)
            for row, frame_shares in zip(static, shares):
                stream.next(row, frame_shares)

        # the lock on its own: applied to the frames' unplanted poses (it leaves each a planted
        # pose with its world transforms, itself a valid input: the work is the same every block)
        plain = PoseStream(model.layout, model.fps)
        unplanted = [plain.next(row) for row in static]
        inputs = [tuple(np.array(a)[None] for a in (p.rotations, p.translations, p.world_rotations, p.world_positions))
                  for p in unplanted]

        def planting():
            state = lock.start(1)
            for (rotations, translations, world_rot, world_pos), frame_shares in zip(inputs, shares):
                lock.apply(state, rotations, translations, frame_shares[None], world_rot, world_pos)

        crowd_static = np.repeat(static[:, None], BATCH, axis=1)
        crowd_shares = np.repeat(shares[:, None], BATCH, axis=1)

        def crowd_poses():
            crowd = CrowdPoses(model.layout, model.fps, BATCH, lock)
            for rows, frame_shares in zip(crowd_static, crowd_shares):
                crowd.next(rows, frame_shares)

        works |= {"pose_us_per_frame": poses, "contact_us_per_frame": planting, "pose_us_per_character_batch": crowd_poses}
    if engine.range_targets is not None:
        frame = engine.stream.step()
        targets = engine.range_targets
        walking = np.zeros(1, dtype=np.int64)  # the unit of the frame: the walk
        live = [Controls(controls.weights.copy(), controls.part_weights) for _ in range(frames)]  # a new snapshot a frame, as live

        def widened():  # what the range stage costs a frame: the controls compared, the swing scaled
            scale = RangeFilter(model.fps)
            for snapshot in live:
                engine.retune(snapshot)
                scale(frame, *targets.targets(walking))

        works["widen_us_per_frame"] = widened
    seconds, ratios, _ = against_yardstick(works, solves, turns)
    for name, ratio in (("pose_us_per_frame", "pose_to_window_solve"), ("contact_us_per_frame", None),
                        ("pose_us_per_character_batch", "pose_batch_to_window_solve"),
                        ("widen_us_per_frame", "widen_to_window_solve")):
        characters = BATCH if name.endswith("_batch") else 1
        figures[name] = seconds[name] * 1e6 / frames / characters if name in works else None
        if ratio:
            figures[ratio] = ratios[name] / characters if name in works else None
    return figures


def measure_gesture(model, controls: Controls, turns: int, solves) -> dict:
    """One character's frame while a gesture plays (the wave held, so its repeat loops), each work
    timed turn about with `solves` (100 bare window solves): the stream stage and the gesture stage
    together (`gesture_stream`: the frame's solving, the gait's solve making the gesture's frame,
    against the gait's stream alone in `stream_to_window_solve`), the gesture stage alone (with
    its own stream's solve: no gait's to make its frame), and the engine's whole frame before posing
    with and without the gesture. None for a model without gestures."""
    from dataclasses import replace

    names = ("gesture_stream", "gesture_stage", "gesture_engine", "engine")
    figures: dict = {f"{name}_{kind}": None for name in names for kind in ("us_per_frame", "to_window_solve")}
    walking = Engine(model)
    if not walking.gestures.names:
        return figures
    frames = 100
    name = walking.gestures.names[0]
    held = replace(controls, gestures=(name,))
    waving, streaming = Engine(model), Engine(model)
    for engine in (walking, waving, streaming):
        for _ in range(30):  # past the ease in: the gesture has the whole upper body
            engine.next_features(held if engine is not walking else controls)
    layer = streaming.gestures
    frame = streaming.next_features(held)

    def gesture_stream():  # the stream stage and the gesture stage of a frame, nothing else
        gait = streaming.stream
        for _ in range(frames):
            layer.begin(held.gestures, gait)
            layer.after(gait.step(), gait.history_ids[:, 1])

    def gesture_stage():  # with its own stream (no gait's solve to make its frame)
        for _ in range(frames):
            layer.begin(held.gestures, None)
            layer.after(frame, streaming.stream.history_ids[:, 1])

    works = {"gesture_stream": gesture_stream, "gesture_stage": gesture_stage,
             "gesture_engine": lambda: [waving.next_features(held) for _ in range(frames)],
             "engine": lambda: [walking.next_features(controls) for _ in range(frames)]}
    seconds, ratios, _ = against_yardstick(works, solves, turns)
    assert layer.playing and waving.gestures.playing  # held all along: it never lowered
    for work in works:
        figures[f"{work}_us_per_frame"] = seconds[work] * 1e6 / frames
        figures[f"{work}_to_window_solve"] = ratios[work]
    figures["gesture_name"] = name
    return figures
