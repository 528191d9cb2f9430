"""MIDI-to-OSC latency and a MIDI flood, through real JACK MIDI (needs a running JACK server:
`jackd --no-realtime -d dummy -r 48000 -p 64 &`).

    python examples/midi_latency.py [--fps 30] [--changes 200] [--flood-seconds 10]

1. Latency: a fader (CC 1, no takeover) jumps to a new value every 150-250 ms; for each jump,
   the time to the arrival of the first OSC frame whose echo shows the new weight, from the
   message's arrival at the instrument's MIDI input and from its sending. Reports p50, p99 and
   max of both. The two differ by JACK's transport (up to a period or two of the JACK server).
   A value no frame showed before the next jump counts as never shown (an infinite latency in
   the p99 and the max, not left out of them). The instrument's closing line counts its late
   frames (sent more than 0.1 ms after their deadline) over the whole run.

   Arrival is measured by a second JACK MIDI input listening to the same sender (JACK hands a
   message to every reader in the same cycle). python-rtmidi stamps each message with the time
   since the previous one, taken by JACK's clock in that cycle; the stamps are anchored to the
   monotonic clock by the message that reached the probe's Python callback soonest after its
   cycle. Arrival times are thus late by that one callback's delay (microseconds), which makes
   the latency from arrival read that much low; the spread of the other callbacks is reported.
2. Flood: a fresh instrument gets 10,000 control changes a second for the given time, with
   two calm seconds before and after; reports the late and dropped frames it counted.
"""

from __future__ import annotations

import argparse
import os
import random
import select
import socket
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Callable

import numpy as np
import rtmidi
from pythonosc.osc_bundle import OscBundle

STARTUP_SECONDS = 600  # a fresh install's first run compiles the kernels before its first frame

MAPPING = """[device]
midi = "latency"
[[control]]
message = "cc"
number = 1
target = "style/elderly"
range = [0.0, 1.27]
"""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fps", type=float, default=30.0)
    parser.add_argument("--changes", type=int, default=200)
    parser.add_argument("--flood-seconds", type=float, default=10.0)
    args = parser.parse_args()
    os.environ["JACK_NO_START_SERVER"] = "1"
    mapping = tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False)
    mapping.write(MAPPING)
    mapping.close()
    latency(mapping.name, args.fps, args.changes)
    if args.flood_seconds > 0:
        flood(mapping.name, args.fps, args.flood_seconds)


def start(mapping: str, fps: float, seconds: float, osc_port: int, phase: str, streaming: Callable[[], bool],
          extra: tuple[str, ...] = ()) -> tuple[subprocess.Popen, rtmidi.MidiOut]:
    """The instrument on a virtual JACK MIDI port of its own name, and a sender connected to it
    (by exact name: JACK keeps a closed port's client around, and renames a client whose name
    is taken), once the instrument streams (`streaming()`): its port opens before its first
    frame, which on a fresh install compiles the kernels for half a minute or more, and changes
    sent meanwhile would be counted as never shown."""
    port = f"latency-{os.getpid()}-{phase}"
    run = subprocess.Popen([sys.executable, "-m", "instrument", "run", "--midi-virtual", port, "--midi-api", "jack",
                            "--mapping", mapping, "--no-feedback", "--osc", f"127.0.0.1:{osc_port}/flat",
                            "--fps", str(fps), "--seconds", str(seconds), *extra], stderr=subprocess.PIPE, text=True)
    out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, name=f"sender-{os.getpid()}-{phase}")
    while not [n for n in out.get_ports() if n.endswith(":" + port)]:
        time.sleep(0.1)
    out.open_port(next(i for i, n in enumerate(out.get_ports()) if n.endswith(":" + port)), name="out")
    deadline = time.monotonic() + STARTUP_SECONDS
    while not streaming():
        if run.poll() is not None or time.monotonic() > deadline:
            sys.exit(f"midi_latency: the instrument did not stream within {STARTUP_SECONDS} s: {run.stderr.read() if run.poll() is not None else ''}")
        time.sleep(0.1)
    return run, out


