"""HID controllers decoded from their report descriptors: simulated hidapi devices serving the real,
published descriptors of the shipped devices (tests/hid_descriptors.py says where each came from)
and reports laid out as those devices send them (built here by hand from the published layouts,
not by the code under test); bad reports, unplugging, learn, `instrument devices`, feedback."""

from __future__ import annotations

import io
import struct
import sys
import types
from argparse import Namespace
from typing import ClassVar

import pytest
from conftest import REPO, play_mapped
from hid_descriptors import (
    DUALSENSE_USB,
    DUALSHOCK4_BT,
    DUALSHOCK4_USB,
    SPACENAVIGATOR_USB,
    SWITCH_PRO_BT,
    SWITCH_PRO_USB,
    XBOX_WIRELESS_BT,
)
from hid_sim import SimulatedDevice, SimulatedHid, ds4_report

from instrument.control import hid as hid_module
from instrument.control.hid import HidInput, choose_mapping, parse_descriptor
from instrument.control.hid_feedback import HidFeedback
from instrument.control.hub import ControlHub
from instrument.control.mapping import Mapper, load_mapping
from instrument.control.state import ControlState
from instrument.errors import UserError
from instrument.terminal import Console
from instrument.runtime.performance import Show, perform
from instrument.shipped import shipped_mappings
from instrument.tomlfile import TomlFile

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


def switch_pro_report(x=0x8000, y=0x8000, rx=0x8000, ry=0x8000, buttons=0, hat=8) -> bytes:
    """Switch Pro Controller over Bluetooth, its simple HID report 0x3F, 12 bytes: two bytes of buttons
    (B A Y X L R ZL ZR, then - + LS RS Home Capture: SDL's SDL_hidapi_switch.c, HandleSimpleControllerState),
    the hat (0 up, clockwise, 8 released) with 4 bits of padding, then the sticks, 16 bits each, centred
    at 0x8000 (dekuNukem's bluetooth_hid_notes.md, "INPUT 0x3F": `3F 28 CA 08 00 80 00 80 00 80 00 80`)."""
    return struct.pack("<BHBHHHH", 0x3F, buttons, hat, x, y, rx, ry)


def spacenav_report(report_id: int, a=0, b=0, c=0) -> bytes:
    """SpaceNavigator: report 1 translation, 2 rotation, three signed 16-bit values each
    (as captured in the udev-hid-bpf case study: `02 00 00 e2 ff 00 00`)."""
    return struct.pack("<Bhhh", report_id, a, b, c)


def spacenav_buttons(pressed: int) -> bytes:
    return bytes([0x03, pressed, 0x00])  # `03 01 00`: button 1


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


# Descriptors

