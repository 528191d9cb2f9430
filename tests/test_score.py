"""Scores: timed cues played by performance time, recorded as a log that replays byte for byte,
live input on top, waits for the performer's cue button, and one-line errors for bad files."""

import filecmp
import json
import subprocess
import sys

import numpy as np
import pytest

from bvh_independent import world_positions
from conftest import REPO, walk_only
from instrument.control.events import ControlEvent
from instrument.control.score import ScorePlayer, eased, load_demo, load_score
from instrument.errors import UserError
from instrument.control.state import ControlState
from instrument.motion.bvh import read_bvh
from oscrecv import Receiver, frame_count, free_port
from waiting import wait_until

RUN = [sys.executable, "-m", "instrument", "run"]


def state_of(model) -> ControlState:
    return ControlState(model.style_names, model.states)


def play(player: ScorePlayer, state: ControlState, seconds: float, fps: float = 30.0, press_at=(), hands=None) -> dict:
    """Frame by frame as the live loop does: the score's events applied to the state; returns
    each frame's time -> (elderly, speed). `hands` moves targets at given frames, as a performer."""
    seen = {}
    for k in range(int(seconds * fps)):
        now = k / fps
        if k in press_at:
            state.set("cue", 1.0)
        for target, value in (hands or {}).get(k, {}).items():
            state.set(target, value)
        for event in player.due(now):
            assert event.source == "score" and event.time == now
            assert state.set(event.control, event.value)
        seen[k] = (state.get("style/elderly"), state.speed)
    return seen


