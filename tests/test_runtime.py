"""The live instrument end to end: real UDP on 127.0.0.1, real processes, real files."""

import filecmp
import gc
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from instrument.control.events import ControlEvent, LogReplay, read_log, read_log_and_end
from instrument.errors import UserError
from instrument.motion.bvh import read_bvh
from instrument.output.osc import MAX_BUNDLE, parse_target
from instrument.output.recorder import BvhRecorder
from instrument.runtime.clock import IDLE_EVERY, IDLE_UNTIL, FrameClock
from instrument.terminal import Console
from instrument.runtime.performance import Show, perform
from conftest import REPO
from frame_indices import FrameIndices
from oscrecv import Receiver, frame_count, free_port
from waiting import wait_until

RUN = [sys.executable, "-m", "instrument", "run"]


def test_flat_profile_sends_every_frame_consecutively_with_all_bones(model):
    receiver = Receiver()
    try:
        result = subprocess.run(RUN + ["--seconds", "2", "--osc", f"127.0.0.1:{receiver.port}/flat", "--quiet"],
                                capture_output=True, text=True, timeout=60)
        wait_until(lambda: frame_count(receiver) >= 60 or result.returncode, "60 frames")
    finally:
        receiver.close()
    assert result.returncode == 0, result.stderr
    assert all(len(d) <= MAX_BUNDLE for d in receiver.datagrams)
    messages = receiver.messages()
    frames = [params[0] for address, params in messages if address == "/walk/frame"]
    assert frames == list(range(60))
    joints = model.layout.skeleton.names
    per_frame = [a for a, _ in messages if a.endswith("/quat") and a.startswith("/walk/bone/")]
    assert len(per_frame) == 60 * len(joints)
    assert {a.split("/")[3] for a in per_frame} == set(joints)
    assert ("/walk/style/elderly" in {a for a, _ in messages}) and ("/walk/speed" in {a for a, _ in messages})
    # the root travels: world position of the root joint changes over the run
    roots = np.array([p for a, p in messages if a == "/walk/root/pos"])
    assert np.linalg.norm(roots[-1] - roots[0]) > 50


def test_vmc_profile_read_by_an_independent_parser(model):
    pytest.importorskip("vmcp", reason="the independent VMC parser vmcp[osc4py3] is not installed")
    from vmcp.events import BoneTransformEvent, RelativeTimeEvent, RootTransformEvent
    from vmcp.facades import on_receive
    from vmcp.osc import OSC
    from vmcp.osc.backend.osc4py3 import as_eventloop as backend

    port = free_port()
    roots, bones, times = [], [], []
    with OSC(backend) as osc:
        receiver = osc.create_receiver("127.0.0.1", port, "vmc").open()
        on_receive(receiver, RootTransformEvent, roots.append)
        on_receive(receiver, BoneTransformEvent, bones.append)
        on_receive(receiver, RelativeTimeEvent, times.append)
        process = subprocess.Popen(RUN + ["--seconds", "2", "--osc", f"127.0.0.1:{port}/vmc", "--quiet"])
        deadline = time.monotonic() + 60
        while process.poll() is None and time.monotonic() < deadline:
            osc.run()
            time.sleep(0.001)
        def drained() -> bool:  # what was sent before the process ended is still being read
            osc.run()
            return len(roots) >= 60 and len(times) >= 60 and len(bones) >= 60 * 21

        wait_until(drained, "60 VMC frames", timeout=30, every=0.002)
    assert process.returncode == 0
    assert len(roots) == 60 and len(times) == 60
    expected = {"Hips", "Spine", "Chest", "Neck", "Head", "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToes",
                "RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToes", "LeftShoulder", "LeftUpperArm",
                "LeftLowerArm", "LeftHand", "RightShoulder", "RightUpperArm", "RightLowerArm", "RightHand"}
    expected |= {f"{side}{finger}{phalanx}" for side in ("Left", "Right") for finger in ("Thumb", "Index", "Middle", "Ring", "Little")
                 for phalanx in ("Proximal", "Intermediate", "Distal")}  # the relaxed hand
    counts = {}
    for event in bones:
        counts[event.joint.value] = counts.get(event.joint.value, 0) + 1
    assert set(counts) == expected
    assert all(c == 60 for c in counts.values())
    assert all(abs(np.linalg.norm([e.rotation.x, e.rotation.y, e.rotation.z, e.rotation.w]) - 1) < 1e-5 for e in bones)


