"""Entry point: parse the subcommand, run it, turn a user's mistake into one line and exit 1."""

from __future__ import annotations

import argparse
import sys

from .. import __version__
from ..errors import UserError
from . import bench_cmd, devices_cmd, info_cmd, inspect_cmd, learn_cmd, log_cmd, recover_cmd, render_cmd, run_cmd, service_cmd, skeleton_cmd, synth_cmd, train_cmd, view_cmd

COMMANDS = (run_cmd, view_cmd, devices_cmd, learn_cmd, log_cmd, inspect_cmd, train_cmd, info_cmd, synth_cmd, bench_cmd, skeleton_cmd, render_cmd, recover_cmd, service_cmd)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="instrument",
        description="A realtime stylistic walk synthesizer: style models from motion capture, live control, OSC out.",
    )
    parser.add_argument("--version", action="version", version=f"instrument {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for command in COMMANDS:
        command.add_parser(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 2
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
