"""Steps on the beat, measured: a real MIDI clock through JACK drives `instrument run --sync midi`
and the footfalls it sends (/walk/footfall, flat OSC profile) are timed against the beats.

    python examples/tempo_lock.py [--bpm 80 120 174] [--seconds 16] [--fps 30]

Starts its own JACK server (dummy driver, named SERVER so that it never disturbs another; 128
frames a cycle at 48 kHz, realtime where the system allows: `--period`, `--no-realtime`) and
stops it at the end. For each tempo a fresh instrument listens on a virtual JACK
MIDI port; a sender (this process) sends MIDI start and then 24 clock ticks a beat, each at its
time on the monotonic clock (a sleep to a millisecond before, then a spin). Beat k is the
scheduled time of tick 24 k. Every /walk/footfall of character 0 is stamped when its datagram
arrives here (the same machine, the same clock), so the offsets include JACK's transport, the
fit, the frame grid (a footfall can only happen on a frame) and the OSC send.

Reports per tempo: the steps per beat the instrument chose (from the footfall interval), the
median and mean step interval and their error against beat / ratio, the footfall-to-beat
offset (median and 95th percentile of its size) after the first 4 s, the footfall (counted
from the clock's start) from which every offset stays within 40 ms (the lock), and the
instrument's late frames. `run(bpm, ...)` is what tests/test_tempo.py calls.
"""

from __future__ import annotations

import argparse
import os
import select
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # private_jack: is a JACK server up

LOCK_MS = 40.0  # a footfall within this of a beat is on it
SETTLE = 4.0  # seconds after the clock's start before the offsets are counted


def send_clock(port, bpm: float, start: float, seconds: float, stop: threading.Event, lateness: list[float]) -> None:
    """MIDI start just before `start`, then ticks at start + k * tick until `seconds` have gone;
    `lateness` gets how late each tick left (the sender's own jitter on a busy machine)."""
    tick = 60.0 / bpm / 24
    try:  # the sender keeps its time on a busy machine, as a sequencer's clock thread does
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(50))
    except (OSError, AttributeError):
        pass
    while time.monotonic() < start - tick:  # start one tick before the first, as a sequencer does
        time.sleep(0.001)
    port.send_message([0xFA])
    k = 0
    while not stop.is_set() and k * tick < seconds:
        due = start + k * tick
        wait = due - time.monotonic()
        if wait > 0.002:
            time.sleep(wait - 0.001)
        while time.monotonic() < due:
            pass
        port.send_message([0xF8])
        lateness.append(time.monotonic() - due)
        k += 1
    port.send_message([0xFC])


@dataclass
class Result:
    bpm: float
    ratio: float
    median_interval: float
    mean_interval: float
    target_interval: float
    offset_median_ms: float
    offset_p95_ms: float
    lock_footfall: int | None  # counted from 1 after the clock's start; None: never locked
    footfalls: int
    late: int | None
    sender_p95_ms: float  # how late the sender's ticks left, 95th percentile

    def line(self) -> str:
        error = 100 * (self.median_interval / self.target_interval - 1)
        mean_error = 100 * (self.mean_interval / self.target_interval - 1)
        return (f"{self.bpm:5.0f} bpm  {self.ratio:g} steps/beat  step {self.median_interval * 1000:.0f} ms median "
                f"({error:+.1f}%), {self.mean_interval * 1000:.1f} ms mean ({mean_error:+.2f}%) of {self.target_interval * 1000:.1f}"
                f"  footfall-to-beat {self.offset_median_ms:.1f} ms median, {self.offset_p95_ms:.1f} ms p95"
                f"  locked from footfall {self.lock_footfall}  ({self.footfalls} footfalls, late frames {self.late}; "
                f"sender's ticks late by {self.sender_p95_ms:.1f} ms p95)")


def footfall_times(sock: socket.socket, until: float) -> list[tuple[float, str, int]]:
    """(arrival time, side, character) of every /walk/footfall until `until` (monotonic)."""
    from pythonosc.osc_bundle import OscBundle
    from pythonosc.osc_message import OscMessage

    out = []
    while time.monotonic() < until:
        ready, _, _ = select.select([sock], [], [], 0.05)
        if not ready:
            continue
        data = sock.recv(65536)
        arrived = time.monotonic()
        if b"/walk/footfall" not in data:
            continue
        items = list(OscBundle(data)) if data.startswith(b"#bundle") else [OscMessage(data)]
        for item in items:
            message = item if isinstance(item, OscMessage) else None
            if message is not None and message.address == "/walk/footfall":
                side, character = message.params[0], message.params[1]
                out.append((arrived, side, character))
    return out


def wait_for_port(midi_out, part: str, deadline: float) -> int:
    while time.monotonic() < deadline:
        names = midi_out.get_ports()
        for k, name in enumerate(names):
            if part in name:
                return k
        time.sleep(0.1)
    raise RuntimeError(f"the instrument's MIDI port {part} never appeared")