@pytest.mark.parametrize("descriptor,lengths,names", [
    (DUALSHOCK4_USB, {1: 64}, ["X", "Y", "Z", "Rz", "Hat"] + [f"Button {k}" for k in range(1, 15)] + ["Rx", "Ry"]),
    (DUALSENSE_USB, {1: 64}, ["X", "Y", "Z", "Rz", "Rx", "Ry", "Hat"] + [f"Button {k}" for k in range(1, 16)]),
    (XBOX_WIRELESS_BT, {1: 17, 2: 2, 4: 2}, ["X", "Y", "Z", "Rz", "Brake", "Accelerator", "Hat"]
     + [f"Button {k}" for k in range(1, 16)] + ["AC Back", "AC Home", "0006:0020"]),
    (SWITCH_PRO_USB, {0x30: 64}, [f"Button {k}" for k in range(1, 15)] + ["X", "Y", "Z", "Rz", "Hat"]
     + [f"Button {k}" for k in range(15, 19)]),
    (SWITCH_PRO_BT, {0x3F: 12}, [f"Button {k}" for k in range(1, 17)] + ["Hat", "X", "Y", "Rx", "Ry"]),
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
    # over Bluetooth: its simple report 0x3F; ZL (Button 7) and Capture (Button 14) held, hat down
    values = decoded(SWITCH_PRO_BT, switch_pro_report(x=65535, y=0, rx=16384, buttons=(1 << 6) | (1 << 13), hat=4))
    assert values["X"] == 1.0 and values["Y"] == 0.0 and values["Rx"] == pytest.approx(16384 / 65535)
    assert values["Ry"] == pytest.approx(0x8000 / 65535)  # at rest
    assert values["Button 7"] == 1.0 and values["Button 14"] == 1.0 and values["Button 8"] == 0.0
    assert values["Hat/down"] == 1.0


def test_switch_pro_over_bluetooth_vendor_reports_are_counted_not_decoded():
    # once a driver (the kernel's hid-nintendo, SDL) has switched it to its full report 0x30, 49 bytes
    # of vendor data: counted as vendor-only, so a silent pad says why
    pad = SimulatedDevice(SWITCH_PRO_BT, 0x057E, 0x2009)
    device = HidInput(Console(stream=io.StringIO()), 0x057E, 0x2009, hid=SimulatedHid(pad))
    pad.send(switch_pro_report(hat=8), bytes([0x30, 0x5A, 0x8E, 0x00, 0x00, 0x00]) + bytes(43))
    assert dict(device.read_raw())["Hat"] == -1.0
    assert device.dropped["vendor-only"] == 1


def test_switch_pro_usb_descriptor_names_its_sticks_with_extended_usages():
    # its USB descriptor names the sticks with 4-byte usages (`0B 30 00 01 00`: Generic Desktop X) while
    # the Usage Page in effect is Buttons; a parser that ignores the high half loses them. (The pad never
    # sends a report in this layout, so none is decoded here: see SWITCH_PRO_USB.)
    sticks = {c.name: c.page for c in parse_descriptor(SWITCH_PRO_USB).controls if c.size == 16}
    assert sticks == {"X": 0x01, "Y": 0x01, "Z": 0x01, "Rz": 0x01}


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

    def prepare(self, frame):
        return frame.index

    def send(self, index):
        self.seen[index] = self.state.get(self.target)
        self.script.get(index, lambda: None)()

    def close(self):
        pass


DRIVES = [  # mapping, device descriptor and ids, a report moving one control, the target and value it gives
    ("sony-dualshock4", DUALSHOCK4_USB, (0x054C, 0x05C4), ds4_report(ry=0), "style/elderly", -1.5),
    ("xbox-wireless-bluetooth", XBOX_WIRELESS_BT, (0x045E, 0x0B13), xbox_report(brake=1023), "style/exhausted", 2.0),
    ("nintendo-switch-pro", SWITCH_PRO_BT, (0x057E, 0x2009), switch_pro_report(rx=65535), "style/masculine", 1.5),
    ("3dconnexion-spacemouse", SPACENAVIGATOR_USB, (0x046D, 0xC626), spacenav_report(2, 0, 0, -350), "turn", 1.2),
    ("generic-gamepad", MADE_UP_JOYSTICK, (0x16C0, 0x05DC), joystick_report(x=0), "turn", 1.2),
    ("sony-dualshock4", DUALSENSE_USB, (0x054C, 0x0CE6), dualsense_report(rx=255), "style/masculine", 1.5),
]


def _shipped_pad(model, name: str, descriptor: bytes, ids: tuple[int, int]):
    """A simulated pad of `descriptor` and `ids`, the shipped mapping `run` chooses for it (by
    vendor:product, or by usages: the joystick, the DualSense), checked to be `name`'s, and the
    device reading it: (sim, state, mapping, console, device)."""
    sim = SimulatedDevice(descriptor, *ids)
    hid = SimulatedHid(sim)
    state = state_of(model)
    mapping, why = choose_mapping([load_mapping(p, state) for p in shipped_mappings()], *ids, hid=hid)
    assert mapping.path.endswith(f"{name}.toml"), why
    console = Console(stream=io.StringIO())
    return sim, state, mapping, console, HidInput(console, *ids, hid=hid)


@pytest.mark.parametrize("name,descriptor,ids,report,target,value", DRIVES, ids=[f"{d[0]}-{d[2][0]:04x}" for d in DRIVES])
def test_every_shipped_hid_mapping_drives_the_walk(model, name, descriptor, ids, report, target, value):
    sim, state, mapping, console, device = _shipped_pad(model, name, descriptor, ids)
    hub = ControlHub([mapping])
    watch = Watch(state, target, {5: lambda: sim.send(report)})
    perform(Show(model, [watch], fps=30, seconds=1.0, apply=hub.apply, state=state, sources=[device.poll]), console)
    assert list(watch.seen) == list(range(30))  # the walk went on every frame
    assert watch.seen[4] != pytest.approx(value)
    assert watch.seen[20] == pytest.approx(value)


# each pad's gesture buttons (wave, raise) as its reports carry them, from the published layouts:
# the DualShock 4's L1, R1 (the shoulder byte's first bits), the Xbox pad's LB, RB (Buttons 7, 8 of
# its 15-bit field), the Switch Pro's L, R (after B A Y X), the joystick's Buttons 5, 6
GESTURE_BUTTONS = [
    ("sony-dualshock4", DUALSHOCK4_USB, (0x054C, 0x05C4), lambda bits: ds4_report(shoulders=bits), (1, 2)),
    ("xbox-wireless-bluetooth", XBOX_WIRELESS_BT, (0x045E, 0x0B13), lambda bits: xbox_report(buttons=bits), (1 << 6, 1 << 7)),
    ("nintendo-switch-pro", SWITCH_PRO_BT, (0x057E, 0x2009), lambda bits: switch_pro_report(buttons=bits), (1 << 4, 1 << 5)),
    ("generic-gamepad", MADE_UP_JOYSTICK, (0x16C0, 0x05DC), lambda bits: joystick_report(buttons=bits), (1 << 4, 1 << 5)),
]


@pytest.mark.parametrize("name,descriptor,ids,report,buttons", GESTURE_BUTTONS, ids=[g[0] for g in GESTURE_BUTTONS])
def test_every_shipped_pads_gesture_buttons_hold_the_gestures_while_pressed(model, name, descriptor, ids, report, buttons):
    """Issue 26's pads: each shipped gamepad's two gesture buttons, pressed and let go through its
    mapping, hold `gesture/wave` and then `gesture/raise` (a press starts one; synthesis/gestures.py)."""
    sim, state, mapping, console, device = _shipped_pad(model, name, descriptor, ids)
    wave_bits, raise_bits = buttons
    script = {5: lambda: sim.send(report(wave_bits)), 20: lambda: sim.send(report(0)),
              30: lambda: sim.send(report(raise_bits)), 45: lambda: sim.send(report(0))}
    wave, raised = Watch(state, "gesture/wave", script), Watch(state, "gesture/raise", {})
    perform(Show(model, [wave, raised], fps=30, seconds=2.0, apply=ControlHub([mapping]).apply, state=state,
                 sources=[device.poll]), console)
    assert (wave.seen[4], wave.seen[18], wave.seen[28]) == (0.0, 1.0, 0.0)
    assert (raised.seen[28], raised.seen[43], raised.seen[59]) == (0.0, 1.0, 0.0)


class EchoWatch(Watch):
    """Records what the frame echoes to control surfaces (/walk/<target> on the wire), not the state."""

    def prepare(self, frame):
        self.seen[frame.index] = frame.echo[self.target]
        return frame.index

    def send(self, index):
        self.script.get(index, lambda: None)()


# each pad's d-pad as its reports carry it: (up, right, down, released), from the published layouts
DPADS = [
    ("sony-dualshock4", DUALSHOCK4_USB, (0x054C, 0x05C4), lambda hat: ds4_report(hat=hat), (0, 2, 4, 8)),
    ("sony-dualshock4", DUALSENSE_USB, (0x054C, 0x0CE6), lambda hat: dualsense_report(hat=hat), (0, 2, 4, 8)),
    ("xbox-wireless-bluetooth", XBOX_WIRELESS_BT, (0x045E, 0x0B13), lambda hat: xbox_report(hat=hat), (1, 3, 5, 0)),
    ("nintendo-switch-pro", SWITCH_PRO_BT, (0x057E, 0x2009), lambda hat: switch_pro_report(hat=hat), (0, 2, 4, 8)),
    ("generic-gamepad", MADE_UP_JOYSTICK, (0x16C0, 0x05DC), lambda hat: joystick_report(hat=hat), (0, 1, 2, 4)),
]


@pytest.mark.parametrize("name,descriptor,ids,report,hats", DPADS, ids=[f"{d[0]}-{d[2][0]:04x}" for d in DPADS])
def test_the_dpad_of_every_shipped_pad_sets_the_gait_and_a_release_keeps_it(model, name, descriptor, ids, report, hats):
    """Up runs, down stands, right walks (mode "set"): the value stays when the pad is let go, and
    the frame's echo (what /walk/gait carries) follows."""
    up, right, down, released = hats
    sim, state, mapping, console, device = _shipped_pad(model, name, descriptor, ids)
    press = lambda hat: lambda: sim.send(report(hat), report(released))  # noqa: E731 (pressed and let go)
    watch = EchoWatch(state, "gait", {5: press(up), 15: press(down), 25: press(right)})
    hub = ControlHub([mapping], console=console)
    perform(Show(model, [watch], fps=30, seconds=35 / 30, apply=hub.apply, state=state, sources=[device.poll]), console)
    gait = watch.seen
    assert gait[5] == 1.0  # walking, as every show starts
    assert gait[12] == 2.0 and gait[22] == 0.0 and gait[32] == 1.0  # run, stand, walk: each kept after the release


def test_spacemouse_push_and_tilt_move_the_style_blend_and_a_button_recalls_a_preset(model):
    sim = SimulatedDevice(SPACENAVIGATOR_USB, 0x046D, 0xC626, usage=(1, 8))
    state = state_of(model)
    mapping = load_mapping(MAPPINGS / "3dconnexion-spacemouse.toml", state)
    weary = mapping.presets["weary"]
    console = Console(stream=io.StringIO())
    device = HidInput(console, 0x046D, 0xC626, hid=SimulatedHid(sim))
    script = {5: lambda: sim.send(spacenav_report(1, 350, 0, 0)),  # pushed right, as far as it goes
              15: lambda: sim.send(spacenav_report(2, 0, 350, 0)),  # tilted sideways
              25: lambda: sim.send(spacenav_report(1, 0, 0, 0), spacenav_report(2, 0, 0, 0)),  # let go: springs back
              30: lambda: sim.send(spacenav_buttons(0b01), spacenav_buttons(0b00))}  # button 1 pressed and let go
    watches = [Watch(state, "style/masculine", script), Watch(state, "style/feminine", {}),
               Watch(state, "style/normal", {}), Watch(state, "style/exhausted", {}), Watch(state, "speed", {})]
    hub = ControlHub([mapping])
    hub.start(state)  # the mapping's morph time, as `run` starts it
    perform(Show(model, watches, fps=30, seconds=3.0, apply=hub.apply, state=state, sources=[device.poll]), console)
    masculine, feminine, normal, exhausted, speed = (w.seen for w in watches)
    assert masculine[4] == pytest.approx(0.0) and masculine[12] == pytest.approx(1.5)  # push: masculine up...
    assert feminine[12] == pytest.approx(-1.5)  # ...and feminine down, the blend moved
    assert normal[14] == pytest.approx(0.0) and normal[22] == pytest.approx(1.5)  # tilt sideways: the normal style
    assert masculine[28] == pytest.approx(0.0) and normal[28] == pytest.approx(0.0)  # the cap sprang back
    assert exhausted[29] == pytest.approx(0.0) and speed[29] == pytest.approx(1.1)  # Rx at rest: mid [1.6, 0.6]
    # button 1: the preset "weary", morphed in over the mapping's morph seconds, and it stays
    assert exhausted[89] == pytest.approx(weary["style/exhausted"]) and speed[89] == pytest.approx(weary["speed"])
    assert exhausted[40] != pytest.approx(weary["style/exhausted"])  # morphing, not jumping


def test_generic_gamepad_is_chosen_by_usages_only_when_no_mapping_names_the_device(model):
    state = state_of(model)
    shipped = [load_mapping(p, state) for p in shipped_mappings()]
    ds4 = SimulatedHid(SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC))
    assert choose_mapping(shipped, 0x054C, 0x09CC, hid=ds4)[0].name == "Sony DualShock 4"
    stick = SimulatedHid(SimulatedDevice(MADE_UP_JOYSTICK, 0x16C0, 0x05DC, usage=(1, 4)))
    assert choose_mapping(shipped, 0x16C0, 0x05DC, hid=stick) == (
        next(m for m in shipped if m.name == "Generic gamepad"), "by its usages")
    chosen, why = choose_mapping(shipped, 0x1234, 0x0002, hid=stick)
    assert chosen is None and "not here" in why
    # a mouse-like device with two axes and three buttons fits nothing: said with what it has
    mouse = bytes.fromhex("05 01 09 02 a1 01 05 09 19 01 29 03 15 00 25 01 75 01 95 03 81 02 95 05 81 03"
                          "05 01 09 30 09 31 15 81 25 7f 75 08 95 02 81 06 c0")
    chosen, why = choose_mapping(shipped, 0x1234, 0x0003, hid=SimulatedHid(SimulatedDevice(mouse, 0x1234, 0x0003)))
    assert chosen is None and "fits its controls (X (-127..127 relative), Y (-127..127 relative), Button 1-3)" in why


def test_every_shipped_device_file_names_its_devices_by_ids_and_by_usages(model):
    state = state_of(model)
    for path in shipped_mappings():
        mapping = load_mapping(path, state)
        if mapping.hid or mapping.hid_usages:
            assert mapping.hid_usages, f"{path}: no hid-usages"
            assert mapping.hid or path.name == "generic-gamepad.toml", f"{path}: no vendor:product"


def test_a_spacemouse_with_an_unlisted_id_takes_the_spacemouse_file_and_a_gamepad_does_not(model):
    state = state_of(model)
    shipped = [load_mapping(p, state) for p in shipped_mappings()]
    nav = SimulatedHid(SimulatedDevice(SPACENAVIGATOR_USB, 0x256F, 0xC6FF, usage=(1, 8)))  # an id no file names
    chosen, why = choose_mapping(shipped, 0x256F, 0xC6FF, hid=nav)
    assert chosen.path.endswith("3dconnexion-spacemouse.toml") and why == "by its usages"
    # a gamepad with all six axes and two buttons is not a multi-axis controller: not the SpaceMouse's file
    pad = SimulatedHid(SimulatedDevice(DUALSENSE_USB, 0x054C, 0x0CE6))
    chosen, why = choose_mapping(shipped, 0x054C, 0x0CE6, hid=pad)
    assert chosen.path.endswith("sony-dualshock4.toml") and why == "by its usages"  # the DualShock 4's layout
    for descriptor, ids, name in ((SWITCH_PRO_BT, (0x057E, 0x2FFF), "nintendo-switch-pro"),
                                  (XBOX_WIRELESS_BT, (0x045E, 0x0FFF), "xbox-wireless-bluetooth"),
                                  (DUALSHOCK4_USB, (0x1234, 0x0004), "sony-dualshock4")):  # clones: ids no file names
        chosen, why = choose_mapping(shipped, *ids, hid=SimulatedHid(SimulatedDevice(descriptor, *ids)))
        assert chosen.path.endswith(f"{name}.toml") and why == "by its usages", name


def test_a_device_whose_descriptor_cannot_be_parsed_says_so_not_that_it_is_away(model):
    state = state_of(model)
    shipped = [load_mapping(p, state) for p in shipped_mappings()]
    broken = SimulatedHid(SimulatedDevice(b"\x05\x01\x09\x05\xa1\x01\x85", 0x1234, 0x0005))  # cut inside an item
    chosen, why = choose_mapping(shipped, 0x1234, 0x0005, hid=broken)
    assert chosen is None and "not here" not in why
    assert "its usages cannot be read: cannot parse the HID report descriptor (7 bytes): byte 6:" in why
    with pytest.raises(UserError, match="byte 6"):
        hid_module.device_descriptor(broken, 0x1234, 0x0005)
    assert hid_module.device_descriptor(broken, 0x1234, 0x0006) is None  # not plugged in


def test_a_recorded_log_with_the_old_dualshock4_names_replays_the_same(model):
    from instrument.control.events import ControlEvent

    state = state_of(model)
    mapper = Mapper(load_mapping(MAPPINGS / "sony-dualshock4.toml", state))
    play_mapped(mapper, state, ControlEvent(0.0, "hid:054c:09cc", "r2", 255.0))  # as logs recorded it: raw 0..255
    play_mapped(mapper, state, ControlEvent(0.0, "hid:054c:09cc", "lx", 0.0))
    assert state.get("style/active") == pytest.approx(2.0) and state.turn == pytest.approx(1.2)


HAT_MAPPING = """[device]
hid = "054c:09cc"

[[control]]
message = "hid"
input = "{input}"
target = "style/elderly"
range = [-1.4, 1.4]
"""


@pytest.mark.parametrize("name", ["Hat", "hat"])  # by usage, and by the DualShock 4's old name
def test_a_released_hat_reaches_its_mapping_with_no_warning(model, tmp_path, name):
    path = tmp_path / "hat.toml"
    path.write_text(HAT_MAPPING.format(input=name))
    state = state_of(model)
    text = io.StringIO()
    console = Console(stream=text)
    pad = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC)
    device = HidInput(console, 0x054C, 0x09CC, hid=SimulatedHid(pad))
    hub = ControlHub([load_mapping(path, state)], console=console)

    def play(report: bytes) -> list:
        pad.send(report)
        events = device.poll(0.0)
        for event in events:
            hub.apply(state, event)
        return [e.value for e in events if e.control == "Hat"]

    assert play(ds4_report(hat=7)) == [1.0] and state.get("style/elderly") == pytest.approx(1.4)  # up-left: 7 of 0..7
    assert play(ds4_report(hat=8)) == [-1.0]  # let go
    assert state.get("style/elderly") == pytest.approx(-1.4)  # the mapping saw the release: the low end
    assert "Hat" not in hub.refused and not any("out of range" in k for k in hub.refused)
    assert "out of range" not in text.getvalue()


