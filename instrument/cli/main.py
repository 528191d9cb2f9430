"""Entry point: parse the subcommand, run it, turn a user's mistake into one line and exit 1.

Only the chosen subcommand's module is imported (numpy, scipy and numba take seconds to load),
so `instrument --version`, `instrument --help` and each command start without the others' cost.
Usage errors (an unknown option, a missing argument) are argparse's: one line, exit 2.

A command that uses numba (all but WITHOUT_NUMBA) says on stderr when it starts compiling the
kernels, which a first run after installing does for about half a minute (progress.CompileNotice).

Ctrl-C and SIGTERM while the parser and the chosen command's module load end the process at once
(exit 130 or 143, no traceback: nothing has been written yet). Once the command runs they are
its own: `run` turns both into a stop flag, the others see KeyboardInterrupt ("interrupted", 130).
"""

from __future__ import annotations

import argparse
import errno
import faulthandler
import importlib
import os
import signal
import sys
import threading
import traceback

from .. import __version__
from ..errors import UserError

# name: (module in instrument.cli, the line `instrument --help` shows; the module's own help says the same)
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("run_cmd", "the live instrument: walk, listen to controls, send OSC (default: the demo performance)"),
    "view": ("view_cmd", "live stick figure of the flat OSC profile (needs matplotlib)"),
    "devices": ("devices_cmd", "list MIDI ports and HID devices, with the shipped mapping for each"),
    "learn": ("learn_cmd", "MIDI or HID learn: pick a target, move a control, write a mapping file"),
    "log": ("log_cmd", "controller logs: export to / import from Standard MIDI Files"),
    "inspect": ("inspect_cmd", "check BVH files: skeleton, frames, steps found, warnings"),
    "train": ("train_cmd", "train style models from BVH takes"),
    "info": ("info_cmd", "describe a model file: styles, states, durations, provenance, licence"),
    "synth": ("synth_cmd", "synthesize a walk with given style weights and write it as BVH"),
    "evaluate": ("evaluate_cmd", "measure a model's walks (skate, floor, ranges, drift, recognisability) against real takes"),
    "bench": ("bench_cmd", "measure parsing and synthesis speed on this machine"),
    "skeleton": ("skeleton_cmd", "write the model's skeleton as a one-frame BVH (or .glb): a T-pose rest to rig, or the template"),
    "render": ("render_cmd", "draw a BVH recording: contact sheet (.png) or animation (.gif)"),
    "convert": ("convert_cmd", "convert a BVH recording to binary glTF (.glb) or BVH, by the --out extension"),
    "recover": ("recover_cmd", "repair the frame count of a BVH recording left by a killed run"),
    "service": ("service_cmd", "write a systemd unit that runs a show file unattended (restart, watchdog)"),
}
EVERY = "*"  # build_parser(EVERY): import every subcommand (the tests check them all)
WITHOUT_NUMBA = {"recover", "log", "devices", "learn", "service"}  # the others compile numba kernels on a first run


def chosen_command(argv: list[str]) -> str | None:
    """The subcommand named on the command line: the first word that is not an option."""
    words = [a for a in argv if not a.startswith("-")]
    return words[0] if words and words[0] in COMMANDS else None


