"""In time with the music (runtime/tempo.py, synthesis/footfalls.py): the MIDI clock follower, the
beat lock on the real engine, footfalls out as OSC and MIDI, through real JACK MIDI and a real
Ableton Link session."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from instrument.models.modelfile import load_model
from instrument.runtime.tempo import (TICKS_PER_BEAT, BeatLock, TempoFollower, choose_ratio, locked_speed, snap_ratio,
                                      step_seconds)
from instrument.shipped import default_model_path
from instrument.synthesis.engine import Engine, default_controls
from instrument.synthesis.footfalls import Footfalls, pacing, side_of
from instrument.synthesis.parameters import GAITS
from waiting import wait_until

REPO = Path(__file__).resolve().parents[1]
MIN_TICKS_FOR_TEST = 30  # ticks before the first loss: the line must exist to see one
sys.path.insert(0, str(REPO / "examples"))
FPS = 30.0


@pytest.fixture(scope="module")
def model():
    return load_model(default_model_path())


def clock_ticks(follower: TempoFollower, bpm: float, first: float, count: int, rng, jitter: float = 0.0015,
                first_tick: int = 0) -> float:
    """`count` ticks at `bpm` from `first`, each late by up to 2 * jitter (a busy USB or JACK
    clock); the time of the tick after them."""
    tick = 60.0 / bpm / TICKS_PER_BEAT
    for k in range(count):
        follower.message("clock", first + (first_tick + k) * tick + abs(rng.normal(0, jitter)))
    return first + (first_tick + count) * tick


def test_the_follower_smooths_a_jittering_clock_and_follows_a_tempo_change_within_a_beat():
    rng = np.random.default_rng(0)
    follower = TempoFollower()
    assert follower.period() is None
    follower.message("start", 0.0)
    clock_ticks(follower, 120, 1.0, 4 * TICKS_PER_BEAT, rng)
    assert follower.period() == pytest.approx(0.5, rel=0.01)
    assert follower.beat_at(1.0 + 4 * 0.5) == pytest.approx(4.0, abs=0.02)  # the first tick after start is beat 0
    # 140 bpm from beat 4: after one beat of ticks the old tempo is gone
    new_tick = 60.0 / 140 / TICKS_PER_BEAT
    for k in range(TICKS_PER_BEAT):
        follower.message("clock", 3.0 + k * new_tick + abs(rng.normal(0, 0.0015)))
    assert follower.period() == pytest.approx(60.0 / 140, rel=0.01)
    assert follower.beat_at(3.0 + TICKS_PER_BEAT * new_tick) == pytest.approx(5.0, abs=0.02)


def test_lost_ticks_do_not_slip_the_beat():
    """A client that misses a cycle of a busy JACK server loses its MIDI: 1 tick in 10 lost here,
    the beats stay where the clock put them."""
    rng = np.random.default_rng(4)
    follower = TempoFollower()
    follower.message("start", 0.0)
    tick = 0.5 / TICKS_PER_BEAT
    for k in range(16 * TICKS_PER_BEAT):
        if k < MIN_TICKS_FOR_TEST or rng.random() > 0.1:
            follower.message("clock", 1.0 + k * tick + abs(rng.normal(0, 0.0015)))
    assert follower.period() == pytest.approx(0.5, rel=0.01)
    assert follower.beat_at(1.0 + 16 * 0.5) == pytest.approx(16.0, abs=0.05)


def test_a_tick_a_cycle_late_is_not_a_lost_one():
    """Over JACK a tick can come a whole cycle late and the next on time: counted as a loss and
    then taken back, the beat stays."""
    follower = TempoFollower()
    follower.message("start", 0.0)
    tick = 0.5 / TICKS_PER_BEAT
    for k in range(16 * TICKS_PER_BEAT):
        late = tick * 1.1 if k > MIN_TICKS_FOR_TEST and k % 20 == 0 else 0.0
        follower.message("clock", 1.0 + k * tick + late)
    assert follower.beat_at(1.0 + 16 * 0.5) == pytest.approx(16.0, abs=0.05)


def jack_delivery(bpm: float, beats: int, rng, period: float = 256 / 48000, lost: float = 0.1,
                  late: float = 0.1, start: float = 1.0) -> list[float]:
    """Arrival times of a clock's ticks as a JACK client that is not realtime on a busy machine
    sees them: each stamped at the end of the server cycle it was sent in, a share `late` a
    cycle later still (the client missed a cycle and read two at once), a share `lost` never."""
    tick = 60.0 / bpm / TICKS_PER_BEAT
    out = []
    for k in range(beats * TICKS_PER_BEAT):
        if k > MIN_TICKS_FOR_TEST and rng.random() < lost:
            continue
        sent = start + k * tick
        arrived = (np.floor(sent / period) + 1) * period + (period if rng.random() < late else 0.0)
        out.append(arrived)
    return out


@pytest.mark.parametrize("bpm", [80.0, 120.0, 174.0])
def test_ticks_lost_or_late_through_jack_do_not_move_the_beat(bpm):
    """Every tick numbered by its nearest place on the fitted line: 10% lost, 10% a cycle late,
    cycles of 5.3 ms (a short-period server): after 16 beats the beat is where the clock put it
    (within 6 ms: the ticks come half a cycle late on average, which is latency, not a slip)."""
    rng = np.random.default_rng(int(bpm))
    follower = TempoFollower()
    follower.message("start", 0.0)
    for moment in jack_delivery(bpm, 16, rng):
        follower.message("clock", moment)
    beat = 60.0 / bpm
    assert follower.period() == pytest.approx(beat, rel=0.01)
    assert abs(follower.beat_at(1.0 + 16 * beat) - 16.0) * beat < 0.006


def test_counting_alone_slips_the_beat_where_ticks_are_lost():
    """The check above can fail: the same ticks counted one by one put the beat 40 ms off and more."""
    moments = np.array(jack_delivery(120.0, 16, np.random.default_rng(120)))
    ticks = np.arange(len(moments))
    slope, intercept = np.polyfit(ticks[-24:], moments[-24:], 1)
    assert abs((1.0 + 16 * 0.5 - intercept) / slope / TICKS_PER_BEAT - 16.0) * 0.5 > 0.04


@pytest.mark.parametrize("after", [100.0, 60.0, 174.0])
def test_a_sudden_tempo_change_is_followed_not_taken_for_lost_ticks(after):
    """From 120 bpm to a slower tempo (whose ticks come late, as lost ones would) or a faster:
    within two beats the period is the new one."""
    rng = np.random.default_rng(5)
    follower = TempoFollower()
    follower.message("start", 0.0)
    end = clock_ticks(follower, 120.0, 1.0, 8 * TICKS_PER_BEAT, rng)
    new_tick = 60.0 / after / TICKS_PER_BEAT
    for k in range(2 * TICKS_PER_BEAT):
        follower.message("clock", end + k * new_tick + abs(rng.normal(0, 0.0015)))
    assert follower.period() == pytest.approx(60.0 / after, rel=0.01)


def test_a_clock_joined_mid_song_gives_its_tempo_without_a_start():
    """A source already playing (or one that always sends its clock) is followed from its ticks."""
    follower = TempoFollower()
    clock_ticks(follower, 130, 2.0, 30, np.random.default_rng(3))
    assert follower.running and follower.period() == pytest.approx(60.0 / 130, rel=0.01)


def test_a_stopped_clock_keeps_its_tempo_and_song_position_sets_the_beat():
    rng = np.random.default_rng(1)
    follower = TempoFollower()
    follower.message("start", 0.0)
    clock_ticks(follower, 100, 0.0, 48, rng)
    follower.message("stop", 1.3)
    assert not follower.running and follower.period() == pytest.approx(0.6, rel=0.01)
    follower.message("clock", 1.4)  # ticks while stopped (some sources keep sending them) change nothing
    assert follower.period() == pytest.approx(0.6, rel=0.01)
    follower.message("songpos", 5.0, 16)  # sixteenth 16: beat 4
    follower.message("continue", 5.0)
    clock_ticks(follower, 100, 10.0, 12, rng, first_tick=0)
    assert follower.running
    assert follower.beat_at(10.0) == pytest.approx(4.0, abs=0.03)


def test_the_ratio_is_the_one_nearest_the_style_and_sticks_near_the_middle():
    assert choose_ratio(0.45, 0.5, None) == 1.0
    assert choose_ratio(0.45, 0.75, None) == 2.0  # 80 bpm: 375 ms steps are nearer 450 than 750
    assert choose_ratio(0.45, 60 / 174, None) == 1.0
    assert choose_ratio(0.7, 60 / 174, None) == 0.5
    # between two ratios the current one stays unless the other fits clearly better
    middle = 0.45 * np.sqrt(2)  # a beat where 1 and 2 steps per beat misfit equally
    assert choose_ratio(0.45, middle * 1.02, 1.0) == 1.0 and choose_ratio(0.45, middle * 0.98, 2.0) == 2.0
    assert [snap_ratio(v) for v in (0.0, 0.2, 0.4, 0.9, 1.6, 2.0)] == [0.0, 0.0, 0.5, 1.0, 2.0, 2.0]


def test_footfall_sides_come_from_the_hip_names():
    assert [side_of(n, 9) for n in ("UpperLeg_L", "RightUpLeg", "LHipJoint", "rhip", "r_thigh", "Hip")] == [0, 1, 0, 9, 1, 9]


def test_a_stands_closing_step_is_a_footfall_the_beat_lock_does_not_read(model):
    """A walk that stops: the stand's closing step (footlock.settle_feet) is reported once, in the
    frame the lock's closing step is done, marked `closing` (a footstep sound plays for it), and
    `pacing` leaves it out; the gait's own footfalls are not marked. Before, a closing step
    reported nothing."""
    from instrument.synthesis.footlock import CLOSED
    from instrument.synthesis.stream import Controls

    engine = Engine(model)
    feet = Footfalls(engine.poses)
    weights = default_controls(model, {"feminine": 1.0}).weights
    falls, done = [], []
    for k in range(150):
        before = engine.poses.lock_state.settling[0].copy()
        pose = engine.frame(k / engine.fps, Controls(weights, gait=GAITS.index("walk" if k < 60 else "stand")))
        after = engine.poses.lock_state.settling[0]
        done += [(k, f) for f in range(2) if 0.0 < before[f] < CLOSED and after[f] == CLOSED]
        falls += [(k, f) for f in feet.after(pose)]
    closing = [(k, f) for k, f in falls if f.closing]
    assert done and len(closing) == len(done)
    assert [k for k, _ in closing] == [k for k, _ in done]
    assert all(f.speed > 0.0 for _, f in closing)  # the foot moved as it came down
    assert not any(f.closing for k, f in falls if k < 60)  # the walk's own steps pace the lock
    assert pacing([f for _, f in falls]) == [f for _, f in falls if not f.closing]


def walk(model, bpm: float | None, seconds: float = 16.0, forced: float = 0.0, stop_at: float | None = None,
         weights=None, clock_start: float = 1.0, gaits: tuple[tuple[float, str], ...] = (), with_closing: bool = False):
    """The live loop's three pieces on the real engine (Engine, Footfalls, BeatLock), frame by frame at
    FPS, performance time as the clock; a MIDI clock at `bpm` (jittering) from `clock_start`; None: no
    lock; `gaits`: (from when, gait) the performer chooses. Returns the footfalls (time, side, speed)
    of character 0 and the lock (with `with_closing`, also the times of its closing steps' footfalls,
    which the lock does not read: `footfalls.pacing`)."""
    engine = Engine(model, fps=FPS)
    feet = Footfalls(engine.poses)
    follower = TempoFollower()
    lock = BeatLock(follower) if bpm else None
    controls = default_controls(model, weights or {"normal": 1.0})
    rng = np.random.default_rng(2)
    tick, k, landed, speeds, out, closing = (60.0 / bpm / TICKS_PER_BEAT if bpm else None), 0, {}, {}, [], []
    if bpm:
        follower.message("start", clock_start - tick)
    for index in range(int(seconds * FPS)):
        now = index / FPS
        while bpm and clock_start + k * tick <= now:
            if stop_at is not None and clock_start + k * tick >= stop_at:
                if follower.running:
                    follower.message("stop", stop_at)
                break
            follower.message("clock", clock_start + k * tick + abs(rng.normal(0, 0.0015)))
            k += 1
        for moment, gait in gaits:
            if abs(now - moment) < 0.5 / FPS:
                controls = replace(controls, gait=GAITS.index(gait))
        if lock is not None:
            for event in lock.decide(now, controls.speed, lambda k: step_seconds(engine, controls, k), landed, speeds,
                                     steps_per_beat=forced):
                speeds[int(event.control.split("/")[1])] = event.value
        used = replace(controls, speed=locked_speed(speeds, controls.speed, 1)) if speeds else controls
        pose = engine.frame(now, used)
        falls = feet.after(pose)
        landed = {f.character: now for f in pacing(falls) if index > 0}
        out += [(f.time, f.side, f.speed) for f in pacing(falls) if f.character == 0]
        closing += [f.time for f in falls if f.closing and f.character == 0]
    return (out, lock, closing) if with_closing else (out, lock)


def offsets_ms(times: np.ndarray, start: float, period: float) -> np.ndarray:
    grid = (times - start) / period
    return np.abs(grid - np.round(grid)) * period * 1000.0


@pytest.mark.parametrize("bpm", [80.0, 120.0, 174.0])
def test_the_footfalls_lock_onto_the_beat(model, bpm):
    falls, lock = walk(model, bpm)
    times = np.array([t for t, _, _ in falls])
    beat = 60.0 / bpm
    period = beat / lock.report.ratio
    assert lock.report.ratio in (0.5, 1.0, 2.0)
    settled = times[times > 1.0 + 4.0]
    assert abs(np.mean(np.diff(settled)) / period - 1) < 0.02  # the step period is the beat's ratio
    assert np.percentile(offsets_ms(settled, 1.0, period), 95) <= 40.0
    after_start = offsets_ms(times[times > 1.0], 1.0, period)
    assert (after_start[2:] <= 40.0).all()  # locked within two steps of the clock's start, and stays
    # the sides alternate and the feet land with a walking foot's speed
    sides = [s for _, s, _ in falls]
    assert all(a != b for a, b in zip(sides, sides[1:]))
    assert 0.05 < np.median([v for _, _, v in falls[1:]]) < 3.0


def test_without_the_lock_the_walk_keeps_its_own_time(model):
    """The check above can fail: the unlocked walk's footfalls drift across the beats."""
    falls, _ = walk(model, None)
    times = np.array([t for t, _, _ in falls])
    assert np.percentile(offsets_ms(times[times > 5.0], 1.0, 0.5), 95) > 40.0


