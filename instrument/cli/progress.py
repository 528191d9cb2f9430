"""A one-line progress bar on stderr (plain lines when stderr is not a terminal)."""

from __future__ import annotations

import sys


class Progress:
    def __init__(self, quiet: bool = False, width: int = 30):
        self.quiet = quiet
        self.width = width
        self.tty = sys.stderr.isatty()
        self.last_phase = ""

    def __call__(self, done: int, total: int, phase: str) -> None:
        if self.quiet:
            return
        if self.tty:
            filled = int(self.width * done / max(total, 1))
            sys.stderr.write(f"\r{phase:<10} [{'#' * filled}{'.' * (self.width - filled)}] {done}/{total}")
            if done >= total:
                sys.stderr.write("\n")
            sys.stderr.flush()
        elif done >= total and phase != self.last_phase:
            print(f"{phase}: {total}/{total}", file=sys.stderr)
            self.last_phase = phase