def test_old_dualshock4_hat_events_in_a_recorded_log_replay_as_the_hat(model, tmp_path):
    from instrument.control.events import ControlEvent

    path = tmp_path / "hat.toml"
    path.write_text(HAT_MAPPING.format(input="hat"))
    state = state_of(model)
    hub = ControlHub([load_mapping(path, state)])
    assert hub.apply(state, ControlEvent(0.0, "hid:054c:09cc", "hat", 7.0))  # as logs recorded it: raw 0..7
    assert state.get("style/elderly") == pytest.approx(1.4)
    assert hub.apply(state, ControlEvent(0.0, "hid:054c:09cc", "hat", 8.0))  # 8: released
    assert state.get("style/elderly") == pytest.approx(-1.4)


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


def test_a_feedback_colour_for_no_style_of_the_model_is_a_one_line_error(tmp_path, model):
    """[feedback.colours] `eldrly = ...` (a style misspelt) was kept and never shown, and
    `colours = "#ff0000"` (no table) crashed with a traceback: both are refused at their line
    when the user names the mapping (its styles held against the model, as its targets are)."""
    path = tmp_path / "pad.toml"
    head = '[device]\nhid = "054c:09cc"\n[feedback]\nreport = 5\nlight-bar = 6\n'
    path.write_text(head + '[feedback.colours]\nelderly = "#7040ff"\neldrly = "#ff8000"\nnone = "#101010"\n')
    with pytest.raises(UserError) as refused:
        load_mapping(path, state_of(model), strict_styles=True)
    # worded as a mapping's target `style/eldrly` is (control/checks.py, the one check of style names)
    assert str(refused.value) == (f"{path}:8: eldrly: style/eldrly: unknown target (this model's styles: "
                                  f"{', '.join(sorted(model.style_names))}); or none, for no style leading")
    assert "eldrly" in load_mapping(path, state_of(model)).feedback.colours  # a shipped mapping, for any model's styles
    path.write_text(head + 'colours = "#ff0000"\n')
    with pytest.raises(UserError, match=r"pad.toml:6: colours: expected a \[feedback.colours\] table"):
        load_mapping(path, state_of(model))
    path.write_text(head + '[feedback.colours]\nelderly = "#7040ff"\nnone = "#101010"\n')
    assert load_mapping(path, state_of(model), strict_styles=True).feedback.colours["elderly"] == (0x70, 0x40, 0xFF)


