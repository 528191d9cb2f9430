"""Controllers end to end: real MIDI through JACK, a simulated DualShock 4, OSC surfaces, show files."""

import filecmp
import json
import subprocess
import sys
import time

import mido
import pytest

from conftest import REPO
from hid_descriptors import DUALSHOCK4_USB
from hid_sim import SimulatedDevice, SimulatedHid, ds4_report
from instrument.control.hid import HidInput
from instrument.control.hub import ControlHub
from instrument.control.mapping import load_mapping
from instrument.control.state import ControlState
from instrument.models.modelfile import default_model_path, load_model
from instrument.terminal import Console
from instrument.runtime.performance import Show, perform
from oscrecv import Receiver, frame_count, free_port
from waiting import StderrLines, wait_until

RUN = [sys.executable, "-m", "instrument", "run"]
NANO = str(REPO / "mappings" / "korg-nanokontrol2.toml")


def frames_and_echo(receiver: Receiver, address: str) -> list[tuple[int, float]]:
    """(frame index, echoed value) per frame, from the flat profile."""
    out, value = [], None
    for a, params in receiver.messages():
        if a == address:
            value = params[0]
        elif a == "/walk/frame":
            out.append((params[0], value))
    return out


def last_frame(receiver: Receiver) -> int:
    frames = [p[0] for a, p in receiver.messages() if a == "/walk/frame"]
    return frames[-1] if frames else -1


def wait_for_port(backend, name: str, timeout: float = 20.0) -> str:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        names = [n for n in backend.get_output_names() if name in n]
        if names:
            return names[0]
        time.sleep(0.1)
    raise AssertionError(f"port {name} never appeared")


