"""The fault suite: nothing a performer, a network or a file can do stops the show.

Real parts throughout: UDP on 127.0.0.1, MIDI through JACK (a private server for the restart
test, so the shared one is never killed), real subprocesses and signals, real files. The random
inputs are seeded, so a failure can be reproduced; examples/fault_soak.py runs the same faults
for as long as one likes.
"""

from __future__ import annotations

import math
import os
import random
import re
import shutil
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REPO
from instrument.cli.main import main
from instrument.control import oscparse
from instrument.control.events import ControlEvent, read_log
from instrument.control.hub import ControlHub
from instrument.control.state import ControlState
from instrument.control.targets import TABLE, problem, raw_problem
from instrument.motion.bvh import read_bvh
from instrument.output.osc import message as osc_message
from frame_indices import FrameIndices
from oscrecv import Receiver, free_port
from private_jack import (alive, free_dead_slots, jack_port_listed, registered_servers, start_private_jack,
                          stop_private_jack)
from waiting import wait_until

RUN = [sys.executable, "-m", "instrument", "run"]
SEED = 13


def bvh_frames(path: Path) -> int:
    counted = re.search(rb"\nFrames: (\d+)", path.read_bytes()) if path.exists() else None
    return int(counted.group(1)) if counted else -1


def assert_valid_bvh(path: Path) -> int:
    """The header counts exactly the frame lines, and an independent reading agrees."""
    text = path.read_bytes()
    header = bvh_frames(path)
    lines = text.split(b"Frame Time:", 1)[1].split(b"\n")[1:]
    assert lines[-1] == b"", "the last frame line is cut"
    assert header == len(lines) - 1, f"header {header}, frame lines {len(lines) - 1}"
    assert read_bvh(path).frames == header
    return header


def assert_one_line_error_or_success(code: int, err: str) -> None:
    assert "Traceback" not in err, err
    if code != 0:
        assert code == 1 and re.search(r"^instrument run: error: .+", err, re.MULTILINE), err


# --- the table of targets -----------------------------------------------------------------------


def test_the_table_accepts_only_targets_of_the_model_and_finite_numbers(model):
    state = ControlState(model.style_names, model.states)
    styles, states = state.style_index, state.states
    assert problem("phase/²", 1.0, styles, states) == "unknown target"  # '²'.isdigit() is True
    assert problem("phase/0", 1.0, styles, states) == "unknown target"
    assert problem(f"phase/{states + 1}", 1.0, styles, states) == "unknown target"
    assert problem("phase/1", 1.0, styles, states) is None
    for bad in ("abc", b"x", None, True, math.nan, math.inf, -math.inf, 10 ** 400, [1.0]):
        assert problem("speed", bad, styles, states) == "not a finite number", bad
    assert problem("style/nobody", 1.0, styles, states) == "unknown target"
    assert problem(f"style/{model.style_names[0]}/extra", 1.0, styles, states) == "unknown target"
    # out of range is refused, as a file refuses it (control/checks.py), not clamped
    assert problem("speed", 99.0, styles, states) == "out of range" and not state.set("speed", 99.0)
    assert not state.set("turn", -99) and state.turn == 0.0
    assert state.set("speed", TABLE["speed"].high) and state.speed == TABLE["speed"].high
    assert not state.set("speed", "2") and state.speed == TABLE["speed"].high


def test_raw_device_events_are_checked_before_a_mapping_sees_them():
    assert raw_problem("midi:x", "cc/1/99", 3.0) is None
    for control in ("cc/x/99", "cc/1/²", "cc/0/1", "cc/17/1", "cc/1/128", "sysex/1/1", "cc/1", 5):
        assert raw_problem("midi:x", control, 3.0) is not None, control
    assert raw_problem("midi:x", "cc/1/7", 128.0) == "MIDI value out of range"
    assert raw_problem("midi:x", "pitchbend/1/0", 16383.0) is None
    assert raw_problem("hid:054c:09cc", "lx", 256.0) == "HID value out of range"
    assert raw_problem("hid:054c:09cc", "Hat", -1.0) is None and raw_problem("hid:054c:09cc", "Hat#2", -1.0) is None  # released
    for control, value in (("X", -1.0), ("Hat", -0.5), ("Hat/up", -1.0)):
        assert raw_problem("hid:054c:09cc", control, value) == "HID value out of range", control


def test_the_hub_refuses_counts_and_never_records_bad_events(model, tmp_path):
    from instrument.control.mapping import load_mapping

    state = ControlState(model.style_names, model.states)
    log = tmp_path / "take.jsonl"
    hub = ControlHub([load_mapping(REPO / "mappings" / "akai-midimix.toml", state)], record=log)
    bad = [ControlEvent(0.0, "midi:x", "cc/x/99", 1.0), ControlEvent(0.0, "osc", "phase/²", 1.0),
           ControlEvent(0.0, "osc", "speed", math.nan), ControlEvent(0.0, "osc", "preset/none", 1.0),
           ControlEvent(0.0, "osc", "nothing", 1.0)]
    assert not any(hub.apply(state, e) for e in bad)
    assert hub.apply(state, ControlEvent(0.5, "osc", "speed", 2.0))
    hub.close()
    assert sum(hub.refused.values()) == len(bad)
    assert [e.control for e in read_log(log)] == ["speed"]


