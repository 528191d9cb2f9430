"""Crowds (`run --characters N`): real UDP on 127.0.0.1, real processes, real files."""

import filecmp
import json
import socket
import subprocess
import sys

import numpy as np
import pytest

from instrument.control.options import MAX_CHARACTERS
from instrument.control.state import ControlState
from instrument.motion.bvh import read_bvh
from instrument.motion.kinematics import local_transforms
from instrument.synthesis.engine import Engine, metres_to_units
from instrument.synthesis.posing import quaternions
from oscrecv import Receiver, frame_count
from waiting import wait_until

RUN = [sys.executable, "-m", "instrument", "run"]


def by_frame(messages: list[tuple[str, list]]) -> list[dict[str, list]]:
    """The flat stream cut into frames at /walk/frame (sent last in each)."""
    frames, current = [], {}
    for address, params in messages:
        current[address] = params
        if address == "/walk/frame":
            frames.append(current)
            current = {}
    return frames


def test_every_character_reaches_a_flat_receiver_and_the_bvh_is_the_chosen_one(model, tmp_path):
    receiver = Receiver()
    bvh = tmp_path / "two.bvh"
    try:
        result = subprocess.run(RUN + ["--characters", "3", "--spacing", "2", "--seconds", "1", "--bvh", str(bvh),
                                       "--bvh-character", "2", "--osc", f"127.0.0.1:{receiver.port}/flat", "--quiet"],
                                capture_output=True, text=True, timeout=120)
        wait_until(lambda: frame_count(receiver) >= 30 or result.returncode, "30 frames")
    finally:
        receiver.close()
    assert result.returncode == 0, result.stderr
    frames = by_frame(receiver.messages())
    assert [f["/walk/frame"][0] for f in frames] == list(range(30))
    joints = model.layout.skeleton.names
    single = {f"/walk/bone/{j}/{kind}" for j in joints for kind in ("quat", "pos")}
    single |= {f"/walk/root/{k}" for k in ("pos", "quat", "local")}
    for frame in frames:
        addresses = set(frame)
        assert single <= addresses  # character 0 at today's addresses
        for k in (1, 2):
            assert {a.replace("/walk/", f"/walk/character/{k}/", 1) for a in single} <= addresses
        assert not any(a.startswith(("/walk/character/0/", "/walk/character/3/")) for a in addresses)
        assert "/walk/spread" in addresses and "/walk/speed" in addresses  # the echo, once
    # placed apart: 2 m (200 cm) from character 0 on the floor, at the start
    start = frames[0]
    for k in (1, 2):
        apart = np.subtract(start[f"/walk/character/{k}/root/pos"], start["/walk/root/pos"])[[0, 2]]
        assert abs(np.linalg.norm(apart) - 2 * metres_to_units(model.layout)) < 30
    # the BVH holds character 2: its rotations are the ones sent for character 2, not character 0's
    motion = read_bvh(bvh)
    assert motion.frames == 30
    rotations, translations = local_transforms(motion)
    recorded = quaternions(rotations)
    sent = {k: np.array([[f[f"{head}/bone/{j}/quat"] for j in joints] for f in frames])
            for k, head in ((0, "/walk"), (2, "/walk/character/2"))}
    assert np.abs(recorded - sent[2]).max() < 1e-3
    assert np.abs(recorded - sent[0]).max() > 0.05
    root = model.layout.root
    local = np.array([f["/walk/character/2/root/local"] for f in frames])
    assert np.abs(translations[:, root] - local).max() < 1e-2


def free_ports(count: int) -> int:
    """The first of `count` consecutive free UDP ports on 127.0.0.1."""
    for _ in range(100):
        first = np.random.default_rng().integers(20000, 60000)
        socks = []
        try:
            for k in range(count):
                s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                socks.append(s)
                s.bind(("127.0.0.1", int(first) + k))
            return int(first)
        except OSError:
            continue
        finally:
            for s in socks:
                s.close()
    raise AssertionError("no free consecutive ports")


