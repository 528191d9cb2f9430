"""How long reading and decoding one HID report takes (target: under 20 us).

Runs a DualShock 4 (its real USB report descriptor, as the tests use it) through `HidInput`:
  decode   one 64-byte report, every control changed (the worst case: all events are made)
  read     one report read from a simulated hidapi device and decoded, only the moved stick changed
  by-field  the reference, same run: the same report decoded field by field from the parsed
            descriptor (each field's bytes sliced, shifted, masked, sign-extended: what a decoder
            without the precomputed shift-and-mask table does)
Prints the median of many repetitions, in microseconds, and the ratios to the reference.

    python examples/hid_decode_bench.py [--repeat 20000]
"""

from __future__ import annotations

import argparse
import io
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))

from hid_descriptors import DUALSHOCK4_USB  # noqa: E402
from hid_sim import SimulatedDevice, SimulatedHid  # noqa: E402

from instrument.control.hid import HidInput  # noqa: E402
from instrument.control.hid_report_descriptor import parse_report_descriptor  # noqa: E402
from instrument.terminal import Console  # noqa: E402


def median_us(action, repeat: int) -> float:
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        action()
        times.append(time.perf_counter() - start)
    return statistics.median(times) * 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=20000)
    args = parser.parse_args()
    sim = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC)
    device = HidInput(Console(stream=io.StringIO()), 0x054C, 0x09CC, hid=SimulatedHid(sim))
    rest = bytes([0x01, 128, 128, 128, 128, 8, 0, 0, 0, 0] + [0] * 54)
    moved = bytes([0x01, 200, 128, 128, 128, 8, 0, 0, 0, 0] + [0] * 54)
    sim.send(rest)
    device.read_raw()  # opened, first report seen

    def decode_all():
        device.last.clear()  # as if every control changed
        device.decode(rest)

    flip = [rest, moved]

    def read_one():
        flip.reverse()
        sim.reports.append(flip[0])
        device.read_raw()

    fields = [f for f in parse_report_descriptor(DUALSHOCK4_USB).inputs[1].fields if not f.constant]

    def by_field():
        values = []
        for f in fields:
            first, last = f.bit // 8, (f.bit + f.size - 1) // 8
            value = (int.from_bytes(moved[first:last + 1], "little") >> (f.bit % 8)) & ((1 << f.size) - 1)
            if f.logical_min < 0 and value >= 1 << (f.size - 1):
                value -= 1 << f.size
            values.append(value)
        return values

    figures = {"decode": median_us(decode_all, args.repeat), "read": median_us(read_one, args.repeat),
               "by-field": median_us(by_field, args.repeat)}
    for name, us in figures.items():
        print(f"{name:10s} {us:8.2f} us  ({us / figures['by-field']:.3f} of field-by-field decoding)")


if __name__ == "__main__":
    main()