# --- OSC: a packet fuzzer -----------------------------------------------------------------------


def valid_packets(model) -> list[bytes]:
    style = model.style_names[0]
    plain = [osc_message("/walk/speed", 1.5), osc_message(f"/walk/style/{style}", 0.7), osc_message("/walk/turn", -0.5),
             osc_message("/walk/phase/2", 2), osc_message("/walk/liveliness", 0.3)]
    bundle = b"#bundle\0" + struct.pack(">Q", 1) + b"".join(struct.pack(">i", len(m)) + m for m in plain)
    return plain + [bundle, b"#bundle\0" + struct.pack(">Q", 1) + struct.pack(">i", len(bundle)) + bundle]


def mutate(rng: random.Random, packet: bytes) -> bytes:
    """One packet changed as a network or a hostile sender would: bits flipped, cut, grown,
    sizes and type tags lied about, or plain noise."""
    data = bytearray(packet)
    kind = rng.randrange(8)
    if kind == 0 and data:
        for _ in range(rng.randint(1, 4)):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
    elif kind == 1:
        data = data[: rng.randrange(len(data) + 1)]
    elif kind == 2:
        data += bytes(rng.randrange(256) for _ in range(rng.randint(1, 40)))
    elif kind == 3 and len(data) > 20:  # a bundle element size that lies
        at = 16 if data.startswith(b"#bundle") else rng.randrange(len(data) - 4)
        data[at: at + 4] = struct.pack(">i", rng.choice([-4, 0, 3, 1 << 30, len(data)]))
    elif kind == 4:  # another type tag: string, blob, nil, true, nothing, unknown
        tag = rng.choice([b",s\0\0", b",b\0\0", b",N\0\0", b",T\0\0", b",\0\0\0", b",x\0\0", b",d\0\0", b",h\0\0"])
        data = bytearray(re.sub(rb",[a-z]\0+", tag, bytes(data), count=1))
    elif kind == 5:  # numbers that are not finite
        data = bytearray(re.sub(rb",f\0\0....", b",f\0\0" + struct.pack(">f", rng.choice([math.nan, math.inf, -math.inf])),
                                bytes(data), count=1, flags=re.DOTALL))
    elif kind == 6:  # an address that is not ours, or not text
        data = bytearray(re.sub(rb"^/walk/[a-z/0-9]+", rng.choice([b"/walk/phase/\xc2\xb2", b"/x", b"/walk/", b"\xff\xfe"]),
                                bytes(data), count=1))
    else:
        data = bytearray(rng.randrange(256) for _ in range(rng.randint(0, 200)))
    return bytes(data)


def test_osc_parsing_never_raises_anything_but_malformed(model):
    rng = random.Random(SEED)
    packets = valid_packets(model)
    state = ControlState(model.style_names, model.states)
    hub = ControlHub([])
    tried = taken = 0
    for _ in range(20000):
        data = mutate(rng, rng.choice(packets))
        tried += 1
        try:
            for message in oscparse.messages(data):
                try:
                    address, value, _ = oscparse.first_number(message)
                except oscparse.Malformed:
                    continue
                if value is not None and address.startswith("/walk/"):
                    taken += hub.apply(state, ControlEvent(0.0, "osc", address[6:], value))
        except oscparse.Malformed:
            pass
        assert all(math.isfinite(v) for v in (state.speed, state.turn, state.liveliness, *state.weights, *state.state_scale))
    assert taken > 0 and tried == 20000


def test_a_live_show_survives_an_osc_packet_fuzzer(model, tmp_path):
    """Thousands of mutated packets at a running show: every frame is made, the recording is a
    valid BVH, the log holds only accepted finite events and replays."""
    rng = random.Random(SEED + 1)
    port, receiver = free_port(), Receiver()
    log, bvh = tmp_path / "fuzz.jsonl", tmp_path / "fuzz.bvh"
    process = subprocess.Popen(RUN + ["--osc-in", str(port), "--osc", f"127.0.0.1:{receiver.port}/flat", "--seconds", "12",
                                      "--record", str(log), "--bvh", str(bvh)], stderr=subprocess.PIPE, text=True)
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    packets, sent = valid_packets(model), 0
    try:
        wait_until(lambda: bvh_frames(bvh) >= 10, "the show's first frames")
        while process.poll() is None and sent < 6000:
            for _ in range(50):
                packet = rng.choice(packets)
                sender.sendto(mutate(rng, packet) if rng.random() < 0.9 else packet, ("127.0.0.1", port))
                sent += 1
            time.sleep(0.01)
        stderr = process.communicate(timeout=120)[1]
    finally:
        sender.close()
        receiver.close()
    assert process.returncode == 0, stderr
    assert "Traceback" not in stderr
    assert sent >= 1000
    assert assert_valid_bvh(bvh) == 360  # every frame of the 12 s
    events = read_log(log)
    assert events and all(math.isfinite(e.value) for e in events)
    assert "refused" in stderr.splitlines()[-1]


