"""HID controllers decoded from their report descriptors: simulated hidapi devices serving the real,
published descriptors of the shipped devices (tests/hid_descriptors.py says where each came from)
and reports laid out as those devices send them (built here by hand from the published layouts,
not by the code under test); bad reports, unplugging, learn, `instrument devices`, feedback."""

from __future__ import annotations

import io
import struct
import sys
from argparse import Namespace
from typing import ClassVar

import pytest
from conftest import REPO
from hid_descriptors import DUALSENSE_USB, DUALSHOCK4_BT, DUALSHOCK4_USB, SPACENAVIGATOR_USB, SWITCH_PRO_USB, XBOX_WIRELESS_BT
from hid_sim import SimulatedDevice, SimulatedHid, ds4_report

from instrument.control import hid as hid_module
from instrument.control.hid import HidInput, choose_mapping, parse_descriptor
from instrument.control.hid_feedback import HidFeedback
from instrument.control.hub import ControlHub
from instrument.control.mapping import Mapper, load_mapping
from instrument.control.state import ControlState
from instrument.errors import UserError
from instrument.runtime.console import Console
from instrument.runtime.performance import perform
from instrument.shipped import shipped_mappings
from instrument.tomlfile import read_toml

MAPPINGS = REPO / "mappings"


def state_of(model) -> ControlState:
    return ControlState(model.style_names, model.states)


# Reports as each device sends them, from the published layouts.

def dualsense_report(lx=128, ly=128, rx=128, ry=128, l2=0, r2=0, hat=8, face=0) -> bytes:
    """DualSense USB input report 1 (the kernel's hid-playstation struct dualsense_input_report):
    sticks, triggers, sequence number, buttons[0] = hat | square cross circle triangle."""
    return bytes([0x01, lx, ly, rx, ry, l2, r2, 0, (face << 4) | hat] + [0] * 55)


def xbox_report(x=32768, y=32768, z=32768, rz=32768, brake=0, accelerator=0, hat=0, buttons=0, back=0) -> bytes:
    """Xbox Wireless (Bluetooth, Linux mode) input report 1, per xpadneo's table: four 16-bit stick
    axes, brake and accelerator 10 bits in 16, hat 4 in 8 (0 = released), 15 buttons in 16, AC Back."""
    return struct.pack("<BHHHHHHBHB", 0x01, x, y, z, rz, brake, accelerator, hat, buttons, back)


def switch_pro_report(x=32768, y=32768, z=32768, rz=32768, buttons=0, hat=8) -> bytes:
    """Switch Pro Controller input report 0x30 as its USB descriptor lays it out: Buttons 1-14 in
    16 bits, X Y Z Rz 16 bits each, hat 4 bits with Buttons 15-18, 52 bytes of padding."""
    return struct.pack("<BHHHHHB", 0x30, buttons & 0x3FFF, x, y, z, rz, hat | ((buttons >> 14) << 4)) + bytes(52)


def spacenav_report(report_id: int, a=0, b=0, c=0) -> bytes:
    """SpaceNavigator: report 1 translation, 2 rotation, three signed 16-bit values each
    (as captured in the udev-hid-bpf case study: `02 00 00 e2 ff 00 00`)."""
    return struct.pack("<Bhhh", report_id, a, b, c)


def spacenav_buttons(pressed: int) -> bytes:
    return bytes([0x03, pressed, 0x00])  # `03 01 00`: button 1


# Descriptors

