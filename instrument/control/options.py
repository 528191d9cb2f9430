"""What each command-line option accepts, in one table, and the one way every value is read.

Every numeric option of every subcommand is listed in OPTIONS with its type and range; an option
that sets a control target takes that target's row (control/spec.py). The options of `instrument
run` are rows of RUN (an `Option` each: its kind, range, help and default), the one table that
both argparse (cli/run_cmd.py) and the show file reader (cli/showplan.py) are built from: a show
file's keys are the flags without `--`, each read as its row says. Values given on the command
line go through `cli.arguments.checked(KEY)` (argparse's type=: a bad value is a usage error,
exit 2) or `value(KEY, text)` (for options that a show file can also give, exit 1); show files go
through `value(KEY, text, where="show.toml:3: fps")`, so their errors name the file, line and
key. A value out of range is refused, never clamped silently. It sits with the target table in
control/ (below runtime and the console, which read [HOST:]PORT addresses through `host_port`).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Callable

from ..errors import UserError, quoted
from ..synthesis.parameters import DEFAULT_SPACING, DEFAULT_VMC_CHARACTERS
from .spec import TABLE

MAX_SECONDS = 7 * 24 * 3600.0  # a week: longer is a typo
MAX_CHARACTERS = 1000  # a crowd larger than this is a typo (docs/crowds.md: how many keep time)


@dataclass(frozen=True)
class Accepts:
    """A whole or real number in [low, high]; `above_low` makes low itself refused (> low).
    `choices` name the whole values 0, 1, ... as the spec's Row.number does (a gait's "run" is 2)."""

    kind: type = float
    low: float | None = None
    high: float | None = None
    above_low: bool = False
    choices: tuple[str, ...] = ()

    def describe(self) -> str:
        word = "a whole number" if self.kind is int else "a number"
        low, high = (f"{x:g}" if self.kind is float else f"{x:d}" for x in (self.low or 0, self.high or 0))
        if self.low is not None and self.high is not None:
            ranged = f"{word} {'above' if self.above_low else 'from'} {low} {'up ' if self.above_low else ''}to {high}"
            return f"{', '.join(self.choices)} or {ranged}" if self.choices else ranged
        if self.low is not None:
            return f"{word} {'above' if self.above_low else 'of at least'} {low}"
        return word

    def read(self, text: object):
        """The value, or ValueError with a message saying what is accepted."""
        if isinstance(text, str) and text in self.choices:
            text = float(self.choices.index(text))
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
    row = TABLE[kind]
    return Accepts(float, row.low, row.high, choices=row.choices)


PORT = Accepts(int, 1, 65535)
POSITIVE_SECONDS = Accepts(float, 0, MAX_SECONDS, above_low=True)

# "COMMAND --option": what it accepts. Options not listed are names, paths or choices.
OPTIONS: dict[str, Accepts] = {
    "view --port": PORT,
    "view --frames": Accepts(int, 1, None),
    "learn --timeout": POSITIVE_SECONDS,
    "log --fps": Accepts(float, 0, 1000, above_low=True),
    "train --fps": Accepts(float, 1, 1000),
    "train --states": Accepts(int, 1, 12),
    "synth --style": target("style"),  # the weight of NAME=W
    "synth --speed": target("speed"),
    "synth --gait": target("gait"),
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


def parse_hid_id(text: object) -> tuple[int, int]:
    """A HID device's VVVV:PPPP (hexadecimal vendor and product id) as (vendor, product), or
    ValueError saying what is expected: the reader of --hid's row, which a mapping's `hid` key
    is read by too."""
    match = re.fullmatch(r"([0-9a-fA-F]{4}):([0-9a-fA-F]{4})", str(text))
    if not match:
        raise ValueError(f"{quoted(text)}: expected VVVV:PPPP (hexadecimal vendor and product id, e.g. 054c:09cc)")
    return int(match.group(1), 16), int(match.group(2), 16)


KINDS = ("text", "path", "number", "address", "flag", "list", "paths", "choice")


@dataclass(frozen=True)
class Option:
    """One option of `instrument run`, as the command line and a show file both take it.

    kind: "text" (a string), "path" (a file; in a show file relative to it), "number" (read by
    `accepts`), "address" ([HOST:]PORT, the port read by `accepts`), "flag" (on or off; true or
    false in a show file), "list" and "paths" (repeatable: a string or a list of strings in a show
    file), "choice" (one of `choices`). `reader`: a text's own form, checked and read (ValueError
    saying what is expected: `read`). `in_file` False: the command line only."""

    flag: str  # "--fps"; its key in a show file is "fps"
    kind: str
    help: str
    accepts: Accepts | None = None
    metavar: str | None = None
    choices: tuple[str, ...] = ()
    default: object = None  # what `run` uses when neither the command line nor the show file gives it
    in_file: bool = True
    reader: Callable[[str], object] | None = None

    @property
    def dest(self) -> str:
        return self.flag[2:].replace("-", "_")

    @property
    def key(self) -> str:
        return self.flag[2:]

    def __post_init__(self):
        if self.kind not in KINDS or (self.kind in ("number", "address")) != (self.accepts is not None) \
                or (self.kind == "choice") != bool(self.choices) or (self.reader is not None and self.kind != "text"):
            raise ValueError(f"Option {self.flag}: kind {self.kind!r}, accepts {self.accepts}, choices {self.choices}, "
                             f"reader {self.reader}")

    def argparse_options(self) -> dict:
        """The keyword arguments of argparse's `add_argument` for this row (values are read by
        `run` through the row, so a show file's and the command line's get one check)."""
        options: dict = {"help": self.help}
        if self.kind == "flag":
            return options | {"action": "store_true", "default": None}  # None: not given (a show file may)
        if self.kind in ("list", "paths"):
            options["action"] = "append"
        if self.choices:
            options["choices"] = self.choices
        return options | ({"metavar": self.metavar} if self.metavar else {})


_OSC_HELP = ("OSC target, repeatable (default: 127.0.0.1:{vmc}/vmc and 127.0.0.1:{flat}/flat); /vmc-unbundled or "
             "/flat-unbundled: one message per datagram, for receivers that reject bundles; a broadcast (x.x.x.255) "
             "or multicast (224-239.x.x.x) address sends to many")  # the ports are output/osc.py's (filled in by run)

RUN: tuple[Option, ...] = (
    Option("--config", "path", "a show file holding any of these options (flags given here win)", metavar="SHOW.toml",
           in_file=False),
    Option("--model", "path", "model file (default: the shipped default model)"),
    Option("--fps", "number", "output frame rate, 24 to 120 (default 30)", Accepts(float, 24, 120), default="30"),
    Option("--seconds", "number", "stop after this many seconds of performance (default: until Ctrl-C)", POSITIVE_SECONDS),
    Option("--osc", "list", _OSC_HELP, metavar="HOST:PORT[/vmc|/flat]"),
    Option("--no-osc", "flag", "send no OSC at all", default=False),
    Option("--bvh", "path", "record the performance as BVH while it plays", metavar="OUT.bvh"),
    Option("--characters", "number", "a crowd of N walkers (default 1; docs/crowds.md)", Accepts(int, 1, MAX_CHARACTERS),
           metavar="N"),
    Option("--spacing", "number", f"a crowd's distance between neighbours on the floor (default {DEFAULT_SPACING:g})",
           Accepts(float, 0, 100, above_low=True), metavar="METRES"),
    Option("--bvh-character", "number", "of a crowd, the character --bvh records (default 0)",
           Accepts(int, 0, MAX_CHARACTERS - 1), metavar="K"),  # and below --characters (checked by run)
    Option("--vmc-characters", "number", "of a crowd, how many characters (0 to M-1) a VMC target sends, character K "
           f"on its port + K (default {DEFAULT_VMC_CHARACTERS}; the flat profile carries them all)",
           Accepts(int, 1, MAX_CHARACTERS), metavar="M"),  # at most --characters are sent
    Option("--midi", "list", "MIDI input: the first port whose name matches (regular expression); repeatable, one "
           "controller each", metavar="PATTERN"),
    Option("--midi-virtual", "list", "create a virtual MIDI input port NAME that other programs connect to; repeatable",
           metavar="NAME"),
    Option("--midi-api", "choice", "MIDI system (default: rtmidi's choice, ALSA on Linux)", choices=("alsa", "jack")),
    Option("--sync", "choice", "step on the beat: follow MIDI clock on the MIDI inputs, or join an Ableton Link "
           "session (docs/tempo.md)", choices=("midi", "link")),
    Option("--midi-out", "text", "a virtual MIDI output port NAME sending each footfall as a note (left 36, right 38, "
           "channel 10)", metavar="NAME"),
    Option("--no-feedback", "flag", "send nothing back to the MIDI controller (default: LEDs and motor faders follow "
           "the state)", default=False),
    Option("--hid", "text", "HID game controller by vendor and product id, e.g. 054c:09cc", metavar="VVVV:PPPP",
           reader=parse_hid_id),
    Option("--mapping", "paths", "mapping file, repeatable (default: the shipped mapping that matches the device)",
           metavar="FILE.toml"),
    Option("--osc-in", "address", "accept control from OSC surfaces (bound to 127.0.0.1 unless HOST is given)", PORT,
           metavar="[HOST:]PORT"),
    Option("--console", "address", "serve the browser console (style mixer + live character) on PORT, bound to "
           "127.0.0.1 unless HOST is given; with a HOST the printed URL carries a token the page needs "
           "(docs/console.md)", Accepts(int, 0, 65535), metavar="[HOST:]PORT"),  # port 0: any free port
    Option("--console-token", "text", "the console's token (default: a new random one when HOST is given)",
           metavar="TOKEN"),
    Option("--presets", "path", "[presets.NAME] tables of target = value, recalled by preset/NAME (a show file holds "
           "them as its own [presets.NAME] tables)", metavar="FILE.toml", in_file=False),
    Option("--morph", "number", "seconds to morph into a recalled preset (default: the mapping's)", target("morph")),
    Option("--record", "path", "record every raw control event with its time", metavar="LOG.jsonl"),
    Option("--replay", "path", "play a controller log once (default with no controllers: the demo, looped)",
           metavar="LOG.jsonl"),
    Option("--score", "path", "play a score of timed cues (docs/scores.md); live controls ride on top",
           metavar="SCORE.toml"),
    Option("--loop", "flag", "play the --replay log or the --score over and over", default=False),
    Option("--humanoid", "path", "joint-to-humanoid-bone map for the VMC profile", metavar="BONES.toml"),
    Option("--vmc-root", "choice", "VMC: the hips carry the walk under a fixed root (default, as VirtualMotionCapture "
           "sends), or /VMC/Ext/Root/Pos carries the path and heading", metavar="hips|path", choices=("hips", "path"),
           default="hips"),
    Option("--no-relaxed-hands", "flag", "VMC: send no finger bones (default: a relaxed hand pose)", default=False),
    Option("--fast", "flag", "no realtime pacing: as fast as the CPU allows (offline rendering)", default=False),
    Option("--normal-priority", "flag", "do not ask for realtime scheduling (default: asked for, so frames stay on "
           "time on a busy machine)", default=False),
    Option("--quiet", "flag", "no status line (the health line stays)", default=False),
    Option("--force", "flag", "let --bvh and --record replace existing files (default: refuse)", default=False),
    Option("--keep-recordings", "flag", "when --bvh or --record exists, record beside it as NAME-2, NAME-3, ... (the "
           "first number free for both), never over it; `instrument service` runs shows with it", default=False),
    Option("--check", "flag", "check the show file and options as a start would (model, mappings, presets, files) and "
           "stop: nothing is opened or written", default=False, in_file=False),
    Option("--health-every", "number", "a health line (frames, late, outputs, devices, memory) this often, 0 for none "
           "(default 60)", Accepts(float, 0, 86400), metavar="SECONDS"),
    Option("--status-port", "address", "answer /walk/status (OSC) and 'status' (JSON) requests on this UDP port "
           "(bound to 127.0.0.1 unless HOST is given)", PORT, metavar="[HOST:]PORT"),
)
RUN_BY_KEY = {option.key: option for option in RUN}
OPTIONS.update({f"run {option.flag}": option.accepts for option in RUN if option.accepts is not None})

def value(key: str, text: object, where: str | None = None):
    """`text` read as OPTIONS[key] says, or a one-line UserError naming the option (or `where`)."""
    try:
        return OPTIONS[key].read(text)
    except ValueError as e:
        raise UserError(f"{where or key.split(' ', 1)[1]}: {e}") from None


def read(key: str, text: object, where: str | None = None) -> object:
    """`text` of `run`'s option `key` ("hid") read by its row's reader, or a one-line UserError
    naming the option and the text (`--hid '1234': expected ...`, as `host_port`'s) or `where`."""
    option = RUN_BY_KEY[key]
    try:
        return option.reader(text)
    except ValueError as e:
        raise UserError(f"{where}: {e}" if where else f"{option.flag} {e}") from None


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