# --- MIDI: a byte fuzzer through JACK -----------------------------------------------------------


def test_a_live_show_survives_a_midi_byte_fuzzer_over_jack(jack, tmp_path):
    from test_controllers import NANO, wait_for_port

    rng = random.Random(SEED + 2)
    bvh, log = tmp_path / "midi.bvh", tmp_path / "midi.jsonl"
    process = subprocess.Popen(RUN + ["--midi-virtual", "fault-fuzz", "--midi-api", "jack", "--mapping", NANO, "--no-osc",
                                      "--seconds", "10", "--bvh", str(bvh), "--record", str(log)],
                               stderr=subprocess.PIPE, text=True)
    import rtmidi

    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, name="fault-fuzzer")
    sent = 0
    try:
        name = wait_for_port(jack, "fault-fuzz", timeout=60)
        out.open_port(out.get_ports().index(name))
        wait_until(lambda: bvh_frames(bvh) >= 10, "the show's first frames")
        while process.poll() is None and sent < 5000:
            status = rng.choice([0xB0, 0x90, 0x80, 0xE0, 0xA0, 0xC0, 0xD0]) | rng.randrange(16)
            length = rng.choice([1, 2, 3, 3, 3])
            message = [status] + [rng.randrange(128) for _ in range(length - 1)]
            try:
                out.send_message(message)
                sent += 1
            except Exception:  # rtmidi refuses some shapes itself; that is the sender's business
                pass
            if sent % 100 == 0:
                time.sleep(0.01)
        stderr = process.communicate(timeout=120)[1]
    finally:
        out.delete()
    assert process.returncode == 0, stderr
    assert "Traceback" not in stderr
    assert sent >= 1000
    assert assert_valid_bvh(bvh) == 300
    assert all(math.isfinite(e.value) and e.source == "midi:fault-fuzz" for e in read_log(log))


# --- logs and show files, mutated ---------------------------------------------------------------


def good_log(tmp_path: Path, model) -> Path:
    path = tmp_path / "good.jsonl"
    events = [ControlEvent(0.1 * k, "osc", target, value) for k, (target, value) in enumerate(
        [("speed", 1.5), (f"style/{model.style_names[0]}", 1.0), ("turn", 0.5), ("phase/1", 2.0), ("liveliness", 1.0)] * 4)]
    path.write_text("".join(e.to_json() + "\n" for e in events))
    return path


def test_a_log_cut_mid_line_replays_up_to_the_cut_with_a_warning(model, tmp_path, capsys):
    text = good_log(tmp_path, model).read_text()
    cut = tmp_path / "cut.jsonl"
    cut.write_text(text[: text.rindex("\n", 0, len(text) - 1) + 20])  # the last line stops after 19 characters
    warnings = []
    events = read_log(cut, warn=warnings.append)
    assert len(events) == text.count("\n") - 1 and len(warnings) == 1 and ":20:" in warnings[0]
    code = main(["run", "--replay", str(cut), "--no-osc", "--fast", "--quiet"])
    err = capsys.readouterr().err
    assert code == 0 and "cut off" in err


def test_mutated_logs_give_a_one_line_error_or_replay_with_warnings(model, tmp_path, capsys):
    rng = random.Random(SEED + 3)
    text = good_log(tmp_path, model).read_text()
    lines = text.splitlines()
    swaps = ['"value": NaN', '"value": "abc"', '"value": 1e999', '"value": 10' + "0" * 400, '"value": true', '"value": null',
             '"control": "phase/\\u00b2"', '"control": "cc/x/99"', '"source": "midi:x"', '"t": -1', '"t": "x"',
             '"control": 5', '"source": null']
    outcomes = {0: 0, 1: 0}
    for trial in range(40):
        mutated = list(lines)
        k = rng.randrange(len(mutated))
        choice = rng.randrange(4)
        if choice == 0:
            key = rng.choice(swaps)
            mutated[k] = re.sub(r'"' + key.split('"')[1] + r'": [^,}]+', key, mutated[k])
        elif choice == 1:
            mutated[k] = mutated[k][: rng.randrange(len(mutated[k]))]
        elif choice == 2:
            mutated[k] = "".join(chr(rng.randrange(32, 0x2FF)) for _ in range(rng.randint(1, 30)))
        else:
            mutated[k] = "[" * 100000  # deep nesting
        path = tmp_path / f"mutated{trial}.jsonl"
        path.write_text("\n".join(mutated) + "\n")
        code = main(["run", "--replay", str(path), "--no-osc", "--fast", "--quiet", "--mapping",
                     str(REPO / "mappings" / "akai-midimix.toml")])
        err = capsys.readouterr().err
        outcomes[code] += 1
        assert code in (0, 1), err
        if code == 1:
            assert err.count("\n") == 1 and f"{path}:" in err, err
    assert outcomes[0] and outcomes[1]  # both kinds of mutation were tried