def test_steps_per_beat_forces_the_ratio(model):
    falls, lock = walk(model, 120.0, seconds=10.0, forced=2.0)
    times = np.array([t for t, _, _ in falls])
    assert lock.report.ratio == 2.0
    assert abs(np.mean(np.diff(times[times > 5.0])) / 0.25 - 1) < 0.03


def test_a_stopped_clock_keeps_the_last_tempo_without_a_jump(model):
    falls, lock = walk(model, 120.0, seconds=14.0, stop_at=7.0)
    times = np.array([t for t, _, _ in falls])
    before, after = np.diff(times[(times > 4.0) & (times < 7.0)]), np.diff(times[times > 7.5])
    assert abs(np.mean(after) / np.mean(before) - 1) < 0.03
    assert np.abs(np.diff(times[times > 4.0])).max() < 0.5 * 1.2  # no step stumbles at the stop


def test_every_gait_locks_a_run_to_its_own_ratio_and_a_stand_keeps_the_lock(model):
    """At 174 bpm (a beat of 345 ms) the walk (its own steps about 550 ms) takes a step every two
    beats, a run (about 380 ms) one a beat; a stand has no footfalls and leaves the lock and the
    clock as they were; the walk started from the stand is on the beat from its third footfall."""
    bpm, beat = 174.0, 60.0 / 174.0
    plan = ((0.0, "walk"), (7.0, "run"), (15.0, "stand"), (20.0, "walk"))
    falls, lock, closing = walk(model, bpm, seconds=30.0, gaits=plan, with_closing=True)
    times = np.array([t for t, _, _ in falls])
    # the stand's closing steps are footfalls a sound plays for, in the stand, which the lock does not read
    assert all(15.0 < t < 20.0 for t in closing)
    walked = times[(times > 4.0) & (times < 7.0)]
    assert np.percentile(offsets_ms(walked, 1.0, 2 * beat), 95) <= 40.0  # half a step a beat
    ran = times[(times > 10.0) & (times < 15.0)]
    assert abs(np.mean(np.diff(ran)) / beat - 1) < 0.03  # a step a beat: the run's own ratio
    assert np.percentile(offsets_ms(ran, 1.0, beat), 95) <= 40.0
    assert not ((times > 17.0) & (times < 20.0)).any()  # standing: no footfall
    again = times[times > 20.0]
    assert len(again) >= 8 and lock.report.ratio == 0.5
    assert (offsets_ms(again[2:], 1.0, 2 * beat) <= 40.0).all()


