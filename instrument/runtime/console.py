"""What the performer reads: warnings (each kind at most once a minute) and a status line."""

from __future__ import annotations

import sys
import time


class Console:
    def __init__(self, quiet: bool = False, stream=None, now=time.monotonic, repeat_after: float = 60.0):
        self.quiet = quiet
        self.stream = stream or sys.stderr
        self.now = now
        self.repeat_after = repeat_after
        self.last_said: dict[str, float] = {}
        self.tty = hasattr(self.stream, "isatty") and self.stream.isatty()
        self.status_shown = False

    def warn(self, key: str, message: str) -> bool:
        """Say `message` unless the same key was said less than a minute ago; True if said."""
        t = self.now()
        if key in self.last_said and t - self.last_said[key] < self.repeat_after:
            return False
        self.last_said[key] = t
        self._line(f"warning: {message}")
        return True

    def say(self, message: str) -> None:
        self._line(message)

    def status(self, text: str) -> None:
        if self.quiet:
            return
        if self.tty:
            self.stream.write("\r" + text[:200].ljust(100))
            self.stream.flush()
            self.status_shown = True
        else:
            self.stream.write(text + "\n")
            self.stream.flush()

    def _line(self, text: str) -> None:
        if self.status_shown:
            self.stream.write("\n")
            self.status_shown = False
        self.stream.write(text + "\n")
        self.stream.flush()