def write(tmp_path, text: str, name: str = "s.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_ramps_follow_their_curves_at_and_after_cues(model, tmp_path):
    path = write(tmp_path, """
[[cue]]
at = 1
ramp = { "style/elderly" = 1.0 }
over = 2

[[cue]]
after = 1                       # one second after the ramp above has finished: at 4 s
ramp = { "style/elderly" = 0.0, speed = 2.0 }
over = 1
curve = "ease"
""")
    state = state_of(model)
    seen = play(ScorePlayer(load_score(path, state), state), state, 6.0)
    assert seen[30] == (0.0, 1.0)
    assert seen[60][0] == pytest.approx(0.5)  # halfway through the linear ramp
    assert seen[90] == (1.0, 1.0) and seen[119] == (1.0, 1.0)
    assert seen[128][0] == pytest.approx(1.0 - eased(8 / 30, "ease")) and seen[128][0] > 1.0 - 8 / 30  # slow in
    assert eased(0.25, "ease") < 0.25 and eased(0.75, "ease") > 0.75 and eased(0.5, "ease") == 0.5
    assert seen[150] == (0.0, 2.0) and seen[179] == (0.0, 2.0)


def test_a_wait_stops_the_score_until_the_cue_button_and_a_repeat_plays_a_section_again(model, tmp_path):
    path = write(tmp_path, """
[presets.old]
"style/elderly" = 1.0
speed = 0.5

[[cue]]
wait = "cue"

[[cue]]
mark = "verse"
preset = "old"
over = 1

[[cue]]
ramp = { "style/elderly" = 0.0, speed = 1.0 }
over = 1

[[cue]]
repeat = "verse"
times = 1
""")
    state = state_of(model)
    player = ScorePlayer(load_score(path, state), state)
    state.set("cue", 1.0)  # a press before the score waits does not count
    seen = play(player, state, 8.0, press_at={60})
    assert all(seen[k] == (0.0, 1.0) for k in range(61))  # waiting for the performer
    assert seen[75][0] == pytest.approx(0.5) and seen[90] == (1.0, 0.5)  # the preset, over a second
    assert seen[120] == (0.0, 1.0)
    assert seen[135][0] == pytest.approx(0.5) and seen[150] == (1.0, 0.5)  # the section again, once
    assert seen[180] == (0.0, 1.0) and seen[239] == (0.0, 1.0)
    assert player.finished


def test_a_performer_takes_a_ramped_target_over_and_a_loop_starts_again(model, tmp_path):
    path = write(tmp_path, """
loop = true
[[cue]]
ramp = { "style/elderly" = 2.0, speed = 2.0 }
over = 2
[[cue]]
hold = 1
""")
    state = state_of(model)
    seen = play(ScorePlayer(load_score(path, state), state), state, 4.0, hands={30: {"style/elderly": -1.0}})
    assert seen[29][0] > 0.9 and seen[30][0] == -1.0 and seen[59][0] == -1.0  # the performer has it now
    assert seen[60] == (-1.0, 2.0)  # the score kept the other target
    assert seen[90][0] == -1.0 and seen[105][0] == pytest.approx(-1.0 + 3.0 * 15 / 60)  # the loop ramps it from there again


DEMO_SECONDS = 81  # one pass of the demo (examples/demo/demo.toml: its last ramp ends at 80 s, then a hold of 1)


def test_demo_score_plays_the_demo(model):
    state = state_of(model)
    player = ScorePlayer(load_score(REPO / "examples" / "demo" / "demo.toml", state, loop=True), state)
    seen = play(player, state, DEMO_SECONDS + 14.0)
    assert max(v[0] for v in seen.values()) == 1.0  # elderly up to 1 between 4 and 8 s
    assert seen[8 * 30][0] == 1.0 and seen[(DEMO_SECONDS + 3) * 30] == (0.0, 1.0)  # back to the average walk
    assert seen[(DEMO_SECONDS + 8) * 30][0] == 1.0  # and again from the top
    assert not player.finished


def play_demo(model, state: ControlState, seconds: float = DEMO_SECONDS) -> tuple[list[ControlEvent], np.ndarray]:
    """The demo for `model`, frame by frame into `state`: the events it handed out, and the
    style weights of each frame."""
    player, events, weights = ScorePlayer(load_demo(model, state), state), [], []
    for k in range(int(seconds * 30)):
        for event in player.due(k / 30):
            assert state.set(event.control, event.value)
            events.append(event)
        weights.append(state.weights.copy())
    return events, np.array(weights)


def test_the_demo_plays_in_any_models_styles(model):
    """The demo is written for the shipped model's styles; a model trained on one's own takes
    plays the same performance in its own: every style faded in and out, one exaggerated to 2 and
    one inverted to -1, as the shipped model's; the shipped model's demo is the file as written."""
    shipped = state_of(model)
    assert load_demo(model, shipped) == load_score(REPO / "examples" / "demo" / "demo.toml", shipped, loop=True)
    mine = ControlState(["proud", "sneaky", "tired"], model.states)
    _, seen = play_demo(model, mine)
    assert (seen.max(axis=0) >= 1.0).all() and seen.max() == 2.0 and seen.min() == -1.0
    assert (seen[-1] == 0.0).all()  # back to the average, so the loop joins
    alone = ControlState(["proud"], model.states)  # one style: faded in, exaggerated, inverted, back
    seen = play_demo(model, alone)[1][:, 0]
    assert max(seen) == 2.0 and min(seen) == -1.0 and seen[-1] == 0.0


def test_the_demo_shows_the_gaits_and_gestures_a_model_has_and_leaves_out_those_it_lacks(model):
    """On the shipped model the demo runs, stands, waves and raises its hands, and ends walking
    with its hands down, as it started; a model trained on walks sets no gait but the walk and no
    gesture, and the cues after the dropped ones keep their times."""
    def gaits_and_gestures(events):
        return [(e.control, e.value) for e in events if e.control == "gait" or e.control.startswith("gesture/")]

    shipped = state_of(model)
    events, _ = play_demo(model, shipped)
    done = gaits_and_gestures(events)
    assert ("gait", 2.0) in done and ("gait", 0.0) in done
    assert ("gesture/wave", 1.0) in done and ("gesture/raise", 1.0) in done
    assert (shipped.gait, shipped.gestures) == (1.0, {"wave": 0.0, "raise": 0.0})  # the loop joins
    walks = walk_only(model)
    state = state_of(walks)
    lean, _ = play_demo(walks, state)
    assert set(gaits_and_gestures(lean)) <= {("gait", 1.0)}
    assert [(e.time, e.control, e.value) for e in lean if e.control.startswith("style/")] == \
        [(e.time, e.control, e.value) for e in events if e.control.startswith("style/")]  # the same timing


def test_run_plays_the_demo_with_a_run_a_stand_and_gestures_and_a_walk_only_model_walks_it(model, tmp_path):
    """`instrument run` with no controller, recorded: the log holds the demo's gait changes and
    gestures, and the BVH shows them (the hips half as fast again a while after the run is set as
    before it at speed 1.4, still a while after the stand, the hands over the head while waving);
    a model trained on walks plays the same demo through without error or warning of a gait or gesture,
    its log never setting one it lacks."""
    from instrument.models.modelfile import save_model

    def demo_run(log: str, *extra: str):
        done = subprocess.run(RUN + ["--fast", "--seconds", str(DEMO_SECONDS), "--no-osc", "--record", log, *extra],
                              capture_output=True, text=True, cwd=tmp_path, timeout=600)
        assert done.returncode == 0 and "Traceback" not in done.stderr, done.stderr
        lines = [json.loads(line) for line in (tmp_path / log).read_text().splitlines()[1:-1]]
        return done, [(e["t"], e["control"], e["value"]) for e in lines]

    _, events = demo_run("shipped.jsonl", "--bvh", "demo.bvh")
    when = {(control, value): t for t, control, value in reversed(events)}  # the first time each was set
    run, walk = when[("gait", 2.0)], min(t for t, c, v in events if (c, v) == ("gait", 1.0) and t > when[("gait", 2.0)])
    stand, wave = when[("gait", 0.0)], when[("gesture/wave", 1.0)]
    assert run < walk < stand < wave < when[("gesture/raise", 1.0)]
    names, positions, fps = world_positions(tmp_path / "demo.bvh")
    hips = positions[:, names.index("Hips")][:, [0, 2]]
    speed = np.r_[0.0, np.linalg.norm(np.diff(hips, axis=0), axis=1) * fps]  # cm/s over the floor, each frame

    def frames(start: float, end: float) -> slice:
        return slice(int(start * fps), int(end * fps))

    assert speed[frames(run + 2, walk)].mean() > 1.5 * speed[frames(run - 4, run)].mean()  # measured 296 and 166
    assert speed[frames(stand + 2, wave)].max() < 10.0  # standing (measured 0)
    hands = positions[:, [names.index("Hand_L"), names.index("Hand_R")], 1].min(axis=1)
    assert (hands > positions[:, names.index("Head"), 1])[frames(wave, wave + 4)].any()  # both over the head

    save_model(tmp_path / "walks.npz", walk_only(model))
    done, events = demo_run("walks.jsonl", "--model", "walks.npz")
    assert not any(c == "gait" and v != 1.0 or c.startswith("gesture/") for _, c, v in events), events
    assert "gait" not in done.stderr and "gesture" not in done.stderr, done.stderr
    assert any(c == "style/elderly" for _, c, _ in events)  # the rest of the demo plays


def test_score_and_its_recorded_log_give_the_same_bvh_byte_for_byte(tmp_path):
    score = write(tmp_path, """
[presets.tired]
"style/exhausted" = 1.0
speed = 0.7

[[cue]]
at = 0.5
ramp = { "style/elderly" = 1.5, turn = 0.4 }
over = 1.2
curve = "ease"

[[cue]]
preset = "tired"
over = 0.7

[[cue]]
hold = 0.5

[[cue]]
ramp = { "style/elderly" = -0.5, "part/feminine/upper" = 1.0 }
over = 0.9
""")
    log, by_score, by_log, live = tmp_path / "take.jsonl", tmp_path / "score.bvh", tmp_path / "log.bvh", tmp_path / "live.bvh"
    common = ["--no-osc", "--quiet", "--seconds", "4"]
    first = subprocess.run(RUN + ["--score", str(score), "--fast", "--record", str(log), "--bvh", str(by_score)] + common,
                           capture_output=True, text=True, timeout=120)
    assert first.returncode == 0, first.stderr
    second = subprocess.run(RUN + ["--replay", str(log), "--fast", "--bvh", str(by_log)] + common, capture_output=True, text=True,
                            timeout=120)
    assert second.returncode == 0, second.stderr
    third = subprocess.run(RUN + ["--score", str(score), "--bvh", str(live)] + common, capture_output=True, text=True, timeout=120)
    assert third.returncode == 0, third.stderr
    header, *lines, end = log.read_text().splitlines()
    assert "instrument_log" in header  # what a replay needs comes first (control.loghead)
    assert len(lines) > 60 and all('"source": "score"' in line for line in lines)
    assert end == '{"end": 4.0}'  # and where the run stopped, last
    assert filecmp.cmp(by_score, by_log, shallow=False)
    assert filecmp.cmp(by_score, live, shallow=False)  # realtime plays the same frames
    assert read_bvh(by_score).frames == 120


def test_a_score_sets_the_gait_by_name_and_its_recorded_log_replays_it(model, tmp_path):
    """Cues that run, stand and walk (by name and by number): `run --fast --bvh --record` records
    them as numbers at their cues' frames, and the log replays the same gait frame by frame."""
    from instrument.control.events import LogReplay, read_log
    from instrument.control.hub import ControlHub

    score = write(tmp_path, '[[cue]]\nat = 0.5\nramp = { gait = "run" }\n\n[[cue]]\nafter = 1\nramp = { gait = "stand" }\n\n'
                            '[[cue]]\nafter = 1\nramp = { gait = 1 }\n')
    log, out = tmp_path / "take.jsonl", tmp_path / "walk.bvh"
    result = subprocess.run(RUN + ["--score", str(score), "--fast", "--no-osc", "--quiet", "--seconds", "4", "--record", str(log),
                                   "--bvh", str(out)], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert read_bvh(out).frames == 120
    *recorded, end = [json.loads(line) for line in log.read_text().splitlines()[1:]]
    assert end == {"end": 4.0}  # the last line: where the run stopped
    assert [(e["control"], e["value"]) for e in recorded] == [("gait", 2.0), ("gait", 0.0), ("gait", 1.0)]
    assert [e["t"] for e in recorded] == pytest.approx([0.5, 1.5, 2.5])

    def gaits(make) -> list[float]:  # the state's gait each frame, the source's events applied as the live loop does
        state, hub, seen = state_of(model), ControlHub([]), []
        source = make(state)
        for k in range(120):
            for event in source.due(k / 30):
                assert hub.apply(state, event)
            seen.append(state.gait)
        return seen

    by_score = gaits(lambda state: ScorePlayer(load_score(score, state), state))
    assert gaits(lambda state: LogReplay(read_log(log))) == by_score
    assert by_score[14] == 1.0 and by_score[15] == 2.0 and by_score[45] == 0.0 and by_score[75] == 1.0


def test_a_score_played_once_ends_a_fast_render(tmp_path):
    score = write(tmp_path, '[[cue]]\nat = 1\nramp = { speed = 1.5 }\nover = 1\n')
    out = tmp_path / "walk.bvh"
    result = subprocess.run(RUN + ["--score", str(score), "--fast", "--no-osc", "--quiet", "--bvh", str(out)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert 60 <= read_bvh(out).frames <= 62  # the score's two seconds


def messages_per_frame(receiver: Receiver, address: str) -> list[float]:
    out, value = [], None
    for a, params in receiver.messages():
        if a == address:
            value = params[0]
        elif a == "/walk/frame":
            out.append(value)
    return out


def test_live_osc_rides_on_top_and_the_cue_button_releases_a_wait(tmp_path):
    """Real UDP both ways: the score waits for /walk/cue from a surface, while the surface moves
    a target of its own that the score does not touch. The take, recorded, replays byte for byte."""
    from pythonosc.udp_client import SimpleUDPClient

    score = write(tmp_path, '[[cue]]\nwait = "cue"\n[[cue]]\nramp = { "style/elderly" = 1.0 }\nover = 0.5\n'
                            '[[cue]]\nhold = 600\n')
    log, live, replayed = tmp_path / "take.jsonl", tmp_path / "live.bvh", tmp_path / "replayed.bvh"
    control_port, receiver = free_port(), Receiver()
    process = subprocess.Popen(RUN + ["--score", str(score), "--osc-in", str(control_port), "--osc",
                                      f"127.0.0.1:{receiver.port}/flat", "--seconds", "12", "--quiet",
                                      "--record", str(log), "--bvh", str(live)],
                               stderr=subprocess.PIPE, text=True)
    surface = SimpleUDPClient("127.0.0.1", control_port)
    try:
        wait_until(lambda: frame_count(receiver) >= 15, "15 frames")
        surface.send_message("/walk/speed", 1.6)
        wait_until(lambda: 1.6 in [round(v, 3) for v in messages_per_frame(receiver, "/walk/speed")], "the surface's speed")
        moved = frame_count(receiver)
        wait_until(lambda: frame_count(receiver) >= moved + 30, "30 more frames")
        assert set(messages_per_frame(receiver, "/walk/style/elderly")) == {0.0}  # still waiting for the cue
        surface.send_message("/walk/cue", 1.0)
        wait_until(lambda: 1.0 in messages_per_frame(receiver, "/walk/style/elderly"), "the ramp's end")
        stderr = process.communicate(timeout=120)[1]  # the run ends on its own after 12 s
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
        receiver.close()
    assert process.returncode == 0, stderr
    elderly = messages_per_frame(receiver, "/walk/style/elderly")
    assert elderly[-1] == 1.0 and len(set(elderly)) > 5  # ramped, not jumped
    assert messages_per_frame(receiver, "/walk/speed")[-1] == pytest.approx(1.6)  # the surface's value stayed
    sources = {json.loads(line)["source"] for line in log.read_text().splitlines()[1:-1]}  # the last line: where the run stopped
    assert sources == {"score", "osc"}  # the score's ramp and the surface's speed and cue
    replay = subprocess.run(RUN + ["--replay", str(log), "--fast", "--no-osc", "--quiet", "--seconds", "12", "--bvh", str(replayed)],
                            capture_output=True, text=True, timeout=120)
    assert replay.returncode == 0, replay.stderr
    assert read_bvh(live).frames == 360 and filecmp.cmp(live, replayed, shallow=False)


@pytest.mark.parametrize("text,message", [
    ('[[cue]]\nat = 1\nramp = { "style/sleepy" = 1 }\n', "s.toml:3: ramp: style/sleepy: unknown target (this model's styles: "),
    ('[[cue]]\nramp = { speed = 1 }\n\n[[cue]]\nhold = 1\nover = 2\n', "s.toml:6: over: only for a ramp or a preset"),
    ('[[cue]]\nramp = { speed = 9 }\n', "s.toml:2: ramp: speed: 9 is out of range (0.25 to 4)"),
    ('[[cue]]\npreset = "nowhere"\n', "s.toml:2: preset: no preset 'nowhere'"),
    ('[[cue]]\nhold = 1\n[[cue]]\nrepeat = "x"\n', "s.toml:4: repeat: no earlier cue has mark = 'x'"),
    ('[[cue]]\nhold = 1\nwait = "cue"\n', "s.toml:3: wait: a cue does one thing"),
    ('[[cue]]\nat = 2\nhold = 1\n[[cue]]\nat = 1\nhold = 1\n', "s.toml:5: at: 1 is before the previous cue's at = 2"),
    ('[[cue]]\nramp = { speed = 1 }\ncurve = "bouncy"\n', "s.toml:3: curve: 'bouncy' is not one of linear, ease"),
    ('tempo = 120\n[[cue]]\nhold = 1\n', "s.toml:1: tempo: unknown key"),
    ('loop = true\n[[cue]]\nramp = { speed = 1 }\n', "s.toml:1: loop: a looping score must take some time"),
    ('[[cue]]\nwait = "applause"\n', "s.toml:2: wait: the only thing to wait for is \"cue\""),
    ('[[cue]]\nhold = -1\n', "s.toml:2: hold: expected a number of seconds"),
    ('name = 3\n[[cue]]\nhold = 1\n', "s.toml:1: name: expected a string"),
    ('[[cue\n', "s.toml:1: "),  # not TOML: the line tomllib names
    ('name = "x"\n\n[cue]\nat = 0\nhold = 1\n', "s.toml:3: cue: write each cue as [[cue]] (a table of its own), not [cue]"),
])
def test_bad_scores_are_one_line_errors_with_file_line_and_key(tmp_path, text, message):
    path = write(tmp_path, text)
    result = subprocess.run(RUN + ["--score", str(path), "--no-osc", "--seconds", "1"], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("text, line, why", [
    ('[[cue]]\nramp = { speed = 1.2 }\n[[cue]]\nwait = "cue"\n', 3, "waits for a cue that no controller is there to press"),
    ('[[cue]]\nmark = "a"\nramp = { speed = 1.2 }\nover = 1\n[[cue]]\nrepeat = "a"\n', 5, "repeats a section for ever"),
])
def test_an_offline_render_of_a_score_that_never_ends_is_refused(tmp_path, text, line, why):
    """`--fast` renders a score until its last cue has finished: one that waits for a cue with no
    controller to press it, or repeats for ever, rendered for ever (a --bvh grew 1 GB an hour)."""
    path, out = write(tmp_path, text), tmp_path / "piece.bvh"
    result = subprocess.run(RUN + ["--score", str(path), "--fast", "--no-osc", "--quiet", "--bvh", str(out)],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 1 and not out.exists()
    assert result.stderr.strip() == f"instrument run: error: --fast needs an end: {path}:{line}: the score {why}" + \
        (" (give the repeat times)" if "repeat" in why else "") + "; give --seconds"


def test_a_show_file_plays_a_score(tmp_path):
    write(tmp_path, '[[cue]]\nramp = { "style/elderly" = 0.5 }\nover = 0.5\n', "cues.toml")
    show = write(tmp_path, 'seconds = 2\nno-osc = true\nquiet = true\nscore = "cues.toml"\nrecord = "take.jsonl"\n', "show.toml")
    result = subprocess.run(RUN + ["--config", str(show)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    *_, last, end = (tmp_path / "take.jsonl").read_text().splitlines()
    assert ControlEvent(0.5, "score", "style/elderly", 0.5).to_json() == last
    assert end == '{"end": 2.0}'  # where the run stopped: the show file's seconds


def test_a_boolean_where_a_number_belongs_is_quoted_as_the_file_spells_it(model, tmp_path):
    """A score's `true` where a number belongs is told back as `true` (TOML's), not Python's `True`."""
    from instrument.errors import UserError

    path = tmp_path / "bad.toml"
    path.write_text('[[cue]]\nat = 1\nramp = { "style/elderly" = true }\n')
    with pytest.raises(UserError) as error:
        load_score(path, state_of(model))
    assert str(error.value).endswith("not a finite number, not true"), str(error.value)