@pytest.mark.parametrize("descriptor,lengths,names", [
    (DUALSHOCK4_USB, {1: 64}, ["X", "Y", "Z", "Rz", "Hat"] + [f"Button {k}" for k in range(1, 15)] + ["Rx", "Ry"]),
    (DUALSENSE_USB, {1: 64}, ["X", "Y", "Z", "Rz", "Rx", "Ry", "Hat"] + [f"Button {k}" for k in range(1, 16)]),
    (XBOX_WIRELESS_BT, {1: 17, 2: 2, 4: 2}, ["X", "Y", "Z", "Rz", "Brake", "Accelerator", "Hat"]
     + [f"Button {k}" for k in range(1, 16)] + ["AC Back", "AC Home", "0006:0020"]),
    (SWITCH_PRO_USB, {0x30: 64}, [f"Button {k}" for k in range(1, 15)] + ["X", "Y", "Z", "Rz", "Hat"]
     + [f"Button {k}" for k in range(15, 19)]),
    (DUALSHOCK4_BT, {1: 10}, ["X", "Y", "Z", "Rz", "Hat"] + [f"Button {k}" for k in range(1, 15)] + ["Rx", "Ry"]),
    (SPACENAVIGATOR_USB, {1: 7, 2: 7, 3: 3}, ["X", "Y", "Z", "Rx", "Ry", "Rz", "Button 1", "Button 2"]),
])
def test_real_descriptors_give_the_published_controls(descriptor, lengths, names):
    parsed = parse_descriptor(descriptor)
    assert {k: layout.length for k, layout in parsed.layouts.items()} == lengths
    assert [c.name for c in parsed.controls] == names


def test_output_reports_come_from_the_descriptor():
    ds4 = parse_descriptor(DUALSHOCK4_USB).outputs
    assert ds4[5][0] == 32  # the light bar's report: 32 bytes with its id
    leds = parse_descriptor(SPACENAVIGATOR_USB).outputs[4]
    assert leds[0] == 2 and [(f.page, f.usage, f.bit, f.size) for f in leds[1]] == [(0x08, 0x4B, 8, 1)]


def test_a_one_byte_maximum_after_a_minimum_of_zero_is_unsigned():
    # "Logical Maximum (255)" written in one byte (25 FF): -1 by the letter of the spec, 255 as meant
    parsed = parse_descriptor(bytes.fromhex("05 01 09 04 a1 01 15 00 25 ff 75 08 95 01 09 30 81 02 c0"))
    assert [(c.name, c.minimum, c.maximum) for c in parsed.controls] == [("X", 0, 255)]


def test_a_descriptor_that_cannot_be_parsed_is_a_clear_error():
    with pytest.raises(UserError, match="cannot parse the HID report descriptor"):
        parse_descriptor(b"\x05\x01\x09\x05\xa1\x01\x85")  # cut inside an item


# Decoding real-shaped reports

def decoded(descriptor: bytes, *reports: bytes) -> dict[str, float]:
    sim = SimulatedDevice(descriptor, 0x1234, 0x5678)
    device = HidInput(Console(stream=io.StringIO()), 0x1234, 0x5678, hid=SimulatedHid(sim))
    sim.send(*reports)
    return dict(device.read_raw())


def test_dualshock4_report_by_usage():
    values = decoded(DUALSHOCK4_USB, ds4_report(lx=0, ly=255, hat=2, face=0b0010, shoulders=0b10_0000, r2=51))
    assert values["X"] == 0.0 and values["Y"] == 1.0 and values["Z"] == pytest.approx(128 / 255)
    assert values["Hat/right"] == 1.0 and values["Hat/up"] == 0.0 and values["Hat"] == pytest.approx(2 / 7)
    assert values["Button 2"] == 1.0 and values["Button 1"] == 0.0  # cross, not square
    assert values["Button 10"] == 1.0  # OPTIONS
    assert values["Ry"] == pytest.approx(0.2)


def test_a_released_hat_reads_minus_one_and_no_direction():
    values = decoded(DUALSHOCK4_USB, ds4_report(hat=8))
    assert values["Hat"] == -1.0 and not any(values[f"Hat/{d}"] for d in ("up", "right", "down", "left"))


def test_xbox_report_by_usage():
    values = decoded(XBOX_WIRELESS_BT, xbox_report(x=0, rz=65535, brake=1023, accelerator=512, hat=1, buttons=0b1_0001, back=1))
    assert values["X"] == 0.0 and values["Rz"] == 1.0 and values["Brake"] == 1.0
    assert values["Accelerator"] == pytest.approx(512 / 1023)
    assert values["Hat/up"] == 1.0  # 1..8 from up, 0 released
    assert values["Button 1"] == 1.0 and values["Button 5"] == 1.0 and values["Button 2"] == 0.0  # A and Y
    assert values["AC Back"] == 1.0