class OneLineParser(argparse.ArgumentParser):
    """argparse, but a usage error is one line naming the option, and a pointer to --help; exit 2."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser(load: str | None = EVERY) -> argparse.ArgumentParser:
    """The parser; subcommands other than `load` are listed by name and summary only."""
    parser = OneLineParser(
        prog="instrument",
        description="A realtime stylistic walk synthesizer: style models from motion capture, live control, OSC out.",
        epilog="Exit status: 0 done, 1 a bad file or value (one line naming it), 2 a usage error, 130 interrupted (143: SIGTERM while loading).",
    )
    parser.add_argument("--version", action="version", version=f"instrument {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, summary) in COMMANDS.items():
        if load in (EVERY, name):
            importlib.import_module(f"{__package__}.{module}").add_parser(sub)
        else:
            sub.add_parser(name, help=summary)
    return parser


# the handling each signal gets once the command runs (Python's own)
COMMAND_HANDLERS = {signal.SIGINT: signal.default_int_handler, signal.SIGTERM: signal.SIG_DFL}


def _end_at_once(signum: int, _frame) -> None:
    """A signal before the command runs: nothing is written yet, so end now (128 + signal, as a
    shell reports it). os._exit, not an exception: an import may swallow an exception."""
    os._exit(128 + signum)


def _set_handlers(handler_for: dict[int, object]) -> None:
    if threading.current_thread() is threading.main_thread():  # (main() called from a thread: left alone)
        for signum, handler in handler_for.items():
            signal.signal(signum, handler)


def _name_crashes() -> None:
    """A crash inside a C library (libjack, hidapi) prints each thread's Python stack to stderr,
    so a show that died says where, not only "Segmentation fault"."""
    if not faulthandler.is_enabled():
        try:
            faulthandler.enable()
        except (RuntimeError, ValueError, OSError):  # no stderr (closed: RuntimeError), or no file behind it
            pass


def main(argv: list[str] | None = None) -> int:
    """The command line's command; `argv` None: this process's own (then its MIDI inputs are left
    to the process's end, and a process that left a port, or holds a dead JACK client, ends as
    soon as the command is done: `_end_past_jack`)."""
    if argv is None:  # this process's own command: its MIDI inputs end with it (jackwatch.release)
        from ..control.jackwatch import ENDS_WITH_PROCESS

        ENDS_WITH_PROCESS.set()
    try:
        code = _command(argv)
    except BaseException:  # a bug's traceback: printed, and past a JACK restart the process still ends at once
        if argv is None and _abandoned():
            traceback.print_exc()
            _end_past_jack(1)
        raise
    if argv is None:
        _end_past_jack(code)
    return code


def _abandoned() -> bool:
    watch = sys.modules.get("instrument.control.jackwatch")
    return watch is not None and watch.ABANDONED.is_set()


def _end_past_jack(code: int) -> None:
    """A process whose MIDI ports were left to its end (jackwatch.release: at a show's end, or past
    a JACK server restart) ends at once with the command's exit status: libjack can crash while
    the interpreter and the C libraries tear down at exit. Everything is written and closed by now."""
    if _abandoned():
        for stream in (sys.stdout, sys.stderr):
            try:
                if stream is not None:
                    stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)


def _command(argv: list[str] | None) -> int:
    _name_crashes()
    _set_handlers({signum: _end_at_once for signum in COMMAND_HANDLERS})
    try:
        argv = sys.argv[1:] if argv is None else argv
        parser = build_parser(chosen_command(argv))
        args = parser.parse_args(argv)
        if args.command is None:
            parser.print_help()
            return 2
        if args.command not in WITHOUT_NUMBA:  # still loading: a signal now ends the process at once
            from .progress import watch_compiling

            watch_compiling()  # a first run says why it waits (numba: loaded now, as the command would)
    finally:
        _set_handlers(COMMAND_HANDLERS)
    try:
        return int(args.run(args) or 0)
    except UserError as error:
        print(f"instrument {args.command}: error: {error}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"instrument {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:  # e.g. `instrument inspect ... | head`
        return 0
    except OSError as error:
        where = _full_disk_writer(error)
        if where is None:
            raise
        print(f"instrument {args.command}: error: {where}: cannot write: {error.strerror}", file=sys.stderr)
        return 1


def _full_disk_writer(error: OSError) -> str | None:
    """What a command could not write for want of space (a full disk, a quota, a file size limit)
    where nothing of ours caught it: numba saving a first run's compiled kernels to its cache.
    None for any other error (a bug: its traceback is wanted)."""
    if error.errno not in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
        return None
    frames = traceback.extract_tb(error.__traceback__)
    if any("numba" in frame.filename and "caching" in frame.filename for frame in frames):
        return f"the kernels' cache {os.environ.get('NUMBA_CACHE_DIR', '')}".rstrip()
    return error.filename or None