def test_nanokontrol2_faders_over_jack_with_pickup_and_exact_replay(jack, tmp_path):
    receiver = Receiver()
    log, live_bvh, replay_bvh = tmp_path / "take.jsonl", tmp_path / "live.bvh", tmp_path / "replay.bvh"
    process = subprocess.Popen(RUN + ["--midi-virtual", "instr-nano", "--midi-api", "jack", "--mapping", NANO,
                                      "--osc", f"127.0.0.1:{receiver.port}/flat", "--seconds", "12", "--quiet",
                                      "--record", str(log), "--bvh", str(live_bvh)], stderr=subprocess.PIPE, text=True)
    try:
        out = jack.open_output(wait_for_port(jack, "instr-nano"))
        wait_until(lambda: last_frame(receiver) >= 15, "15 frames")

        def cc(value, number=1):
            out.send(mido.Message("control_change", channel=0, control=number, value=value))

        def frames_go_by(count=5):  # the instrument has read what was sent before
            now = last_frame(receiver)
            wait_until(lambda: last_frame(receiver) >= now + count, f"{count} more frames")

        cc(120)  # elderly fader, first value: only tells where the fader is
        frames_go_by()
        cc(110)  # far from the parameter (0 is at 42): not picked up
        frames_go_by()
        ignored_until = last_frame(receiver)
        cc(43)  # near the parameter: picked up
        frames_go_by()
        for value in range(44, 101, 2):  # a real fader move: small steps, milliseconds apart
            cc(value)
            time.sleep(0.005)

        def shows_the_sweeps_end():
            echo = frames_and_echo(receiver, "/walk/style/elderly")
            return echo and echo[-1][1] == pytest.approx(100 / 127 * 3 - 1, abs=1e-6)

        # the walk shows where the fader stopped; on a starved machine JACK's dummy driver has been
        # seen to lose a fader's last messages, so after 5 s the performer nudges it there again
        try:
            wait_until(shows_the_sweeps_end, "the sweep's last value", timeout=5.0)
        except AssertionError:
            cc(99)
            cc(100)
            wait_until(shows_the_sweeps_end, "the sweep's last value, sent again")
        frames_go_by()
        out.close()
    finally:
        stderr = process.communicate(timeout=60)[1]
        receiver.close()
    assert process.returncode == 0, stderr
    echo = frames_and_echo(receiver, "/walk/style/elderly")
    assert [f for f, _ in echo] == list(range(len(echo)))
    assert all(v == 0.0 for f, v in echo if f <= ignored_until)
    first_change = next(f for f, v in echo if v != 0.0)
    # 120 and 110 were never taken: the first value the walk shows is 43's (when is the machine's business)
    assert first_change > ignored_until
    assert echo[first_change][1] == pytest.approx(43 / 127 * 3 - 1, abs=1e-6)
    assert echo[-1][1] == pytest.approx(100 / 127 * 3 - 1, abs=1e-6)
    # the recorded raw events replay to the same frames, byte for byte, as fast as the CPU allows; the log
    # carries the mapping it was recorded with (its first line), so no --mapping is needed
    result = subprocess.run(RUN + ["--replay", str(log), "--no-osc", "--fast", "--seconds", "12",
                                   "--bvh", str(replay_bvh), "--quiet"], capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert filecmp.cmp(live_bvh, replay_bvh, shallow=False)


def gait_sequence(receiver: Receiver) -> list[float]:
    """The echoed /walk/gait values in the order they came, each change once."""
    out: list[float] = []
    for address, params in receiver.messages():
        if address == "/walk/gait" and (not out or out[-1] != params[0]):
            out.append(params[0])
    return out


def replayed_gaits(log, seconds: float) -> list[float]:
    """`gait_sequence` of a log replayed in real time (no UDP lost) to the flat profile."""
    replayed = Receiver()
    try:
        result = subprocess.run(RUN + ["--replay", str(log), "--osc", f"127.0.0.1:{replayed.port}/flat",
                                       "--seconds", repr(seconds), "--quiet"], capture_output=True, text=True, timeout=120)
    finally:
        replayed.close()
    assert result.returncode == 0, result.stderr
    return gait_sequence(replayed)


# the shipped buttons that set the gait (mode "set"): the message a press sends, for stand, walk, run
GAIT_BUTTONS = {
    "korg-nanokontrol2": lambda number, on: mido.Message("control_change", control=number, value=127 if on else 0),
    "akai-midimix": lambda number, on: mido.Message("note_on", note=number, velocity=127 if on else 0),
}
GAIT_NUMBERS = {"korg-nanokontrol2": (43, 41, 44), "akai-midimix": (3, 6, 9)}  # REW PLAY FF; REC ARM 1-3


@pytest.mark.parametrize("name", sorted(GAIT_BUTTONS))
def test_the_gait_buttons_of_a_shipped_mapping_over_jack_reach_the_echo_and_replay(jack, tmp_path, name):
    """Pressing a shipped mapping's run, stand and walk buttons through real JACK MIDI sets the
    gait the flat stream echoes (/walk/gait); the recorded raw events replay to the same gaits."""
    receiver = Receiver()
    log = tmp_path / "take.jsonl"
    process = subprocess.Popen(RUN + ["--midi-virtual", "instr-gait", "--midi-api", "jack", "--mapping",
                                      str(REPO / "mappings" / f"{name}.toml"), "--osc", f"127.0.0.1:{receiver.port}/flat",
                                      "--seconds", "120", "--quiet", "--record", str(log), "--no-feedback"],
                               stderr=subprocess.PIPE, text=True)
    stand, walk, run = GAIT_NUMBERS[name]
    try:
        out = jack.open_output(wait_for_port(jack, "instr-gait"))
        wait_until(lambda: last_frame(receiver) >= 15, "15 frames")
        for number, gait in ((run, 2.0), (stand, 0.0), (walk, 1.0)):
            def press() -> bool:  # pressed again after a while if nothing came back, as a performer would:
                # JACK's dummy driver without realtime drops an event now and then on a loaded machine
                out.send(GAIT_BUTTONS[name](number, True))
                out.send(GAIT_BUTTONS[name](number, False))  # let go: the gait stays
                try:
                    return bool(wait_until(lambda: gait_sequence(receiver)[-1:] == [gait], "echo", timeout=10.0))
                except AssertionError:
                    return False

            wait_until(press, f"/walk/gait {gait:g}", every=0.0)
        now = last_frame(receiver)
        wait_until(lambda: last_frame(receiver) >= now + 5, "5 more frames")
        out.close()
    finally:
        process.terminate()  # a clean stop, like Ctrl-C: the log is closed whole
        stderr = process.communicate(timeout=60)[1]
        receiver.close()
    assert process.returncode == 0, stderr
    assert gait_sequence(receiver) == [1.0, 2.0, 0.0, 1.0]  # walking at the start, then run, stand, walk
    assert replayed_gaits(log, last_frame(receiver) / 30 + 1.0) == [1.0, 2.0, 0.0, 1.0]


def test_an_unplugged_midi_device_is_reported_and_reconnected(jack, tmp_path):
    device, receiver = jack.open_output("FakeKontrol", virtual=True), Receiver()
    process = subprocess.Popen(RUN + ["--midi", "FakeKontrol", "--midi-api", "jack", "--osc", f"127.0.0.1:{receiver.port}/flat",
                                      "--quiet", "--bvh", str(tmp_path / "walk.bvh")], stderr=subprocess.PIPE, text=True)
    stderr = StderrLines(process)
    try:
        wait_until(lambda: frame_count(receiver) >= 30, "30 frames")
        device.close()  # unplugged
        stderr.wait_for("unplugged")
        device = jack.open_output("FakeKontrol", virtual=True)  # plugged back in
        stderr.wait_for("connected")
        device.send(mido.Message("control_change", channel=0, control=8, value=127))
        now = frame_count(receiver)
        wait_until(lambda: frame_count(receiver) >= now + 10, "10 more frames")
    finally:
        process.terminate()  # a clean stop, like Ctrl-C
        process.wait(60)
        device.close()
        receiver.close()
    assert process.returncode == 0, stderr.text()
    from instrument.motion.bvh import read_bvh

    frames = [p[0] for a, p in receiver.messages() if a == "/walk/frame"]
    assert frames == list(range(len(frames)))  # the walk never stopped
    assert read_bvh(tmp_path / "walk.bvh").frames >= len(frames)


def test_simulated_dualshock4_steers_drives_a_style_and_survives_unplug(capsys):
    model = load_model(default_model_path())
    pad = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC, name="Wireless Controller")  # its real USB descriptor
    console = Console()
    device = HidInput(console, 0x054C, 0x09CC, hid=SimulatedHid(pad))
    state = ControlState(model.style_names, model.states)
    hub = ControlHub([load_mapping(REPO / "mappings" / "sony-dualshock4.toml", state)])
    hub.start(state)  # the mapping's morph time (1 s), as `run` starts it
    seen = []

    class Watch:
        name = "watch"

        def prepare(self, frame):
            return (frame.index, frame.echo["turn"], frame.echo["style/active"], frame.echo["speed"])

        def send(self, values):
            seen.append(values)
            index = values[0]
            if index == 10:
                pad.send(ds4_report(lx=0, r2=255))  # full left, R2 pressed
            if index == 30:
                pad.plugged = False  # cable pulled
            if index == 80:
                pad.plugged = True
            if index == 120:
                pad.send(ds4_report(lx=128, r2=0, face=0b0010))  # centre, release, cross: preset "proud"

        def close(self):
            pass

    perform(Show(model, [Watch()], fps=30, seconds=6.0, apply=hub.apply, state=state, sources=[device.poll]), console)
    err = capsys.readouterr().err
    assert [s[0] for s in seen] == list(range(180))  # the walk never stopped
    by_frame = {s[0]: s for s in seen}
    assert by_frame[15][1] == pytest.approx(1.2) and by_frame[15][2] == pytest.approx(2.0)  # steering left, active 2
    assert "lost" in err and "reconnected" in err
    assert pad.opened >= 2
    assert by_frame[170][1] == 0.0 and by_frame[170][2] == pytest.approx(0.5)  # preset "proud" recalled


