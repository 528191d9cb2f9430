"""The command line's own checks: argparse types read through the option table
(control/options.py), and options given without the one they belong to, or with one they
contradict (refused rather than ignored)."""

from __future__ import annotations

import argparse
from collections.abc import Callable

from ..control.options import OPTIONS
from ..errors import UserError

# "COMMAND --option": the option without which it means nothing (refused rather than ignored)
NEEDS: dict[str, str] = {
    "run --console-token": "--console",
    "bench --console": "--pacing",
    "bench --console-pages": "--console",
}


# "COMMAND --option": the option it contradicts (both given: refused rather than one dropped)
EXCLUDES: dict[str, str] = {
    "run --no-osc": "--osc",
}


def _given(args: argparse.Namespace, option: str) -> bool:
    value = getattr(args, option[2:].replace("-", "_"), None)
    return value is not None and value is not False  # a flag left off is False


def check_needs(command: str, args: argparse.Namespace, where: Callable[[str], str] = lambda option: "") -> None:
    """A one-line UserError for an option given without the option it belongs to (NEEDS), or with
    one it contradicts (EXCLUDES); `where(option)` starts it (a show file's "show.toml:3: key: ")."""
    for key, partner in NEEDS.items():
        name, option = key.split(" ", 1)
        if name == command and _given(args, option) and not _given(args, partner):
            raise UserError(f"{where(option)}{option} means nothing without {partner} (on the command line or in the show file)")
    for key, other in EXCLUDES.items():
        name, option = key.split(" ", 1)
        if name == command and _given(args, option) and _given(args, other):
            raise UserError(f"{where(option) or where(other)}{option} and {other} contradict each other: give one (on the command line or in the show file)")


def checked(key: str):
    """An argparse type= that reads OPTIONS[key]: a bad value is a usage error naming the option."""

    def read(text: str):
        try:
            return OPTIONS[key].read(text)
        except ValueError as e:
            raise argparse.ArgumentTypeError(str(e)) from None

    read.__name__ = key.split(" --", 1)[1]  # argparse names the type in some messages
    return read
