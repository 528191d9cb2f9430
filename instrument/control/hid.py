"""Any HID controller: its controls read from the device's own report descriptor, named by usage.

The descriptor (hidapi's get_report_descriptor, or the hidraw ioctl where the binding lacks it)
is parsed once by hid_report_descriptor.py (the project's own parser; why, it says there). Each
input report is then decoded with a precomputed table of bit positions and normalised the same
way for every device: an axis, trigger, dial or slider reads 0..1 over its logical range (a
stick at rest is near 0.5), a button 0 or 1, a hat switch `Hat` (its position, 0..1, or -1 when
released) and the four buttons `Hat/up`, `Hat/right`, `Hat/down`, `Hat/left`.

A control's name is its usage: `X Y Z Rx Ry Rz Slider Dial Wheel Hat`, `Accelerator Brake ...`
(simulation page), `AC Home`, `AC Back` (consumer page), `Button <n>`, or `PPPP:UUUU` (usage page
and usage, hexadecimal) for any other; a usage met again on the same device is `<name>#2`, `#3`,
... Vendor-defined pages (FF00 and up), constant (padding) fields and array fields (keyboard-style
key lists) are not controls.

Reports that do not fit the descriptor are dropped and counted: unknown report id, shorter than
the descriptor says, or garbage (a value outside its logical range in a field without a null state);
so are vendor-only reports (declared, but with no control a performer plays: a DualShock 4 over
Bluetooth switched by the kernel's driver into its report 0x11 mode sends only those).
"""

from __future__ import annotations

import fcntl
import functools
import math
import os
import re
import sys
import time
from dataclasses import dataclass, field

from ..errors import UserError
from ..terminal import Console
from .events import RawEvent, Source
from .hid_report_descriptor import DescriptorError, parse_report_descriptor

RETRY_SECONDS = 1.0
READS_PER_POLL = 64  # reports drained per frame at most: a flood is read over several frames, never blocks one

GENERIC_DESKTOP, SIMULATION, LEDS, BUTTONS, CONSUMER = 0x01, 0x02, 0x08, 0x09, 0x0C
USAGE_NAMES = {
    GENERIC_DESKTOP: {0x30: "X", 0x31: "Y", 0x32: "Z", 0x33: "Rx", 0x34: "Ry", 0x35: "Rz", 0x36: "Slider", 0x37: "Dial",
                      0x38: "Wheel", 0x39: "Hat"},
    SIMULATION: {0xBA: "Rudder", 0xBB: "Throttle", 0xC4: "Accelerator", 0xC5: "Brake", 0xC8: "Steering"},
    CONSUMER: {0x223: "AC Home", 0x224: "AC Back"},
}
# what a device says it is: the usage of its application collection, matched by a mapping's `hid-usages`
APPLICATION_NAMES = {(GENERIC_DESKTOP, 0x04): "Joystick", (GENERIC_DESKTOP, 0x05): "Game Pad",
                     (GENERIC_DESKTOP, 0x08): "Multi-axis Controller"}
HAT_DIRECTIONS = ("up", "right", "down", "left")
HAT_EIGHT = (("up",), ("up", "right"), ("right",), ("down", "right"), ("down",), ("down", "left"), ("left",), ("up", "left"))
HAT_FOUR = (("up",), ("right",), ("down",), ("left",))

_NAMED = "|".join(sorted((n for names in USAGE_NAMES.values() for n in names.values()), key=len, reverse=True))
USAGE_NAME = re.compile(rf"(?:(?:{_NAMED})|Hat/(?:up|right|down|left)|Button [1-9][0-9]*|[0-9a-f]{{4}}:[0-9a-f]{{4}})"
                        r"(?:#[2-9]|#[1-9][0-9]+)?")

# The DualShock 4's names before controls were named by usage (mapping files and recorded logs
# written then still work): name -> (usage name, full scale of the old raw value)
DS4_NAMES = {"lx": ("X", 255.0), "ly": ("Y", 255.0), "rx": ("Z", 255.0), "ry": ("Rz", 255.0), "l2": ("Rx", 255.0),
             "r2": ("Ry", 255.0), "hat": ("Hat", 7.0)}  # the old hat: 0 (up) to 7 (up-left) clockwise, 8 released
