"""The report descriptor parser against the HID 1.11 item rules (section 6.2.2), on small descriptors
written here item by item (the expected fields worked out by hand from the spec) and on the
Switch Pro Controller's published descriptor, whose sticks use 4-byte extended usages."""

from __future__ import annotations

import pytest
from hid_descriptors import SWITCH_PRO_USB

from instrument.control.hid_report_descriptor import DescriptorError, parse_report_descriptor

GAMEPAD = "05 01 09 05 a1 01"  # Usage Page (Generic Desktop), Usage (Game Pad), Collection (Application)
END = "c0"


def fields(hex_items: str, kind: str = "inputs", report_id: int = 0) -> list[tuple]:
    report = getattr(parse_report_descriptor(bytes.fromhex(hex_items)), kind)[report_id]
    return [(f.bit, f.size, f.page, f.usage, f.logical_min, f.logical_max, f.variable, f.constant) for f in report.fields]


def test_switch_pro_sticks_are_read_from_their_extended_usages():
    # its report 0x30: id byte, Buttons 1-14 and 2 bits padding, then `0B 30 00 01 00` ... : X, Y, Z, Rz
    # given as 4-byte usages (page 0x0001 in the high half) while the Usage Page in effect is Buttons
    sticks = [f for f in parse_report_descriptor(SWITCH_PRO_USB).inputs[0x30].fields if f.size == 16]
    assert [(f.bit, f.page, f.usage, f.logical_min, f.logical_max) for f in sticks] == [
        (24, 0x01, 0x30, 0, 65535), (40, 0x01, 0x31, 0, 65535), (56, 0x01, 0x32, 0, 65535), (72, 0x01, 0x35, 0, 65535)]


def test_extended_usage_minimum_and_maximum_carry_their_own_page():
    # Usage Minimum (0x0009:0001), Usage Maximum (0x0009:0003) under the Generic Desktop page
    got = fields(GAMEPAD + "1b 01 00 09 00 2b 03 00 09 00 15 00 25 01 75 01 95 03 81 02 95 05 81 03" + END)
    assert [(bit, page, usage) for bit, _, page, usage, *_ in got if usage] == [(0, 9, 1), (1, 9, 2), (2, 9, 3)]


def test_a_report_count_beyond_the_usages_repeats_the_last_usage_and_counts_every_field():
    descriptor = parse_report_descriptor(bytes.fromhex(
        GAMEPAD + "85 01 09 30 09 31 15 00 26 ff 00 75 08 95 04 81 02" + END))  # 2 usages, 4 fields of 8 bits
    report = descriptor.inputs[1]
    assert [(f.bit, f.usage) for f in report.fields] == [(8, 0x30), (16, 0x31), (24, 0x31), (32, 0x31)]
    assert report.length == 5 and descriptor.numbered  # the id byte and four bytes


def test_signed_logical_ranges_and_padding():
    got = fields(GAMEPAD + "09 30 16 a2 fe 26 5e 01 75 10 95 01 81 06"  # X: -350..350 in two bytes, relative
                 "15 81 25 7f 75 08 09 36 81 02"  # Slider: -127..127 in one byte
                 "75 04 95 01 81 03" + END)  # 4 bits of constant padding, no usage
    assert got == [(0, 16, 1, 0x30, -350, 350, True, False), (16, 8, 1, 0x36, -127, 127, True, False),
                   (24, 4, 0, 0, -127, 127, True, True)]


def test_push_and_pop_restore_the_global_state():
    got = fields(GAMEPAD + "15 00 26 ff 00 75 08 95 01"
                 "a4 05 09 19 01 29 08 25 01 75 01 95 08 81 02 b4"  # Push; Buttons 1-8 of one bit; Pop
                 "09 30 81 02" + END)  # X: 8 bits, 0..255, on the Generic Desktop page again
    assert got[-1] == (8, 8, 1, 0x30, 0, 255, True, False)
    assert [(bit, size, page, usage) for bit, size, page, usage, *_ in got[:8]] == [(k, 1, 9, k + 1) for k in range(8)]


def test_array_items_delimiters_and_long_items():
    got = fields("05 07 19 00 29 65 15 00 25 65 75 08 95 02 81 00"  # two key slots: an array of usage indices
                 "fe 02 00 aa bb"  # a long item: skipped
                 "05 01 a9 01 09 30 09 31 a9 00 15 00 25 01 75 01 95 01 81 02"  # a delimited set: its first usage
                 "75 07 81 03")
    assert [(bit, size, page, usage, variable) for bit, size, page, usage, _, _, variable, _ in got] == [
        (0, 8, 7, 0, False), (8, 8, 7, 0, False), (16, 1, 1, 0x30, True), (17, 7, 0, 0, True)]


def test_output_and_feature_reports_are_laid_out_apart_from_inputs():
    descriptor = parse_report_descriptor(bytes.fromhex(
        GAMEPAD + "85 01 09 30 15 00 25 7f 75 08 95 01 81 02"
        "85 02 05 08 09 4b 25 01 75 01 95 01 91 02 75 07 91 03"  # output report 2: one LED, 7 bits padding
        "85 03 06 00 ff 09 20 26 ff 00 75 08 95 03 b1 02" + END))  # feature report 3: three vendor bytes
    assert sorted(descriptor.inputs) == [1] and sorted(descriptor.outputs) == [2] and sorted(descriptor.features) == [3]
    led = descriptor.outputs[2].fields[0]
    assert (led.bit, led.size, led.page, led.usage) == (8, 1, 0x08, 0x4B) and descriptor.outputs[2].length == 2
    assert descriptor.features[3].length == 4


@pytest.mark.parametrize("hex_items,where", [
    ("05 01 09 05 a1 01 85", "byte 6: item 0x85 needs 1 data bytes, 0 left"),
    (GAMEPAD + "b4", "byte 6: Pop without a Push"),
    (GAMEPAD + "85 00", "byte 6: Report ID 0"),
    (GAMEPAD + "09 30 75 08 95 01 81 02 85 01", "byte 14: a Report ID after fields declared without one"),
    (GAMEPAD + "c0 c0", "byte 7: End Collection without a Collection"),
    (GAMEPAD + "75 00", "byte 6: Report Size 0"),
    (GAMEPAD + "75 08 96 ff ff 81 02", "byte 11: input report 0 longer than 16384 bytes"),
    (GAMEPAD + "0c", "byte 6: item 0x0c of the reserved type"),
])
def test_a_descriptor_that_cannot_be_laid_out_says_where(hex_items, where):
    with pytest.raises(DescriptorError, match=where):
        parse_report_descriptor(bytes.fromhex(hex_items))


def test_each_application_collection_gives_its_usage():
    # Usage (Game Pad) before Collection (Application); a Physical collection inside is not an application;
    # a second application (Usage Page Consumer, Usage Consumer Control) after the first one closes
    descriptor = parse_report_descriptor(bytes.fromhex(
        GAMEPAD + "09 01 a1 00 09 30 15 00 25 7f 75 08 95 01 81 02 c0" + END + "05 0c 09 01 a1 01 c0"))
    assert descriptor.applications == [(0x01, 0x05), (0x0C, 0x01)]
