"""How long the command line takes to start, against a bare Python started in the same run.

The figure is a ratio (and the difference) because absolute times depend on the machine and its
load; `python -c pass` measured alternately with the commands carries the same noise.
"""

from __future__ import annotations

import statistics
import subprocess
import sys
import time

from .main import COMMANDS

BARE = ("-c", "pass")


def _seconds(arguments: tuple[str, ...], repeat: int) -> float:
    """Median wall time of `python ARGUMENTS` over `repeat` runs."""
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        subprocess.run([sys.executable, *arguments], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, check=False)
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def measure_startup(repeat: int) -> dict[str, dict[str, float]]:
    """{command line: {seconds, bare_seconds, ratio}} for --version, --help and each `COMMAND --help`."""
    lines = [("--version",), ("--help",)] + [(name, "--help") for name in COMMANDS]
    figures = {}
    for line in lines:
        bare = _seconds(BARE, repeat)
        seconds = _seconds(("-m", "instrument", *line), repeat)
        figures["instrument " + " ".join(line)] = {"seconds": seconds, "bare_seconds": bare, "ratio": seconds / bare}
    return figures
