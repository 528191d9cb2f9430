"""A HID report descriptor parsed into the fields of each report (HID 1.11, section 6.2.2).

Why our own: the instrument needs only where each field's bits are and what usage, range and
flags it has, which is this one walk over the items. hid-tools (GPL-2.0-only) does not fit an
MIT project; hid-parser 0.1.0 (MIT) mis-sizes every report in which a Report Count exceeds the
usages given (it does not repeat the last usage, so the DualShock 4's report 1 comes out 11
bytes, not 64), reads 4-byte extended usages under the current page (losing the Switch Pro
Controller's sticks), and stops on Push, Pop and Delimiter items.

What is read: main items (Input, Output, Feature, Collection: the usage of each application
collection, End Collection), global items (Usage Page, Logical Minimum/Maximum as signed numbers,
Report Size, Report ID, Report Count, Push, Pop), local items (Usage, Usage Minimum/Maximum,
Delimiter: the first usage of a delimited set), 4-byte extended usages (usage page in the high
16 bits), long items (skipped).
Physical ranges, units, designators and strings are read past: nothing here uses them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

INPUT, OUTPUT, FEATURE = "input", "output", "feature"
_MAIN_KINDS = {0x8: INPUT, 0x9: OUTPUT, 0xB: FEATURE}
_COLLECTION, _END_COLLECTION = 0xA, 0xC
_APPLICATION = 0x01  # the kind of collection that says what a device is (Game Pad, Multi-axis Controller)
_MAIN, _GLOBAL, _LOCAL = 0, 1, 2  # item types
_USAGE_PAGE, _LOGICAL_MINIMUM, _LOGICAL_MAXIMUM, _REPORT_SIZE, _REPORT_ID, _REPORT_COUNT, _PUSH, _POP = (
    0x0, 0x1, 0x2, 0x7, 0x8, 0x9, 0xA, 0xB)  # global item tags read (physical range, unit: not needed)
_USAGE, _USAGE_MINIMUM, _USAGE_MAXIMUM, _DELIMITER = 0x0, 0x1, 0x2, 0xA  # local item tags read
MAX_REPORT_SIZE = 256  # bits in one field: the kernel's limit too
MAX_REPORT_BYTES = 16384  # one report at most (the kernel's HID_MAX_BUFFER_SIZE)

CONSTANT, VARIABLE, RELATIVE, NULL_STATE = 0x01, 0x02, 0x04, 0x40  # main item flags


class DescriptorError(ValueError):
    """The bytes are not a report descriptor this parser can lay out (the message says where)."""


@dataclass(frozen=True)
class Field:
    """One field of a report: `size` bits at `bit`, counted from the start of the report as sent
    (its id byte included when the descriptor numbers its reports)."""

    report_id: int  # 0 when the descriptor numbers no reports
    bit: int
    size: int
    page: int  # usage page and usage; 0, 0 for a field declared with no usage (padding)
    usage: int
    flags: int
    logical_min: int
    logical_max: int

    @property
    def constant(self) -> bool:
        return bool(self.flags & CONSTANT)

    @property
    def variable(self) -> bool:
        """A value per usage (an axis, a button), rather than an array of the usages pressed now."""
        return bool(self.flags & VARIABLE)

    @property
    def relative(self) -> bool:
        return bool(self.flags & RELATIVE)

    @property
    def null_state(self) -> bool:
        return bool(self.flags & NULL_STATE)


@dataclass
class Report:
    """One report of one kind (input, output or feature): its fields in order and its length."""

    report_id: int
    bits: int = 0  # of its fields, the id byte included
    fields: list[Field] = field(default_factory=list)

    @property
    def length(self) -> int:
        """Bytes as sent, the id byte included."""
        return (self.bits + 7) // 8


@dataclass
class ReportDescriptor:
    """The reports a descriptor declares, by kind and report id (0: not numbered)."""

    inputs: dict[int, Report] = field(default_factory=dict)
    outputs: dict[int, Report] = field(default_factory=dict)
    features: dict[int, Report] = field(default_factory=dict)
    numbered: bool = False
    applications: list[tuple[int, int]] = field(default_factory=list)  # usage of each application collection (Game Pad, ...)

    def reports(self, kind: str) -> dict[int, Report]:
        return {INPUT: self.inputs, OUTPUT: self.outputs, FEATURE: self.features}[kind]


@dataclass
class _Globals:
    page: int = 0
    logical_min: int = 0
    logical_max: int = 0
    size: int = 0
    count: int = 0
    report_id: int = 0


def _items(data: bytes):
    """(offset, type, tag, size in bytes, unsigned value, signed value) for each short item; long items skipped."""
    at = 0
    while at < len(data):
        prefix = data[at]
        if prefix == 0xFE:  # long item: size byte, tag byte, data (none are defined)
            if at + 2 >= len(data):
                raise DescriptorError(f"byte {at}: a long item cut short")
            at += 3 + data[at + 1]
            if at > len(data):
                raise DescriptorError("a long item runs past the end")
            continue
        size = (0, 1, 2, 4)[prefix & 0x03]
        if at + 1 + size > len(data):
            raise DescriptorError(f"byte {at}: item 0x{prefix:02x} needs {size} data bytes, "
                                  f"{len(data) - at - 1} left")
        raw = data[at + 1:at + 1 + size]
        yield at, (prefix >> 2) & 0x03, prefix >> 4, size, int.from_bytes(raw, "little"), int.from_bytes(raw, "little", signed=True)
        at += 1 + size


def parse_report_descriptor(data: bytes) -> ReportDescriptor:
    """Every input, output and feature report a descriptor declares, field by field.
    DescriptorError (saying at which byte) if it is cut short or inconsistent."""
    out = ReportDescriptor()
    state, stack = _Globals(), []
    usages: list[tuple[int, int]] = []  # (page, usage) declared since the last main item
    usage_min: tuple[int, int] | None = None
    in_delimited_set, set_has_usage = False, False  # alternative usages for one control: the first counts
    collections = 0
    for at, kind, tag, size, value, signed in _items(data):
        if kind == _MAIN:
            if tag in _MAIN_KINDS:
                _add_fields(out, _MAIN_KINDS[tag], state, usages, value, at)
            elif tag == _COLLECTION:
                collections += 1
                if value == _APPLICATION:
                    out.applications.append(usages[0] if usages else (0, 0))
            elif tag == _END_COLLECTION:
                collections -= 1
                if collections < 0:
                    raise DescriptorError(f"byte {at}: End Collection without a Collection")
            usages, usage_min = [], None  # locals last until the next main item
        elif kind == _GLOBAL:
            if tag == _USAGE_PAGE:
                state.page = value
            elif tag == _LOGICAL_MINIMUM:
                state.logical_min = signed
            elif tag == _LOGICAL_MAXIMUM:
                state.logical_max = signed
            elif tag == _REPORT_SIZE:
                if not 0 < value <= MAX_REPORT_SIZE:
                    raise DescriptorError(f"byte {at}: Report Size {value} (1 to {MAX_REPORT_SIZE} bits)")
                state.size = value
            elif tag == _REPORT_ID:
                if not 0 < value <= 255:
                    raise DescriptorError(f"byte {at}: Report ID {value} (1 to 255)")
                if not out.numbered and (out.inputs or out.outputs or out.features):
                    raise DescriptorError(f"byte {at}: a Report ID after fields declared without one")
                out.numbered, state.report_id = True, value
            elif tag == _REPORT_COUNT:
                state.count = value
            elif tag == _PUSH:
                stack.append(_Globals(**vars(state)))
            elif tag == _POP:
                if not stack:
                    raise DescriptorError(f"byte {at}: Pop without a Push")
                state = stack.pop()
        elif kind == _LOCAL:
            if tag == _DELIMITER:  # opens (1) or closes (0) a set of alternative usages
                in_delimited_set, set_has_usage = bool(value), False
                continue
            if tag not in (_USAGE, _USAGE_MINIMUM, _USAGE_MAXIMUM) or (in_delimited_set and set_has_usage):
                continue
            set_has_usage = in_delimited_set
            usage = (value >> 16, value & 0xFFFF) if size == 4 else (state.page, value)  # 4 bytes: extended usage
            if tag == _USAGE:
                usages.append(usage)
            elif tag == _USAGE_MINIMUM:
                usage_min = usage
            elif usage_min is None:
                raise DescriptorError(f"byte {at}: Usage Maximum without a Usage Minimum")
            else:
                page = usage_min[0] if size < 4 else usage[0]
                usages.extend((page, u) for u in range(usage_min[1], usage[1] + 1))
                usage_min = None
        else:
            raise DescriptorError(f"byte {at}: item 0x{data[at]:02x} of the reserved type")
    return out


def _add_fields(out: ReportDescriptor, kind: str, state: _Globals, usages: list[tuple[int, int]], flags: int, at: int) -> None:
    """The fields of one Input, Output or Feature item: Report Count fields of Report Size bits.
    A variable item gives each field the next usage, the last one repeated when they run out
    (HID 1.11, 6.2.2.8); an array item's fields all carry its first usage (they hold usage
    indices, not values); a field with no usage at all is padding (page 0, usage 0)."""
    reports = out.reports(kind)
    report = reports.get(state.report_id)
    if report is None:
        report = reports[state.report_id] = Report(state.report_id, 8 if out.numbered else 0)
    if state.count and not state.size:
        raise DescriptorError(f"byte {at}: {kind} item with no Report Size")
    if report.bits + state.count * state.size > 8 * MAX_REPORT_BYTES:
        raise DescriptorError(f"byte {at}: {kind} report {state.report_id} longer than {MAX_REPORT_BYTES} bytes")
    for k in range(state.count):
        page, usage = (usages[min(k, len(usages) - 1)] if flags & VARIABLE else usages[0]) if usages else (0, 0)
        report.fields.append(Field(state.report_id, report.bits, state.size, page, usage, flags,
                                   state.logical_min, state.logical_max))
        report.bits += state.size