def test_vmc_sends_character_k_on_port_p_plus_k():
    first = free_ports(4)
    receivers = [Receiver(first + k) for k in range(4)]  # the fourth port gets nothing: --vmc-characters 3
    try:
        result = subprocess.run(RUN + ["--characters", "5", "--vmc-characters", "3", "--seconds", "1", "--osc",
                                       f"127.0.0.1:{first}/vmc", "--quiet"], capture_output=True, text=True, timeout=120)
        wait_until(lambda: all(sum(d.count(b"/VMC/Ext/T\x00") for d in list(r.datagrams)) >= 30 for r in receivers[:3])
                   or result.returncode, "30 VMC frames on each port")
    finally:
        for receiver in receivers:
            receiver.close()
    assert result.returncode == 0, result.stderr
    assert not receivers[3].datagrams
    hips = []
    for receiver in receivers[:3]:
        messages = receiver.messages()
        assert sum(a == "/VMC/Ext/T" for a, _ in messages) == 30
        hips.append(np.array([p[1:4] for a, p in messages if a == "/VMC/Ext/Bone/Pos" and p[0] == "Hips"]))
    for k in (1, 2):  # each port its own character: in the first row of three, 1.5 m apart at the start (metres in VMC)
        assert abs(np.linalg.norm((hips[k][0] - hips[0][0])[[0, 2]]) - 1.5 * k) < 0.3


def walk_means(model, spread: float, frames: int = 150) -> np.ndarray:
    """(N, D) each character's static features averaged over its last four strides."""
    engine = Engine(model, characters=4)
    state = ControlState(model.style_names, model.states)
    state.set("spread", spread)
    state.set("style/elderly", 0.5)
    made = np.array([engine.sample(i / model.fps, state.snapshot(), state.spread) for i in range(frames)])
    return made[-128:].mean(axis=0)


def test_spread_gives_each_character_its_own_style_and_none_alike_at_zero(model):
    alike, spread = walk_means(model, 0.0), walk_means(model, 1.0)
    joints = slice(4, None)  # the joint rotations (the root's rates follow the cadence)

    def apart(means):
        return max(np.abs(means[k, joints] - means[0, joints]).max() for k in range(1, len(means)))

    assert apart(spread) > 5 * apart(alike)
    assert apart(spread) > 0.05  # radians: a visible difference in some joint's average pose
    engine = Engine(model, characters=4)
    state = ControlState(model.style_names, model.states)
    engine.retune(state.snapshot(), 0.0)
    assert all(np.array_equal(w, engine.mix.weights[0]) for w in engine.mix.weights)
    state.set("spread", 1.0)
    engine.retune(state.snapshot(), state.spread)
    assert np.array_equal(engine.mix.weights[0], state.weights)  # character 0 is the performance itself
    state.set("style/elderly", 1.0)
    engine.retune(state.snapshot(), state.spread)
    mixes = [tuple(w) for w in engine.mix.weights[1:]]  # around the performed weights, each its own, none adding weight
    assert len(set(mixes)) == 3
    assert all(abs(sum(m) - 1) < 1e-9 and np.abs(np.subtract(m, state.weights)).max() > 0.2 for m in mixes)


def test_spread_is_a_control_target_like_the_others():
    state = ControlState(["elderly"], 5)
    assert "spread" in state.targets() and state.knows("spread")
    assert not state.set("spread", 3.0) and state.spread == 0.0  # out of its range: refused (control/checks.py)
    assert state.set("spread", 1.0) and state.spread == 1.0
    assert not state.set("spread", float("nan"))
    assert state.echo()["spread"] == 1.0
    state.set("reset", 1.0)
    assert state.spread == 0.0