def test_switch_pro_report_by_usage():
    values = decoded(SWITCH_PRO_USB, switch_pro_report(x=65535, y=0, buttons=(1 << 6) | (1 << 15), hat=4))
    assert values["X"] == 1.0 and values["Y"] == 0.0
    assert values["Button 7"] == 1.0 and values["Button 16"] == 1.0 and values["Button 8"] == 0.0
    assert values["Hat/down"] == 1.0


def test_switch_pro_sticks_decode_from_their_extended_usages():
    # its descriptor names the sticks with 4-byte usages (`0B 30 00 01 00`: Generic Desktop X) while
    # the Usage Page in effect is Buttons; a parser that ignores the high half loses them
    sticks = {c.name: c.page for c in parse_descriptor(SWITCH_PRO_USB).controls if c.size == 16}
    assert sticks == {"X": 0x01, "Y": 0x01, "Z": 0x01, "Rz": 0x01}
    values = decoded(SWITCH_PRO_USB, switch_pro_report(x=0, y=65535, z=16384, rz=49152))
    assert values["X"] == 0.0 and values["Y"] == 1.0
    assert values["Z"] == pytest.approx(16384 / 65535) and values["Rz"] == pytest.approx(49152 / 65535)


def test_spacenavigator_reports_by_usage():
    values = decoded(SPACENAVIGATOR_USB, spacenav_report(1, 350, -350, 0), bytes.fromhex("02 00 00 e2 ff 00 00"),
                     spacenav_buttons(0b10))
    assert values["X"] == 1.0 and values["Y"] == 0.0 and values["Z"] == 0.5
    assert values["Ry"] == pytest.approx((350 - 30) / 700)  # the case study's captured rotation, -30
    assert values["Button 2"] == 1.0 and values["Button 1"] == 0.0


def test_only_controls_that_changed_are_events():
    sim = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC)
    device = HidInput(Console(stream=io.StringIO()), 0x054C, 0x09CC, hid=SimulatedHid(sim))
    sim.send(ds4_report())
    assert len(device.read_raw()) > 20  # the first report tells where everything is
    sim.send(ds4_report(), ds4_report(r2=255))
    assert device.read_raw() == [("Ry", 1.0)]


def test_short_unknown_and_garbage_reports_are_counted_and_dropped():
    console_text = io.StringIO()
    pad = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC)
    device = HidInput(Console(stream=console_text), 0x054C, 0x09CC, hid=SimulatedHid(pad))
    pad.send(ds4_report()[:10],  # the 10-byte report 1 a DualShock 4 sends over Bluetooth before it is set up
             bytes([0x11, 0xC0, 0x00]) + bytes(75),  # its Bluetooth report 0x11: an id this descriptor lacks
             ds4_report(lx=0))
    assert dict(device.read_raw())["X"] == 0.0  # the good report after the bad ones still counts
    assert device.dropped == {"short": 1, "unknown id": 1, "garbage": 0, "vendor-only": 0}
    mouse = SimulatedDevice(SPACENAVIGATOR_USB, 0x046D, 0xC626)
    nav = HidInput(Console(stream=console_text), 0x046D, 0xC626, hid=SimulatedHid(mouse))
    mouse.send(spacenav_report(1, 0x7FFF, 0, 0), spacenav_report(1, 100, 0, 0))  # 32767: outside -350..350
    assert nav.read_raw()[0] == ("X", pytest.approx(450 / 700))
    assert nav.dropped["garbage"] == 1
    assert "dropped reports that do not fit its descriptor" in console_text.getvalue()
    assert "(1 reports dropped)" in nav.describe()


def test_dualshock4_over_bluetooth_basic_reports_play_and_vendor_mode_reports_are_counted():
    text = io.StringIO()
    pad = SimulatedDevice(DUALSHOCK4_BT, 0x054C, 0x05C4)
    device = HidInput(Console(stream=text), 0x054C, 0x05C4, hid=SimulatedHid(pad))
    pad.send(ds4_report(lx=0)[:10],  # report 1 over Bluetooth: the same fields as over USB, 10 bytes
             bytes([0x11, 0xC0, 0x00]) + bytes(75))  # report 0x11, once a driver has switched it over: vendor data
    assert dict(device.read_raw())["X"] == 0.0
    assert device.dropped["vendor-only"] == 1 and "1 vendor-only" in text.getvalue()