DS4_NAMES.update({f"button/{b}": (f"Button {k + 1}", 1.0) for k, b in enumerate(
    ("square", "cross", "circle", "triangle", "l1", "r1", "l2", "r2", "share", "options", "l3", "r3"))})
DS4_NAMES.update({f"button/{d}": (f"Hat/{d}", 1.0) for d in HAT_DIRECTIONS})


def canonical_input(name: str) -> str | None:
    """The usage name a mapping's `input` stands for (DualShock 4 names included), or None if none."""
    if name in DS4_NAMES:
        return DS4_NAMES[name][0]
    return name if USAGE_NAME.fullmatch(name) else None


def legacy_event(control: str, value: float) -> tuple[str, float]:
    """A recorded DualShock 4 event of the old naming (raw 0..255; the hat 0..7, 8 released) as a
    usage-named one (0..1; a released hat -1)."""
    name, scale = DS4_NAMES[control]
    if name == "Hat" and value > scale:
        return name, -1.0
    return name, value / scale


def is_usage_name(name: str) -> bool:
    """Whether `name` can stand in a mapping's `hid-usages`: a control's usage name or an application's."""
    return USAGE_NAME.fullmatch(name) is not None or name in APPLICATION_NAMES.values()


def usage_name(page: int, usage: int) -> str:
    if page == BUTTONS:
        return f"Button {usage}"
    return USAGE_NAMES.get(page, {}).get(usage) or f"{page:04x}:{usage:04x}"


@dataclass(frozen=True)
class HidControl:
    """One control of a device: where its bits are and what they mean."""

    name: str
    page: int
    usage: int
    report_id: int  # 0 when the device numbers no reports
    bit: int  # first bit, counted from the start of the report as read (its id byte included)
    size: int  # bits
    minimum: int  # logical range
    maximum: int
    relative: bool = False  # as declared (a SpaceMouse declares its displacements relative)
    null_state: bool = False  # values outside the range mean "nothing" (a released hat)

    @property
    def kind(self) -> str:
        if self.name.startswith("Hat"):
            return "hat"
        return "button" if self.page == BUTTONS or (self.size == 1 and self.maximum - self.minimum == 1) else "axis"


@dataclass(frozen=True)
class OutputField:
    """A field of an output report (for feedback): LEDs are set from it by usage."""

    page: int
    usage: int
    report_id: int
    bit: int
    size: int
    minimum: int
    maximum: int


class ReportLayout:
    """How to decode one input report: each control's shift and mask into the report read as one
    little-endian integer. (For the tens of fields a controller has this is several times faster
    than a numpy bit table, whose per-call overhead dominates: 1.8 against 8 us for a DualShock 4.)"""

    def __init__(self, report_id: int, length: int, controls: list[HidControl]):
        self.report_id, self.length, self.controls = report_id, length, controls
        self.fields = [(c.bit, (1 << c.size) - 1) for c in controls]
        self.signed = [(k, 1 << (c.size - 1), 1 << c.size) for k, c in enumerate(controls) if c.minimum < 0]
        # a hat outside its range is released, null-state flag or not (the Switch Pro's USB descriptor lacks it)
        self.checked = [(k, c.minimum, c.maximum) for k, c in enumerate(controls)
                        if not (c.null_state or c.kind == "hat") and _narrower(c)]
        self.hats = [k for k, c in enumerate(controls) if c.kind == "hat"]

    def raw(self, report: bytes) -> list[int] | None:
        """The logical value of every control, or None for garbage (a value outside a range that has no null state)."""
        bits = int.from_bytes(report[:self.length], "little")
        raw = [(bits >> shift) & mask for shift, mask in self.fields]
        for k, half, wrap in self.signed:
            if raw[k] >= half:
                raw[k] -= wrap
        for k, low, high in self.checked:
            if not low <= raw[k] <= high:
                return None
        return raw

    def unit(self, k: int, raw: int) -> float:
        """A logical value as 0..1 over the control's range; -1 outside it (a released hat)."""
        c = self.controls[k]
        if not c.minimum <= raw <= c.maximum:
            return -1.0
        return (raw - c.minimum) / (c.maximum - c.minimum) if c.maximum > c.minimum else float(raw > c.minimum)