def test_mutated_show_files_give_a_one_line_error_or_a_show(model, tmp_path, capsys):
    rng = random.Random(SEED + 4)
    style = model.style_names[0]
    show = (f'seconds = 1\nfps = 30\nno-osc = true\nfast = true\nquiet = true\n'
            f'[presets.calm]\n"style/{style}" = 0.5\nspeed = 0.8\n')
    replacements = ["seconds = -1", 'seconds = "x"', "fps = 1000", "fps = nan", "no-osc = 3", "fast = []",
                    '"style/nobody" = 1', "speed = nan", "speed = inf", 'speed = "fast"', "[presets.calm.x]", "volume = 11",
                    "seconds = 1e999", "= 1", "[[presets]]"]
    for trial in range(30):
        lines = show.splitlines()
        k = rng.randrange(len(lines))
        if rng.random() < 0.7:
            lines[k] = rng.choice(replacements)
        else:
            lines[k] = lines[k][: rng.randrange(len(lines[k]) + 1)] + rng.choice(["\x00", "\xff", "'", '"', "[", "é"])
        path = tmp_path / f"show{trial}.toml"
        path.write_text("\n".join(lines) + "\n")
        code = main(["run", "--config", str(path)])
        err = capsys.readouterr().err
        assert_one_line_error_or_success(code, err)
        if code == 1:
            assert err.count("\n") == 1, err


# --- signals at random times, start-up included -------------------------------------------------


def random_stop_moment(rng: random.Random, path: Path) -> None:
    """Wait until a random moment: half the time during start-up (Python loading, the model,
    the first frame's compilation), half the time into the show (up to a second of frames)."""
    if rng.random() < 0.5:
        time.sleep(rng.uniform(0.0, 3.0))
    else:
        wait_until(lambda: bvh_frames(path) >= 1, "the first frame", timeout=120)
        time.sleep(rng.uniform(0.0, 1.0))


# how a show stopped by a signal may end: done; stopped while it loaded (130, 143: cli/main.py);
# or killed by the signal itself in the interpreter's first tens of milliseconds, before Python
# ran a line of it (-2, -15: measured with the signal sent 0 to 30 ms after the start)
SIGNAL_EXITS = (0, 128 + signal.SIGINT, 128 + signal.SIGTERM, -signal.SIGINT, -signal.SIGTERM)


def signal_trial(rng: random.Random, path: Path) -> tuple[int, str]:
    """A show recording BVH to `path`, stopped by SIGINT or SIGTERM at a random moment
    (`random_stop_moment`): its exit status and stderr (this test's trial, and the soak's:
    examples/fault_soak.py)."""
    process = subprocess.Popen(RUN + ["--no-osc", "--bvh", str(path), "--fast", "--seconds", "600", "--quiet"],
                               stderr=subprocess.PIPE, text=True)
    random_stop_moment(rng, path)
    process.send_signal(rng.choice([signal.SIGINT, signal.SIGTERM]))
    stderr = process.communicate(timeout=120)[1]
    return process.returncode, stderr


def test_signals_at_random_times_leave_a_valid_bvh_or_none(tmp_path):
    rng = random.Random(SEED + 5)
    for trial in range(8):
        path = tmp_path / f"take{trial}.bvh"
        code, stderr = signal_trial(rng, path)
        assert "Traceback" not in stderr, stderr
        assert code in SIGNAL_EXITS, stderr
        if path.exists():
            assert assert_valid_bvh(path) >= 1
        else:
            assert code != 0 or "before the first frame" in stderr or stderr == ""


# Sends the process a signal the moment `instrument.cli.run_cmd` is about to be imported: the
# deterministic version of a Ctrl-C while the command line loads.
SIGNAL_ON_IMPORT = """
import os, sys
class SignalOnImport:
    def find_spec(self, name, path=None, target=None):
        if name == "instrument.cli.run_cmd":
            os.kill(os.getpid(), {signum})
        return None
sys.meta_path.insert(0, SignalOnImport())
sys.argv = ["instrument", *{arguments!r}]
"""
ENTRY_POINTS = {
    "python -m instrument": "import runpy; runpy.run_module('instrument', run_name='__main__', alter_sys=True)",
    "console script": "from instrument.cli.main import main; sys.exit(main())",  # what pip's `instrument` script runs
}


@pytest.mark.parametrize("entry", ENTRY_POINTS)
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_signal_while_the_command_loads_ends_it_quietly_with_nothing_written(tmp_path, entry, signum):
    bvh, log = tmp_path / "take.bvh", tmp_path / "take.jsonl"
    arguments = ["run", "--no-osc", "--fast", "--seconds", "5", "--bvh", str(bvh), "--record", str(log)]
    code = SIGNAL_ON_IMPORT.format(signum=int(signum), arguments=arguments) + ENTRY_POINTS[entry]
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert "Traceback" not in result.stderr, result.stderr
    assert result.stderr == "" and result.stdout == ""
    assert result.returncode == 128 + signum  # 130 for Ctrl-C, 143 for SIGTERM: `instrument --help` says so
    assert not bvh.exists() and not log.exists()
    assert list(tmp_path.iterdir()) == []


# --- a device or an event that raises in the live loop ------------------------------------------


