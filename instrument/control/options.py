"""What each command-line option accepts, in one table, and the one way every value is read.

Every numeric option of every subcommand is listed in OPTIONS with its type and range; an option
that sets a control target takes that target's row (control/spec.py). Values given on the command
line go through `cli.arguments.checked(KEY)` (argparse's type=: a bad value is a usage error,
exit 2) or `value(KEY, text)` (for options that a show file can also give, exit 1); show files go
through `value(KEY, text, where="show.toml:3: fps")`, so their errors name the file, line and
key. A value out of range is refused, never clamped silently. It sits with the target table in
control/ (below runtime and the console, which read [HOST:]PORT addresses through `host_port`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ..errors import UserError, quoted
from .spec import TABLE

MAX_SECONDS = 7 * 24 * 3600.0  # a week: longer is a typo
MAX_CHARACTERS = 1000  # a crowd larger than this is a typo (docs/crowds.md: how many keep time)


@dataclass(frozen=True)
class Accepts:
    """A whole or real number in [low, high]; `above_low` makes low itself refused (> low)."""

    kind: type = float
    low: float | None = None
    high: float | None = None
    above_low: bool = False

    def describe(self) -> str:
        word = "a whole number" if self.kind is int else "a number"
        low, high = (f"{x:g}" if self.kind is float else f"{x:d}" for x in (self.low or 0, self.high or 0))
        if self.low is not None and self.high is not None:
            return f"{word} {'above' if self.above_low else 'from'} {low} {'up ' if self.above_low else ''}to {high}"
        if self.low is not None:
            return f"{word} {'above' if self.above_low else 'of at least'} {low}"
        return word

    def read(self, text: object):
        """The value, or ValueError with a message saying what is accepted."""
        try:
            number = self.kind(text) if not isinstance(text, float) or self.kind is float else None
        except (TypeError, ValueError, OverflowError):
            number = None
        if number is None or (self.kind is float and not math.isfinite(number)):
            raise ValueError(f"expected {self.describe()}, not {quoted(text)}")
        too_low = self.low is not None and (number <= self.low if self.above_low else number < self.low)
        if too_low or (self.high is not None and number > self.high):
            raise ValueError(f"expected {self.describe()}, not {quoted(text)}")
        return number


def target(kind: str) -> Accepts:
    """What an option that sets a control target accepts: that target's row (control/spec.py),
    so `synth --speed 9` is refused as a show's `speed = 9` is."""
    return Accepts(float, TABLE[kind].low, TABLE[kind].high)


PORT = Accepts(int, 1, 65535)
POSITIVE_SECONDS = Accepts(float, 0, MAX_SECONDS, above_low=True)

# "COMMAND --option": what it accepts. Options not listed are names, paths or choices.
OPTIONS: dict[str, Accepts] = {
    "run --fps": Accepts(float, 24, 120),
    "run --seconds": POSITIVE_SECONDS,
    "run --morph": target("morph"),
    "run --osc-in": PORT,  # the port of [HOST:]PORT
    "run --status-port": PORT,  # the port of [HOST:]PORT
    "run --console": Accepts(int, 0, 65535),  # the port of [HOST:]PORT; 0: any free port
    "run --health-every": Accepts(float, 0, 86400),  # seconds; 0: no health line
    "run --characters": Accepts(int, 1, MAX_CHARACTERS),
    "run --spacing": Accepts(float, 0, 100, above_low=True),  # metres
    "run --bvh-character": Accepts(int, 0, MAX_CHARACTERS - 1),  # and below --characters (checked in run)
    "run --vmc-characters": Accepts(int, 1, MAX_CHARACTERS),  # at most --characters are sent
    "view --port": PORT,
    "view --frames": Accepts(int, 1, None),
    "learn --timeout": POSITIVE_SECONDS,
    "log --fps": Accepts(float, 0, 1000, above_low=True),
    "train --fps": Accepts(float, 1, 1000),
    "train --states": Accepts(int, 1, 12),
    "synth --style": target("style"),  # the weight of NAME=W
    "synth --speed": target("speed"),
    "synth --gait": target("gait"),  # or its name (stand, walk, run): Row.number
    "synth --turn": target("turn"),
    "synth --seconds": Accepts(float, 0, 3600, above_low=True),
    "synth --lookahead": Accepts(int, 1, 1000),
    "synth --liveliness": target("liveliness"),
    "synth --seed": Accepts(int, 0, 2**32 - 1),
    "synth --gesture": Accepts(float, 0, 3600),  # the seconds of NAME@SECONDS
    "bench --repeat": Accepts(int, 1, 1000),
    "bench --pacing": POSITIVE_SECONDS,
    "bench --fps": Accepts(float, 1, 1000),
    "bench --console-pages": Accepts(int, 0, 100),
    "render --every": Accepts(int, 1, None),
    "evaluate --seconds": Accepts(float, 2, 600),  # of each generated walk
    "service --watchdog": Accepts(float, 1, 3600),  # seconds without an answer from the frame loop
}

def value(key: str, text: object, where: str | None = None):
    """`text` read as OPTIONS[key] says, or a one-line UserError naming the option (or `where`)."""
    try:
        return OPTIONS[key].read(text)
    except ValueError as e:
        raise UserError(f"{where or key.split(' ', 1)[1]}: {e}") from None


def host_port(key: str, text: object, where: str | None = None) -> tuple[str, int, bool]:
    """`[HOST:]PORT` of option `key` as (host, port, whether a host was named); the port read as
    OPTIONS[key] says, the host 127.0.0.1 when none is named. A one-line UserError naming the
    option (or `where`) for anything else."""
    where = where or f"{key.split(' ', 1)[1]} {text!r}"
    host, _, port = str(text).rpartition(":")
    if not port.strip().isdigit():
        raise UserError(f"{where}: expected [HOST:]PORT, e.g. 127.0.0.1:9000 or 9000")
    try:
        number = OPTIONS[key].read(port)
    except ValueError as e:
        raise UserError(f"{where}: port: {e}") from None
    return host or "127.0.0.1", number, bool(host)
