"""Mapping files: which control of which device drives which target, in which mode.

A mapping is TOML (format in the README). Loading checks every key, and a mistake is one line
naming the file, the line and the key. At run time a `Mapper` turns raw events of its device
into target events (`TargetEvent`): it decodes 14-bit pairs, NRPN and relative encoders
(stateful, so replaying the same raw events gives the same values), applies range, curve and
deadzone, and soft takeover (none, pick-up, value scaling). It reads the control state (where a
relative encoder or a pick-up starts from) but never sets it: the hub checks and applies what it
returns, on the one path every input's targets take (ControlHub.apply_target). A button in mode
"set" asks for one fixed `value` when pressed (three buttons for gait's stand, walk and run).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from ..errors import UserError, quoted
from ..tomlfile import Field, TomlFile, key_lines
from .events import ControlEvent, TargetEvent
from .hid import DS4_NAMES, canonical_input, is_usage_name, legacy_event, unit_with_deadzone
from .hid_feedback import FeedbackSpec, parse_feedback
from .options import parse_hid_id
from .checks import between, is_number, row_of, unknown, value_refusal
from .presetfile import model_of, read_presets
from .spec import TABLE, Row

if TYPE_CHECKING:  # (numpy and the synthesis behind it: not needed to read a mapping)
    from .state import ControlState

MESSAGES = ("cc", "cc14", "nrpn", "note", "pitchbend", "hid")
MODES = ("absolute", "toggle", "momentary", "set", "relative-twos", "relative-signed", "relative-signed2", "relative-offset")
BUTTONS = ("note", "cc", "hid")  # messages a button sends (what mode "set" takes)
TAKEOVERS = ("none", "pickup", "scale")
CURVES = ("linear", "exp")
PICKUP_THRESHOLD = 3.0 / 128.0  # of the target's range (Mixxx)
FAST_SWEEP = 0.050  # seconds: a value this soon after an accepted one is accepted too (Mixxx)
# a mapping's schema (tomlfile.Field): the top, and each [[control]] table; what depends on other keys is
# checked in load_mapping and _control ([presets]: control/presetfile.py)
TOP = {"name": Field("string"), "device": Field("table"), "control": Field("tables"), "presets": Field("table"),
       "morph": Field("number", TABLE["morph"].low, TABLE["morph"].high, units="seconds"), "feedback": Field("table")}
# a [[control]] table's schema (tomlfile.Field); what depends on other keys (number's limit, input) is checked in _control
CONTROL = {
    "message": Field("choice", choices=MESSAGES, required=f"the kind of message ({', '.join(MESSAGES)})"),
    "target": Field("string", required="the control target it drives (docs/controls.md)"),
    "channel": Field("whole", 1, 16), "number": Field("whole", 0, 16383), "input": Field("string"),
    "mode": Field("choice", choices=MODES), "range": Field("list"), "curve": Field("choice", choices=CURVES),
    "takeover": Field("choice", choices=TAKEOVERS), "step": Field("number", 0, above_low=True),
    "deadzone": Field("number", 0, 1, below_high=True), "invert": Field("bool"),
    "value": Field("value"),  # mode "set": the value a press sets (a number, or a name: gait's "run")
}


@dataclass(frozen=True, eq=False)  # identity: each control of a file is its own, and hashing stays cheap
class ControlSpec:
    message: str  # cc, cc14, nrpn, note, pitchbend, hid
    target: str
    channel: int = 1  # 1 to 16
    number: int = 0  # CC number, NRPN parameter, note; for cc14 the MSB's CC (the LSB is number + 32)
    input: str = ""  # for hid: the control's usage name (X, Rz, Hat/up, Button 3, ...; see control/hid.py)
    mode: str = "absolute"
    range: tuple[float, float] = (0.0, 1.0)
    curve: str = "linear"
    takeover: str = "none"
    step: float = 0.01  # relative encoders: target units per tick
    deadzone: float = 0.0  # hid axes: share of the half-range around the centre that reads as centre
    invert: bool = False
    value: float | None = None  # mode "set": what a press sets the target to

    @property
    def key(self) -> str:
        return self.input if self.message == "hid" else f"{self.message}/{self.channel}/{self.number}"

    @property
    def travel(self) -> tuple[float, float]:
        """The values the two ends of the control's travel stand for: its range, but for a target
        of named values (gait) half a value further out at each end (and held to the range), so
        that the nearest whole value, which such a target takes, cuts the travel into equal
        zones, one per name: a fader on gait [0, 2] stands, walks and runs in its thirds (a
        quarter, a half and a quarter of it before)."""
        low, high = self.range
        row = TABLE.get(self.target.split("/")[0])
        if row is None or not row.choices:
            return low, high
        half = 0.5 if high > low else -0.5
        return low - half, high + half


@dataclass(frozen=True)
class Mapping:
    name: str
    path: str
    midi: str | None  # MIDI port name pattern (regular expression, case-insensitive)
    hid: tuple[tuple[int, int], ...] | None  # (vendor id, product id) of each model of the device
    controls: tuple[ControlSpec, ...]
    presets: dict[str, dict[str, float]] = field(default_factory=dict)
    morph: float = 0.0  # default seconds to morph into a recalled preset
    hid_usages: tuple[str, ...] = ()  # a HID device with all these usages (controls, application) fits, whatever its ids
    feedback: FeedbackSpec | None = None  # HID output reports (LEDs, a light bar), from [feedback]
    text: str = ""  # the TOML it was read from: a recorded log carries it, so the replay reads events alike


def load_mapping(path: str | Path, state: ControlState | None = None, text: str | None = None,
                 strict_styles: bool = False) -> Mapping:
    """The mapping file at `path` (or, given `text`, that TOML, with errors naming `path`).

    Its [presets] and the ranges of its controls are checked by the one check of every control
    value (control/checks.py). With `state`, targets are checked against its model; a style the
    model lacks is refused with `strict_styles` (a mapping the user names), else left for
    `style_problems` to warn about (a shipped or logged mapping, written for another model)."""
    path = Path(path)
    doc = TomlFile(path, text)
    text, data = doc.text, doc.data
    model = model_of(state, strict_styles)

    def fail(message: str, *path: str | int) -> UserError:
        """The error at the key's full path (("control", 2, "range")), named by its last name:
        the name alone is ambiguous (`name` is the mapping's and may be a style's colour too)."""
        return doc.error(path, message, str(path[-1]))

    doc.check((), data, TOP)
    device = data.get("device", {})
    midi, hid = device.get("midi"), device.get("hid")
    for key in device:
        if key not in ("midi", "hid", "hid-usages"):
            raise fail("unknown key in [device] (midi, hid or hid-usages)", "device", key)
    usages = device.get("hid-usages", [])
    if not (isinstance(usages, list) and all(isinstance(u, str) and is_usage_name(u) for u in usages)):
        raise fail("expected a list of HID usage names (X, Rz, Hat, Button 1, ..., and what the device is: "
                   "Game Pad, Joystick, Multi-axis Controller)", "device", "hid-usages")
    if midi is not None:
        if not isinstance(midi, str):
            raise fail("must be a string (a port name pattern)", "device", "midi")
        try:
            re.compile(midi)
        except re.error as e:
            raise fail(f"not a regular expression: {e}", "device", "midi") from None
    hid_ids = None
    if hid is not None:
        try:
            hid_ids = tuple(parse_hid_id(h) for h in (hid if isinstance(hid, list) else [hid]))
        except ValueError as e:
            raise fail(str(e), "device", "hid") from None
    controls = [_control(doc, item, k, fail, model) for k, item in enumerate(data.get("control", []))]
    presets = read_presets(doc, model)
    morph = data.get("morph", 0.0)
    feedback = parse_feedback(data["feedback"], fail, model) if "feedback" in data else None
    return Mapping(str(data.get("name", path.stem)), str(path), midi, hid_ids, tuple(controls), presets, float(morph),
                   tuple(usages), feedback, text)


def _control(doc: TomlFile, item: dict, index: int, fail, model: tuple) -> ControlSpec:
    message = item.get("message")
    limit = 16383 if message == "nrpn" else 127
    numbered = message in ("cc", "cc14", "nrpn", "note")  # their number's range is the message's, not the widest
    doc.check(("control", index), item, CONTROL | {"number": Field("whole", 0, limit)} if numbered else CONTROL)
    values = dict(item)
    if "range" in values:
        r = values["range"]
        if not (len(r) == 2 and all(is_number(v) for v in r) and r[0] != r[1]):
            raise fail("expected [low, high], two different finite numbers", "control", index, "range")
        values["range"] = (float(r[0]), float(r[1]))
    if numbered and "number" not in values:
        raise fail(f"expected a whole number from 0 to {limit}", "control", index, "number")
    if message == "cc14" and values["number"] > 31:
        raise fail("a 14-bit pair has its MSB on CC 0 to 31 (the LSB is number + 32)", "control", index, "number")
    if message == "hid":
        values["input"] = canonical_input(str(values.get("input")))
        if values["input"] is None:
            raise fail(f"{quoted(item.get('input'))} is not a HID usage name (X, Y, Z, Rx, Ry, Rz, Slider, Dial, Wheel, Hat/up, "
                       "Button 1, PPPP:UUUU, ...)", "control", index, "input")
    target = values["target"]
    row = row_of(target, *model)
    if row is None or row.kind == "store":
        raise fail(unknown(target, *model).text if row is None else f"{target}: a mapping recalls presets, "
                   "it does not store them", "control", index, "target")
    if values.get("mode") == "set" or "value" in values:
        values["value"] = _set_value(item, row, target, fail, index)
        return ControlSpec(**values)
    for end in item.get("range", (0.0, 1.0)):  # every value the control can send is inside the target's range
        why = value_refusal(row, target, end)
        if why is not None:
            raise fail(f"the control's range sends {end:g}: {why.text}", "control", index,
                       "range" if "range" in values else "target")
    return ControlSpec(**values)


def _set_value(item: dict, row: Row, target: str, fail, index: int) -> float:
    """The value a button in mode "set" sets (checked by the one check: a name is its number)."""
    if item.get("mode") != "set":
        raise fail('only for mode = "set" (a button that sets its target to this value)', "control", index, "value")
    if "value" not in item:
        raise fail('missing: the value a press sets (mode = "set")', "control", index, "value")
    if item["message"] not in BUTTONS:
        raise fail(f'mode = "set" is for a button ({", ".join(BUTTONS)}), not {item["message"]}', "control", index, "mode")
    if row.action:
        raise fail(f'{target}: mode = "set" sets a value, and {target} is pressed (mode = "momentary")', "control", index, "mode")
    for key in ("range", "curve", "takeover", "step", "deadzone", "invert"):
        if key in item:
            raise fail('not for mode = "set" (a press sets `value`)', "control", index, key)
    why = value_refusal(row, target, item["value"])
    if why is not None:
        raise fail(why.text, "control", index, "value")
    return float(row.number(item["value"]))


def preset_problems(mapping: Mapping, presets: dict[str, dict[str, float]]) -> list[str]:
    """preset/NAME targets of a mapping that no preset answers (the mapping's own, the show
    file's or a preset file's): a button that would do nothing, refused at start."""
    return [c.target for c in mapping.controls if c.target.startswith("preset/") and c.target[len("preset/"):] not in presets]


def target_line(mapping: Mapping, target: str) -> int:
    """The 1-based line of the mapping's text where a control's `target = "..."` is `target` (for error messages), or 1."""
    index = next((k for k, c in enumerate(mapping.controls) if c.target == target), None)
    return 1 if index is None else key_lines(mapping.text).get(("control", index, "target"), 1)


def style_problems(mapping: Mapping, state: ControlState) -> list[str]:
    """Targets of a mapping that the loaded model lacks (reported at start, not fatal)."""
    return [c.target for c in mapping.controls if not state.knows(c.target) and not c.target.startswith("preset/")]


@dataclass
class _Memory:
    """What a control remembers between events."""

    msb: int | None = None  # 14-bit: the last MSB
    lsb: int = 0
    toggled: bool = False
    last_position: float | None = None  # the hardware position (target units) of the last event
    last_accepted: float = -math.inf  # time of the last accepted value


class Mapper:
    """Raw events of one device -> the target events they ask for."""

    def __init__(self, mapping: Mapping, presets: dict[str, dict[str, float]] | None = None):
        self.mapping = mapping
        self.presets = mapping.presets if presets is None else presets
        self.by_key: dict[str, list[ControlSpec]] = {}
        for spec in mapping.controls:
            if spec.message == "cc14":  # both halves of the pair arrive as plain CCs
                for number in (spec.number, spec.number + 32):
                    self.by_key.setdefault(f"cc/{spec.channel}/{number}", []).append(spec)
            else:
                self.by_key.setdefault(spec.key, []).append(spec)
        self.memory: dict[ControlSpec, _Memory] = {spec: _Memory() for spec in mapping.controls}
        self.awaiting: set[ControlSpec] = set()  # controls whose hardware is away from their parameter
        self.nrpn: dict[int, list[int]] = {}  # channel -> [parameter MSB, parameter LSB, data MSB]

    def decode(self, state: ControlState, event: ControlEvent) -> list[TargetEvent] | None:
        """The target events one raw event asks for (none: half of a pair, a release, a fader
        away from its value), in the mapping's order; None if no control of the mapping uses it.
        What a control remembers (a pair's MSB, a toggle, where the hardware is) moves either way."""
        if event.control in DS4_NAMES:  # recorded before HID controls were named by usage
            event = ControlEvent(event.time, event.source, *legacy_event(event.control, event.value))
        parts = event.control.split("/")
        if parts[0] == "cc" and len(parts) == 3 and parts[2] in ("99", "98", "6", "38", "96", "97"):
            targets = self._nrpn(state, int(parts[1]), int(parts[2]), int(event.value), event.time)
            if targets is not None:
                return targets
        specs = self.by_key.get(event.control)
        if not specs:
            return None
        targets = []
        for spec in specs:
            value = self._decode(state, spec, event)
            if value is not None:
                targets += self._target(state, spec, value, event.time)
        return targets

    def _nrpn(self, state: ControlState, channel: int, cc: int, value: int, time: float) -> list[TargetEvent] | None:
        slot = self.nrpn.setdefault(channel, [0, 0, 0])
        if cc in (99, 98):  # the parameter's number, in two halves
            slot[0 if cc == 99 else 1] = value
            return []
        parameter = slot[0] * 128 + slot[1]
        specs = self.by_key.get(f"nrpn/{channel}/{parameter}")
        if not specs:
            return None
        targets = []
        for spec in specs:
            if cc == 6:
                slot[2] = value
                raw = value / 127.0 if spec.mode == "absolute" else None
                if raw is None:
                    continue
            elif cc == 38:
                raw = (slot[2] * 128 + value) / 16383.0
            else:  # 96 increment, 97 decrement
                ticks = 1 if cc == 96 else -1
                targets += self._target(state, spec, self._relative(state, spec, ticks), time)
                continue
            targets += self._target(state, spec, self._scale(spec, raw), time)
        return targets

    def _decode(self, state: ControlState, spec: ControlSpec, event: ControlEvent) -> float | None:
        """The target value an event asks for, or None (half of a pair, a release, ...)."""
        raw = event.value
        memory = self.memory[spec]
        if spec.message == "cc14":
            if event.control == f"cc/{spec.channel}/{spec.number}":  # MSB: a new coarse value resets the LSB
                memory.msb, memory.lsb = int(raw), 0
            else:
                memory.lsb = int(raw)
            if memory.msb is None:
                return None
            return self._scale(spec, (memory.msb * 128 + memory.lsb) / 16383.0)
        if spec.mode.startswith("relative"):
            return self._relative(state, spec, _ticks(spec.mode, int(raw)))
        if spec.mode == "set":
            return spec.value if raw > 0 else None  # pressed; its release leaves the value
        if spec.mode in ("toggle", "momentary"):
            pressed = raw > 0
            if spec.mode == "momentary":
                return spec.range[1] if pressed else spec.range[0]
            if not pressed:
                return None
            memory.toggled = not memory.toggled
            return spec.range[1] if memory.toggled else spec.range[0]
        if spec.message == "pitchbend":
            return self._scale(spec, raw / 16383.0)
        if spec.message == "hid":
            return self._scale(spec, unit_with_deadzone(raw, spec.deadzone))
        return self._scale(spec, raw / 127.0)

    def _scale(self, spec: ControlSpec, unit: float) -> float:
        unit = min(max(unit, 0.0), 1.0)
        if spec.invert:
            unit = 1.0 - unit
        if spec.curve == "exp":
            unit = unit * unit
        low, high = spec.travel
        return between(low + (high - low) * unit, *spec.range)

    def _relative(self, state: ControlState, spec: ControlSpec, ticks: int) -> float:
        low, high = sorted(spec.range)
        return min(max(state.get(spec.target) + ticks * spec.step, low), high)

    def _target(self, state: ControlState, spec: ControlSpec, value: float, time: float) -> list[TargetEvent]:
        """The control's target event for `value` (none while a pick-up waits, or for a preset
        button let go or naming no preset)."""
        if spec.target.startswith("preset/"):
            pressed = value > min(spec.range) and spec.target[7:] in self.presets
            return [TargetEvent(time, spec.target, value)] if pressed else []
        if spec.mode == "absolute" and spec.takeover != "none":
            value = self._takeover(state, spec, value, time)
            if value is None:
                return []
        return [TargetEvent(time, spec.target, value)]

    def _takeover(self, state: ControlState, spec: ControlSpec, position: float, time: float) -> float | None:
        """Soft takeover: the value to set, or None while the hardware is away from the parameter."""
        memory = self.memory[spec]
        current = state.get(spec.target)
        previous, memory.last_position = memory.last_position, position
        span = abs(spec.range[1] - spec.range[0])
        if previous is None:  # the first value after enabling only tells where the hardware is
            return None
        if spec.takeover == "scale":
            if abs(position - current) <= PICKUP_THRESHOLD * span or position == previous:
                memory.last_accepted = time
                return position
            end = max(spec.range) if position > previous else min(spec.range)
            if (end - previous) == 0:
                return position
            value = current + (position - previous) * (end - current) / (end - previous)
            memory.last_accepted = time
            return between(value, current, end)
        near = abs(position - current) <= PICKUP_THRESHOLD * span
        held = abs(previous - current) <= PICKUP_THRESHOLD * span  # it was at the parameter: a move of a fader in hand
        crossed = (previous - current) * (position - current) < 0
        recent = time - memory.last_accepted <= FAST_SWEEP
        if near or held or crossed or recent:
            memory.last_accepted = time
            self.awaiting.discard(spec)
            return position
        self.awaiting.add(spec)
        return None


def _ticks(mode: str, value: int) -> int:
    """Signed steps of a relative encoder message, in its encoding."""
    if mode == "relative-twos":  # 1..63 up, 127..65 down
        return value - 128 if value >= 64 else value
    if mode == "relative-signed":  # bit 6 is the sign: 1..63 up, 65..127 down
        return -(value - 64) if value >= 64 else value
    if mode == "relative-signed2":  # bit 6 set means up: 65..127 up, 1..63 down
        return value - 64 if value >= 64 else -value
    return value - 64  # relative-offset: 64 is no change
