"""The fault suite for as long as one likes: a live show fuzzed with OSC packets, MIDI bytes
over JACK and 60 kB bundles, then stopped by a signal; then signals at random times.

    python examples/fault_soak.py --minutes 10 --signal-trials 20

Uses the fuzzers of tests/test_faults.py (same mutations, same seeds), real UDP on 127.0.0.1,
the running JACK server if there is one, and a subprocess `instrument run`. Prints what was
tried and what held: packets and messages sent, frames made, late and dropped, the BVH and the
log valid, every accepted event recorded. Needs the test extra (pip install -e '.[test]').
"""

from __future__ import annotations

import argparse
import math
import os
import random
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from test_faults import (RUN, SEED, SIGNAL_EXITS, assert_valid_bvh, bvh_frames, mutate, signal_trial,  # noqa: E402
                         valid_packets)

from instrument.control.events import read_log  # noqa: E402
from instrument.models.modelfile import default_model_path, load_model  # noqa: E402
from instrument.output.osc import message as osc_message  # noqa: E402
from oscrecv import Receiver, free_port  # noqa: E402


def midi_sender(port_name: str):
    """An rtmidi output connected to the show's virtual input, or None without JACK."""
    try:
        import rtmidi

        os.environ.setdefault("JACK_NO_START_SERVER", "1")
        out = rtmidi.MidiOut(rtmidi.API_UNIX_JACK, name="soak-fuzzer")
        until = time.monotonic() + 30
        while time.monotonic() < until:
            names = [n for n in out.get_ports() if port_name in n]
            if names:
                out.open_port(out.get_ports().index(names[0]))
                return out
            time.sleep(0.2)
        out.delete()
    except Exception as error:
        print(f"no MIDI fuzzing: {error}")
    return None