def test_fast_replay_writes_the_same_bvh_every_time_and_as_in_realtime(tmp_path):
    log = tmp_path / "log.jsonl"
    log.write_text("".join(ControlEvent(t / 10, "test", c, v).to_json() + "\n" for t, c, v in
                           [(5, "style/elderly", 1.0), (12, "speed", 1.3), (20, "style/feminine", -0.5), (25, "turn", 0.3)]))
    paths = [tmp_path / f"{k}.bvh" for k in range(3)]
    for k, path in enumerate(paths):
        mode = ["--fast"] if k < 2 else []
        result = subprocess.run(RUN + ["--replay", str(log), "--seconds", "3", "--no-osc", "--bvh", str(path), "--quiet"] + mode,
                                capture_output=True, text=True, timeout=60)
        assert result.returncode == 0, result.stderr
    assert filecmp.cmp(paths[0], paths[1], shallow=False)
    assert filecmp.cmp(paths[0], paths[2], shallow=False)
    assert read_bvh(paths[0]).frames == 90


def test_a_dead_target_leaves_the_run_and_the_recording_intact(tmp_path):
    dead = free_port()  # nothing listens there: the kernel refuses, the instrument says so and goes on
    receiver = Receiver()
    path = tmp_path / "take.bvh"
    try:
        result = subprocess.run(RUN + ["--seconds", "2", "--osc", f"127.0.0.1:{dead}/flat", "--osc", f"127.0.0.1:{receiver.port}/vmc",
                                       "--bvh", str(path), "--quiet"], capture_output=True, text=True, timeout=60)
        wait_until(lambda: sum(d.count(b"/VMC/Ext/OK\x00") for d in list(receiver.datagrams)) >= 60 or result.returncode, "60 frames")
    finally:
        receiver.close()
    assert result.returncode == 0, result.stderr
    assert f"OSC target 127.0.0.1:{dead}/flat" in result.stderr and "refused" in result.stderr.lower()
    assert result.stderr.count("warning:") == 1  # once a minute, not once a frame
    assert read_bvh(path).frames == 60
    assert sum(1 for a, _ in receiver.messages() if a == "/VMC/Ext/OK") == 60