@pytest.mark.parametrize("key", ["name", "report", "leds", "hid", "midi", "feedback", "colours"])
def test_a_bad_colour_named_as_another_key_is_refused_at_its_own_line(tmp_path, model, key):
    """A colour under [feedback.colours] named as a key of elsewhere (`name = "#101010"`) was
    refused at that other key's line (the mapping's `name`, line 1): the error was found by the
    key's name alone. It names the colour's own line."""
    path = tmp_path / "pad.toml"
    path.write_text('name = "pad"\n[device]\nhid = "054c:09cc"\nmidi = "pad"\n[feedback]\nleds = true\nreport = 5\n'
                    f'light-bar = 6\n[feedback.colours]\nelderly = "#7040ff"\n{key} = "#101010"\n')
    with pytest.raises(UserError) as refused:
        load_mapping(path, state_of(model), strict_styles=True)
    assert str(refused.value).startswith(f"{path}:11: {key}: style/{key}: unknown target"), refused.value
    path.write_text(path.read_text().replace('"#101010"', '"#10101"'))  # a shipped mapping's (any style): its bad colour
    with pytest.raises(UserError) as refused:
        load_mapping(path, state_of(model))
    assert str(refused.value) == f"{path}:11: {key}: '#10101': expected a colour as \"#rrggbb\""


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
    show = Show(model, [watch, feedback], fps=30, seconds=3.0, apply=hub.apply, state=state, sources=[device.poll])
    perform(show, console)
    assert list(watch.seen) == list(range(90))  # the walk never stopped
    assert "lost" in text.getvalue() and "reconnected" in text.getvalue()
    assert sim.written == [bytes([4, 1]), bytes([4, 1])]  # report 4, LED bit on: at connect and at reconnect
    assert replugged_at and watch.seen[89] == pytest.approx(-1.2)  # steering works again after the replug


