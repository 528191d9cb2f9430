"""Devices as one protocol: the kind rule shared by the hub and the log reader, HID replays, one
mapper per device (two real JACK MIDI ports), MIDI read through mido, and a toy device registered
from this file that drives the walk."""

from __future__ import annotations

import filecmp
import json

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
    controls = {json.loads(line)["control"] for line in lines[1:]}
    assert {"X", "Y", "Button 1"} <= controls and all('"hid:16c0:05dc"' in line for line in lines[1:])
    assert run("--replay", str(log), "--mapping", GENERIC, "--fast", "--seconds", "3", "--bvh", str(again)) == 0
    assert filecmp.cmp(live, again, shallow=False)
    assert run("--replay", str(log), "--fast", "--seconds", "3", "--bvh", str(header)) == 0  # the header's mapping
    assert filecmp.cmp(live, header, shallow=False)
    still = tmp_path / "still.jsonl"  # the same header, no events: a different walk, so the equality above says something
    still.write_text(lines[0] + "\n")
    assert run("--replay", str(still), "--fast", "--seconds", "3", "--bvh", str(tmp_path / "still.bvh")) == 0
    assert not filecmp.cmp(live, tmp_path / "still.bvh", shallow=False)