def _narrower(c: HidControl) -> bool:
    """Whether the logical range leaves values of the field's bits out (only then can a value be garbage)."""
    if c.minimum < 0:
        return c.minimum > -(1 << (c.size - 1)) or c.maximum < (1 << (c.size - 1)) - 1
    return c.minimum > 0 or c.maximum < (1 << c.size) - 1


@dataclass
class Descriptor:
    """A parsed report descriptor: the input controls by report id, and the output fields."""

    layouts: dict[int, ReportLayout]
    outputs: dict[int, tuple[int, list[OutputField]]] = field(default_factory=dict)  # report id -> (bytes, fields)
    vendor_only: set[int] = field(default_factory=set)  # input reports declared with no controls (vendor data)
    applications: tuple[str, ...] = ()  # what the device says it is (Game Pad, Multi-axis Controller, PPPP:UUUU)

    @property
    def controls(self) -> list[HidControl]:
        return [c for layout in self.layouts.values() for c in layout.controls]

    @property
    def numbered(self) -> bool:
        return 0 not in self.layouts


def parse_descriptor(data: bytes | list[int]) -> Descriptor:
    """Controls and output fields of a report descriptor; UserError if it cannot be parsed.
    Remembered: a device plugged back in mid-performance costs no parsing (ms) in the live loop."""
    return _parse(bytes(data))


@functools.lru_cache(maxsize=32)
def _parse(data: bytes) -> Descriptor:
    try:
        parsed = parse_report_descriptor(data)
    except DescriptorError as error:
        raise UserError(f"cannot parse the HID report descriptor ({len(data)} bytes): {error}") from None
    layouts: dict[int, ReportLayout] = {}
    vendor_only: set[int] = set()
    seen: dict[str, int] = {}
    for report_id, report in sorted(parsed.inputs.items()):
        controls = []
        for f in report.fields:
            if f.constant or not f.variable or f.page >= 0xFF00 or f.page == 0 or f.size > 32:
                continue
            name = usage_name(f.page, f.usage)
            seen[name] = seen.get(name, 0) + 1
            if seen[name] > 1:
                name = f"{name}#{seen[name]}"
            maximum = f.logical_max
            if f.logical_min >= 0 > maximum:  # "25 FF" after a minimum of 0 means 255, as the kernel reads it
                maximum &= (1 << f.size) - 1
            controls.append(HidControl(name, f.page, f.usage, report_id, f.bit, f.size, f.logical_min, maximum,
                                       relative=f.relative, null_state=f.null_state))
        if controls:
            layouts[report_id] = ReportLayout(report_id, report.length, controls)
        else:
            vendor_only.add(report_id)
    outputs = {}
    for report_id, report in sorted(parsed.outputs.items()):
        fields = [OutputField(f.page, f.usage, report_id, f.bit, f.size, f.logical_min, f.logical_max)
                  for f in report.fields if not f.constant]
        outputs[report_id] = (report.length, fields)
    applications = tuple(APPLICATION_NAMES.get(a) or f"{a[0]:04x}:{a[1]:04x}" for a in parsed.applications)
    return Descriptor(layouts, outputs, vendor_only, applications)


HIDIOCGRDESCSIZE = 0x80044801  # _IOR('H', 0x01, int)
HIDIOCGRDESC = 0x90044802  # _IOR('H', 0x02, struct hidraw_report_descriptor): u32 size + 4096 bytes


def hidraw_descriptor(path: str | bytes) -> bytes:
    """A device's report descriptor through the hidraw ioctl (Linux), for bindings without the call."""
    fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    try:
        size = bytearray(4)
        fcntl.ioctl(fd, HIDIOCGRDESCSIZE, size)
        buffer = bytearray(4 + 4096)
        buffer[:4] = size
        fcntl.ioctl(fd, HIDIOCGRDESC, buffer)
        return bytes(buffer[4:4 + int.from_bytes(size, "little")])
    finally:
        os.close(fd)


