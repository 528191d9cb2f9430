"""MIDI learn over real JACK MIDI, the detection of every message kind, and Standard MIDI Files."""

import subprocess
import sys
import time

import mido
import pytest

from instrument.control.events import ControlEvent, read_log
from instrument.control.learn import detect
from instrument.control.mapping import Mapper, load_mapping
from instrument.control.smf import export_smf, import_smf
from instrument.control.state import ControlState
from conftest import play_mapped
from test_controllers import wait_for_port

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]


def cc(number, values, channel=1):
    return [(f"cc/{channel}/{number}", float(v)) for v in values]


@pytest.mark.parametrize("raw,expected", [
    (cc(7, range(0, 128, 9)), ("cc", 7, "absolute")),
    ([x for v in range(0, 128, 16) for x in cc(1, [v]) + cc(33, [v])], ("cc14", 1, "absolute")),
    (cc(99, [2]) + cc(98, [44]) + cc(6, [10]) + cc(38, [5]), ("nrpn", 300, "absolute")),
    (cc(20, [1, 1, 2, 1, 127, 127, 126, 127]), ("cc", 20, "relative-twos")),
    (cc(20, [1, 1, 2, 1, 65, 65, 66, 65]), ("cc", 20, "relative-signed")),
    (cc(20, [65, 65, 66, 65, 1, 1, 2, 1]), ("cc", 20, "relative-signed2")),
    (cc(20, [65, 65, 66, 65, 63, 63, 62, 63]), ("cc", 20, "relative-offset")),
    ([("note/1/36", 100.0), ("note/1/36", 0.0)], ("note", 36, "momentary")),
    ([("pitchbend/2/0", 100.0), ("pitchbend/2/0", 16000.0)], ("pitchbend", 0, "absolute")),
])
def test_detection(raw, expected):
    learned = detect(raw)
    assert (learned.message, learned.number, learned.mode) == expected


def test_learn_over_jack_writes_a_working_mapping(jack, tmp_path):
    out = tmp_path / "mine.toml"
    process = subprocess.Popen([sys.executable, "-m", "instrument", "learn", "--midi-virtual", "learn-test", "--midi-api", "jack",
                                "--out", str(out), "--timeout", "20"],
                               stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, bufsize=1)
    port = jack.open_output(wait_for_port(jack, "learn-test"))

    def answer(text):
        process.stdin.write(text + "\n")
        process.stdin.flush()
        for line in process.stdout:
            if "move the control" in line:
                return

    def send(messages):
        for m in messages:
            port.send(m)
            time.sleep(0.01)
        for line in process.stdout:  # wait until it says what it learned
            if "learned" in line:
                return line

    process.stdout.readline()  # the list of targets
    answer("style/elderly")
    learned = send([mido.Message("control_change", control=7, value=v) for v in range(0, 128, 8)])
    assert "cc channel 1 number 7 (absolute)" in learned
    answer("speed")
    pairs = [m for v in range(0, 128, 16) for m in (mido.Message("control_change", control=2, value=v),
                                                   mido.Message("control_change", control=34, value=v))]
    assert "cc14 channel 1 number 2" in send(pairs)
    answer("turn")
    encoder = [mido.Message("control_change", channel=3, control=20, value=v) for v in (1, 1, 2, 1, 127, 127, 126, 127)]
    assert "relative-twos" in send(encoder)
    answer("gait")  # a fader: the gait's zones, the row's range
    assert "cc channel 1 number 5 (absolute)" in send([mido.Message("control_change", control=5, value=v) for v in range(0, 128, 8)])
    answer("gait=run")  # a button that sets one gait
    assert "note channel 1 number 44" in send([mido.Message("note_on", note=44, velocity=100),
                                                mido.Message("note_on", note=44, velocity=0)])
    process.stdin.write("\n")
    process.stdin.flush()
    assert process.wait(30) == 0, process.stderr.read()
    port.close()
    state = ControlState(STYLES, 5)
    mapper = Mapper(load_mapping(out, state))
    play_mapped(mapper, state, ControlEvent(0, "midi:x", "cc/1/7", 127))  # first value: pick-up only learns the position
    play_mapped(mapper, state, ControlEvent(1, "midi:x", "cc/1/7", 42))
    assert state.get("style/elderly") == pytest.approx(42 / 127 * 3 - 1)
    for _ in range(3):
        play_mapped(mapper, state, ControlEvent(2, "midi:x", "cc/4/20", 1))
    assert state.turn == pytest.approx(0.03)
    play_mapped(mapper, state, ControlEvent(3, "midi:x", "note/1/44", 100))  # gait=run: pressed...
    play_mapped(mapper, state, ControlEvent(3, "midi:x", "note/1/44", 0))  # ...and let go: it stays
    assert state.gait == 2.0
    play_mapped(mapper, state, ControlEvent(4, "midi:x", "cc/1/5", 127))  # the gait fader: pick-up learns where it is
    play_mapped(mapper, state, ControlEvent(5, "midi:x", "cc/1/5", 126))  # near run (2): taken, its top third runs
    assert state.gait == 2.0  # its top third is run, held to the range (control/mapping.ControlSpec.travel)
    play_mapped(mapper, state, ControlEvent(5.01, "midi:x", "cc/1/5", 10))  # a fast sweep down to its bottom third: stand
    assert state.snapshot().gait == 0