def test_osc_surface_controls_and_presets(tmp_path):
    control_port, receiver = free_port(), Receiver()
    presets = tmp_path / "presets.toml"
    presets.write_text('[presets.bold]\n"style/feminine" = 2.0\nspeed = 1.5\n')
    process = subprocess.Popen(RUN + ["--osc-in", str(control_port), "--osc", f"127.0.0.1:{receiver.port}/flat",
                                      "--presets", str(presets), "--quiet"], stderr=subprocess.PIPE, text=True)
    from pythonosc.udp_client import SimpleUDPClient

    client = SimpleUDPClient("127.0.0.1", control_port)

    def echoed(address: str, value: float) -> bool:
        echo = frames_and_echo(receiver, address)
        return bool(echo) and echo[-1][1] == pytest.approx(value)

    try:
        wait_until(lambda: last_frame(receiver) >= 20, "20 frames")
        client.send_message("/walk/style/elderly", 1.5)
        wait_until(lambda: echoed("/walk/style/elderly", 1.5), "elderly 1.5 echoed")
        client.send_message("/walk/preset/bold", 1.0)
        wait_until(lambda: echoed("/walk/speed", 1.5), "the preset's speed echoed")
        client.send_message("/walk/nonsense", 1.0)  # ignored
    finally:
        process.terminate()
        stderr = process.communicate(timeout=60)[1]
    receiver.close()
    assert process.returncode == 0, stderr
    elderly = frames_and_echo(receiver, "/walk/style/elderly")
    feminine = frames_and_echo(receiver, "/walk/style/feminine")
    assert elderly[-1][1] == pytest.approx(1.5) and feminine[-1][1] == pytest.approx(2.0)
    speed = frames_and_echo(receiver, "/walk/speed")
    assert speed[-1][1] == pytest.approx(1.5)