def test_a_device_poll_or_an_event_that_raises_is_counted_and_the_show_goes_on(model):
    import io

    from instrument.terminal import Console
    from instrument.runtime.performance import Show, perform

    state = ControlState(model.style_names, model.states)
    hub = ControlHub([], console=Console(quiet=True))
    polls = []

    def unplugged_mid_read(now: float) -> list[ControlEvent]:  # a device whose read fails every time
        polls.append(now)
        raise OSError(5, "Input/output error")

    def surface(now: float) -> list[ControlEvent]:  # a working source: speed up, one event that breaks apply
        return [ControlEvent(now, "osc", "speed", 1.0 + now), *([ControlEvent(now, "osc", "explode", 1.0)] if now == 0.5 else [])]

    def apply(state: ControlState, event: ControlEvent) -> bool:
        if event.control == "explode":
            raise ValueError("an event nobody foresaw")
        return hub.apply(state, event)

    frames, said = FrameIndices(), io.StringIO()
    show = Show(model, [frames], fps=30, seconds=1.0, fast=True, apply=apply, state=state,
                sources=[unplugged_mid_read, surface])
    summary = perform(show, Console(stream=said))
    assert frames.indices == list(range(30))  # every frame made
    assert summary.input_errors == {f"poll {unplugged_mid_read.__qualname__}": len(polls), "apply osc": 1}
    assert len(polls) >= 15  # polled at every look whose backlog was empty (a busy machine leaves some for the next)
    assert state.speed > 1.9  # the working source's events reached the walk, after the failures too
    lines = said.getvalue().splitlines()
    assert sum("OSError" in line and "the walk goes on" in line for line in lines) == 1  # said once, not every frame
    assert sum("apply osc failed: ValueError: an event nobody foresaw" in line for line in lines) == 1


# --- the console: closed, stalled ----------------------------------------------------------------


def stalled_pipe() -> tuple[int, int]:
    """A pipe already full, that nobody reads: a write to it blocks."""
    read_end, write_end = os.pipe()
    os.set_blocking(write_end, False)
    try:
        while True:
            os.write(write_end, b"x" * 4096)
    except BlockingIOError:
        pass
    os.set_blocking(write_end, True)
    return read_end, write_end


def test_a_stalled_stderr_never_freezes_the_show_and_sigterm_still_works(tmp_path):
    read_end, write_end = stalled_pipe()
    path = tmp_path / "take.bvh"
    try:
        process = subprocess.Popen(RUN + ["--no-osc", "--bvh", str(path), "--fps", "120"], stderr=write_end)
        os.close(write_end)
        wait_until(lambda: bvh_frames(path) >= 1200, "ten seconds of frames with stderr stalled", timeout=120)
        process.send_signal(signal.SIGTERM)
        assert process.wait(30) == 0
    finally:
        os.close(read_end)
    assert assert_valid_bvh(path) >= 1200


@pytest.mark.parametrize("how", ["head", "closed"])
def test_a_closed_stderr_never_stops_the_show(tmp_path, how):
    path = tmp_path / "take.bvh"
    if how == "head":  # `instrument run 2>&1 | head -3`
        command = f"{' '.join(RUN)} --no-osc --seconds 4 --bvh {path} 2>&1 | head -3"
        result = subprocess.run(["bash", "-c", command], capture_output=True, text=True, timeout=120)
        assert len(result.stdout.splitlines()) == 3
    else:  # `2>&-`
        result = subprocess.run(["bash", "-c", f"{' '.join(RUN)} --no-osc --seconds 4 --bvh {path} 2>&-"], timeout=120)
    assert result.returncode == 0
    assert assert_valid_bvh(path) == 120


# --- JACK restart mid-show ----------------------------------------------------------------------


def private_jack(tmp_path: Path, monkeypatch, port: str):
    """What both JACK-restart tests start from: rtmidi; the name of a private server (the shared
    one is never killed), which every JACK client made from here on uses; its log file; and a
    mapping of CC 1 on the MIDI device `port` to speed."""
    if shutil.which("jackd") is None:
        pytest.skip("JACK is not installed (apt-get install jackd2)")
    import rtmidi

    server_name = f"instrument-test-{port}"  # a fixed name: jackd frees a killed one's registry slot at its next start
    monkeypatch.setenv("JACK_DEFAULT_SERVER", server_name)
    monkeypatch.setenv("JACK_NO_START_SERVER", "1")
    mapping = tmp_path / "speed.toml"
    mapping.write_text(f'[device]\nmidi = "{port}"\n[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "speed"\n'
                       'range = [0.25, 4.0]\n')
    return rtmidi, server_name, tmp_path / "jackd.txt", mapping


def test_a_killed_private_server_leaves_no_registry_slot_behind(tmp_path, monkeypatch):
    """The restart tests' upkeep: JACK has 8 server slots, and a killed server's slot outlives it
    (CI failed once all were taken); the next start frees it."""
    rtmidi, server_name, jackd_log, _ = private_jack(tmp_path, monkeypatch, "fault-slot")
    server = start_private_jack(rtmidi, server_name, jackd_log)
    server.kill()
    server.wait(30)
    assert registered_servers().get(server_name) == server.pid  # the dead server's slot, still taken
    assert server_name in free_dead_slots(jackd_log)
    assert server_name not in registered_servers()
    assert all(alive(pid) for pid in registered_servers().values())


