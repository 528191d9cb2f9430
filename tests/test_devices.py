"""Devices as one protocol: the kind rule shared by the hub and the log reader, HID replays, one
mapper per device (two real JACK MIDI ports), MIDI read through mido, and a toy device registered
from this file that drives the walk."""

from __future__ import annotations

import filecmp
import json

import pytest

from conftest import REPO
from hid_sim import SimulatedDevice, SimulatedHid
from test_hid import MADE_UP_JOYSTICK, joystick_report

from instrument.control import hid as hid_module

GENERIC = str(REPO / "mappings" / "generic-gamepad.toml")


def run(*args: str) -> int:
    from instrument.cli.main import main

    return main(["run", "--no-osc", "--quiet", "--normal-priority", *args])


def test_a_hid_session_replays_with_the_mapping_it_needs(monkeypatch, tmp_path):
    """A joystick no mapping names, played through the generic gamepad (chosen by usages), is
    recorded; its log replays to the same BVH with --mapping and from the log's own header."""
    stick = SimulatedDevice(MADE_UP_JOYSTICK, 0x16C0, 0x05DC, "Knob box", usage=(1, 4))
    monkeypatch.setattr(hid_module, "hidapi", lambda: SimulatedHid(stick))
    # a moment at rest, full forward (speed up), then hard right (turn), each held for some frames
    stick.send(*[None] * 5, joystick_report(y=0), *[None] * 20, joystick_report(x=1023, y=0), *[None] * 20,
               joystick_report(x=512, y=512, buttons=1))
    log, live, again, header = (tmp_path / n for n in ("pad.jsonl", "live.bvh", "replay.bvh", "header.bvh"))
    assert run("--hid", "16c0:05dc", "--mapping", GENERIC, "--fast", "--seconds", "3", "--record", str(log),
               "--bvh", str(live)) == 0
    lines = log.read_text().splitlines()
    controls = {json.loads(line)["control"] for line in lines[1:-1]}  # the last line: where the run stopped
    assert {"X", "Y", "Button 1"} <= controls and all('"hid:16c0:05dc"' in line for line in lines[1:-1])
    assert json.loads(lines[-1]) == {"end": 3.0}
    assert run("--replay", str(log), "--mapping", GENERIC, "--fast", "--seconds", "3", "--bvh", str(again)) == 0
    assert filecmp.cmp(live, again, shallow=False)
    assert run("--replay", str(log), "--fast", "--seconds", "3", "--bvh", str(header)) == 0  # the header's mapping
    assert filecmp.cmp(live, header, shallow=False)
    still = tmp_path / "still.jsonl"  # the same header, no events: a different walk, so the equality above says something
    still.write_text(lines[0] + "\n")
    assert run("--replay", str(still), "--fast", "--seconds", "3", "--bvh", str(tmp_path / "still.bvh")) == 0
    assert not filecmp.cmp(live, tmp_path / "still.bvh", shallow=False)


class Watch:
    """An output that keeps each frame's speed and turn, and stops the show once `done` says so."""

    name = "watch"

    def __init__(self, done=lambda seen: False):
        from instrument.runtime.stopping import StopFlag

        self.seen: list[tuple[int, float, float]] = []
        self.done, self.stop = done, StopFlag()

    def prepare(self, frame):
        return frame.index, frame.echo["speed"], frame.echo["turn"]

    def send(self, values):
        self.seen.append(values)
        if self.done(self.seen):
            self.stop.request()

    def close(self):
        pass


