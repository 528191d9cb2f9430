"""Soak test: the live loop for a simulated day, faster than realtime, with faults injected.

The real loop (`perform`), the real hub and mappings, real UDP: an OSC control surface sends
to the instrument's --osc-in socket, both OSC profiles go to receivers on 127.0.0.1. Only the
HID game controller is simulated (tests/hid_sim.py: a DualShock 4 serving its real USB report
descriptor and reports laid out as it sends them, unplugged and plugged back, raising the same
`OSError('read error')` as hidapi). On a schedule of performance time:

    every 20 min   a performer plays for 10 min (an OSC fader every second, the pad's stick
                   and buttons), then nobody does: after 2 min the attract mode tours presets
    every 10 min   the pad is unplugged for 30 s
    every 15 min   the flat receiver goes away for 60 s (the kernel refuses: ECONNREFUSED)

It reports per simulated hour: resident memory, open file handles, frames, frames that took
longer than a frame period (would have been late in realtime), console warnings; then memory
growth per simulated hour (least squares over hours 1 to the end, the first hour being
warm-up) and any crash. `--realtime` runs the same at the real pace (late and dropped frames
counted by the clock itself).

    python examples/soak.py --hours 24                 # simulated day, as fast as the CPU allows
    python examples/soak.py --realtime --hours 0.5     # 30 minutes of wall time
"""

from __future__ import annotations

import argparse
import json
import socket
import sys
import time
from pathlib import Path

import numpy as np

TOP = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(TOP / "tests"))  # the simulated hidapi and the real descriptor the tests use

from hid_descriptors import DUALSHOCK4_USB
from hid_sim import SimulatedDevice, SimulatedHid, ds4_report

from instrument.control.attract import Attract, AttractSettings
from instrument.control.devices import OscInput
from instrument.control.hid import HidInput
from instrument.control.hub import ControlHub
from instrument.control.mapping import load_mapping
from instrument.control.score import preset_tour
from instrument.control.state import ControlState
from instrument.models.modelfile import load_model
from instrument.output.osc import OscTarget, message
from instrument.output.outputs import OscOutput, make_profile
from instrument.terminal import Console
from instrument.runtime.health import Health, open_files, rss_bytes
from instrument.runtime.performance import Show, perform
from instrument.runtime.priority import realtime_scheduling
from instrument.shipped import default_model_path


class Sink:
    """A receiver on 127.0.0.1 that drains what it gets and can go away and come back on its port."""

    def __init__(self):
        self.sock = None
        self.port = 0
        self.up()

    def up(self):
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(("127.0.0.1", self.port))
        self.sock.setblocking(False)
        self.port = self.sock.getsockname()[1]

    def down(self):
        self.sock.close()
        self.sock = None

    def drain(self) -> int:
        count = 0
        while self.sock is not None:
            try:
                self.sock.recv(65536)
                count += 1
            except BlockingIOError:
                return count
        return count