def run(bpm: float, seconds: float = 16.0, fps: float = 30.0, extra: list[str] | None = None, sync: bool = True) -> Result:
    """One tempo: a fresh instrument, the clock for `seconds`, the footfalls measured (`sync`
    False: the same instrument not following the clock, for its late frames)."""
    import rtmidi

    os.environ["JACK_NO_START_SERVER"] = "1"
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    name = f"tempo-clock-{os.getpid()}-{int(bpm)}"
    process = subprocess.Popen([sys.executable, "-m", "instrument", "run", "--midi-virtual", name, "--midi-api", "jack",
                                *(["--sync", "midi"] if sync else []), "--no-feedback", "--fps", f"{fps:g}",
                                "--osc", f"127.0.0.1:{sock.getsockname()[1]}/flat"] + (extra or []),
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    midi_out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, name="tempo-sender")
    stop = threading.Event()
    lateness: list[float] = []
    try:
        midi_out.open_port(wait_for_port(midi_out, name, time.monotonic() + 120), "clock")
        # the walk is running once frames arrive: wait for one, then start the clock
        ready = time.monotonic() + 120
        while time.monotonic() < ready and not select.select([sock], [], [], 0.5)[0]:
            pass
        # beats at a random phase of the frame grid (the frames are sent on it): as a real band would be
        start = time.monotonic() + 1.0 + np.random.default_rng(int(bpm)).uniform(0.0, 1.0 / fps)
        sender = threading.Thread(target=send_clock, args=(midi_out, bpm, start, seconds, stop, lateness), daemon=True)
        sender.start()
        falls = footfall_times(sock, start + seconds)
        sender.join(10)
    finally:
        stop.set()
        process.terminate()
        output = process.communicate(timeout=60)[0]
        midi_out.close_port()
        midi_out.delete()
        sock.close()
    late = None
    for line in output.splitlines():
        if "stopped after" in line and "late" in line:
            late = int(line.split("late ")[1].split(",")[0])
    return measure(bpm, start, [t for t, _, character in falls if character == 0], late,
                   1000.0 * float(np.percentile(lateness, 95)))


def measure(bpm: float, start: float, times: list[float], late: int | None, sender_p95_ms: float = 0.0) -> Result:
    """The figures of footfall times (monotonic) against beats at start + k * 60 / bpm."""
    beat = 60.0 / bpm
    times = np.array([t for t in times if t > start])
    intervals = np.diff(times[times > start + SETTLE])
    ratio = min((0.5, 1.0, 2.0), key=lambda r: abs(np.log(np.median(intervals) * r / beat)))
    period = beat / ratio
    grid = (times - start) / period
    offsets = np.abs(grid - np.round(grid)) * period * 1000.0
    settled = offsets[times > start + SETTLE]
    off = np.flatnonzero(offsets > LOCK_MS)
    lock = 1 if len(off) == 0 else (int(off[-1]) + 2 if off[-1] + 1 < len(offsets) else None)
    return Result(bpm, ratio, float(np.median(intervals)), float(np.mean(intervals)), period, float(np.median(settled)),
                  float(np.percentile(settled, 95)), lock, len(times), late, sender_p95_ms)


SERVER = "tempo-lock"  # the benchmark's own JACK server: it never disturbs another's


def start_server(period: int, realtime: bool) -> subprocess.Popen:
    """A private JACK server (dummy driver, 48 kHz, `period` frames a cycle, realtime if asked
    and allowed), named SERVER; this process and the instruments it starts use it."""
    import rtmidi
    from private_jack import free_dead_slots, server_up

    os.environ["JACK_DEFAULT_SERVER"] = SERVER
    free_dead_slots(Path(os.devnull))
    command = ["jackd", "-R" if realtime else "--no-realtime", "-n", SERVER, "-d", "dummy", "-r", "48000",
               "-p", str(period)]
    server = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    until = time.monotonic() + 30
    while not server_up(rtmidi):
        if server.poll() is not None or time.monotonic() > until:
            server.kill()
            raise SystemExit(f"the JACK server did not start: {' '.join(command)}")
        time.sleep(0.2)
    return server


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bpm", type=float, nargs="+", default=[80.0, 120.0, 174.0])
    parser.add_argument("--seconds", type=float, default=16.0)
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--period", type=int, default=128, help="JACK frames a cycle at 48 kHz (128: 2.7 ms)")
    parser.add_argument("--no-realtime", action="store_true", help="the JACK server without realtime scheduling")
    parser.add_argument("--baseline", action="store_true",
                        help="also run each tempo without --sync: the late frames of the same show not following the clock")
    args = parser.parse_args()
    os.environ["JACK_NO_START_SERVER"] = "1"
    server = start_server(args.period, not args.no_realtime)
    print(f"JACK: {args.period} frames at 48 kHz ({1000 * args.period / 48000:.1f} ms), "
          f"{'no ' if args.no_realtime else ''}realtime", flush=True)
    try:
        for bpm in args.bpm:
            print(run(bpm, args.seconds, args.fps).line(), flush=True)
            if args.baseline:
                print(f"{bpm:5.0f} bpm without --sync: late frames {run(bpm, args.seconds, args.fps, sync=False).late}",
                      flush=True)
    finally:
        server.terminate()
        server.wait(10)


if __name__ == "__main__":
    main()