def soak(minutes: float, rate: int, folder: Path) -> bool:
    model = load_model(default_model_path())
    rng = random.Random(SEED)
    port = free_port()
    bvh, log = folder / "soak.bvh", folder / "soak.jsonl"
    jack = subprocess.run(["pgrep", "-x", "jackd"], capture_output=True).returncode == 0
    command = RUN + ["--osc-in", str(port), "--no-osc", "--bvh", str(bvh), "--record", str(log)]
    if jack:
        nano = str(ROOT / "mappings" / "korg-nanokontrol2.toml")
        command += ["--midi-virtual", "soak-in", "--midi-api", "jack", "--mapping", nano]
    process = subprocess.Popen(command, stderr=subprocess.PIPE, text=True)
    midi = midi_sender("soak-in") if jack else None
    packets = valid_packets(model)
    storm = b"#bundle\0" + struct.pack(">Q", 1) + b"".join(
        struct.pack(">i", len(m)) + m for m in [osc_message("/walk/speed", 1.0 + (k % 50) / 100) for k in range(2500)])
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent = {"osc packets": 0, "osc mutated": 0, "midi messages": 0, "60 kB bundles": 0}
    while bvh_frames(bvh) < 10 and process.poll() is None:
        time.sleep(0.05)
    started = time.monotonic()
    end = started + minutes * 60
    next_storm = started + 10
    while time.monotonic() < end and process.poll() is None:
        slice_start = time.monotonic()
        for _ in range(rate // 20):
            mutated = rng.random() < 0.9
            sock.sendto(mutate(rng, rng.choice(packets)) if mutated else rng.choice(packets), ("127.0.0.1", port))
            sent["osc packets"] += 1
            sent["osc mutated"] += mutated
            if midi is not None:
                status = rng.choice([0xB0, 0x90, 0x80, 0xE0, 0xA0, 0xC0, 0xD0]) | rng.randrange(16)
                try:
                    midi.send_message([status] + [rng.randrange(128) for _ in range(rng.choice([1, 2, 2, 2]))])
                    sent["midi messages"] += 1
                except Exception:
                    pass
        if time.monotonic() >= next_storm:
            sock.sendto(storm, ("127.0.0.1", port))
            sent["60 kB bundles"] += 1
            next_storm += 10
        time.sleep(max(0.0, 0.05 - (time.monotonic() - slice_start)))
    seconds = time.monotonic() - started
    process.send_signal(signal.SIGTERM)
    stderr = process.communicate(timeout=120)[1]
    if midi is not None:
        midi.delete()
    sock.close()
    summary = next((l for l in reversed(stderr.splitlines()) if l.startswith("stopped after")), "(no summary line)")
    frames = assert_valid_bvh(bvh)
    events = read_log(log)
    ok = process.returncode == 0 and "Traceback" not in stderr and all(math.isfinite(e.value) for e in events)
    print(f"soak: {seconds:.0f} s, " + ", ".join(f"{k} {v}" for k, v in sent.items()))
    print(f"  show: exit {process.returncode}; {summary}")
    print(f"  BVH valid, {frames} frames (header = frame lines = an independent reading); "
          f"log replays, {len(events)} accepted events, all finite; {'held' if ok else 'FAILED'}")
    return ok


def storm_figures(folder: Path) -> bool:
    """Two 12 s shows at 30 fps, the same but for ten 60 kB bundles (2,500 messages each, 0.5 s
    apart) in the second: late and dropped frames, the longest gap between frames arriving at a
    receiver, and every message recorded."""
    messages = [osc_message("/walk/speed", 1.0 + (k % 100) / 100) for k in range(2500)]
    bundle = b"#bundle\0" + struct.pack(">Q", 1) + b"".join(struct.pack(">i", len(m)) + m for m in messages)
    ok = True
    for storm in (False, True):
        port, receiver = free_port(), Receiver()
        bvh, log = folder / f"storm{storm}.bvh", folder / f"storm{storm}.jsonl"
        process = subprocess.Popen(RUN + ["--osc-in", str(port), "--osc", f"127.0.0.1:{receiver.port}/flat", "--seconds", "12",
                                          "--bvh", str(bvh), "--record", str(log)], stderr=subprocess.PIPE, text=True)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        while bvh_frames(bvh) < 60 and process.poll() is None:
            time.sleep(0.05)
        for k in range(10 if storm else 0):
            sock.sendto(bundle, ("127.0.0.1", port))
            time.sleep(0.5)
        stderr = process.communicate(timeout=120)[1]
        receiver.close()
        sock.close()
        arrivals = [stamp for stamp, datagram in zip(receiver.arrivals, receiver.datagrams)
                    if b"/walk/frame" in datagram][30:]  # after warming up
        seen = len(read_log(log))
        summary = next((l for l in reversed(stderr.splitlines()) if l.startswith("stopped after")), "(no summary line)")
        gap = max((b - a for a, b in zip(arrivals, arrivals[1:])), default=float("nan")) * 1000
        expected = 10 * len(messages) if storm else 0
        ok &= process.returncode == 0 and seen == expected
        print(f"{'storm of ten 60 kB bundles' if storm else 'reference, no storm':28s}: {summary}; longest gap between "
              f"frames {gap:.1f} ms (33.3 is on time); messages recorded {seen} of {expected}")
    return ok


def signal_trials(count: int, folder: Path) -> bool:
    rng = random.Random(SEED + 5)
    outcomes: dict[str, int] = {}
    ok = True
    for trial in range(count):
        path = folder / f"signal{trial}.bvh"
        code, stderr = signal_trial(rng, path)
        if path.exists():
            frames = assert_valid_bvh(path)
            kind = "valid BVH" if frames >= 1 else "EMPTY BVH"
        else:
            kind = "no file (stopped before the first frame)"
        ok &= "Traceback" not in stderr and code in SIGNAL_EXITS and kind != "EMPTY BVH"
        outcomes[kind] = outcomes.get(kind, 0) + 1
    print(f"signals: {count} trials at random times: " + ", ".join(f"{k} {v}" for k, v in outcomes.items())
          + f"; {'held' if ok else 'FAILED'}")
    return ok


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--minutes", type=float, default=2.0, help="length of the fuzzed show (default 2)")
    parser.add_argument("--rate", type=int, default=1000, help="OSC packets (and MIDI messages) a second (default 1000)")
    parser.add_argument("--signal-trials", type=int, default=10, help="runs stopped by a signal at a random time (default 10)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="instrument-soak-") as folder:
        ok = storm_figures(Path(folder))
        ok &= soak(args.minutes, args.rate, Path(folder))
        ok &= signal_trials(args.signal_trials, Path(folder))
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