def test_a_binding_without_the_descriptor_call_uses_hidraw_and_says_what_failed():
    text = io.StringIO()
    sim = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC, descriptor_call=False, path=b"/nonexistent/hidraw9")
    device = HidInput(Console(stream=text), 0x054C, 0x09CC, hid=SimulatedHid(sim))
    assert device.poll(0.0) == []  # the hidraw ioctl path is tried on the device's path, and fails
    assert "cannot open HID device hid:054c:09cc" in text.getvalue() and "No such file" in text.getvalue()
    assert device.device is None  # waiting for it, not raising


# Shipped mappings drive the walk

class Watch:
    """An output that records one target's value each frame and sends reports at given frames."""

    name = "watch"

    def __init__(self, state: ControlState, target: str, script: dict):
        self.state, self.target, self.script, self.seen = state, target, script, {}

    def prepare(self, pose, echo):
        return pose.index

    def send(self, index):
        self.seen[index] = self.state.get(self.target)
        self.script.get(index, lambda: None)()

    def close(self):
        pass


DRIVES = [  # mapping, device descriptor and ids, a report moving one control, the target and value it gives
    ("sony-dualshock4", DUALSHOCK4_USB, (0x054C, 0x05C4), ds4_report(ry=0), "style/elderly", -1.5),
    ("xbox-wireless-bluetooth", XBOX_WIRELESS_BT, (0x045E, 0x0B13), xbox_report(brake=1023), "style/exhausted", 2.0),
    ("nintendo-switch-pro", SWITCH_PRO_USB, (0x057E, 0x2009), switch_pro_report(x=0), "turn", 1.2),
    ("3dconnexion-spacemouse", SPACENAVIGATOR_USB, (0x046D, 0xC626), spacenav_report(2, 0, 0, -350), "turn", 1.2),
    ("generic-gamepad", DUALSENSE_USB, (0x054C, 0x0CE6), dualsense_report(rx=255), "style/masculine", 1.5),
]


@pytest.mark.parametrize("name,descriptor,ids,report,target,value", DRIVES, ids=[d[0] for d in DRIVES])
def test_every_shipped_hid_mapping_drives_the_walk(model, name, descriptor, ids, report, target, value):
    sim = SimulatedDevice(descriptor, *ids)
    hid = SimulatedHid(sim)
    state = state_of(model)
    shipped = [load_mapping(p, state) for p in shipped_mappings()]
    mapping, why = choose_mapping(shipped, *ids, hid=hid)  # by vendor:product, or by usages (the DualSense)
    assert mapping.path.endswith(f"{name}.toml"), why
    console = Console(stream=io.StringIO())
    device = HidInput(console, *ids, hid=hid)
    hub = ControlHub([mapping])
    watch = Watch(state, target, {5: lambda: sim.send(report)})
    perform(model, [watch], console, fps=30, seconds=1.0, live_sources=[device.poll], apply=hub.apply, state=state)
    assert list(watch.seen) == list(range(30))  # the walk went on every frame
    assert watch.seen[4] != pytest.approx(value)
    assert watch.seen[20] == pytest.approx(value)


def test_generic_gamepad_is_chosen_by_usages_only_when_no_mapping_names_the_device(model):
    state = state_of(model)
    shipped = [load_mapping(p, state) for p in shipped_mappings()]
    ds4 = SimulatedHid(SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC))
    assert choose_mapping(shipped, 0x054C, 0x09CC, hid=ds4)[0].name == "Sony DualShock 4"
    nav = SimulatedHid(SimulatedDevice(SPACENAVIGATOR_USB, 0x1234, 0x0001, usage=(1, 8)))
    chosen, why = choose_mapping(shipped, 0x1234, 0x0001, hid=nav)  # two buttons: not a gamepad
    assert chosen is None and "fits its controls" in why
    chosen, why = choose_mapping(shipped, 0x1234, 0x0002, hid=nav)
    assert chosen is None and "not here" in why