def test_dualshock4_light_bar_shows_the_leading_styles_colour(model):
    colours = TomlFile(MAPPINGS / "sony-dualshock4.toml").data["feedback"]["colours"]
    rgb = {name: bytes.fromhex(text[1:]) for name, text in colours.items()}
    sim = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC)
    state = state_of(model)
    mapping = load_mapping(MAPPINGS / "sony-dualshock4.toml", state)
    console = Console(stream=io.StringIO())
    device = HidInput(console, 0x054C, 0x09CC, hid=SimulatedHid(sim))
    feedback = HidFeedback(device, mapping.feedback, console)
    watch = Watch(state, "style/active", {5: lambda: sim.send(ds4_report(r2=255)),
                                          15: lambda: sim.send(ds4_report(r2=100, l2=200))})
    show = Show(model, [watch, feedback], fps=30, seconds=1.0, apply=ControlHub([mapping]).apply, state=state,
                sources=[device.poll])
    perform(show, console)
    assert [len(r) for r in sim.written] == [32] * len(sim.written)  # report 5's length, from the descriptor
    assert all(r[0] == 5 and r[1] == 0x02 for r in sim.written)  # report id, "set the light bar"
    assert [r[6:9] for r in sim.written] == [rgb["none"], rgb["active"], rgb["exhausted"]]