def test_midi_logs_round_trip_through_a_standard_midi_file(tmp_path):
    events = [ControlEvent(k / 30, "midi:nanoKONTROL2", f"cc/1/{k % 8}", float(k % 128)) for k in range(50)]
    events += [ControlEvent(0.5, "midi:pads", "note/10/36", 100.0), ControlEvent(0.6, "midi:pads", "note/10/36", 0.0),
               ControlEvent(1.0, "midi:pads", "pitchbend/2/0", 12000.0)]
    events.sort(key=lambda e: e.time)
    path = tmp_path / "take.mid"
    export_smf(events, path)
    midi = mido.MidiFile(str(path))
    assert midi.type == 1 and midi.ticks_per_beat == 1000
    names = [next(m.name for m in t if m.type == "track_name") for t in midi.tracks[1:]]
    assert names == ["nanoKONTROL2", "pads"]
    again = import_smf(path, fps=30)
    key = lambda e: (round(e.time * 30), e.source, e.control, e.value)  # noqa: E731
    assert sorted(map(key, again)) == sorted(map(key, events))


def test_cli_log_export_import(tmp_path):
    log = tmp_path / "take.jsonl"
    log.write_text(ControlEvent(1 / 3, "midi:x", "cc/1/7", 64.0).to_json() + "\n")
    run = lambda *a: subprocess.run([sys.executable, "-m", "instrument", "log", *a], capture_output=True, text=True)  # noqa: E731
    assert run("export", str(log), "--out", str(tmp_path / "t.mid")).returncode == 0
    assert run("import", str(tmp_path / "t.mid"), "--out", str(tmp_path / "back.jsonl")).returncode == 0
    assert read_log(tmp_path / "back.jsonl") == read_log(log)
    other = tmp_path / "mixed.jsonl"
    other.write_text(ControlEvent(0, "demo", "speed", 1.0).to_json() + "\n")
    result = run("export", str(other), "--out", str(tmp_path / "m.mid"))
    assert result.returncode == 1 and "only MIDI events" in result.stderr


def test_a_missing_midi_file_is_said_as_every_missing_input_is(tmp_path):
    """`log import` of a file that is not there: "cannot read: No such file or directory", as
    `log export` and every other input say it (it said "not a readable MIDI file ([Errno 2] ...)");
    a file that is not MIDI keeps its own line."""
    from instrument.errors import UserError

    with pytest.raises(UserError, match=r"^.*nothere\.mid: cannot read: No such file or directory$"):
        import_smf(tmp_path / "nothere.mid")
    (tmp_path / "text.mid").write_text("not midi\n")
    with pytest.raises(UserError, match=r"text\.mid: not a readable MIDI file \(MThd not found"):
        import_smf(tmp_path / "text.mid")
    for name, data in [("short.mid", b"garbage"), ("cut.mid", b"MThd\x00\x00\x00\x06\x00\x01\x00\x01")]:
        (tmp_path / name).write_bytes(data)  # mido's EOFError says nothing: the line says why
        with pytest.raises(UserError, match=rf"{name}: not a readable MIDI file \(it ends before its header or a track does\)$"):
            import_smf(tmp_path / name)