def test_two_midi_controllers_each_play_through_their_own_mapping(jack, model, tmp_path):
    """Two JACK MIDI ports, two mappings that both use CC 1 of channel 1: the left one's drives
    the speed, the right one's the turn; the log replays to the same frames."""
    import mido
    from test_controllers import wait_for_port

    from instrument.control.devices import MidiInput
    from instrument.control.events import LogReplay, read_log
    from instrument.control.hub import ControlHub
    from instrument.control.loghead import logged_mappings, logged_per_device
    from instrument.control.mapping import load_mapping
    from instrument.control.state import ControlState
    from instrument.terminal import Console
    from instrument.runtime.performance import Show, perform

    state = ControlState(model.style_names, model.states)
    files = []
    for side, target, low, high in (("left", "speed", 0.5, 1.5), ("right", "turn", -1.0, 1.0)):
        path = tmp_path / f"{side}.toml"
        path.write_text(f'name = "{side}"\n[device]\nmidi = "instr-{side}"\n'
                        f'[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "{target}"\nrange = [{low}, {high}]\n')
        files.append(path)
    mappings = [load_mapping(f, state) for f in files]
    console, log = Console(quiet=True), tmp_path / "two.jsonl"
    left, right = (MidiInput(console, virtual=f"instr-{side}", api="jack") for side in ("left", "right"))
    senders = [jack.open_output(wait_for_port(jack, f"instr-{side}")) for side in ("left", "right")]
    try:
        hub = ControlHub(mappings, record=log, console=console)

        def send_both() -> None:
            senders[0].send(mido.Message("control_change", channel=0, control=1, value=127))  # speed 1.5
            senders[1].send(mido.Message("control_change", channel=0, control=1, value=0))  # turn -1

        def resend(now: float) -> list:
            """A message sent while JACK still makes the new connection can be lost (the left
            one's was, once in a CI run): the faders' positions go again each half second until
            the show has both, as a controller's keep coming while they move."""
            if watch.seen and len(watch.seen) % 15 == 0 and watch.seen[-1][1:] != (1.5, -1.0):
                send_both()
            return []

        send_both()
        watch = Watch(lambda seen: seen[-1][1] == 1.5 and seen[-1][2] == -1.0)
        show = Show(model, [watch], fps=30, seconds=120.0, apply=hub.apply, state=state,
                    sources=[resend, left.poll, right.poll])
        perform(show, console, stop=watch.stop)
        hub.close()
    finally:
        for thing in senders + [left, right]:
            thing.close()
    assert watch.seen[-1][1:] == (1.5, -1.0)  # both arrived (else the show ran its two minutes)
    assert {e.source for e in read_log(log)} == {"midi:instr-left", "midi:instr-right"}
    assert hub.refused == {}
    # the log carries both mappings; replayed, each device's events go to its own again
    again = ControlState(model.style_names, model.states)
    replay_hub = ControlHub(logged_mappings(log, again), per_device=logged_per_device(log))
    echo = Watch()
    show = Show(model, [echo], fps=30, seconds=len(watch.seen) / 30, replay=LogReplay(read_log(log)), fast=True,
                apply=replay_hub.apply, state=again)
    perform(show, console)
    assert echo.seen == watch.seen


class Knob:
    """A toy device, written here and nowhere in the package: one knob, turned by the test, read
    as 0 to 127 (the device protocol of instrument/control/kinds.py)."""

    def __init__(self):
        from instrument.control.events import Source

        self.source = Source.of("toy", "knob")
        self.turns: list[float] = []

    def poll(self, now: float):
        from instrument.control.events import RawEvent

        events, self.turns = [RawEvent(now, self.source, "knob", value) for value in self.turns], []
        return events

    def describe(self) -> str:
        return "toy knob"

    def close(self) -> None:
        pass


class KnobDecoder:
    """The toy kind's decoder: the knob, 0 to 127, is the speed from 0.6 to 1.6."""

    def __init__(self, mapping, hub):
        self.hub = hub

    def apply(self, state, event):
        from instrument.control.events import TargetEvent

        if event.control != "knob" or not 0 <= event.value <= 127:
            return "not a knob turn"
        return self.hub.apply_target(state, TargetEvent(event.time, "speed", 0.6 + event.value / 127))


def test_a_toy_device_registered_from_a_test_file_drives_the_walk(model, tmp_path):
    from test_controllers import frames_and_echo

    from instrument.control import kinds
    from instrument.control.events import LogReplay, read_log
    from instrument.control.hub import ControlHub
    from instrument.control.state import ControlState
    from instrument.output.osc import OscTarget
    from instrument.output.outputs import OscOutput, make_profile
    from instrument.terminal import Console
    from instrument.runtime.performance import Show, perform
    from oscrecv import Receiver
    from waiting import wait_until

    kinds.register(kinds.DeviceKind("toy", "toy", KnobDecoder))
    receiver, knob, console, log = Receiver(), Knob(), Console(quiet=True), tmp_path / "knob.jsonl"
    try:
        state = ControlState(model.style_names, model.states)
        hub = ControlHub([], record=log, console=console)

        def turn(seen):  # the performer: full up at frame 10, down at frame 30, a bad turn at 31
            index = seen[-1][0]
            knob.turns += {10: [127.0], 30: [0.0], 31: [500.0]}.get(index, [])
            return False

        watch = Watch(turn)
        osc = OscOutput(OscTarget("127.0.0.1", receiver.port, "flat"), make_profile("flat", model), console)
        show = Show(model, [osc, watch], fps=30, seconds=1.5, apply=hub.apply, state=state, sources=[knob.poll])
        perform(show, console)
        hub.close()
        wait_until(lambda: len(frames_and_echo(receiver, "/walk/speed")) >= 45, "45 frames on the socket")
        echo = frames_and_echo(receiver, "/walk/speed")
        assert [f for f, _ in echo] == list(range(45))
        at_rest = echo[0][1]
        assert all(v == at_rest for f, v in echo if f <= 10) and at_rest not in (0.6, 1.6)
        up = next(f for f, v in echo if v != at_rest)
        assert up in (11, 12) and echo[up][1] == pytest.approx(1.6, abs=1e-6)  # float32 on the wire
        assert echo[-1][1] == pytest.approx(0.6, abs=1e-6)
        assert hub.refused == {"not a knob turn": 1}
        # the log holds the toy's raw events; the registered kind reads them again in a replay
        assert {e.source for e in read_log(log)} == {"toy:knob"}
        again = Watch()
        show = Show(model, [again], fps=30, seconds=1.5, replay=LogReplay(read_log(log)), fast=True,
                    apply=ControlHub([]).apply, state=ControlState(model.style_names, model.states))
        perform(show, console)
        assert again.seen == watch.seen
    finally:
        kinds.REGISTRY.pop("toy")
        receiver.close()