def test_dualshock4_light_bar_stays_dark_over_bluetooth_and_the_console_says_why(model):
    # its Bluetooth descriptor has no output report 5 (the light bar sits in vendor report 0x11 there,
    # which the kernel's hid-playstation driver writes with a CRC): nothing is sent, one line says so
    text = io.StringIO()
    sim = SimulatedDevice(DUALSHOCK4_BT, 0x054C, 0x05C4)
    state = state_of(model)
    mapping = load_mapping(MAPPINGS / "sony-dualshock4.toml", state)
    console = Console(stream=text)
    device = HidInput(console, 0x054C, 0x05C4, hid=SimulatedHid(sim))
    feedback = HidFeedback(device, mapping.feedback, console)
    watch = Watch(state, "style/active", {5: lambda: sim.send(ds4_report(r2=255)[:10])})
    show = Show(model, [watch, feedback], fps=30, seconds=0.5, apply=ControlHub([mapping]).apply, state=state,
                sources=[device.poll])
    perform(show, console)
    assert watch.seen[14] == pytest.approx(2.0)  # it plays
    assert sim.written == []
    assert "no output report 5 long enough for the light bar" in text.getvalue()


# A device the project has never seen (MADE_UP_JOYSTICK, above)

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
        "gait=run": [None, joystick_report(hat=0), rest],  # the hat's up: a button that sets the gait
        "gait=stand": [None, rest] + [joystick_report(slider=s) for s in (0, 90, 127, 0)],  # an axis: not a button, skipped
    }

    class Performer(io.StringIO):
        answers: ClassVar[list[str]] = ["turn", "style/elderly", "gait=run", "gait=stand", ""]

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
    assert "learned HID Hat/up (button) -> gait=run" in said and "gait=stand is a button" in said
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
    assert len(mapping.controls) == 3 and state.gait == 1.0
    stick.send(joystick_report(hat=0), rest)  # up pressed and let go: the gait learned for it stays
    for event in device.poll(1.0):
        hub.apply(state, event)
    assert state.gait == 2.0