def test_an_osc_surface_sets_the_gait_by_number_or_by_name_and_a_bad_name_is_refused(tmp_path):
    """`/walk/gait f 2` and `/walk/gait s "stand"` reach the echo; `s "sprint"` is refused by the one
    check, warned about and counted, and the show goes on; a message with more than one argument
    (gait's or any address's) is taken by its first, the rest said in one line; the log holds the
    numbers and replays them."""
    from pythonosc.udp_client import SimpleUDPClient

    control_port, receiver = free_port(), Receiver()
    log = tmp_path / "take.jsonl"
    process = subprocess.Popen(RUN + ["--osc-in", str(control_port), "--osc", f"127.0.0.1:{receiver.port}/flat",
                                      "--record", str(log)], stderr=subprocess.PIPE, text=True)
    client = SimpleUDPClient("127.0.0.1", control_port)
    try:
        wait_until(lambda: last_frame(receiver) >= 20, "20 frames")
        client.send_message("/walk/gait", 2.0)
        wait_until(lambda: gait_sequence(receiver)[-1:] == [2.0], "run (2) echoed")
        client.send_message("/walk/gait", "sprint")  # no such gait: refused, nothing changes
        client.send_message("/walk/gait", ["stand", "run"])  # two arguments: taken by the first, the rest said
        wait_until(lambda: gait_sequence(receiver)[-1:] == [0.0], "stand (0) echoed")
        client.send_message("/walk/speed", [1.5, 3.0])  # any address alike (said once a minute: not again)
        wait_until(lambda: frames_and_echo(receiver, "/walk/speed")[-1][1] == 1.5, "speed 1.5 echoed")
        client.send_message("/walk/gait", "walk")
        wait_until(lambda: gait_sequence(receiver)[-1:] == [1.0], "walk (1) echoed")
    finally:
        process.terminate()
        stderr = process.communicate(timeout=60)[1]
        receiver.close()
    assert process.returncode == 0, stderr
    assert gait_sequence(receiver) == [1.0, 2.0, 0.0, 1.0]
    assert "gait: not a finite number or one of stand, walk, run, not 'sprint'" in stderr
    left = [line for line in stderr.splitlines() if "more (type tags" in line]
    assert left == [f"warning: took /walk/gait on 127.0.0.1:{control_port} by its first argument and left 1 more "
                    "(type tags 's'): a control takes one value (such messages are taken so; the next is shown in a minute)"]
    assert "refused {'not a finite number': 1}" in stderr
    recorded = [line for line in log.read_text().splitlines()[1:] if '"gait"' in line]
    assert [json.loads(line)["value"] for line in recorded] == [2.0, 0.0, 1.0]  # names recorded as their numbers
    assert replayed_gaits(log, last_frame(receiver) / 30 + 1.0) == [1.0, 2.0, 0.0, 1.0]


def test_each_distinct_bad_osc_address_is_named_and_its_repeats_counted(tmp_path):
    """A performer's OSC typos: the warning was throttled per kind, so a second unknown address
    within the minute was only counted and never named. Each distinct bad address (or control)
    is named once; its repeats are counted, not said again."""
    from pythonosc.udp_client import SimpleUDPClient

    control_port, receiver = free_port(), Receiver()
    process = subprocess.Popen(RUN + ["--osc-in", str(control_port), "--osc", f"127.0.0.1:{receiver.port}/flat"],
                               stderr=subprocess.PIPE, text=True)
    stderr = StderrLines(process)
    client = SimpleUDPClient("127.0.0.1", control_port)
    try:
        wait_until(lambda: last_frame(receiver) >= 20, "20 frames")
        for address in ("/walk/speeed", "/walk/tunr", "/walk/speeed", "/foo/speed", "/bar/speed", "/foo/speed"):
            client.send_message(address, 0.5)
        client.send_message("/walk/style/nrmal", 0.5)  # said last: the ones before it are taken by then
        stderr.wait_for("'style/nrmal'")
    finally:
        process.terminate()
        process.wait(60)
        receiver.close()
    text = stderr.text()
    assert process.returncode == 0, text
    warnings = [line for line in text.splitlines() if line.startswith("warning:")]
    for named in ("'speeed'", "'tunr'", "'style/nrmal'", "'/foo/speed'", "'/bar/speed'"):
        assert sum(named in line for line in warnings) == 1, (named, warnings)
    assert "'unknown target': 4" in text and "'address': 3" in text  # every one counted