def read_descriptor(device, path) -> bytes:
    """The report descriptor of an open hidapi device: the binding's call where it has it."""
    if hasattr(device, "get_report_descriptor"):
        return bytes(device.get_report_descriptor())
    return hidraw_descriptor(path)


def hidapi():
    """The hidapi binding: on Linux its hidraw backend (`import hidraw`, the same API), which reads
    USB and Bluetooth devices through /dev/hidraw*; elsewhere, or without it, `import hid` (on Linux
    that one is libusb: USB devices only, none over Bluetooth). A UserError says how to get it."""
    if sys.platform.startswith("linux"):
        try:
            import hidraw

            return hidraw
        except ImportError:
            pass
    try:
        import hid
    except ImportError as error:
        raise UserError(f"HID is not available: {error} (pip install hidapi)") from None
    return hid


def open_device(hid, info: dict) -> tuple[object, Descriptor]:
    """Open one enumerated device without blocking and parse its descriptor (OSError or UserError if not)."""
    device = hid.device()
    device.open_path(info["path"])
    try:
        device.set_nonblocking(1)
        return device, parse_descriptor(read_descriptor(device, info["path"]))
    except BaseException:
        device.close()
        raise


def describe_controls(controls: list[HidControl]) -> str:
    """Controls in one line: axes with their ranges, buttons as a span."""
    parts, buttons = [], []
    for c in controls:
        if c.page == BUTTONS and "#" not in c.name:
            buttons.append(c.usage)
            continue
        extra = " relative" if c.relative else ""
        parts.append(f"{c.name} ({c.minimum}..{c.maximum}{extra})" if c.kind == "axis" else c.name)
    if buttons:
        parts.append(f"Button {min(buttons)}-{max(buttons)}" if len(buttons) > 1 else f"Button {buttons[0]}")
    return ", ".join(parts)