def test_instrument_devices_lists_each_hid_devices_controls_by_usage(monkeypatch, capsys):
    from instrument.cli import devices_cmd

    bus = SimulatedHid(SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC, "Wireless Controller"),
                       SimulatedDevice(SPACENAVIGATOR_USB, 0x046D, 0xC626, "SpaceNavigator", usage=(1, 8)),
                       SimulatedDevice(MADE_UP_JOYSTICK, 0x16C0, 0x05DC, "Knob box", usage=(1, 4)),
                       SimulatedDevice(DUALSENSE_USB, 0x054C, 0x0CE6, "DualSense"),
                       SimulatedDevice(SPACENAVIGATOR_USB, 0x1234, 0x0001, "Six axes, two buttons", usage=(1, 8)),
                       SimulatedDevice(b"\x05\x01\x09\x05\xa1\x01\x85", 0x1234, 0x0005, "Broken pad"),
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
    assert "sony-dualshock4.toml (by its usages)" in next(line for line in lines if "DualSense" in line)
    assert "3dconnexion-spacemouse.toml (by its usages)" in next(line for line in lines if "Six axes" in line)
    broken = next(k for k, line in enumerate(lines) if "Broken pad" in line)
    assert "no shipped mapping" in lines[broken]
    assert lines[broken + 1].startswith("    controls: (cannot read them: cannot parse the HID report descriptor (7 bytes): byte 6:")
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
    assert "HID mapping: Sony DualShock 4" in err and "by its usages" in err
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