def test_ctrl_c_leaves_a_valid_recording_and_a_log_that_replays_the_whole_take(tmp_path):
    path, log, receiver = tmp_path / "take.bvh", tmp_path / "take.jsonl", Receiver()
    score = tmp_path / "once.toml"  # one cue at the start: the take's rest has no control move
    score.write_text('[[cue]]\nramp = { "style/elderly" = 1.0, gait = "run" }\n[[cue]]\nhold = 1000\n')
    process = subprocess.Popen(RUN + ["--score", str(score), "--osc", f"127.0.0.1:{receiver.port}/flat", "--bvh", str(path),
                                      "--record", str(log), "--quiet"], stderr=subprocess.PIPE, text=True)
    try:
        wait_until(lambda: frame_count(receiver) >= 30, "30 frames")  # however long start-up takes
        sent = frame_count(receiver)
        process.send_signal(signal.SIGINT)
        stderr = process.communicate(timeout=60)[1]
    finally:
        receiver.close()
    assert process.returncode == 0, stderr
    assert read_bvh(path).frames >= sent >= 30  # every frame sent was recorded
    # the log's events are all at 0 s: its replay plays as long as the take (it stopped at its last event)
    replayed = tmp_path / "replayed.bvh"
    result = subprocess.run(RUN + ["--replay", str(log), "--fast", "--no-osc", "--bvh", str(replayed), "--quiet"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert max(e.time for e in read_log(log)) == 0.0
    assert replayed.read_text() == path.read_text()


def test_a_killed_run_is_recovered(tmp_path):
    path, receiver = tmp_path / "take.bvh", Receiver()
    process = subprocess.Popen(RUN + ["--osc", f"127.0.0.1:{receiver.port}/flat", "--bvh", str(path), "--quiet"])
    try:
        wait_until(lambda: frame_count(receiver) >= 30, "30 frames")
        process.kill()
        process.wait(60)
    finally:
        receiver.close()
    result = subprocess.run([sys.executable, "-m", "instrument", "recover", str(path)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert read_bvh(path).frames >= 30


def test_recording_never_overwrites(tmp_path, model):
    path = tmp_path / "keep.bvh"
    path.write_text("precious")
    with pytest.raises(UserError, match="already exists"):
        BvhRecorder(path, model.layout.skeleton, 30.0)
    assert path.read_text() == "precious"


class Exploding:
    name = "exploding"

    def __init__(self):
        self.calls = 0

    def prepare(self, frame):
        return frame.pose()

    def send(self, prepared):
        self.calls += 1
        raise RuntimeError("renderer crashed")

    def close(self):
        raise RuntimeError("and cannot close")


def test_an_output_that_fails_never_stops_the_clock_or_the_others(model, capsys):
    exploding, collecting = Exploding(), FrameIndices()
    console = Console()
    summary = perform(Show(model, [exploding, collecting], fps=30, seconds=1.0, fast=True), console)
    assert collecting.indices == list(range(30))
    assert exploding.calls == 30 and summary.output_errors == {"exploding": 30}
    err = capsys.readouterr().err
    assert err.count("output exploding failed") == 1


def test_the_clock_keeps_absolute_deadlines_and_catches_up_without_a_burst():
    now = [100.0]
    sleeps = []

    def sleep(s):
        sleeps.append(s)
        now[0] += s

    def tick():  # the fake clock moves on a little whenever it is read (so spinning ends)
        now[0] += 1e-5
        return now[0]

    clock = FrameClock(50.0, now=tick, sleep=sleep)
    sends = []
    for k in range(10):
        now[0] += 0.005  # 5 ms of work per frame
        if k == 0:
            clock.restart()  # as the live loop does once the first frame is made
        assert clock.hold() < 1e-4
        sends.append(now[0])
        clock.advance(lead=0.006)
    assert sends[-1] - sends[0] == pytest.approx(9 * 0.02, abs=1e-4)  # on the grid: no drift
    assert clock.late == 0
    now[0] += 0.065  # one frame takes 65 ms
    assert clock.hold() > 0.04
    assert clock.late == 1
    clock.advance(lead=0.006)
    assert clock.dropped >= 2
    after = []
    for _ in range(3):
        now[0] += 0.001
        clock.hold()
        after.append(now[0])
        clock.advance(lead=0.006)
    # back on the grid at once, one period apart: no burst of back-to-back frames
    assert np.diff(after) == pytest.approx([0.02, 0.02], abs=2e-4)
    assert (after[0] - sends[0]) % 0.02 == pytest.approx(0.0, abs=2e-4) or (after[0] - sends[0]) % 0.02 == pytest.approx(0.02, abs=2e-4)


def test_the_clock_does_idle_work_while_waiting_and_still_wakes_on_time():
    now = [0.0]
    sleeps, idle_at = [], []

    def sleep(s):
        sleeps.append(s)
        now[0] += s

    def tick():
        now[0] += 1e-6
        return now[0]

    clock = FrameClock(30.0, now=tick, sleep=sleep)
    clock.restart()
    clock.advance(lead=0.002, idle=lambda: idle_at.append(now[0]))
    woke = now[0]
    assert woke == pytest.approx(1 / 30 - 0.002, abs=1e-4)  # idling does not move the wake-up
    assert max(sleeps[:-1]) <= IDLE_EVERY + 1e-12
    gaps = np.diff([0.0] + idle_at)
    assert len(idle_at) >= (1 / 30 - 0.002 - IDLE_UNTIL) / IDLE_EVERY - 1 and gaps.max() <= IDLE_EVERY + 1e-4
    assert IDLE_UNTIL - 1e-4 <= woke - idle_at[-1] <= IDLE_UNTIL + 1e-4  # the last look leaves the wake-up its time


class Echoes:
    name = "echoes"

    def __init__(self):
        self.frames = []

    def prepare(self, frame):
        return frame.index, frame.echo["style/elderly"]

    def send(self, frame):
        self.frames.append(frame)

    def close(self):
        pass


class Poses(Echoes):
    name = "poses"

    def prepare(self, frame):
        return frame.index, frame.crowd.world_positions.copy()


def _made_while_waiting() -> bool:
    """Whether the engine's retune running now was called by the live loop's look while it waits
    for a frame (`between_frames`), not by the frame itself."""
    frame = sys._getframe(2)
    for _ in range(3):
        if frame is None:
            return False
        if "between_frames" in frame.f_code.co_name:
            return True
        frame = frame.f_back
    return False


def test_live_events_taken_while_waiting_count_for_the_coming_frame(model, monkeypatch):
    """A live source is read many times between frames; every event is stamped with the time of
    the frame it comes before, and that frame already shows it, as a replay of the log does: the
    same poses, though the live loop made the frames' tables while it waited (Engine.retune).
    The source has news at its first look for each frame only (a fader moved while the loop
    waited), so tables made ahead are the ones the frames use."""
    from instrument.runtime import performance
    from instrument.synthesis.engine import Engine

    fps = 30.0
    calls, events, restyles = [], [], []

    class Watched(Engine):
        """The live loop's engine, noting where each restyle was made: ahead, or in a frame."""

        def retune(self, *args, **kwargs):
            made = super().retune(*args, **kwargs)
            if made == "restyled":
                restyles.append("ahead" if _made_while_waiting() else "frame")
            return made

    def source(now):
        calls.append(now)
        if calls.count(now) > 1:
            return []
        event = ControlEvent(now, "direct", "style/elderly", len(events) / 100.0)
        events.append(event)
        return [event]

    monkeypatch.setattr(performance, "Engine", Watched)
    echoes, poses, replayed = Echoes(), Poses(), Poses()
    perform(Show(model, [echoes, poses], fps=fps, seconds=0.5, sources=[source]), Console(quiet=True))
    monkeypatch.undo()
    perform(Show(model, [replayed], fps=fps, seconds=0.5, replay=LogReplay(events), fast=True), Console(quiet=True))
    assert [i for i, _ in echoes.frames] == list(range(15))
    assert all(np.array_equal(live, again) for (_, live), (_, again) in zip(poses.frames, replayed.frames, strict=True))
    assert all(abs(t * fps - round(t * fps)) < 1e-9 for t in calls)  # always a frame's time
    assert len(calls) > 3 * len(echoes.frames)  # looked at while waiting, not once a frame
    # the frames used tables made while the loop waited: most of them (a busy machine may leave a
    # frame no time to wait, and that frame retunes itself), not one that happened to
    assert restyles.count("ahead") > len(restyles) / 2, restyles
    for index, shown in echoes.frames:
        latest = [e.value for e in events if e.time <= index / fps + 1e-9][-1]
        assert shown == latest


def test_one_slow_restyle_ahead_does_not_keep_the_later_ones_in_their_frames(model, monkeypatch):
    """The loop retunes ahead only where its recent restyles' time fits before waking. One restyle
    ahead made slow (a stall of the machine inside the engine's work: longer than a frame) must
    not keep every later one in its frame for the rest of the show: the engine times the restyles
    the frames make too, so the slow one ages out of the estimate and the loop retunes ahead again."""
    from instrument.runtime import performance
    from instrument.synthesis.engine import Engine

    fps = 30.0
    where, looked = [], []

    class Stalled(Engine):
        """The live loop's engine, its first restyle ahead of a frame held up by 0.1 s in its work."""

        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            interpolation = self.features[0]  # retuned by a restyle only
            made = interpolation.retune

            def retune(mix, stream):
                made(mix, stream)
                ahead = _made_while_waiting()
                where.append("ahead" if ahead else "frame")
                if ahead and where.count("ahead") == 1:
                    time.sleep(0.1)

            interpolation.retune = retune

    def source(now):
        looked.append(now)
        if looked.count(now) > 1:  # news at the first look for each frame only
            return []
        return [ControlEvent(now, "direct", "style/elderly", (len(set(looked)) % 50) / 50.0)]

    monkeypatch.setattr(performance, "Engine", Stalled)
    perform(Show(model, [], fps=fps, seconds=2.5, sources=[source]), Console(quiet=True))
    assert "ahead" in where
    first = where.index("ahead")
    assert "ahead" in where[first + 1:]  # retuned ahead again after the slow one


def test_the_lead_holds_a_restyle_in_the_frame_however_rare():
    """A style change taken at a frame's start (after the loop's last look while waiting) is
    retuned in that frame's work. When such frames are fewer than one in a hundred the recent p99
    of the work does not hold them: the loop then wakes early enough for a typical frame plus the
    dearest restyle the engine timed, and as before for the p99 when that is more."""
    from instrument.runtime.performance import LEAD_MARGIN, LEAD_SPREAD, frame_lead

    fps = 120.0
    work = [0.0002] * 150 + [0.0011] + [0.0002] * 149  # one frame in 300 restyled in its work
    _, plain = frame_lead(work, [], fps)
    assert plain < 0.0011  # without a timed restyle: the p99's lead, shorter than the restyling frame's work
    expected, lead = frame_lead(work, [0.0009, 0.0007], fps)
    assert expected >= 0.0002 + 0.0009 and lead == LEAD_SPREAD * expected + LEAD_MARGIN
    varied = [0.003] * 290 + [0.006] * 10  # a crowd whose frames vary by more than a restyle: the p99 rules
    assert frame_lead(varied, [0.0009], fps)[0] == np.percentile(varied, 99)
    assert frame_lead(work, [0.05], fps)[1] == 0.9 / fps  # never more than most of a frame


def test_realtime_scheduling_is_taken_or_refused_with_a_reason():
    probe = ("import os; from instrument.runtime.priority import realtime_scheduling\n"
             "{drop}refused = realtime_scheduling()\n"
             "print(repr(refused), os.sched_getscheduler(0) == os.SCHED_FIFO)")
    result = subprocess.run([sys.executable, "-c", probe.format(drop="")], capture_output=True, text=True, timeout=60)
    refused, fifo = result.stdout.split(" ")
    assert (refused == "None") == (fifo.strip() == "True")  # says what really happened
    if os.geteuid() == 0:  # an unprivileged user with no rtprio limit is refused, with a reason
        drop = "import resource; resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0)); os.setgid(65534); os.setuid(65534)\n"
        result = subprocess.run([sys.executable, "-c", probe.format(drop=drop)], capture_output=True, text=True, timeout=60)
        assert result.returncode == 0, result.stderr
        assert "not permitted" in result.stdout and result.stdout.strip().endswith("False")


def test_realtime_scheduling_takes_the_crowd_helpers_started_before_it_along():
    """A crowd's frame waits for its helper threads (synthesis/cores.py): one started earlier (by a
    long MLPG solve, as `instrument bench` does before its crowd trials) must not stay at normal
    priority behind every ordinary program while the loop runs realtime."""
    probe = ("import os; from instrument.synthesis.mlpg import _pool, helper_thread_ids\n"
             "from instrument.runtime.priority import realtime_scheduling\n"
             "_pool().submit(int).result()\n"
             "refused = realtime_scheduling()\n"
             "print(repr(refused), len(helper_thread_ids()), all(os.sched_getscheduler(t) == os.SCHED_FIFO "
             "for t in helper_thread_ids()))")
    result = subprocess.run([sys.executable, "-c", probe], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    refused, helpers, fifo = result.stdout.split()
    if refused != "None":
        pytest.skip(f"realtime scheduling refused here: {refused}")
    assert int(helpers) >= 1 and fifo == "True"


def test_log_replay_and_its_errors(tmp_path):
    log = tmp_path / "log.jsonl"
    log.write_text('{"t": 0.5, "source": "x", "control": "speed", "value": 1.2}\n{"t": 0.1, "source": "x", "control": "turn", "value": 1}\n')
    events = read_log(log)
    assert [e.control for e in events] == ["turn", "speed"]
    replay = LogReplay(events, loop=True)
    assert [e.control for e in replay.due(0.2)] == ["turn"]
    assert [e.control for e in replay.due(1.0)] == ["speed"]
    assert [e.control for e in replay.due(1.65)] == ["turn"]  # looped: the log is 1.5 s long
    log.write_text('{"t": 0.1, "source": "x", "control": "turn", "value": 1}\n{"end": 4.0}\n')
    events, end = read_log_and_end(log)
    assert end == 4.0 and [e.control for e in events] == ["turn"]
    replay = LogReplay(events, loop=True, end=end)
    assert [e.control for e in replay.due(0.2)] + [e.control for e in replay.due(4.0)] == ["turn"]
    assert [e.control for e in replay.due(4.15)] == ["turn"]  # looped where the recorded run stopped
    for bad, message in [("{not json\n", "not JSON"), ('{"t": 1}\n', "missing key 'source'"),
                         ('{"t": -1, "source": "x", "control": "c", "value": 1}\n', "finite numbers"),
                         ('{"end": "soon"}\n', "expected one last line"), ('{"end": 1, "t": 2}\n', "expected one last line"),
                         ('{"end": 0.5}\n{"t": 1, "source": "x", "control": "c", "value": 1}\n', "ends at 0.5 s, before"),
                         ('{"end": 2}\n{"end": 3}\n', "expected one last line")]:
        log.write_text('{"t": 0, "source": "x", "control": "c", "value": 1}\n' + bad)
        with pytest.raises(UserError, match=f"{log}:[23]: .*{message}"):
            read_log(log)


@pytest.mark.parametrize("args,message", [
    (["--fps", "200"], "--fps: expected a number from 24 to 120, not '200'"),
    (["--osc", "localhost"], "expected HOST:PORT"),
    (["--osc", "127.0.0.1:99999"], "port must be 1 to 65535"),
    (["--osc", "127.0.0.1:9000/midi"], "unknown profile"),
    (["--replay", "missing.jsonl"], "missing.jsonl: cannot read"),
    (["--fast"], "--fast needs an end"),
    (["--hid", "12345678"], "error: --hid '12345678': expected VVVV:PPPP"),  # the option named, as every option's is
    # read by its row before any mapping is chosen: with a mapping for HID given, it was read only as the device
    # opened, and its error named no option
    (["--hid", "12345678", "--mapping", str(REPO / "mappings" / "sony-dualshock4.toml"), "--no-osc"],
     "error: --hid '12345678': expected VVVV:PPPP"),
])
def test_run_errors_are_one_line(args, message):
    result = subprocess.run(RUN + args, capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_target_parsing():
    assert str(parse_target("127.0.0.1:39539")) == "127.0.0.1:39539/vmc"
    assert str(parse_target("127.0.0.1:7000")) == "127.0.0.1:7000/flat"
    assert parse_target("::1:9000/vmc").host == "::1"


def test_a_python_osc_server_receives_consecutive_frames():
    """The same stream through python-osc's own server and dispatcher, as a user's patch would see it."""
    import threading

    from pythonosc.dispatcher import Dispatcher
    from pythonosc.osc_server import ThreadingOSCUDPServer

    frames, elderly = [], []
    dispatcher = Dispatcher()
    dispatcher.map("/walk/frame", lambda address, index, time_s: frames.append(index))
    dispatcher.map("/walk/style/elderly", lambda address, value: elderly.append(value))
    server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        result = subprocess.run(RUN + ["--seconds", "10", "--osc", f"127.0.0.1:{server.server_address[1]}/flat", "--quiet"],
                                capture_output=True, text=True, timeout=60)
        wait_until(lambda: len(frames) >= 300 or result.returncode, "300 frames")
    finally:
        server.shutdown()
    assert result.returncode == 0, result.stderr
    assert sorted(frames) == list(range(300))
    assert max(elderly) == pytest.approx(1.0)  # the demo sweeps elderly up to 1 from 4 s to 8 s


class Phases:
    """A sink that notes whether the loop is making a frame (from its start to `send`) when each
    collection of Python's garbage collector begins."""

    name = "phases"

    def __init__(self):
        self.in_frame = False
        self.collections: list[tuple[int, bool]] = []  # (frame, began while a frame was being made)
        self.frame = -1
        self.enabled_during: list[bool] = []
        self.kept: list[list] = []

    def prepare(self, frame):
        self.frame = frame.index
        self.enabled_during.append(gc.isenabled())
        self.kept.append([[] for _ in range(20)])  # containers that live on: the collector has work to do
        return frame.index

    def send(self, index):
        self.in_frame = False  # sent: the next frame's work begins at its wake-up

    def started(self, phase, info):
        # while the show runs (the loop keeps the collector off after its first frame; that it does
        # is asserted through `enabled_during`): after its last frame the loop wakes for one that
        # never comes, and a collection once it has switched the collector back on is not in a frame
        if phase == "start" and self.frame >= 1 and not gc.isenabled():
            self.collections.append((self.frame, self.in_frame))

    def close(self):
        pass


def test_the_garbage_collector_runs_between_frames_never_inside_one(model):
    phases = Phases()
    original_advance = FrameClock.advance

    def advance(clock, *args, **kwargs):  # a frame's work begins when the clock wakes the loop
        original_advance(clock, *args, **kwargs)
        phases.in_frame = True

    thresholds = gc.get_threshold()
    gc.set_threshold(50, 2, 2)  # collections often enough to see where they fall
    gc.callbacks.append(phases.started)
    FrameClock.advance = advance
    try:
        perform(Show(model, [phases], fps=120, seconds=4.0, fast=True), Console(quiet=True))
    finally:
        FrameClock.advance = original_advance
        gc.callbacks.remove(phases.started)
        gc.set_threshold(*thresholds)
    assert len(phases.collections) > 3  # the show made garbage, and it was collected
    assert not any(during for _, during in phases.collections), phases.collections
    assert phases.enabled_during[0] and not any(phases.enabled_during[1:])  # off once the first frame warmed up
    assert gc.isenabled()  # and on again after the show


def test_a_pose_that_is_not_a_number_is_held_not_sent(model, monkeypatch, capsys):
    """A bug that makes a character's pose NaN (as a stand's closing step did at 25 and 60 fps)
    does not reach the wire: the character holds its last finite pose, every frame is still sent,
    the console says so once, and the show goes on (read off real UDP by the test's own parser)."""
    from instrument.output.outputs import OscOutput, make_profile
    from instrument.output.osc import parse_target
    from instrument.synthesis.posing import CrowdPoses

    made = CrowdPoses.next

    def broken(self, *args, **kwargs):  # frames 10 to 14 come out NaN, as from a bug in posing
        pose = made(self, *args, **kwargs)
        if 10 <= pose.index <= 14:
            pose.rotations[0, 3] = np.nan
            pose.world_positions[0] = np.nan
        return pose

    monkeypatch.setattr(CrowdPoses, "next", broken)
    receiver = Receiver()
    try:
        console = Console()
        output = OscOutput(parse_target(f"127.0.0.1:{receiver.port}/flat"), make_profile("flat", model), console)
        summary = perform(Show(model, [output], fps=30, seconds=1.0, fast=True), console)
        wait_until(lambda: frame_count(receiver) >= 30, "30 frames")
    finally:
        receiver.close()
    assert summary.frames == 30 and summary.held == 5
    messages = receiver.messages()
    assert [p[0] for a, p in messages if a == "/walk/frame"] == list(range(30))
    floats = [v for _, p in messages for v in p if isinstance(v, float)]
    assert floats and np.isfinite(floats).all()
    roots = np.array([p for a, p in messages if a == "/walk/root/pos"])
    assert (roots[10:15] == roots[9]).all() and (roots[15] != roots[9]).any()  # held, then on again
    assert capsys.readouterr().err.count("not a number") == 1


def test_a_crowd_member_not_finite_from_its_first_frame_stands_at_the_origin_and_the_others_go_on():
    """FinitePoses on two characters: one NaN (then infinite) from the first frame, with nothing
    sent before, is held at the origin unrotated; the other is passed as made, frame by frame."""
    from instrument.runtime.finite import FinitePoses
    from instrument.synthesis.posing import CrowdPose

    rng = np.random.default_rng(1)
    guard = FinitePoses()
    for index, bad in enumerate((np.nan, np.inf, -np.inf)):
        arrays = [rng.random((2, 4, 3, 3)), rng.random((2, 4, 3)), rng.random((2, 4, 3, 3)), rng.random((2, 4, 3))]
        arrays[1][0, 2, 1] = bad
        sent, held = guard(CrowdPose(index, index / 30, *arrays))
        assert held.tolist() == [0]
        assert (sent.translations[0] == 0.0).all() and (sent.world_positions[0] == 0.0).all()
        assert (sent.rotations[0] == np.eye(3)).all() and (sent.world_rotations[0] == np.eye(3)).all()
        assert (sent.rotations[1] == arrays[0][1]).all() and (sent.world_positions[1] == arrays[3][1]).all()
    fine = [rng.random((2, 4, 3, 3)), rng.random((2, 4, 3)), rng.random((2, 4, 3, 3)), rng.random((2, 4, 3))]
    sent, held = guard(CrowdPose(3, 0.1, *fine))
    assert len(held) == 0 and sent.world_positions is fine[3]  # finite: passed on as it is


KERNELS_AFTER_THE_FIRST_FRAME = r"""
import sys
from numba.core.registry import CPUDispatcher
from instrument.control.events import ControlEvent, LogReplay
from instrument.models.modelfile import default_model_path, load_model
from instrument.runtime.performance import Show, compile_kernels, perform
from instrument.terminal import Console

def kernels():
    return {f"{name}.{attr}": set(kernel.overloads) for name, module in list(sys.modules.items())
            if name.startswith("instrument.") for attr, kernel in vars(module).items() if isinstance(kernel, CPUDispatcher)}

played = [(0.3, "gait", 2.0), (0.4, "gesture/wave", 1.0), (0.6, "gesture/wave", 0.0), (1.2, "gait", 0.0)]
events = [ControlEvent(t, "direct", target, value) for t, target, value in played]
first = {}
model = load_model(default_model_path())
compiled = sys.argv[1:] == ["run"]  # as `run` does: compile_kernels before anything opens, then perform rehearses no more
if compiled:
    compile_kernels(model, 1, 30)
perform(Show(model, [], fps=30, seconds=2.5, replay=LogReplay(events), fast=True), Console(quiet=True),
        on_frame=lambda index, clock, summary: first.update(kernels()) if index == 0 else None, compiled=compiled)
print(" ".join(sorted(name for name, signatures in kernels().items() if signatures - first.get(name, set()))))
"""


@pytest.mark.parametrize("caller", ["perform", "run"])
def test_a_show_loads_every_kernel_before_its_first_frame(caller):
    """A run, a stand and a wave first asked for mid-show find their kernels ready: numba compiles
    (or loads from its cache) a kernel at its first call, and on a new install that was the
    show's first run or wave, dropping 76 frames at 30 fps after the documented warm-up. In a
    process of its own (this one's kernels are loaded by other tests): no kernel gains a signature
    after the first frame (before the rehearsal: the gestures' six and widen's stride means),
    whether `perform` rehearses or, as in `run`, `compile_kernels` did before it."""
    done = subprocess.run([sys.executable, "-c", KERNELS_AFTER_THE_FIRST_FRAME, caller], capture_output=True, text=True,
                          timeout=600, cwd=REPO)
    assert done.returncode == 0, done.stderr
    assert done.stdout.split() == []


def test_run_rehearses_the_show_once(monkeypatch):
    """`run` rehearsed twice: in compile_kernels before anything opened, and again in perform
    (start-up time for nothing). Counted by wrapping the real rehearsal: once."""
    from instrument.cli.main import main
    from instrument.runtime import performance

    rehearsals = []
    real = performance.rehearse
    monkeypatch.setattr(performance, "rehearse", lambda *args: rehearsals.append(args) or real(*args))
    assert main(["run", "--seconds", "0.5", "--no-osc", "--quiet", "--normal-priority"]) == 0
    assert len(rehearsals) == 1