def test_a_recorded_log_with_the_old_dualshock4_names_replays_the_same(model):
    from instrument.control.events import ControlEvent

    state = state_of(model)
    mapper = Mapper(load_mapping(MAPPINGS / "sony-dualshock4.toml", state))
    mapper.apply(state, ControlEvent(0.0, "hid:054c:09cc", "r2", 255.0))  # as logs recorded it: raw 0..255
    mapper.apply(state, ControlEvent(0.0, "hid:054c:09cc", "lx", 0.0))
    assert state.get("style/active") == pytest.approx(2.0) and state.turn == pytest.approx(1.2)


def test_a_mapping_naming_no_usage_is_a_one_line_error(tmp_path, model):
    path = tmp_path / "pad.toml"
    path.write_text('[device]\nhid = "054c:09cc"\n\n[[control]]\nmessage = "hid"\ninput = "Twist"\ntarget = "turn"\n')
    with pytest.raises(UserError, match=r"pad.toml:6: input: 'Twist' is not a HID usage name"):
        load_mapping(path, state_of(model))
    path.write_text('[device]\nhid-usages = ["X", "Pedal"]\n')
    with pytest.raises(UserError, match=r"pad.toml:2: hid-usages"):
        load_mapping(path, state_of(model))
    path.write_text('[device]\nhid = "054c:09cc"\n[feedback]\nreport = 5\n')
    with pytest.raises(UserError, match=r"light-bar: a light bar needs both"):
        load_mapping(path, state_of(model))


# Unplugging and feedback

def test_spacemouse_unplugged_and_replugged_its_led_on_each_time(model):
    text = io.StringIO()
    sim = SimulatedDevice(SPACENAVIGATOR_USB, 0x046D, 0xC626, usage=(1, 8))
    hid = SimulatedHid(sim)
    state = state_of(model)
    mapping = load_mapping(MAPPINGS / "3dconnexion-spacemouse.toml", state)
    console = Console(stream=text)
    device = HidInput(console, 0x046D, 0xC626, hid=hid)
    feedback = HidFeedback(device, mapping.feedback, console)
    hub = ControlHub([mapping])

    def unplug():
        sim.plugged = False

    def replug():
        sim.plugged = True

    def twist():
        sim.send(spacenav_report(2, 0, 0, 350))

    replugged_at = {}

    class TwistAfterReconnect(Watch):
        def send(self, index):
            super().send(index)
            if device.connections == 2 and not replugged_at:
                replugged_at["frame"] = index
                twist()

    watch = TwistAfterReconnect(state, "turn", {10: unplug, 20: replug})
    perform(model, [watch, feedback], console, fps=30, seconds=3.0, live_sources=[device.poll], apply=hub.apply, state=state)
    assert list(watch.seen) == list(range(90))  # the walk never stopped
    assert "lost" in text.getvalue() and "reconnected" in text.getvalue()
    assert sim.written == [bytes([4, 1]), bytes([4, 1])]  # report 4, LED bit on: at connect and at reconnect
    assert replugged_at and watch.seen[89] == pytest.approx(-1.2)  # steering works again after the replug


def test_dualshock4_light_bar_shows_the_leading_styles_colour(model):
    colours = read_toml(MAPPINGS / "sony-dualshock4.toml")[1]["feedback"]["colours"]
    rgb = {name: bytes.fromhex(text[1:]) for name, text in colours.items()}
    sim = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC)
    state = state_of(model)
    mapping = load_mapping(MAPPINGS / "sony-dualshock4.toml", state)
    console = Console(stream=io.StringIO())
    device = HidInput(console, 0x054C, 0x09CC, hid=SimulatedHid(sim))
    feedback = HidFeedback(device, mapping.feedback, console)
    watch = Watch(state, "style/active", {5: lambda: sim.send(ds4_report(r2=255)),
                                          15: lambda: sim.send(ds4_report(r2=100, l2=200))})
    perform(model, [watch, feedback], console, fps=30, seconds=1.0, live_sources=[device.poll],
            apply=ControlHub([mapping]).apply, state=state)
    assert [len(r) for r in sim.written] == [32] * len(sim.written)  # report 5's length, from the descriptor
    assert all(r[0] == 5 and r[1] == 0x02 for r in sim.written)  # report id, "set the light bar"
    assert [r[6:9] for r in sim.written] == [rgb["none"], rgb["active"], rgb["exhausted"]]