class CountingStream:
    """The console's stream: counts lines and keeps the last few (memory must not grow)."""

    def __init__(self):
        self.lines = 0
        self.last: list[str] = []

    def write(self, text: str) -> None:
        for line in text.splitlines():
            if line.strip():
                self.lines += 1
                self.last = (self.last + [line])[-5:]

    def flush(self) -> None:
        pass

    def isatty(self) -> bool:
        return False


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--hours", type=float, default=24.0, help="simulated (or, with --realtime, real) hours (default 24)")
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--realtime", action="store_true", help="at the real pace instead of as fast as possible")
    parser.add_argument("--json", metavar="FILE", help="also write the figures as JSON")
    args = parser.parse_args()

    model = load_model(default_model_path())
    state = ControlState(model.style_names, model.states)
    stream = CountingStream()
    console = Console(quiet=True, stream=stream)  # warnings, not the status line
    pad = SimulatedDevice(DUALSHOCK4_USB, 0x054C, 0x09CC, name="Wireless Controller")  # its real USB descriptor
    ds4 = load_mapping(TOP / "mappings" / "sony-dualshock4.toml", state)
    presets = {"old": {"style/elderly": 1.2, "speed": 0.8}, "proud": {"style/masculine": 1.5, "style/active": 0.5},
               "light": {"style/feminine": 1.5, "style/youthful": 1.0, "speed": 1.2}}
    hub = ControlHub([ds4], presets)
    hub.start(state)  # the mapping's morph time, as `run` starts it
    hid = HidInput(console, 0x054C, 0x09CC, hid=SimulatedHid(pad))
    surface_in = OscInput(console, "127.0.0.1:0")
    surface_port = surface_in.sock.getsockname()[1]
    surface = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sinks = {"flat": Sink(), "vmc": Sink()}
    outputs = [OscOutput(OscTarget("127.0.0.1", sink.port, kind), make_profile(kind, model), console) for kind, sink in sinks.items()]
    health = Health(console, outputs, [hid, surface_in], every=0)
    rng = np.random.default_rng(7)
    period = 1.0 / args.fps
    seen = {"frame": -1}
    unplugs = {"n": 0}

    def inject(now: float) -> list:
        """Faults and a performer, by performance time; sends real UDP to the surface socket."""
        minute = now / 60.0
        playing = minute % 20 < 10
        plugged = not (minute % 10 >= 9.5)
        unplugs["n"] += pad.plugged and not plugged
        pad.plugged = plugged
        flat_down = minute % 15 >= 14
        if flat_down and sinks["flat"].sock is not None:
            sinks["flat"].down()
        elif not flat_down and sinks["flat"].sock is None:
            sinks["flat"].up()
        frame = round(now * args.fps)
        if frame == seen["frame"]:  # read again while waiting for the same frame: once is enough
            return []
        seen["frame"] = frame
        if playing and frame % round(args.fps) == 0:  # once a second: a fader on the surface, the pad's stick
            style = model.style_names[int(rng.integers(len(model.style_names)))]
            surface.sendto(message(f"/walk/style/{style}", float(rng.uniform(-1, 2))), ("127.0.0.1", surface_port))
            report = ds4_report(lx=int(rng.integers(256)), r2=int(rng.integers(256)), face=0b0010 if rng.random() < 0.05 else 0)
            if pad.plugged:  # an unplugged pad sends nothing
                pad.send(report)
        if frame % 30 == 0:
            for sink in sinks.values():
                sink.drain()
        return []

    attract = Attract(AttractSettings(after=120.0, score=preset_tour(list(presets), presets, morph=8.0, hold=20.0)),
                      [hid.poll, surface_in.poll], state, console)
    hours: list[dict] = []
    marks = {"last": time.monotonic(), "slow": 0, "frames": 0, "started": time.monotonic()}

    def on_frame(index, clock, summary) -> None:
        health.frame(index, clock, summary)
        now = time.monotonic()
        marks["slow"] += not args.realtime and now - marks["last"] > period  # took longer than a frame period
        marks["last"] = now
        if (index + 1) % round(3600 * args.fps) == 0:
            hours.append({"hour": len(hours) + 1, "rss_mb": rss_bytes() / 1e6, "open_files": open_files(),
                          "frames": summary.frames, "slow_frames": marks["slow"], "late": clock.late, "dropped": clock.dropped,
                          "warnings": stream.lines, "wall_s": round(now - marks["started"], 1)})
            print(json.dumps(hours[-1]), flush=True)

    if args.realtime:
        refused = realtime_scheduling()  # as `instrument run` does
        print(f"realtime scheduling {refused or 'taken'}", flush=True)
    start_rss, start_files = rss_bytes() / 1e6, open_files()
    crash = None
    try:
        show = Show(model, outputs, fast=not args.realtime, apply=hub.apply, state=state, fps=args.fps,
                    seconds=args.hours * 3600.0, sources=[inject, attract.poll])
        summary = perform(show, console, on_frame=on_frame)
    except Exception as error:  # the point of a soak: report it
        crash, summary = f"{type(error).__name__}: {error}", None
    for thing in (hid, surface_in, hub, health):
        thing.close()
    surface.close()
    result = {
        "simulated_hours": args.hours, "realtime": args.realtime, "fps": args.fps, "crash": crash,
        "frames": summary.frames if summary else None, "wall_seconds": round(time.monotonic() - marks["started"], 1),
        "slow_frames": marks["slow"], "late": summary.late if summary else None, "dropped": summary.dropped if summary else None,
        "output_errors": summary.output_errors if summary else None, "rss_mb_start": round(start_rss, 1),
        "rss_mb_end": round(rss_bytes() / 1e6, 1), "open_files_start": start_files, "open_files_end": open_files(),
        "pad_unplugs": unplugs["n"], "pad_reconnects": hid.connections - 1, "pad_reports_read": hid.reports, "console_lines": stream.lines, "console_last": stream.last, "hours": hours,
    }
    if len(hours) >= 3:  # growth after the first (warm-up) hour
        x = np.array([h["hour"] for h in hours[1:]], float)
        y = np.array([h["rss_mb"] for h in hours[1:]])
        result["rss_growth_mb_per_hour"] = round(float(np.polyfit(x, y, 1)[0]), 4)
    print(json.dumps({k: v for k, v in result.items() if k != "hours"}, indent=1))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1) + "\n")
    return 1 if crash else 0


if __name__ == "__main__":
    sys.exit(main())