def test_hidapi_prefers_the_hidraw_backend_on_linux(monkeypatch):
    # the hidapi wheel ships both: `hidraw` (Linux hidraw: USB and Bluetooth) and `hid` (libusb: USB only)
    assert hid_module.hidapi().__name__ == ("hidraw" if sys.platform.startswith("linux") else "hid")
    hidraw, libusb = types.ModuleType("hidraw"), types.ModuleType("hid")
    monkeypatch.setitem(sys.modules, "hidraw", hidraw)
    monkeypatch.setitem(sys.modules, "hid", libusb)
    monkeypatch.setattr(sys, "platform", "linux")
    assert hid_module.hidapi() is hidraw
    monkeypatch.setitem(sys.modules, "hidraw", None)  # not installed: `import hidraw` raises ImportError
    assert hid_module.hidapi() is libusb
    monkeypatch.setitem(sys.modules, "hidraw", hidraw)
    monkeypatch.setattr(sys, "platform", "darwin")  # elsewhere the `hid` module is the native backend
    assert hid_module.hidapi() is libusb
    monkeypatch.setitem(sys.modules, "hid", None)
    with pytest.raises(UserError, match="HID is not available.*pip install hidapi"):
        hid_module.hidapi()


def kernel_hidraw_ioctl(descriptor: bytes, calls: list):
    """fcntl.ioctl as the kernel's hidraw driver answers the two descriptor ioctls (drivers/hid/hidraw.c):
    HIDIOCGRDESCSIZE writes the size as a 32-bit int; HIDIOCGRDESC reads the size the caller put in the
    struct's first 4 bytes and copies that many descriptor bytes after them (EINVAL above the real size)."""
    def ioctl(fd, request, buffer):
        calls.append(request)
        if request == hid_module.HIDIOCGRDESCSIZE:
            assert len(buffer) == 4
            buffer[:4] = len(descriptor).to_bytes(4, "little")
        elif request == hid_module.HIDIOCGRDESC:
            assert len(buffer) == 4 + 4096  # struct hidraw_report_descriptor
            size = int.from_bytes(buffer[:4], "little")
            if size > len(descriptor):
                raise OSError(22, "Invalid argument")
            buffer[4:4 + size] = descriptor[:size]
        else:
            raise OSError(25, "Inappropriate ioctl for device")
        return 0
    return ioctl


def test_the_hidraw_ioctl_reads_the_descriptor_as_the_kernel_gives_it(monkeypatch, tmp_path):
    node = tmp_path / "hidraw0"  # stands for /dev/hidraw0: opened and closed for real
    node.write_bytes(b"")
    calls = []
    monkeypatch.setattr(hid_module.fcntl, "ioctl", kernel_hidraw_ioctl(SPACENAVIGATOR_USB, calls))
    assert hid_module.hidraw_descriptor(str(node)) == SPACENAVIGATOR_USB
    assert calls == [hid_module.HIDIOCGRDESCSIZE, hid_module.HIDIOCGRDESC]
    # a binding without get_report_descriptor: the device is opened through the ioctl on its path and plays
    sim = SimulatedDevice(SPACENAVIGATOR_USB, 0x046D, 0xC626, descriptor_call=False, path=str(node).encode())
    device = HidInput(Console(stream=io.StringIO()), 0x046D, 0xC626, hid=SimulatedHid(sim))
    sim.send(spacenav_report(2, 0, 0, 350))
    assert dict(device.read_raw())["Rz"] == 1.0