def test_a_jack_server_restart_mid_show_is_recovered(tmp_path, monkeypatch):
    rtmidi, server_name, jackd_log, mapping = private_jack(tmp_path, monkeypatch, "fault-restart")

    def start_server() -> subprocess.Popen:
        return start_private_jack(rtmidi, server_name, jackd_log)

    def port_listed() -> str | None:
        return jack_port_listed(rtmidi, "fault-restart")

    receiver, log, errors = Receiver(), tmp_path / "take.jsonl", tmp_path / "stderr.txt"
    server = start_server()
    process = None
    try:
        assert port_listed() is None
        with errors.open("w") as sink:  # a file, not a pipe: a pipe nobody reads would stall the show once full
            process = subprocess.Popen(RUN + ["--midi-virtual", "fault-restart", "--midi-api", "jack", "--mapping",
                                              str(mapping), "--osc", f"127.0.0.1:{receiver.port}/flat", "--seconds", "600",
                                              "--record", str(log)], stderr=sink, text=True)

        def speed_becomes(value: float) -> None:
            def sent_and_seen():
                time.sleep(0.5)  # every look is a new JACK client, which the server tells every other one of
                name = port_listed()
                if name is None:
                    return False
                try:
                    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, name="fault-sender")
                except Exception:  # the server is busy or between lives: look again
                    return False
                try:
                    ports = out.get_ports()
                    if name not in ports:
                        return False
                    out.open_port(ports.index(name))
                    out.send_message([0xB0, 1, round((value - 0.25) / 3.75 * 127)])
                    time.sleep(0.3)
                finally:
                    out.delete()
                speeds = [p[0] for a, p in receiver.messages() if a == "/walk/speed"]
                return speeds and abs(speeds[-1] - value) < 1e-3
            try:
                wait_until(sent_and_seen, f"speed {value} through JACK", timeout=120)
            except AssertionError as failure:
                raise AssertionError(f"{failure}; the show is {'on' if process.poll() is None else 'over'}, "
                                     f"it said: {errors.read_text()[-2000:]}") from None

        speed_becomes(4.0)
        stop_private_jack(server)
        server = start_server()
        speed_becomes(0.25)  # the virtual port was made again on the new server

        def feedback_listed() -> bool:
            time.sleep(0.5)
            try:
                probe = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, name="fault-probe")
            except Exception:
                return False
            try:
                return any("fault-restart feedback" in n for n in probe.get_ports())
            finally:
                probe.delete()
        wait_until(feedback_listed, "the feedback port made again", timeout=120)
        frames_before_end = len([1 for a, _ in receiver.messages() if a == "/walk/frame"])
        process.send_signal(signal.SIGTERM)
        process.wait(timeout=60)
        stderr = errors.read_text()
    finally:
        if process is not None and process.poll() is None:
            process.kill()
        stop_private_jack(server)
        receiver.close()
    assert process.returncode == 0, stderr
    assert "JACK server went away" in stderr and "on again" in stderr
    assert "waiting for the JACK server" in stderr  # the status line said so meanwhile
    frames = [p[0] for a, p in receiver.messages() if a == "/walk/frame"]
    assert frames == list(range(len(frames))) and len(frames) >= frames_before_end  # the walk never stopped
    assert [e.value for e in read_log(log)][-1] == 0.0


# a MIDI controller's stand-in: its own JACK client with an output port, sending a CC 1 of each
# value read from stdin; it dies with its server, as a hardware bridge's client does
SENDER = """
import sys
import rtmidi
out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, name="fault-sender")
out.open_virtual_port("fault-pattern-out")
for line in sys.stdin:
    out.send_message([0xB0, 1, int(line)])
"""


