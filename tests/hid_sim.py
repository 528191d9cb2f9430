"""A simulated hidapi module: devices that serve real report descriptors and real-shaped reports.

It behaves as cython-hidapi does on Linux: `enumerate(vendor, product)` lists what is plugged
in (nothing once unplugged), `device()` gives a handle whose `open_path` raises OSError('open
failed') for a device that is gone, `read(size)` returns [] when nothing waits and at most `size`
bytes of a report, and raises OSError('read error') once the device is unplugged; `write`
raises OSError('write error') then. Reports are queued as the device would send them; a None in
the queue is a moment with nothing to read (a read returns [] there).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field


@dataclass
class SimulatedDevice:
    descriptor: bytes
    vendor: int
    product: int
    name: str = ""
    usage: tuple[int, int] = (1, 5)  # usage page and usage of its top-level collection (gamepad)
    descriptor_call: bool = True  # False: a binding without get_report_descriptor (the hidraw ioctl is used)
    path: bytes = b""
    plugged: bool = True
    reports: deque = field(default_factory=deque)
    written: list = field(default_factory=list)
    opened: int = 0

    def send(self, *reports: bytes | None) -> None:
        self.reports.extend(reports)


class _Handle:
    def __init__(self, bus: SimulatedHid):
        self.bus, self.sim = bus, None

    def open_path(self, path):
        sim = next((d for d in self.bus.devices if d.path == path and d.plugged), None)
        if sim is None:
            raise OSError("open failed")
        sim.opened += 1
        self.sim = sim

    def set_nonblocking(self, flag):
        return 0

    def read(self, size):
        if self.sim is None:
            raise ValueError("not open")
        if not self.sim.plugged:
            raise OSError("read error")
        if not self.sim.reports:
            return []
        report = self.sim.reports.popleft()
        return [] if report is None else list(report[:size])

    def write(self, data):
        if self.sim is None:
            raise ValueError("not open")
        if not self.sim.plugged:
            raise OSError("write error")
        self.sim.written.append(bytes(data))
        return len(data)

    def close(self):
        self.sim = None


class _HandleWithDescriptor(_Handle):
    def get_report_descriptor(self, max_length=4096):
        return list(self.sim.descriptor[:max_length])


class SimulatedHid:
    """Stands in for the `hid` module with the given devices plugged in."""

    def __init__(self, *devices: SimulatedDevice):
        self.devices = list(devices)
        for k, d in enumerate(self.devices):
            d.path = d.path or f"/dev/hidraw-sim{k}".encode()

    def enumerate(self, vendor=0, product=0):
        wanted = [d for d in self.devices
                  if d.plugged and (not vendor or d.vendor == vendor) and (not product or d.product == product)]
        return [{"path": d.path, "vendor_id": d.vendor, "product_id": d.product, "product_string": d.name,
                 "usage_page": d.usage[0], "usage": d.usage[1], "interface_number": 0} for d in wanted]

    def device(self):
        # a device's handle has the descriptor call if the binding has it (hidapi >= 0.14 does)
        return _HandleWithDescriptor(self) if all(d.descriptor_call for d in self.devices) else _Handle(self)


def ds4_report(lx=128, ly=128, rx=128, ry=128, hat=8, face=0, shoulders=0, l2=0, r2=0) -> bytes:
    """DualShock 4 USB input report 1, laid out by hand from the published layout (not by the code
    under test): sticks, hat (8 = released) with square/cross/circle/triangle in the high nibble,
    L1 R1 L2 R2 SHARE OPTIONS L3 R3, counter, triggers, then motion and touch."""
    return bytes([0x01, lx, ly, rx, ry, (face << 4) | hat, shoulders, 0, l2, r2] + [0] * 54)