class HidInput:
    """A HID device by vendor and product id, decoded from its report descriptor, polled without blocking.

    `hid` is the hidapi module (or a stand-in with the same `enumerate` and `device`). Events are
    the controls that changed, normalised (see the module docstring); an unplugged device is said
    on the console and reopened about once a second, while the walk goes on."""

    def __init__(self, console: Console, vendor: int, product: int, hid=None):
        self.hid = hid if hid is not None else hidapi()
        self.console, self.vendor, self.product = console, vendor, product
        self.source = Source.of("hid", f"{vendor:04x}:{product:04x}")
        self.device = None
        self.descriptor: Descriptor | None = None
        self.last: dict[int, list[int]] = {}  # report id -> logical values last seen
        self.hat_state: dict[str, float] = {}
        self.next_attempt = 0.0
        self.connections = 0  # how many times it was opened (feedback is sent again after each)
        # vendor-only: reports of a mode the descriptor leaves to the device's own driver
        self.dropped = {"short": 0, "unknown id": 0, "garbage": 0, "vendor-only": 0}
        self.reports = 0
        self.read_size = 64
        self._open()  # before the performance starts: the first descriptor is parsed here, not in a frame

    def _open(self) -> None:
        now = time.monotonic()
        if now < self.next_attempt:
            return
        self.next_attempt = now + RETRY_SECONDS
        found = self.hid.enumerate(self.vendor, self.product)
        if not found:
            self.console.warn(f"hid {self.source}", f"HID device {self.vendor:04x}:{self.product:04x} not found; waiting for it")
            return
        problems = []
        for info in found:  # a device may have several interfaces: the first with controls
            try:
                device, descriptor = open_device(self.hid, info)
            except (OSError, UserError) as error:
                problems.append(str(error))
                continue
            if not descriptor.layouts:
                device.close()
                problems.append("its report descriptor declares no controls")
                continue
            self.device, self.descriptor, self.last, self.hat_state = device, descriptor, {}, {}
            self.read_size = max(64, *(layout.length for layout in descriptor.layouts.values()))  # hidraw cuts longer reports
            self.console.say(f"HID device {self.source} {'reconnected' if self.connections else 'connected'}: "
                             f"{describe_controls(descriptor.controls)}")
            self.connections += 1
            return
        self.console.warn(f"hid {self.source}", f"cannot open HID device {self.source}: {'; '.join(problems)}")

    def _lost(self, error: Exception) -> None:
        self.console.warn(f"hid gone {self.source}", f"HID device {self.source} lost ({error}); the walk goes on, reconnecting")
        try:
            self.device.close()
        except OSError:
            pass
        self.device = None
        self.next_attempt = time.monotonic() + RETRY_SECONDS

    def read_raw(self) -> list[tuple[str, float]]:
        """The controls that changed in every report waiting, in order, as (name, normalised value)."""
        if self.device is None:
            self._open()
            if self.device is None:
                return []
        out: list[tuple[str, float]] = []
        for _ in range(READS_PER_POLL):
            try:
                report = self.device.read(self.read_size)
            except (OSError, ValueError) as error:  # unplugged: hidapi raises OSError ('read error')
                self._lost(error)
                break
            if not report:
                break
            out += self.decode(bytes(report))
        return out

    def decode(self, report: bytes) -> list[tuple[str, float]]:
        """One report's changed controls; a report that does not fit the descriptor is counted and dropped."""
        self.reports += 1
        descriptor = self.descriptor
        report_id = report[0] if descriptor.numbered else 0
        layout = descriptor.layouts.get(report_id)
        problem = None
        if layout is None:
            problem = "vendor-only" if report_id in descriptor.vendor_only else "unknown id"
        elif len(report) < layout.length:
            problem = "short"
        else:
            raw = layout.raw(report)
            if raw is None:
                problem = "garbage"
        if problem is not None:
            self.dropped[problem] += 1
            self.console.warn(f"hid dropped {self.source}", f"HID device {self.source}: dropped reports that do not fit its "
                              f"descriptor ({', '.join(f'{n} {k}' for k, n in self.dropped.items() if n)})")
            return []
        last = self.last.get(layout.report_id)
        self.last[layout.report_id] = raw
        if last == raw:
            return []
        changed = range(len(raw)) if last is None else [k for k, (now, before) in enumerate(zip(raw, last)) if now != before]
        controls = layout.controls
        out = [(controls[k].name, layout.unit(k, raw[k])) for k in changed]
        for k in layout.hats:
            if last is None or raw[k] != last[k]:
                out += self._hat(controls[k], raw[k])
        return out

    def _hat(self, control: HidControl, raw: int) -> list[tuple[str, float]]:
        """Hat/up, Hat/right, Hat/down, Hat/left as buttons (the ones that changed)."""
        positions = HAT_EIGHT if control.maximum - control.minimum == 7 else HAT_FOUR
        step = raw - control.minimum
        pressed = positions[step] if 0 <= step < len(positions) else ()
        prefix, _, suffix = control.name.partition("#")
        out = []
        for direction in HAT_DIRECTIONS:
            name = f"{prefix}/{direction}" + (f"#{suffix}" if suffix else "")
            value = float(direction in pressed)
            if self.hat_state.get(name) != value:
                self.hat_state[name] = value
                out.append((name, value))
        return out

    def poll(self, now: float) -> list[RawEvent]:
        return [RawEvent(now, self.source, control, value) for control, value in self.read_raw()]

    def write(self, report: bytes) -> bool:
        """Send an output report (feedback); False if the device is not open or refused it."""
        if self.device is None:
            return False
        try:
            return self.device.write(report) >= 0
        except (OSError, ValueError):
            return False  # the next read notices an unplugged device

    def describe(self) -> str:
        dropped = sum(self.dropped.values())
        return f"{self.source} {'on' if self.device else 'waiting'}" + (f" ({dropped} reports dropped)" if dropped else "")

    def close(self) -> None:
        if self.device is not None:
            self.device.close()
            self.device = None


def device_descriptor(hid, vendor: int, product: int) -> Descriptor | None:
    """The descriptor of a device plugged in now (its first interface with controls), None if it is
    not here; UserError saying why if it is here but cannot be read (a descriptor that cannot be
    parsed says at which byte)."""
    problems = []
    for info in hid.enumerate(vendor, product):
        try:
            device, descriptor = open_device(hid, info)
        except (OSError, UserError) as error:
            problems.append(str(error))
            continue
        device.close()
        if descriptor.layouts:
            return descriptor
        problems.append("its report descriptor declares no controls")
    if problems:
        raise UserError("; ".join(dict.fromkeys(problems)))
    return None