def test_show_file_starts_the_whole_setup(tmp_path):
    receiver = Receiver()
    show = tmp_path / "show.toml"
    show.write_text(f'seconds = 2\nosc = ["127.0.0.1:{receiver.port}/flat"]\nquiet = true\nbvh = "take.bvh"\n'
                    f'replay = "cues.jsonl"\n[presets.calm]\n"style/elderly" = 0.5\n')
    (tmp_path / "cues.jsonl").write_text('{"t": 0.5, "source": "cue", "control": "preset/calm", "value": 1}\n')
    result = subprocess.run(RUN + ["--config", str(show)], capture_output=True, text=True, timeout=60)
    wait_until(lambda: frame_count(receiver) >= 60 or result.returncode, "60 frames")
    receiver.close()
    assert result.returncode == 0, result.stderr
    assert (tmp_path / "take.bvh").exists()
    assert frames_and_echo(receiver, "/walk/style/elderly")[-1][1] == pytest.approx(0.5)


@pytest.mark.parametrize("text,message", [
    ('seconds = 2\nvolume = 11\n', "show.toml:2: volume: unknown option"),
    ('seconds = 2\nquiet = "yes"\n', "show.toml:2: quiet: expected true or false"),
    ('seconds = [2]\n', "show.toml:1: seconds: expected a string or a number"),
    ('seconds = 2\nmodel = 5\n', "show.toml:2: model: expected a file name in quotes, not 5"),
    ('seconds = 2\nfps = 200\n', "show.toml:2: fps: expected a number from 24 to 120, not '200'"),
    ('seconds = 2\nosc = ["127.0.0.1:9000", "127.0.0.1:99999"]\n', "show.toml:2: osc: '127.0.0.1:99999': port must be 1 to 65535"),
    ('seconds = 2\n[presets.x]\n"style/sleepy" = 1\n', "show.toml:3: presets.x: style/sleepy: unknown target"),
    ('seconds = 2\n\n[presets.calm]\n"speed" = 1\n\n[presets."x"]  # a note\n"speed" = 2\n"style/sleepy" = 1\n',
     "show.toml:8: presets.x: style/sleepy: unknown target"),
    ('seconds = 2\n[presets.x]\nspeed = 1\nturn = "left"\n', "show.toml:4: presets.x: turn: not a finite number, not 'left'"),
    ('seconds = 2\npresets.x = 3\n', "show.toml:2: presets.x: expected a table of target = number"),
    ('seconds = 2\npresets.calm.speed = 1\npresets.calm.turn = true\n', "show.toml:3: presets.calm: turn: not a finite number"),
    ('seconds = 2\nconsole-token = "s3cret"\n', "--console-token means nothing without --console"),
    ('# fps is set below\nseconds = 2\n\nfps = 500\n', "show.toml:4: fps: expected a number from 24 to 120"),
    ('seconds = 2\nname = "fps = 1"\n', "show.toml:2: name: unknown option"),
    ('seconds = 2\nosc_in = "9001"\n', "show.toml:2: osc_in: unknown option (the show file takes the flags of `instrument run`; "
                                        "did you mean osc-in?)"),
    ('seconds = 2\nosc-in = "127.0.0.1:x"\n', "show.toml:2: osc-in: expected [HOST:]PORT"),
    ('seconds = 2\nosc = [\n  "127.0.0.1:9000",\n  "127.0.0.1:99999",\n]\n', "show.toml:4: osc: '127.0.0.1:99999'"),
])
def test_bad_show_files_are_one_line_errors(tmp_path, text, message):
    show = tmp_path / "show.toml"
    show.write_text(text)
    result = subprocess.run(RUN + ["--config", str(show)], capture_output=True, text=True, timeout=60)
    assert result.returncode == 1
    assert message in result.stderr and len(result.stderr.strip().splitlines()) == 1


