"""MIDI-to-OSC latency and a MIDI flood, through real JACK MIDI (needs a running JACK server:
`jackd --no-realtime -d dummy -r 48000 -p 256 &`).

    python examples/midi_latency.py [--fps 30] [--changes 100] [--flood-seconds 10]

1. Latency: a fader (CC 1, no takeover) jumps to a new value every 150-250 ms; for each jump,
   the time from sending the MIDI message to the arrival of the first OSC frame whose echo
   shows the new weight. Reports p50, p99 and max.
2. Flood: 10,000 control changes a second for the given time while the instrument runs;
   reports the late and dropped frames the instrument counted.
"""

from __future__ import annotations

import argparse
import os
import random
import socket
import subprocess
import sys
import tempfile
import threading
import time

import mido
import numpy as np
from pythonosc.osc_bundle import OscBundle

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
    parser.add_argument("--changes", type=int, default=100)
    parser.add_argument("--flood-seconds", type=float, default=10.0)
    args = parser.parse_args()
    os.environ["JACK_NO_START_SERVER"] = "1"
    backend = mido.Backend("mido.backends.rtmidi/UNIX_JACK", load=True)
    mapping = tempfile.NamedTemporaryFile("w", suffix=".toml", delete=False)
    mapping.write(MAPPING)
    mapping.close()

    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    arrivals: list[tuple[float, float]] = []  # (arrival time, echoed elderly weight)
    stop = threading.Event()

    def listen() -> None:
        sock.settimeout(0.1)
        while not stop.is_set():
            try:
                data = sock.recv(65536)
            except socket.timeout:
                continue
            now = time.monotonic()
            for m in OscBundle(data):
                if m.address == "/walk/style/elderly":
                    arrivals.append((now, m.params[0]))

    threading.Thread(target=listen, daemon=True).start()
    seconds = args.changes * 0.2 + args.flood_seconds + 8
    run = subprocess.Popen([sys.executable, "-m", "instrument", "run", "--midi-virtual", "latency", "--midi-api", "jack",
                            "--mapping", mapping.name, "--no-feedback", "--osc", f"127.0.0.1:{sock.getsockname()[1]}/flat",
                            "--fps", str(args.fps), "--seconds", str(seconds)], stderr=subprocess.PIPE, text=True)
    while not [n for n in backend.get_output_names() if "latency" in n]:
        time.sleep(0.1)
    out = backend.open_output([n for n in backend.get_output_names() if "latency" in n][0])
    time.sleep(2.0)
    latencies = []
    value = 0
    for _ in range(args.changes):
        value = (value + random.randint(5, 60)) % 128
        sent = time.monotonic()
        out.send(mido.Message("control_change", control=1, value=value))
        time.sleep(random.uniform(0.15, 0.25))
        seen = [t for t, v in list(arrivals) if t >= sent and abs(v - value / 100.0) < 1e-4]
        if seen:
            latencies.append(seen[0] - sent)
    flood_start = time.monotonic()
    count = 0
    while time.monotonic() - flood_start < args.flood_seconds:
        for _ in range(10):
            out.send(mido.Message("control_change", control=1, value=count % 128))
            count += 1
        time.sleep(max(0.0, flood_start + count / 10_000 - time.monotonic()))
    out.close()
    stderr = run.communicate()[1]
    stop.set()
    lat = np.array(latencies) * 1000
    period = 1000 / args.fps
    print(f"latency over {len(lat)} changes at {args.fps:g} fps (frame period {period:.1f} ms): "
          f"p50 {np.percentile(lat, 50):.1f} ms, p99 {np.percentile(lat, 99):.1f} ms, max {lat.max():.1f} ms "
          f"(target: at most {period + 2:.1f} ms)")
    print(f"flood: {count} messages in {args.flood_seconds:g} s ({count / args.flood_seconds:.0f}/s)")
    lines = stderr.strip().splitlines()
    print("instrument:", next((l for l in reversed(lines) if l.startswith("stopped")), "\n".join(lines[-5:])))


if __name__ == "__main__":
    main()