def matches_usages(wanted: tuple[str, ...], descriptor: Descriptor) -> bool:
    """Whether a device has every usage a mapping's `hid-usages` asks for (controls and what it is)."""
    names = {c.name for c in descriptor.controls} | set(descriptor.applications)
    return all(w in names for w in wanted)


def unit_with_deadzone(value: float, deadzone: float) -> float:
    """A normalised reading with `deadzone` (share of the half-travel) around the centre read as centre."""
    if deadzone <= 0 or value < 0:
        return max(value, 0.0)
    centred = max(-1.0, min(1.0, value * 2.0 - 1.0))
    if abs(centred) <= deadzone:
        return 0.5
    return (math.copysign((abs(centred) - deadzone) / (1.0 - deadzone), centred) + 1.0) / 2.0


def choose_mapping(mappings: list, vendor: int, product: int, hid=None) -> tuple[object | None, str]:
    """The mapping naming this device's vendor:product, else the one whose `hid-usages` it has (the
    most specific), read from the device now; with a sentence saying why, or why none fits."""
    by_id = [m for m in mappings if m.hid and (vendor, product) in m.hid]
    if by_id:
        return by_id[0], "by vendor:product"
    candidates = [m for m in mappings if m.hid_usages]
    if not candidates:
        return None, "no mapping names this device"
    try:
        descriptor = device_descriptor(hid if hid is not None else hidapi(), vendor, product)
    except UserError as error:
        return None, f"no mapping names this device, and its usages cannot be read: {error}"
    if descriptor is None:
        return None, "no mapping names this device, and it is not here to read its usages from"
    fitting = [m for m in candidates if matches_usages(m.hid_usages, descriptor)]
    if not fitting:
        return None, f"no mapping names this device or fits its controls ({describe_controls(descriptor.controls)})"
    return max(fitting, key=lambda m: len(m.hid_usages)), "by its usages"


@dataclass(frozen=True)
class LearnedHid:
    """A HID control found by moving it: its usage name, and whether it rests in the middle."""

    input: str
    button: bool
    centred: bool

    def toml(self, target: str, value_range: tuple[float, float] | None, value: str | None = None) -> str:
        """The [[control]] table; with `value`, a button that sets the target to it (gait=run)."""
        lines = ["[[control]]", 'message = "hid"', f'input = "{self.input}"']
        if value is not None:
            return "\n".join(lines + ['mode = "set"', f'target = "{target}"', f'value = "{value}"']) + "\n"
        if self.button:
            lines.append('mode = "momentary"')
        lines.append(f'target = "{target}"')
        if value_range is not None and not self.button:
            lines.append(f"range = [{value_range[0]}, {value_range[1]}]")
        if self.centred:
            lines.append("deadzone = 0.1")
        return "\n".join(lines) + "\n"


LEARN_TRAVEL = 0.25  # an axis must travel this share of its range to count as moved (a resting stick jitters)


def detect_hid(raw: list[tuple[str, float]]) -> LearnedHid | None:
    """Which control was moved, from the (name, normalised value) events that came: a button pressed
    wins; else the axis that travelled furthest. None if nothing moved enough."""
    pressed = [name for name, value in raw if value > 0 and (name.startswith("Button ") or "/" in name)]
    if pressed:
        return LearnedHid(pressed[0], True, False)
    travel: dict[str, list[float]] = {}
    for name, value in raw:
        if not name.startswith("Hat"):
            travel.setdefault(name, []).append(value)
    if not travel:
        return None
    name = max(travel, key=lambda n: max(travel[n]) - min(travel[n]))
    values = travel[name]
    if max(values) - min(values) < LEARN_TRAVEL:
        return None
    return LearnedHid(name, False, abs(values[0] - 0.5) < 0.1 or abs(values[-1] - 0.5) < 0.1)