def test_a_bad_preset_file_names_its_line(tmp_path):
    presets = tmp_path / "mine.toml"
    presets.write_text('[presets.calm]\n"style/elderly" = 0.5\n\n[presets.x]\n"speed" = 1.2\n"style/nope" = 1\n')
    result = subprocess.run(RUN + ["--presets", str(presets), "--no-osc", "--seconds", "1"], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 1
    assert f"{presets}:6: presets.x: style/nope: unknown target" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_a_console_token_without_a_console_is_refused():
    result = subprocess.run(RUN + ["--console-token", "s3cret", "--no-osc", "--seconds", "1"], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 1
    assert "--console-token means nothing without --console" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_midi_feedback_follows_a_preset_recall(jack, tmp_path):

    control_port = free_port()
    # runs until stopped: the JACK dummy server sometimes stalls a client's start for seconds
    process = subprocess.Popen(RUN + ["--midi-virtual", "instr-fb", "--midi-api", "jack", "--mapping", NANO, "--no-osc",
                                      "--osc-in", str(control_port), "--seconds", "60", "--quiet"], stderr=subprocess.PIPE, text=True)
    try:
        received = []
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            names = [n for n in jack.get_input_names() if "instr-fb feedback" in n]
            if names:
                break
            time.sleep(0.1)
        from pythonosc.udp_client import SimpleUDPClient

        surface = SimpleUDPClient("127.0.0.1", control_port)
        for attempt in range(3):  # a connection made while the dummy server stalls can come to nothing: make it again
            listener = jack.open_input(names[0], callback=received.append)
            surface.send_message("/walk/style/masculine", 0.1 * (attempt + 1))  # a change not made by the fader: fed back
            waited = time.monotonic() + 3
            while not received and time.monotonic() < waited:
                time.sleep(0.05)
            if received:
                break
            listener.close()
        assert received, "no feedback came through JACK"
        surface.send_message("/walk/preset/proud", 1.0)  # masculine 1.5, active 0.5, exhausted -1

        # the morph (1.5 s in the mapping) ends on the preset: each fader is told where its parameter now stands
        expected = {4: round((1.5 + 1) / 3 * 127), 0: round((0.5 + 1) / 3 * 127), 2: 0}  # masculine, active, exhausted at the bottom
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline:
            values = {m.control: m.value for m in list(received) if m.type == "control_change"}
            if all(values.get(control) == value for control, value in expected.items()):
                break
            time.sleep(0.1)
    finally:
        process.terminate()  # a clean stop (SIGTERM ends the performance like Ctrl-C)
        stderr = process.communicate(timeout=60)[1]
    listener.close()
    assert process.returncode == 0, stderr
    values = {m.control: m.value for m in received if m.type == "control_change"}
    assert {control: values.get(control) for control in expected} == expected
    assert len({m.value for m in received if m.type == "control_change" and m.control == 4}) > 2  # it moved there, not jumped


@pytest.mark.skipif(__import__("os").path.exists("/dev/snd/seq"), reason="this machine has ALSA MIDI: nothing fails")
@pytest.mark.parametrize("port", [["--midi-virtual", "instr-nowhere"], ["--midi-out", "instr-nowhere"]])
def test_midi_through_a_missing_alsa_is_one_line_suggesting_jack(port):
    """Where there is no ALSA sequencer (a container, a JACK-only machine) the error is one line
    (libasound's own line caught into it), naming ALSA's failure and how to use JACK instead."""
    mapping = ["--mapping", str(REPO / "mappings" / "generic-8-faders.toml")]  # (no "MIDI mapping:" line)
    result = subprocess.run(RUN + port + mapping + ["--no-osc", "--seconds", "1"], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("instrument run: error: MIDI is not available"), result.stderr
    assert "give --midi-api jack" in lines[0] and "ALSA" in lines[0]


@pytest.mark.parametrize("port", [["--midi-virtual", "instr-nowhere"], ["--midi-out", "instr-nowhere"]])
def test_midi_through_jack_with_no_server_is_one_line_suggesting_alsa(port, tmp_path):
    """With --midi-api jack and no JACK server (a server name nothing answers to), libjack's own
    lines ("Cannot connect to server socket ...", five of them) are kept off stderr: the error is
    one line, naming the failure and how to use ALSA instead."""
    mapping = ["--mapping", str(REPO / "mappings" / "generic-8-faders.toml")]  # (no "MIDI mapping:" line)
    environment = dict(__import__("os").environ, JACK_DEFAULT_SERVER=f"instr-nowhere-{tmp_path.name}",
                       JACK_NO_START_SERVER="1")
    result = subprocess.run(RUN + port + mapping + ["--midi-api", "jack", "--no-osc", "--seconds", "1"], capture_output=True,
                            text=True, timeout=120, env=environment)
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("instrument run: error: MIDI is not available (jack API)"), result.stderr
    assert "give --midi-api alsa" in lines[0]