def finish(run: subprocess.Popen, out: rtmidi.MidiOut) -> str:
    """The instrument's closing line (frames, late, dropped)."""
    out.close_port()
    out.delete()
    lines = run.communicate()[1].strip().splitlines()
    return next((l for l in reversed(lines) if l.startswith("stopped")), "\n".join(lines[-5:]))


SO_TIMESTAMPNS = 35  # Linux's (asm-generic/socket.h); Python's socket module does not name it
SO_RXQ_OVFL = 40  # Linux's: each datagram carries how many the socket has dropped so far
RECEIVE_BUFFER = 4 << 20  # bytes: some seconds of frames, for a listener kept off the CPU on a busy machine


def _kernel_stamps(sock: socket.socket) -> bool:
    """Ask the kernel to stamp each datagram with its arrival; False where it cannot."""
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_TIMESTAMPNS, 1)
    except OSError:
        print("  (no kernel receive stamps here: arrivals are stamped when this script reads them)")
        return False
    return True


def _listening(sock: socket.socket) -> None:
    """A receive buffer of some seconds of frames, and the kernel's count of the datagrams it
    dropped on each datagram (where Linux gives it): a change no frame is seen to show, on a
    listener kept off the CPU, is then told apart from one the instrument never showed."""
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER)
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_RXQ_OVFL, 1)
    except OSError:
        pass


def _dropped(ancillary: list) -> int | None:
    """The socket's count of dropped datagrams so far, from a datagram's ancillary data."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_RXQ_OVFL:
            return struct.unpack("I", data[:4])[0]
    return None


def _arrival(ancillary: list) -> float:
    """The kernel's receive stamp (CLOCK_REALTIME) of a datagram, on the monotonic clock."""
    for level, kind, data in ancillary:
        if level == socket.SOL_SOCKET and kind == SO_TIMESTAMPNS:
            seconds, nanoseconds = struct.unpack("qq", data[:16])
            return seconds + nanoseconds * 1e-9 - (time.time() - time.monotonic())
    return time.monotonic()