# A device the project has never seen

# A made-up joystick: X, Y 10 bits; 4 bits padding; Slider, Dial signed 8 bits; a 4-way hat with a
# null state; 12 buttons; no report ids. Bits: X 0-9, Y 10-19, Slider 24-31, Dial 32-39, Hat 40-43,
# Buttons 44-55.
MADE_UP_JOYSTICK = bytes.fromhex(
    "05 01 09 04 a1 01"
    "15 00 26 ff 03 75 0a 95 02 09 30 09 31 81 02"
    "75 04 95 01 81 03"
    "15 81 25 7f 75 08 09 36 09 37 95 02 81 02"
    "09 39 15 00 25 03 35 00 46 0e 01 65 14 75 04 95 01 81 42 65 00"
    "05 09 19 01 29 0c 15 00 25 01 75 01 95 0c 81 02"
    "c0")


def joystick_report(x=512, y=512, slider=0, dial=0, hat=4, buttons=0) -> bytes:
    bits = x | y << 10 | (slider & 0xFF) << 24 | (dial & 0xFF) << 32 | hat << 40 | buttons << 44
    return bits.to_bytes(7, "little")


def test_a_made_up_joystick_is_decoded_with_no_code_for_it():
    values = decoded(MADE_UP_JOYSTICK, joystick_report(x=1023, slider=-127, dial=127, hat=1, buttons=1 << 11))
    assert values["X"] == 1.0 and values["Y"] == pytest.approx(512 / 1023)
    assert values["Slider"] == 0.0 and values["Dial"] == 1.0
    assert values["Hat/right"] == 1.0 and values["Button 12"] == 1.0


def test_a_made_up_joystick_is_learnable(model, tmp_path, monkeypatch, capsys):
    from instrument.cli import learn_cmd

    stick = SimulatedDevice(MADE_UP_JOYSTICK, 0x16C0, 0x05DC, usage=(1, 4))
    monkeypatch.setattr(hid_module, "hidapi", lambda: SimulatedHid(stick))
    rest = joystick_report()
    moves = {  # what the performer does after each answer: nothing yet when asked (None), then the move
        "turn": [None, rest] + [joystick_report(slider=s) for s in (0, 40, 90, 127, 60, 0, -60, -127, -20, 0)],
        "style/elderly": [None, joystick_report(buttons=1 << 4), rest],
    }

    class Performer(io.StringIO):
        answers: ClassVar[list[str]] = ["turn", "style/elderly", ""]

        def readline(self):
            answer = self.answers.pop(0)
            stick.send(*moves.get(answer, []))
            return answer + "\n"

    monkeypatch.setattr(sys, "stdin", Performer())
    out = tmp_path / "stick.toml"
    assert learn_cmd.run(Namespace(out=str(out), model=None, midi=None, midi_virtual=None, midi_api=None, force=False,
                                   hid="16C0:05DC", timeout=10.0)) == 0
    said = capsys.readouterr().out
    assert "learned HID Slider (axis) -> turn" in said and "learned HID Button 5 (button) -> style/elderly" in said
    state = state_of(model)
    mapping = load_mapping(out, state)  # a valid mapping file
    assert mapping.hid == ((0x16C0, 0x05DC),)
    device = HidInput(Console(stream=io.StringIO()), 0x16C0, 0x05DC, hid=SimulatedHid(stick))
    hub = ControlHub([mapping])
    stick.reports.clear()
    stick.send(joystick_report(slider=127, buttons=1 << 4))
    for event in device.poll(0.0):
        hub.apply(state, event)
    assert state.turn == pytest.approx(1.0) and state.get("style/elderly") == 1.0  # a button: 1 while held