def test_a_recorded_crowd_replays_byte_for_byte(tmp_path):
    score = tmp_path / "spread.toml"
    score.write_text('[[cue]]\nat = 0.2\nramp = { spread = 1.0, "style/elderly" = 1.0 }\nover = 1.5\n'
                     '[[cue]]\nafter = 0.2\nramp = { liveliness = 1.0, speed = 1.4 }\nover = 0.5\n')
    log, first, second = tmp_path / "crowd.jsonl", tmp_path / "first.bvh", tmp_path / "second.bvh"
    common = ["--bvh-character", "3", "--no-osc", "--quiet", "--fast", "--seconds", "3"]
    result = subprocess.run(RUN + ["--characters", "4", "--spacing", "2.5"] + common
                            + ["--score", str(score), "--record", str(log), "--bvh", str(first)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert '"spread"' in log.read_text()
    assert json.loads(log.read_text().splitlines()[0])["crowd"] == {"characters": 4, "spacing": 2.5}
    # the log's header says which crowd it played: no --characters or --spacing needed
    result = subprocess.run(RUN + common + ["--replay", str(log), "--bvh", str(second)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 0, result.stderr
    assert filecmp.cmp(first, second, shallow=False)
    assert read_bvh(first).frames == 90
    # an option given on the command line wins over the header's (and walks another crowd)
    other = tmp_path / "other.bvh"
    result = subprocess.run(RUN + common + ["--spacing", "1.5", "--replay", str(log), "--bvh", str(other)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert not filecmp.cmp(first, other, shallow=False)  # spacing 1.5, not 2.5: character 3 stands elsewhere


def test_a_log_with_a_bad_crowd_is_one_line(tmp_path):
    log = tmp_path / "bad.jsonl"
    log.write_text(json.dumps({"instrument_log": 1, "mappings": [], "crowd": {"characters": 0, "spacing": 1.0}}) + "\n")
    result = subprocess.run(RUN + ["--replay", str(log), "--no-osc", "--fast"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert f"{log}:1: header crowd characters: expected a whole number from 1" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


@pytest.mark.parametrize("args, message", [
    (["--characters", "0"], "--characters: expected a whole number from 1 to"),
    (["--characters", "2.5"], "--characters: expected a whole number"),
    (["--characters", str(MAX_CHARACTERS + 1)], "--characters: expected"),
    (["--spacing", "0"], "--spacing: expected a number above 0"),
    (["--spacing", "nan"], "--spacing: expected"),
    (["--characters", "3", "--bvh-character", "3"], "--bvh-character: expected a character of the crowd, 0 to 2, not 3"),
    (["--bvh-character", "1"], "--bvh-character: expected a character of the crowd, 0 to 0, not 1"),
    (["--characters", "10", "--osc", "127.0.0.1:65530/vmc"], "10 characters need VMC ports 65530 to 65539, past 65535"),
    (["--characters", "30", "--osc", "127.0.0.1:65530/vmc"], "16 characters need VMC ports 65530 to 65545, past 65535"),
    (["--vmc-characters", "0"], "--vmc-characters: expected a whole number from 1 to"),
])
def test_bad_crowd_options_are_one_line(args, message):
    result = subprocess.run(RUN + args + ["--seconds", "1", "--no-osc"] * ("--osc" not in args), capture_output=True,
                            text=True, timeout=60)
    assert result.returncode == 1
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_a_show_file_takes_a_crowd_and_names_its_bad_line(tmp_path):
    show = tmp_path / "show.toml"
    show.write_text('seconds = 1\nno-osc = true\nquiet = true\nfast = true\ncharacters = 0\n')
    result = subprocess.run(RUN + ["--config", str(show)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert f"{show}:5: characters: expected a whole number from 1 to {MAX_CHARACTERS}, not '0'" in result.stderr
    show.write_text('seconds = 1\nno-osc = true\nquiet = true\nfast = true\ncharacters = 3\nbvh-character = 2\nbvh = "c.bvh"\n')
    result = subprocess.run(RUN + ["--config", str(show)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert read_bvh(tmp_path / "c.bvh").frames == 30


@pytest.mark.parametrize("stand_frames", [8, 17, 23])
def test_character_0_of_a_crowd_stops_and_sets_off_exactly_as_a_run_of_one(model, stand_frames):
    """The same promise through gait changes: the lead's stop (called off after `stand_frames`,
    before it has stood, or after) and its start, while the others brake and set off at their own
    steps. A feature at stride 1 was drawn towards the stand by a factor 1 whenever another body
    braked (not the same bits), and a stop called off summed a body's travel grouped by the
    crowd's longest stance."""
    single, crowd = Engine(model), Engine(model, characters=3)
    state = ControlState(model.style_names, model.states)
    state.set("spread", 1.0)
    state.set("style/active", 1.0)
    changes = {40: "stand", 40 + stand_frames: "walk", 140: "stand", 200: "walk"}
    for i in range(260):
        if i in changes:
            assert state.set("gait", changes[i])
        controls = state.snapshot()
        alone = single.frame(i / model.fps, controls, state.spread)
        lead = crowd.frame(i / model.fps, controls, state.spread)
        assert np.array_equal(alone.rotations[0], lead.rotations[0]), i
        assert np.array_equal(alone.world_positions[0], lead.world_positions[0]), i


def test_character_0_of_a_crowd_walks_exactly_as_a_run_of_one(model):
    """docs/crowds.md's promise: the lead does not change when a crowd grows around it (same
    frames, same planted feet, bit for bit), through a style jump out of the data."""
    single, crowd = Engine(model), Engine(model, characters=3)
    state = ControlState(model.style_names, model.states)
    state.set("spread", 1.0)
    state.set("liveliness", 0.5)
    moved = 0.0
    for i in range(90):
        if i == 45:
            state.set("style/feminine", 2.0)
        controls = state.snapshot()
        alone = single.frame(i / model.fps, controls, state.spread)
        lead = crowd.frame(i / model.fps, controls, state.spread)
        assert np.array_equal(alone.rotations[0], lead.rotations[0]), i
        assert np.array_equal(alone.world_positions[0], lead.world_positions[0]), i
        moved = max(moved, np.abs(lead.world_positions[1] - lead.world_positions[0]).max())
    assert moved > 0.0  # the others are elsewhere (and walk otherwise)


def test_a_crowds_range_stage_over_the_cores_makes_the_numbers_of_its_stage_made_whole(model, monkeypatch):
    """A crowd's range stage runs part by part (`RangeTargets.filtered`, each part's targets and
    filter in one call on a core of its own): the same frames, bit for bit, as the targets made
    for the whole crowd and then filtered, through a style jump and spread. Every frame's stage is
    seen cut in two parts that cover the crowd (the kernel's calls, counted where the engine hands
    them to the cores), so a stage run whole would fail here."""
    from instrument.synthesis import cores, engine

    monkeypatch.setattr(cores, "_cores", lambda: 2)  # two parts, whatever this machine has
    count = 2 * cores.LEAST_PER_PART
    parted, whole = Engine(model, characters=count), Engine(model, characters=count)
    targets = whole.range_targets
    targets.filtered = lambda frames, units, scale: scale(frames, *targets.targets(units))
    calls = []  # each range stage handed to the cores: the characters of each of its parts
    handed = engine.over_cores

    def watched(kernel, arguments):
        if kernel is engine.range_part:
            calls.append([len(part[0]) for part in arguments])  # a part's first argument: its characters' units
        handed(kernel, arguments)

    monkeypatch.setattr(engine, "over_cores", watched)
    state = ControlState(model.style_names, model.states)
    state.set("spread", 1.0)
    for i in range(40):
        if i == 20:
            state.set("style/feminine", 0.8)
        controls = state.snapshot()
        ours, theirs = (e.frame(i / model.fps, controls, state.spread) for e in (parted, whole))
        assert np.array_equal(ours.rotations, theirs.rotations), i
        assert np.array_equal(ours.world_positions, theirs.world_positions), i
    half = count // 2
    assert calls == [[half, count - half]] * 40  # every frame's range stage went in two parts, the whole crowd


def test_an_osc_surface_moves_the_spread_and_sees_it_echoed(tmp_path):
    from pythonosc.udp_client import SimpleUDPClient

    from oscrecv import free_port

    control_port, receiver = free_port(), Receiver()
    log = tmp_path / "surface.jsonl"
    process = subprocess.Popen(RUN + ["--characters", "3", "--osc-in", str(control_port), "--record", str(log),
                                      "--osc", f"127.0.0.1:{receiver.port}/flat", "--quiet"], stderr=subprocess.PIPE, text=True)

    def spread_echoed() -> bool:
        return any(a == "/walk/spread" and p[0] == pytest.approx(0.75) for a, p in receiver.messages()[-400:])

    try:
        wait_until(lambda: frame_count(receiver) >= 10, "10 frames")
        SimpleUDPClient("127.0.0.1", control_port).send_message("/walk/spread", 0.75)
        wait_until(spread_echoed, "spread 0.75 echoed")
    finally:
        process.terminate()
        stderr = process.communicate(timeout=60)[1]
        receiver.close()
    assert process.returncode == 0, stderr
    assert '"control": "spread", "value": 0.75' in log.read_text()


def test_the_largest_crowd_search_tries_a_failed_size_again(monkeypatch):
    """The bench's search for the largest crowd keeping time: a size fails when two trials in a
    row fail, so one trial lost to another program's burst does not end the search low. The
    machine is simulated (3 s realtime trials cannot be made to fail on purpose): crowds up to
    600 keep time, except that the first trial of every size fails."""
    from instrument.cli import crowd_bench
    from instrument.runtime import priority

    trials: dict[int, int] = {}

    def keeps_time(model, count):
        trials[count] = trials.get(count, 0) + 1
        held = count <= 600 and trials[count] > 1
        return held, (0.01 if held else 30.0), (0 if held else 9)

    monkeypatch.setattr(crowd_bench, "keeps_time", keeps_time)
    monkeypatch.setattr(priority, "realtime_scheduling", lambda: None)  # the test process stays as it is
    found = crowd_bench.largest_crowd(None, 50.0)
    assert found["largest_crowd_first_failing"] > 600 >= found["largest_crowd_30fps"] > 540
    assert all(trials[count] == 2 for count in trials)  # each size failed once, then decided by its second trial
    low = str(found["largest_crowd_30fps"])
    assert found["largest_crowd_tried"][low] == [0.01, 0, 2]


def test_a_change_of_some_characters_speeds_retunes_only_them_to_the_same_frames(model, monkeypatch):
    """The beat lock sets a character's speed at its footfalls: the engine then makes only those
    characters' durations and stride means again (engine._changed_speeds), and the crowd walks
    exactly as when every character's are made again."""
    import instrument.synthesis.engine as engine_module
    from instrument.synthesis.stream import Controls

    def walk(partial: bool) -> list[np.ndarray]:
        if not partial:
            monkeypatch.setattr(engine_module, "_changed_speeds", lambda before, now, count: None)
        crowd, rng = Engine(model, characters=40), np.random.default_rng(3)
        weights = np.zeros(len(model.style_names))
        weights[1] = 0.8
        speeds, frames = np.ones(40), []
        for i in range(60):
            speeds = speeds.copy()
            speeds[rng.integers(0, 40, 3)] = rng.uniform(0.6, 1.6, 3)  # three footfalls a frame
            pose = crowd.frame(i / model.fps, Controls(weights, speed=speeds, liveliness=0.3), 0.7)
            frames.append(pose.world_positions.copy())
        monkeypatch.undo()
        return frames

    partial, whole = walk(True), walk(False)
    assert all(np.array_equal(a, b) for a, b in zip(partial, whole))
    assert not np.array_equal(partial[-1][0], partial[-1][1])  # they walk (and otherwise)


def test_the_locked_speeds_array_follows_the_states_speeds_as_they_are_set_and_cleared():
    from instrument.control.state import LockSpeeds
    from instrument.runtime.tempo import locked_speed

    kept, plain = LockSpeeds(), {}
    rng = np.random.default_rng(0)
    for frame in range(50):
        if frame == 30:
            kept.clear()
            plain.clear()
        for k in rng.integers(0, 12, 2):
            speed = float(rng.uniform(0.5, 2.0))
            kept[int(k)], plain[int(k)] = speed, speed
        performed = float(rng.uniform(0.5, 2.0))
        assert np.array_equal(locked_speed(kept, performed, 12), locked_speed(plain, performed, 12)), frame
    assert not kept.changed  # read: nothing waits to be brought up to date


def test_a_crowd_past_the_variance_limit_walks_as_with_its_tables_made_whole(model):
    """Past the styles (elderly x4) with a wide spread, the characters' own offsets carry some
    variances to their limit (the performed weights' alone stay within the styles' span), so a
    character's precisions are not two factors: the stream makes each row it reads from the
    character's log offset (CrowdLambda's clip_*), where every character's whole tables were made
    at each change (20 ms a frame for 32 characters while a fader moved). The walk is the one the
    whole tables make."""
    from instrument.synthesis.engine import default_controls
    from instrument.synthesis.interpolation import CrowdLambda

    controls = default_controls(model, {"elderly": 4.0, "youthful": -1.0})
    made, whole = Engine(model, 6), Engine(model, 6)
    interpolation = whole.features[0]
    retune = interpolation.retune

    def made_whole(mix, stream):  # the same tables, every character's put together by numpy
        retune(mix, stream)
        tables = stream.tables
        shape = tables.mean_shared.shape
        stream.tables = CrowdLambda(tables.means, np.zeros(shape), tables.precisions, np.ones(shape),
                                    np.zeros(len(tables.plain), dtype=bool))

    interpolation.retune = made_whole
    for _ in range(90):
        assert np.allclose(made.next_features(controls, 1.5), whole.next_features(controls, 1.5), rtol=1e-9, atol=1e-9)
    tables = made.stream.tables
    assert tables.limit > 0 and tables.plain.tolist() == [True] + [False] * 5  # character 0 has no offset of its own