def test_a_jack_server_restart_with_midi_pattern_reconnects_to_the_port(tmp_path, monkeypatch):
    """As the test above, with `--midi PATTERN`: the instrument reads another client's port, which
    comes back (made again by its owner) after the server's restart."""
    rtmidi, server_name, jackd_log, mapping = private_jack(tmp_path, monkeypatch, "fault-pattern")
    receiver, log, errors = Receiver(), tmp_path / "take.jsonl", tmp_path / "stderr.txt"
    senders: list[subprocess.Popen] = []

    def new_sender() -> subprocess.Popen:
        def made() -> subprocess.Popen | None:
            sender = subprocess.Popen([sys.executable, "-c", SENDER], stdin=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
            senders.append(sender)
            until = time.monotonic() + 20
            while sender.poll() is None and time.monotonic() < until:
                time.sleep(0.5)  # every look is a new JACK client, which the server tells every other one of
                if jack_port_listed(rtmidi, "fault-pattern-out", readable=True):
                    return sender
            sender.kill()  # the server was busy: a new sender
            sender.wait(30)
            return None
        return wait_until(made, "the sender's port on the JACK server", timeout=120)

    def speed_becomes(sender: subprocess.Popen, value: float) -> None:
        def sent_and_seen() -> bool:
            time.sleep(0.5)
            try:
                sender.stdin.write(f"{round((value - 0.25) / 3.75 * 127)}\n")
                sender.stdin.flush()
            except (BrokenPipeError, OSError):
                return False
            time.sleep(0.3)
            speeds = [p[0] for a, p in receiver.messages() if a == "/walk/speed"]
            return bool(speeds) and abs(speeds[-1] - value) < 1e-3
        try:
            wait_until(sent_and_seen, f"speed {value} through JACK", timeout=120)
        except AssertionError as failure:
            raise AssertionError(f"{failure}; the show is {'on' if process.poll() is None else 'over'}, "
                                 f"it said: {errors.read_text()[-2000:]}") from None

    server = start_private_jack(rtmidi, server_name, jackd_log)
    process = None
    try:
        sender = new_sender()
        with errors.open("w") as sink:  # a file, not a pipe: a pipe nobody reads would stall the show once full
            process = subprocess.Popen(RUN + ["--midi", "fault-pattern-out", "--midi-api", "jack", "--no-feedback",
                                              "--mapping", str(mapping), "--osc", f"127.0.0.1:{receiver.port}/flat",
                                              "--seconds", "600", "--record", str(log)], stderr=sink, text=True)
        speed_becomes(sender, 4.0)
        stop_private_jack(server)
        sender.kill()  # its client died with the server: its owner makes the port again on the new one
        sender.wait(30)
        server = start_private_jack(rtmidi, server_name, jackd_log)
        sender = new_sender()
        speed_becomes(sender, 0.25)  # the instrument found the port again and reads it

        def on_again() -> bool:  # a status line after the reconnect line says the port is on
            said = errors.read_text().splitlines()
            back = [n for n, line in enumerate(said) if re.search(r"MIDI input '[^']*fault-pattern-out' connected", line)]
            return bool(back) and any(line.startswith("frame ") and line.endswith("fault-pattern-out on")
                                      for line in said[back[-1]:])
        wait_until(on_again, "a status line saying the port is on again", timeout=120)
        process.send_signal(signal.SIGTERM)
        process.wait(timeout=60)
        stderr = errors.read_text()
    finally:
        if process is not None and process.poll() is None:
            process.kill()
        for sender in senders:  # the live one ends cleanly (its client leaves the server), others are gone
            sender.stdin.close()
            try:
                sender.wait(30)
            except subprocess.TimeoutExpired:
                sender.kill()
                sender.wait(30)
        stop_private_jack(server)
        receiver.close()
    assert process.returncode == 0, stderr
    assert "JACK server went away" in stderr
    assert re.search(r"MIDI input '[^']*fault-pattern-out' connected", stderr), stderr[-2000:]  # the reconnect line
    status = [line for line in stderr.splitlines() if line.startswith("frame ")]
    assert "fault-pattern-out waiting" in stderr or "waiting for the JACK server" in stderr  # meanwhile
    assert status and status[-1].endswith("fault-pattern-out on"), status[-1:]  # and true again after
    frames = [p[0] for a, p in receiver.messages() if a == "/walk/frame"]
    assert frames == list(range(len(frames)))  # the walk never stopped
    assert [e.value for e in read_log(log)][-1] == 0.0


# --- a storm of big bundles ---------------------------------------------------------------------


def test_a_storm_of_60_kb_bundles_is_taken_whole_without_stopping_the_show(tmp_path):
    port, receiver = free_port(), Receiver()
    log, bvh = tmp_path / "storm.jsonl", tmp_path / "storm.bvh"
    # a long show, stopped once every bundle is taken: a busy machine takes them more slowly, and
    # what is tested is that none is lost and no frame stops, not how soon they are taken
    process = subprocess.Popen(RUN + ["--osc-in", str(port), "--osc", f"127.0.0.1:{receiver.port}/flat", "--seconds", "600",
                                      "--record", str(log), "--bvh", str(bvh)], stderr=subprocess.PIPE, text=True)
    messages = [osc_message("/walk/speed", 1.0 + (k % 100) / 100) for k in range(2500)]
    bundle = b"#bundle\0" + struct.pack(">Q", 1) + b"".join(struct.pack(">i", len(m)) + m for m in messages)
    assert 60_000 <= len(bundle) <= 65_507
    sender = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        wait_until(lambda: bvh_frames(bvh) >= 30, "the show's first second")
        for k in range(10):
            sender.sendto(bundle, ("127.0.0.1", port))
            taken = (k + 1) * len(messages)
            wait_until(lambda: log.exists() and log.stat().st_size > 0 and _lines(log) >= taken, f"bundle {k + 1} taken")
        process.send_signal(signal.SIGINT)
        stderr = process.communicate(timeout=120)[1]
    finally:
        if process.poll() is None:
            process.kill()
        sender.close()
        receiver.close()
    assert process.returncode == 0, stderr
    assert assert_valid_bvh(bvh) >= 30  # the show went on through the storm, and its recording is whole
    assert len(read_log(log)) == 10 * len(messages)  # nothing lost
    print(stderr.splitlines()[-1])  # late and dropped frames: figures for docs/robustness.md, not asserted


def _lines(path: Path) -> int:
    with open(path, "rb") as f:
        return f.read().count(b"\n")


# --- a renderer whose name resolves only later -------------------------------------------------


def test_a_target_name_that_does_not_resolve_yet_is_tried_until_it_does(capsys):
    """The network's name service is the one stand-in here (a test must not send DNS queries
    off the machine): it answers as glibc does for an unknown name until the renderer is "on"."""
    from instrument.output.osc import OscTarget, UdpOut
    from instrument.terminal import Console

    receiver = Receiver()
    switched_on = [False]
    asked = []

    def lookup(host, port, type=0):
        asked.append(host)
        if not switched_on[0]:
            raise socket.gaierror(socket.EAI_NONAME, "Name or service not known")
        return socket.getaddrinfo("127.0.0.1", port, type=type)

    out = UdpOut(OscTarget("renderer.venue", receiver.port, "flat"), Console(), lookup=lookup)
    try:
        for _ in range(20):
            out.send([osc_message("/walk/frame", 0)])  # dropped, never raised
        assert "cannot resolve 'renderer.venue' yet" in capsys.readouterr().err
        wait_until(lambda: len(asked) >= 2, "a second try of the name", timeout=30)
        switched_on[0] = True

        def arrived():
            out.send([osc_message("/walk/frame", 1)])
            return any(a == "/walk/frame" and p == [1] for a, p in receiver.messages())
        wait_until(arrived, "frames reaching the renderer once its name resolves", timeout=30)
    finally:
        out.close()
        receiver.close()
    assert not any(p == [0] for a, p in receiver.messages() if a == "/walk/frame")
    assert "resolved to 127.0.0.1" in capsys.readouterr().err


# --- the console and the log in-process ---------------------------------------------------------


def test_console_lines_to_a_stalled_pipe_are_queued_then_dropped_never_blocking():
    import threading

    from instrument import terminal as console_module
    from instrument.terminal import Console

    read_end, write_end = stalled_pipe()
    stream = os.fdopen(write_end, "w")
    console = Console(stream=stream)
    finished = threading.Event()

    def speak():
        for k in range(console_module.QUEUE_LIMIT + 500):
            console.say(f"line {k}")
        finished.set()

    threading.Thread(target=speak, daemon=True).start()
    assert finished.wait(60), "the console blocked its caller"
    assert console.dropped > 0 and len(console.pending) == console_module.QUEUE_LIMIT  # the rest: dropped, counted
    assert not console.flush(timeout=0.2)  # still stuck: the lines wait in the writer, not in the caller
    os.close(read_end)  # the reader goes away: the writer finds the pipe closed and gives up quietly
    wait_until(lambda: console.closed, "the console noticing the closed pipe")
    console.say("after")  # dropped, not raised


def test_the_event_log_stops_at_its_limit_and_counts_what_it_lost(tmp_path, monkeypatch):
    from instrument.control import eventlog

    monkeypatch.setattr(eventlog, "LIMIT", 10_000)
    log = eventlog.EventLog(tmp_path / "take.jsonl", '{"instrument_log": 1, "mappings": []}')
    events = [ControlEvent(k / 30, "osc", "speed", 1.0 + k / 1000) for k in range(1000)]
    for event in events:
        log.write(event)
    log.close()
    kept = read_log(tmp_path / "take.jsonl")
    assert (tmp_path / "take.jsonl").stat().st_size <= 10_000
    assert len(kept) + log.lost == len(events) and log.lost > 0 and "limit" in log.error
    assert kept == events[: len(kept)]  # what was kept is the start, in order, whole lines


def test_the_console_names_each_subject_once_a_minute_and_at_most_a_few_subjects_of_a_kind():
    """Warnings are throttled per kind and subject (the address, control or device): each
    distinct subject is said once a minute, its repeats not; a flood of distinct subjects of one
    kind says SUBJECTS_PER_KEY of them a minute, not thousands of lines."""
    import io

    from instrument.terminal import SUBJECTS_PER_KEY, Console

    clock = [0.0]
    out = io.StringIO()
    console = Console(stream=out, now=lambda: clock[0])
    assert console.warn("osc-in address", "bad /a", subject="/a")
    assert not console.warn("osc-in address", "bad /a", subject="/a")  # a repeat: counted by the caller
    assert console.warn("osc-in address", "bad /b", subject="/b")  # another address: named
    assert console.warn("refused osc unknown target", "bad /a", subject="/a")  # another kind: its own
    said = sum(console.warn("osc-in address", f"bad /x{k}", subject=f"/x{k}") for k in range(1000))
    assert said == SUBJECTS_PER_KEY - 2
    clock[0] = 61.0  # a minute on: said again
    assert console.warn("osc-in address", "bad /a", subject="/a") and console.warn("osc-in address", "bad /x999", subject="/x999")
    assert out.getvalue().count("warning:") == 2 + 1 + SUBJECTS_PER_KEY - 2 + 2