def latency(mapping: str, fps: float, count: int) -> None:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    arrivals: list[tuple[float, float]] = []  # (arrival time, echoed elderly weight)
    stop = threading.Event()

    stamped = _kernel_stamps(sock)
    _listening(sock)
    dropped = [0]  # datagrams the kernel dropped before this script read them (the latest count)

    def listen() -> None:
        """Take every datagram with the time the kernel received it (SO_TIMESTAMPNS, so this
        process's own wait for the CPU on a busy machine is not counted as the instrument's), and
        parse only when none is waiting: parsing one bundle with python-osc takes longer than the
        instrument takes to send the next."""
        sock.setblocking(False)
        while not stop.is_set():
            select.select([sock], [], [], 0.1)
            received = []
            while True:
                try:
                    data, ancillary, _, _ = sock.recvmsg(65536, 128)  # room for the stamp and the drop count
                except BlockingIOError:
                    break
                received.append((data, _arrival(ancillary) if stamped else time.monotonic()))
                dropped[0] = _dropped(ancillary) or dropped[0]
            for data, now in received:
                for m in OscBundle(data):
                    if m.address == "/walk/style/elderly":
                        arrivals.append((now, m.params[0]))

    threading.Thread(target=listen, daemon=True).start()
    run, out = start(mapping, fps, count * 0.2 + 6, sock.getsockname()[1], "latency", lambda: bool(arrivals))
    probe = rtmidi.MidiIn(rtmidi.API_UNIX_JACK, name=f"probe-{os.getpid()}", queue_size_limit=1 << 20)
    probe.open_port(next(i for i, n in enumerate(probe.get_ports()) if n.startswith(f"sender-{os.getpid()}-latency:")))
    probed: list[tuple[float, float, int]] = []  # (callback time, JACK time since the previous message, value)
    probe.set_callback(lambda message, _: probed.append((time.monotonic(), message[1], message[0][2])))
    time.sleep(2.0)
    changes = []  # (sent, value)
    value = 0
    for _ in range(count):
        value = (value + random.randint(5, 60)) % 128
        changes.append((time.monotonic(), value))
        out.send_message([0xB0, 1, value])
        time.sleep(random.uniform(0.15, 0.25))
    probe.close_port()
    probe.delete()
    closing = finish(run, out)
    time.sleep(0.5)  # the listener has read what the kernel holds
    stop.set()
    # the first OSC frame showing each value before the next change was sent (a value never
    # shown in that time counts as never shown: an infinite latency in the figures, not left out)
    ends = [s for s, _ in changes[1:]] + [changes[-1][0] + 0.25]
    shown = [min((t for t, v in arrivals if s <= t < end and abs(v - x / 100.0) < 1e-4), default=np.inf)
             for (s, x), end in zip(changes, ends)]

    callback_times, gaps, values = np.array(probed).T
    since_first = np.cumsum(gaps)
    delays = callback_times - since_first
    probe_arrivals = delays.min() + since_first  # each message's arrival at a JACK input, monotonic clock
    sent, value = np.array(changes).T
    shown = np.array(shown)
    arrived = np.full(len(sent), np.nan)
    for k in range(len(sent)):  # the probe's message of that value just after it was sent
        match = np.flatnonzero((values == value[k]) & (callback_times >= sent[k]) & (callback_times < sent[k] + 0.15))
        if len(match):
            arrived[k] = probe_arrivals[match[0]]
    period = 1000 / fps
    print(f"latency at {fps:g} fps (frame period {period:.1f} ms), {np.isfinite(shown).sum()} of {len(shown)} changes seen "
          f"before the next ({np.isfinite(arrived).sum()} probed); target: at most {period + 2:.1f} ms")
    unseen = ~np.isfinite(shown)
    if unseen.any():  # never probed: the message reached no JACK input (a non-realtime server on a busy machine)
        print(f"  {unseen.sum()} never shown, {(unseen & ~np.isfinite(arrived)).sum()} of them never reached the probe "
              "either (left out of the latency from arrival, infinite from sending)")
    if dropped[0]:
        print(f"  {dropped[0]} OSC datagrams dropped by the kernel before this script read them: "
              "changes not seen may have been shown")
    for name, start_times in (("from arrival", arrived), ("from sending", sent)):
        lat = (shown - start_times)[np.isfinite(start_times)] * 1000  # a change never shown: inf
        p50, p99 = (_percentile(lat, q) for q in (50, 99))
        print(f"  {name}: p50 {p50:.1f} ms, p99 {p99:.1f} ms, max {lat.max():.1f} ms")
    transit = (arrived - sent)[np.isfinite(arrived)] * 1000
    print(f"  JACK transport (sending to arrival): p50 {np.median(transit):.2f} ms, max {transit.max():.2f} ms; "
          f"probe callbacks came a median {(np.median(delays) - delays.min()) * 1000:.3f} ms later than the soonest one")
    print(f"  instrument: {closing}")


def _percentile(values: np.ndarray, q: float) -> float:
    """numpy's percentile, except with a change never shown (inf) among them: then the value at or
    above the rank (inf where the rank falls among those), not a mix of an inf and a finite one."""
    return float(np.percentile(values, q, method="linear" if np.isfinite(values).all() else "higher"))


def flood(mapping: str, fps: float, seconds: float) -> None:
    """A fresh instrument: 2 s calm, the flood, 2 s calm; its late frames are the flood's. It
    records every event it takes, which also counts what reached it."""
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(("127.0.0.1", 0))
    log = Path(tempfile.mkdtemp()) / "flood.jsonl"
    sink.settimeout(0.0)

    def streaming() -> bool:
        try:
            return bool(sink.recv(65536))
        except BlockingIOError:
            return False

    run, out = start(mapping, fps, seconds + 6, sink.getsockname()[1], "flood", streaming, ("--record", str(log)))
    time.sleep(2.0)
    flood_start = time.monotonic()
    count = 0
    while time.monotonic() - flood_start < seconds:
        for _ in range(10):
            out.send_message([0xB0, 1, count % 128])
            count += 1
        time.sleep(max(0.0, flood_start + count / 10_000 - time.monotonic()))
    closing = finish(run, out)
    taken = len(log.read_text().splitlines())
    print(f"flood: {count} messages sent in {seconds:g} s ({count / seconds:.0f}/s), {taken} taken by the instrument (and recorded)")
    print(f"  instrument: {closing}")
    sink.close()


if __name__ == "__main__":
    main()