def test_run_plays_two_midi_controllers_each_through_its_own_mapping(jack, tmp_path):
    """`run --midi-virtual A --midi-virtual B` with a mapping for each: the same CC on the two ports
    drives two targets; the recorded log replays (its header's two mappings) to the same BVH."""
    import subprocess
    import sys

    import mido
    from test_controllers import frames_and_echo, last_frame, wait_for_port

    from oscrecv import Receiver
    from waiting import wait_until

    files = []
    for side, target, low, high in (("left", "speed", 0.5, 1.5), ("right", "turn", -1.0, 1.0)):
        path = tmp_path / f"{side}.toml"
        path.write_text(f'name = "{side}"\n[device]\nmidi = "cli-{side}"\n'
                        f'[[control]]\nmessage = "cc"\nnumber = 1\ntarget = "{target}"\nrange = [{low}, {high}]\n')
        files.append(str(path))
    receiver = Receiver()
    log, live, replay = tmp_path / "two.jsonl", tmp_path / "live.bvh", tmp_path / "replay.bvh"
    command = [sys.executable, "-m", "instrument", "run", "--quiet", "--midi-api", "jack"]
    process = subprocess.Popen(command + ["--midi-virtual", "cli-left", "--midi-virtual", "cli-right",
                                          "--mapping", files[0], "--mapping", files[1], "--seconds", "8",
                                          "--osc", f"127.0.0.1:{receiver.port}/flat", "--record", str(log),
                                          "--bvh", str(live)], stderr=subprocess.PIPE, text=True)
    try:
        senders = [jack.open_output(wait_for_port(jack, f"cli-{side}")) for side in ("left", "right")]
        wait_until(lambda: last_frame(receiver) >= 15, "15 frames")
        senders[0].send(mido.Message("control_change", channel=0, control=1, value=127))
        senders[1].send(mido.Message("control_change", channel=0, control=1, value=0))
        wait_until(lambda: frames_and_echo(receiver, "/walk/turn")[-1][1] == -1.0, "the right port's turn")
        for sender in senders:
            sender.close()
    finally:
        stderr = process.communicate(timeout=120)[1]
        receiver.close()
    assert process.returncode == 0, stderr
    assert frames_and_echo(receiver, "/walk/speed")[-1][1] == 1.5  # the left port's, through its own mapping
    assert {json.loads(line)["source"] for line in log.read_text().splitlines()[1:-1]} == {"midi:cli-left", "midi:cli-right"}
    result = subprocess.run(command + ["--replay", str(log), "--no-osc", "--fast", "--seconds", "8", "--bvh", str(replay)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert filecmp.cmp(live, replay, shallow=False)


def test_a_log_recorded_before_decoders_per_device_replays_as_it_was_played(model, tmp_path):
    """A header without "decoders" (every log recorded before): every MIDI device went through the
    first MIDI mapping, with one memory; the replay does the same, while a new log splits them."""
    from instrument.control.events import RawEvent, read_log
    from instrument.control.hub import ControlHub
    from instrument.control.loghead import header_line, logged_mappings, logged_per_device
    from instrument.control.mapping import load_mapping
    from instrument.control.state import ControlState

    state = ControlState(model.style_names, model.states)
    texts = {"left": 'midi = "left"\n[[control]]\nmessage = "cc14"\nnumber = 1\ntarget = "speed"\nrange = [0.5, 1.5]\n',
             "right": 'midi = "right"\n[[control]]\nmessage = "cc14"\nnumber = 1\ntarget = "turn"\nrange = [-1.0, 1.0]\n'}
    mappings = []
    for side, text in texts.items():
        (tmp_path / f"{side}.toml").write_text(f'name = "{side}"\n[device]\n' + text)
        mappings.append(load_mapping(tmp_path / f"{side}.toml", state))
    # the MSB from one port, the LSB from the other: one pair for a decoder per kind, two halves apart
    events = [RawEvent(0.0, "midi:left", "cc/1/1", 127.0), RawEvent(0.1, "midi:right", "cc/1/33", 127.0)]
    results = {}
    for per_device in (False, True):
        log = tmp_path / f"{per_device}.jsonl"
        log.write_text(header_line(mappings, per_device=per_device) + "\n" + "".join(e.to_json() + "\n" for e in events))
        again = ControlState(model.style_names, model.states)
        hub = ControlHub(logged_mappings(log, again), per_device=logged_per_device(log))
        assert all(hub.apply(again, e) for e in read_log(log))
        results[per_device] = (again.get("speed"), again.get("turn"))
    assert results[False] == (1.5, 0.0)  # as played then: the left mapping's pair, completed by the right port's LSB
    # a decoder each: the left's MSB alone (LSB 0), the right's LSB with no MSB yet (nothing)
    assert results[True][0] == pytest.approx(0.5 + 127 * 128 / 16383) and results[True][1] == 0.0