def test_instrument_devices_lists_each_hid_devices_controls_by_usage(monkeypatch, capsys):
    from instrument.cli import devices_cmd

    bus = SimulatedHid(SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC, "Wireless Controller"),
                       SimulatedDevice(SPACENAVIGATOR_USB, 0x046D, 0xC626, "SpaceNavigator", usage=(1, 8)),
                       SimulatedDevice(MADE_UP_JOYSTICK, 0x16C0, 0x05DC, "Knob box", usage=(1, 4)),
                       SimulatedDevice(DUALSENSE_USB, 0x054C, 0x0CE6, "DualSense"),
                       SimulatedDevice(SPACENAVIGATOR_USB, 0x1234, 0x0001, "Six axes, two buttons", usage=(1, 8)),
                       SimulatedDevice(b"", 0x046D, 0xC077, "USB Optical Mouse", usage=(1, 2)))
    monkeypatch.setattr(hid_module, "hidapi", lambda: bus)
    monkeypatch.setattr(devices_cmd, "hidapi", lambda: bus)
    assert devices_cmd.run(Namespace(midi_api="jack")) == 0
    out = capsys.readouterr().out.split("HID devices:")[1]
    assert "054c:09cc Wireless Controller  ->  " in out and "sony-dualshock4.toml (by vendor:product)" in out
    assert "X (0..255), Y (0..255), Z (0..255), Rz (0..255), Hat, Rx (0..255), Ry (0..255), Button 1-14" in out
    assert "X (-350..350 relative)" in out and "3dconnexion-spacemouse.toml" in out
    lines = out.splitlines()
    knobs = lines.index("    controls: X (0..1023), Y (0..1023), Slider (-127..127), Dial (-127..127), Hat, Button 1-12")
    assert "Knob box" in lines[knobs - 1] and "generic-gamepad.toml (by its usages)" in lines[knobs - 1]
    assert "generic-gamepad.toml (by its usages)" in next(line for line in lines if "DualSense" in line)
    assert "no shipped mapping" in next(line for line in lines if "Six axes" in line)
    assert "Mouse" not in out


def test_instrument_run_plays_a_hid_device_through_its_mapping_with_feedback(monkeypatch, tmp_path, capsys):
    from instrument.cli.main import main

    pad = SimulatedDevice(DUALSENSE_USB, 0x054C, 0x0CE6, "DualSense")
    light = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC, "Wireless Controller")
    bus = SimulatedHid(pad, light)
    monkeypatch.setattr(hid_module, "hidapi", lambda: bus)
    pad.send(dualsense_report(), None, None, dualsense_report(l2=255))
    log = tmp_path / "take.jsonl"
    assert main(["run", "--hid", "054c:0ce6", "--seconds", "1", "--no-osc", "--quiet", "--normal-priority",
                 "--record", str(log)]) == 0
    err = capsys.readouterr().err
    assert "HID mapping: Generic gamepad" in err and "by its usages" in err
    assert '"control": "Rx", "value": 1.0' in log.read_text()  # recorded by usage, normalised
    light.send(ds4_report(r2=255))
    assert main(["run", "--hid", "054c:09cc", "--seconds", "1", "--no-osc", "--quiet", "--normal-priority"]) == 0
    assert light.written and light.written[-1][:2] == bytes([5, 2])  # the light bar was set
    assert main(["run", "--hid", "1234:0001", "--seconds", "1", "--no-osc", "--quiet"]) == 1
    assert "--hid 1234:0001: no mapping names this device, and it is not here to read its usages from" in capsys.readouterr().err


def test_hidraw_ioctl_numbers_follow_the_kernels_ioc_macro():
    # include/uapi/asm-generic/ioctl.h: _IOR(type, nr, size) = 2 << 30 | size << 16 | type << 8 | nr;
    # include/uapi/linux/hidraw.h: HIDIOCGRDESCSIZE _IOR('H', 0x01, int), HIDIOCGRDESC _IOR('H', 0x02,
    # struct hidraw_report_descriptor { __u32 size; __u8 value[HID_MAX_DESCRIPTOR_SIZE = 4096]; })
    def ior(kind: str, number: int, size: int) -> int:
        return 2 << 30 | size << 16 | ord(kind) << 8 | number

    assert hid_module.HIDIOCGRDESCSIZE == ior("H", 0x01, 4)
    assert hid_module.HIDIOCGRDESC == ior("H", 0x02, 4 + 4096)