# ---- through real JACK MIDI: the instrument as run, a real clock, OSC and MIDI out ----------------

def test_a_midi_clock_through_jack_sets_the_step_period(jack):
    """`instrument run --sync midi` with a real clock over JACK at 90 bpm: the steps take a beat
    (667 ms; the walk's own are about 520 ms), footfalls timed as they arrive by OSC. How near the
    beats they land depends on how busy the machine is (a client of a busy JACK server loses the
    MIDI of the cycles it misses): examples/tempo_lock.py reports it; here only the period."""
    from tempo_lock import run

    result = run(90.0, seconds=10.0)
    assert result.ratio == 1.0
    assert abs(result.mean_interval / (60.0 / 90.0) - 1) < 0.05


def test_footfalls_are_notes_on_the_midi_out_port(jack, tmp_path):
    name = f"tempo-steps-{os.getpid()}"
    process = subprocess.Popen([sys.executable, "-m", "instrument", "run", "--midi-out", name, "--midi-api", "jack",
                                "--no-osc", "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    received = []  # (arrival, message)
    port = None
    try:
        deadline = time.monotonic() + 120
        while port is None and time.monotonic() < deadline:
            names = [n for n in jack.get_input_names() if name in n]
            port = jack.open_input(names[0], callback=lambda m: received.append((time.monotonic(), m))) if names else None
            time.sleep(0.1)
        assert port is not None, "the --midi-out port never appeared"
        while sum(m.type == "note_on" for _, m in received) < 12 and time.monotonic() < deadline:
            time.sleep(0.1)
    finally:
        process.terminate()
        process.communicate(timeout=60)
        if port is not None:
            # the show's end lets every sounding note go (its close waits for JACK to send it:
            # ended at once without, a sampler was left with a stuck note)
            wait_until(lambda: not _sounding(received), "a note-off for every note still sounding", timeout=10)
            port.close()
    ons = [(t, m) for t, m in received if m.type == "note_on"]
    assert len(ons) >= 12
    assert {m.note for _, m in ons} == {36, 38} and all(m.channel == 9 and 1 <= m.velocity <= 127 for _, m in ons)
    # left, right, left...: a note follows the other foot's, or (a client of a busy JACK server
    # loses the MIDI of the cycles it misses) its own foot's after a whole stride, the other lost
    gaps = np.diff([t for t, _ in ons])
    step = np.median(gaps)
    alternate = np.array([a.note != b.note for (_, a), (_, b) in zip(ons, ons[1:])])
    assert alternate.mean() >= 0.75 and (gaps[~alternate] > 1.5 * step).all(), (step, gaps[~alternate])
    offs = [m for _, m in received if m.type == "note_off"]
    assert offs  # a note is let go


def _sounding(received: list) -> set[int]:
    """The notes whose last message was a note-on."""
    last = {}
    for _, m in received:
        if m.type in ("note_on", "note_off"):
            last[m.note] = m.type == "note_on" and m.velocity > 0
    return {note for note, on in last.items() if on}


def test_sync_midi_without_a_midi_input_is_one_line():
    result = subprocess.run([sys.executable, "-m", "instrument", "run", "--sync", "midi", "--no-osc", "--seconds", "1"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode != 0
    assert "--sync midi" in result.stderr and "Traceback" not in result.stderr


# ---- Ableton Link: a second peer in this process ------------------------------------------------------

def test_a_link_session_sets_the_tempo_and_beats():
    link = pytest.importorskip("link")
    from instrument.runtime.link import LinkTempo

    ours = LinkTempo()
    peer = link.Link(90.0)
    peer.enabled = True
    try:
        deadline = time.monotonic() + 30
        while ours.peers() == 0 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ours.peers() >= 1
        state = peer.captureAppSessionState()
        state.setTempo(93.0, peer.clock().micros())
        peer.commitAppSessionState(state)
        while abs(ours.period() - 60.0 / 93.0) > 1e-3 and time.monotonic() < deadline:
            time.sleep(0.05)
        assert ours.period() == pytest.approx(60.0 / 93.0, rel=1e-3)
        now = time.monotonic()
        theirs = peer.captureAppSessionState().beatAtTime(peer.clock().micros(), 4.0)
        assert ours.beat_at(now) == pytest.approx(theirs, abs=0.02)  # the same beat on time.monotonic()
    finally:
        peer.enabled = False
        ours.close()


# ---- the live loop: the lock as `perform` runs it, and the `sync` control ------------------------------

class SteadyTempo:
    """A tempo source that cannot exist here otherwise without a second machine: a steady
    beat on the monotonic clock from its making (what a perfect clock or Link would give)."""

    running = True

    def __init__(self, bpm: float):
        self.beat, self.start = 60.0 / bpm, time.monotonic()

    def period(self) -> float:
        return self.beat

    def beat_at(self, moment: float) -> float:
        return (moment - self.start) / self.beat


class FootfallSink:
    name = "footfalls"

    def __init__(self):
        self.times: list[float] = []

    def prepare(self, frame):
        self.times += [f.time for f in frame.footfalls if f.character == 0]

    def send(self, prepared) -> None:
        pass

    def close(self) -> None:
        pass


@pytest.mark.parametrize("sync", [1.0, 0.0])
def test_perform_locks_the_steps_unless_the_sync_control_is_off(model, sync):
    """At 90 bpm (steps of 667 ms: the average style's own are about 520 ms) the locked walk's
    steps take a beat; with `sync` 0 the walk keeps its own time."""
    from instrument.control.state import ControlState
    from instrument.runtime.performance import Show, perform
    from instrument.terminal import Console

    state = ControlState(model.style_names, model.states)
    state.set("sync", sync)
    sink = FootfallSink()
    lock = BeatLock(SteadyTempo(90.0))
    perform(Show(model, [sink], FPS, seconds=8.0, state=state, beat_lock=lock), Console(quiet=True))
    step = np.mean(np.diff([t for t in sink.times if t > 3.0]))
    if sync:
        assert lock.report.ratio == 1.0 and step == pytest.approx(60.0 / 90.0, rel=0.03)
    else:
        assert lock.report.ratio is None and step < 0.6


class CrowdSink:
    """Every character's footfalls (performance time) and every frame's poses."""

    name = "crowd"

    def __init__(self):
        self.falls: dict[int, list[float]] = {}
        self.poses: list[np.ndarray] = []

    def prepare(self, frame):
        for f in frame.footfalls:
            self.falls.setdefault(f.character, []).append(f.time)
        self.poses.append(frame.crowd.world_positions.copy())

    def send(self, prepared) -> None:
        pass

    def close(self) -> None:
        pass


def synced_show(model, sink, lock: BeatLock | None, seconds: float, characters: int = 1, hub=None, replay=None,
                spread: float = 0.0, liveliness: float = 0.0):
    from instrument.control.state import ControlState
    from instrument.runtime.performance import Show, perform
    from instrument.terminal import Console

    state = ControlState(model.style_names, model.states)
    state.set("spread", spread)
    state.set("liveliness", liveliness)
    show = Show(model, [sink], FPS, seconds=seconds, characters=characters, state=state, beat_lock=lock, replay=replay,
                apply=None if hub is None else hub.apply)
    return perform(show, Console(quiet=True))


def grid_offsets_ms(times: np.ndarray, phase: float, period: float) -> np.ndarray:
    grid = (times - phase) / period
    return np.abs(grid - np.round(grid)) * period * 1000.0


def test_every_character_of_a_crowd_steps_on_the_beat(model):
    """Three characters of different styles (spread), so of different rhythms: each one's
    footfalls on the grid of the beat, not only character 0's (the grid's phase from character 0)."""
    sink = CrowdSink()
    lock = BeatLock(SteadyTempo(100.0))
    synced_show(model, sink, lock, 12.0, characters=3, spread=1.0)
    period = 0.6 / lock.report.ratio
    first = np.array(sink.falls[0])
    first = first[first > 4.0]
    phase = period / (2 * np.pi) * np.angle(np.mean(np.exp(2j * np.pi * first / period)))
    for character in range(3):
        times = np.array(sink.falls[character])
        settled = times[times > 4.0]
        assert len(settled) >= 8
        assert np.percentile(grid_offsets_ms(settled, phase, period), 95) <= 40.0, character


def test_a_synced_show_replays_exactly_from_its_log(model, tmp_path):
    """The lock's decisions are in the --record log: replayed without any tempo source, a crowd's
    every frame is the same, to the bit."""
    from instrument.control.events import LogReplay, read_log
    from instrument.control.hub import ControlHub

    log = tmp_path / "synced.jsonl"
    hub = ControlHub([], record=log)
    live = CrowdSink()
    synced_show(model, live, BeatLock(SteadyTempo(90.0)), 8.0, characters=2, hub=hub, spread=0.8)
    hub.close()
    events = read_log(log)
    assert sum(e.source == "tempo" for e in events) >= 10
    again = CrowdSink()
    synced_show(model, again, None, 8.0, characters=2, replay=LogReplay(events), spread=0.8)
    assert len(again.poses) == len(live.poses)
    assert all(np.array_equal(a, b) for a, b in zip(live.poses, again.poses))
    unlocked = CrowdSink()  # the check can fail: the same show without the log's tempo events walks otherwise
    synced_show(model, unlocked, None, 8.0, characters=2, spread=0.8)
    assert not all(np.array_equal(a, b) for a, b in zip(live.poses, unlocked.poses))


class SentFootfalls:
    """Character 0's footfalls, stamped with the deadline of the frame that sends them (the moment
    the loop shows the frame, where the lock puts the beats; a frame a busy machine sends late is
    the clock's lateness, which `instrument bench` measures, not the lock's) and the source's beat
    then (a later tempo change moves the beats of the past on a Link timeline)."""

    name = "sent footfalls"

    def __init__(self, tempo):
        self.tempo = tempo
        self.clock = None
        self.times: list[float] = []
        self.beats: list[float] = []

    def watch(self, clock) -> None:
        self.clock = clock

    def prepare(self, frame):
        return [f for f in frame.footfalls if f.character == 0] or None

    def send(self, prepared) -> None:
        due = self.clock.deadline()
        self.times += [due] * len(prepared)
        self.beats += [self.tempo.beat_at(due)] * len(prepared)

    def close(self) -> None:
        pass


def test_link_start_stop_keeps_the_tempo_when_stopped_and_locks_when_started(model):
    """A second Link peer in this process plays at 100 bpm, stops, changes to 125 bpm while
    stopped and plays again: while stopped the walk keeps its last step period (no jump); from
    the third footfall after each start every footfall is on a beat of the session."""
    import threading

    link = pytest.importorskip("link")
    from instrument.control.state import ControlState
    from instrument.runtime.link import LinkTempo
    from instrument.runtime.performance import Show, perform
    from instrument.runtime.stopping import StopFlag
    from instrument.terminal import Console

    ours = LinkTempo()
    peer = link.Link(100.0)
    peer.startStopSyncEnabled = True
    peer.enabled = True
    marks: dict[str, float] = {}

    sink = SentFootfalls(ours)
    lock = BeatLock(ours)
    stop = StopFlag()

    def transport():
        """Each phase ends on what the show did (footfalls sent, the tempo seen), each wait with
        a generous deadline, so a slow machine only makes the show longer."""
        def commit(change):
            state = peer.captureAppSessionState()
            change(state, peer.clock().micros())
            peer.commitAppSessionState(state)

        def wait(condition) -> bool:
            deadline = time.monotonic() + 60
            while not condition():
                if time.monotonic() > deadline or stop:
                    return False
                time.sleep(0.02)
            return True

        def footfalls_since(mark: str) -> int:
            return sum(t > marks[mark] for t in list(sink.times))

        try:
            if not wait(lambda: ours.peers() > 0):
                return
            commit(lambda s, now: s.setTempo(100.0, now))
            if not wait(lambda: abs(ours.period() - 0.6) < 1e-6):
                return
            marks["start"] = time.monotonic()
            commit(lambda s, now: s.setIsPlaying(True, now))
            if not wait(lambda: footfalls_since("start") >= 10):
                return
            marks["stop"] = time.monotonic()
            commit(lambda s, now: s.setIsPlaying(False, now))
            if not wait(lambda: footfalls_since("stop") >= 2):
                return
            commit(lambda s, now: s.setTempo(125.0, now))  # while stopped: waits for the start
            if not wait(lambda: abs(ours.period() - 0.48) < 1e-6) or not wait(lambda: footfalls_since("stop") >= 6):
                return
            marks["again"] = time.monotonic()
            commit(lambda s, now: s.setIsPlaying(True, now))
            wait(lambda: footfalls_since("again") >= 10)
        finally:
            stop.request()

    controller = threading.Thread(target=transport, daemon=True)
    try:
        controller.start()
        state = ControlState(model.style_names, model.states)
        perform(Show(model, [sink], FPS, seconds=300.0, state=state, beat_lock=lock), Console(quiet=True), stop=stop)
        controller.join(30)
    finally:
        peer.enabled = False
        ours.close()
    assert set(marks) == {"start", "stop", "again"}, "the peer never joined the session"
    times, beats = np.array(sink.times), np.array(sink.beats)

    def beat_offsets_ms(chosen: np.ndarray, bpm: float) -> np.ndarray:
        grid = beats[chosen] * lock.report.ratio
        return np.abs(grid - np.round(grid)) * 60.0 / bpm / lock.report.ratio * 1000.0

    first = np.flatnonzero((times > marks["start"]) & (times < marks["stop"]))
    playing = times[first]
    assert (beat_offsets_ms(first[2:], 100.0) <= 40.0).all()
    # stopped: the step period of the last steps played, no jump (the tempo change waits for the start)
    stopped = np.diff(times[(times > marks["stop"]) & (times < marks["again"])])
    beat = 60.0 / 100.0 / lock.report.ratio
    assert abs(np.mean(stopped) / beat - 1) < 0.02  # (a step is a whole number of frames: their mean)
    assert np.abs(np.diff(playing[-3:]) / beat - 1).max() < 0.1 and np.abs(stopped / beat - 1).max() < 0.1
    second = np.flatnonzero(times > marks["again"])
    again = times[second]
    assert len(again) >= 8
    assert (beat_offsets_ms(second[2:], 125.0) <= 40.0).all()
    assert np.mean(np.diff(again[2:])) == pytest.approx(60.0 / 125.0 / lock.report.ratio, rel=0.03)  # (a median is 14 or 15 frames)


# ---- selecting the sync: show files, the console ---------------------------------------------------------

def test_a_show_file_selects_the_sync_and_a_bad_one_is_one_line(tmp_path):
    good = tmp_path / "synced.toml"
    good.write_text('sync = "midi"\nmidi-virtual = ["clock"]\nmidi-api = "jack"\n')
    result = subprocess.run([sys.executable, "-m", "instrument", "run", "--config", str(good), "--check"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0 and "the show is fine" in result.stdout, result.stderr
    bad = tmp_path / "bad.toml"
    bad.write_text('sync = "clock"\n')
    result = subprocess.run([sys.executable, "-m", "instrument", "run", "--config", str(bad), "--check"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1 and "bad.toml" in result.stderr and "sync" in result.stderr
    alone = tmp_path / "alone.toml"  # midi clock needs a MIDI input: said naming the file's key
    alone.write_text('sync = "midi"\n')
    result = subprocess.run([sys.executable, "-m", "instrument", "run", "--config", str(alone), "--check"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode != 0 and "alone.toml" in result.stderr and "--midi" in result.stderr


def test_the_console_turns_the_lock_on_and_off_and_chooses_steps_per_beat():
    """The console builds its page from the spec table: `sync` as two buttons (off, on), the
    steps per beat as a slider, both in the walk section of a run with --sync (only); a page's
    "off" turns the lock off."""
    from instrument.control.spec import rows_for_page
    from instrument.control.state import ControlState

    assert not {"sync", "steps-per-beat"} & {row["pattern"] for row in rows_for_page()}  # a run without --sync
    rows = {row["pattern"]: row for row in rows_for_page({"sync"})}
    assert rows["sync"]["choices"] == ["off", "on"] and rows["sync"]["section"] == "walk"
    assert rows["steps-per-beat"]["section"] == "walk" and rows["steps-per-beat"]["range"] == [0.0, 2.0]
    state = ControlState(["a"], 5)
    assert state.set("sync", "off") and state.sync == 0.0
    assert state.set("sync", "on") and state.sync == 1.0


def test_run_replay_of_a_synced_log_writes_the_same_bvh(model, tmp_path):
    """End to end: a synced show recorded (its log and a BVH), then `instrument run --replay LOG
    --fast --bvh` with no tempo source at all: the same motion, line for line."""
    from instrument.control.hub import ControlHub
    from instrument.output.outputs import RecorderOutput

    log, live, replayed = tmp_path / "synced.jsonl", tmp_path / "live.bvh", tmp_path / "replayed.bvh"
    hub = ControlHub([], record=log)
    recorder = RecorderOutput(str(live), model, FPS)
    synced_show(model, recorder, BeatLock(SteadyTempo(84.0)), 8.0, hub=hub)
    hub.close()
    result = subprocess.run([sys.executable, "-m", "instrument", "run", "--replay", str(log), "--fast", "--seconds", "8",
                             "--no-osc", "--quiet", "--bvh", str(replayed)], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr

    def motion(path):
        text = path.read_text()
        return text[text.index("MOTION"):].splitlines()

    assert motion(replayed) == motion(live)
    free = tmp_path / "free.bvh"  # the check can fail: the log without its tempo events walks otherwise
    (tmp_path / "untimed.jsonl").write_text("".join(line for line in log.read_text().splitlines(keepends=True)
                                                    if '"tempo"' not in line))
    subprocess.run([sys.executable, "-m", "instrument", "run", "--replay", str(tmp_path / "untimed.jsonl"), "--fast",
                    "--seconds", "8", "--no-osc", "--quiet", "--bvh", str(free)], check=True, timeout=600)
    assert motion(free) != motion(live)


def test_the_step_lengths_of_many_characters_are_each_ones_own(model):
    """The lock asks for the steps of every character whose foot landed in one call (a crowd's
    frame has tens of footfalls): the same numbers as asking one by one."""
    engine = Engine(model, 6)
    controls = default_controls(model, {"elderly": 0.7})
    engine.frame(0.0, controls, 1.0)  # each character its own style (spread 1) and step
    each = [step_seconds(engine, controls, k) for k in range(6)]
    assert np.array_equal(step_seconds(engine, controls, np.arange(6)), each)
    assert len(set(each)) > 1
