"""Waiting for events in the tests: poll with a generous deadline instead of sleeping a fixed time.

A loaded machine (CI, eight jobs on two cores) can take seconds to start a process; a test that
sleeps a fixed time and then expects a count fails there. These helpers wait for the thing itself.
"""

from __future__ import annotations

import subprocess
import threading
import time
from typing import Callable

GENEROUS = 120.0  # seconds: only ever reached when something is really wrong


def wait_until(condition: Callable[[], object], what: str, timeout: float = GENEROUS, every: float = 0.02):
    """Poll `condition` until it returns something true (returned), or fail naming `what`."""
    deadline = time.monotonic() + timeout
    while True:
        result = condition()
        if result:
            return result
        if time.monotonic() > deadline:
            raise AssertionError(f"waited {timeout:g} s for {what}")
        time.sleep(every)


class StderrLines:
    """Collects a running process's stderr line by line, so a test can wait for a message."""

    def __init__(self, process: subprocess.Popen):
        self.lines: list[str] = []
        self.thread = threading.Thread(target=self._read, args=(process.stderr,), daemon=True)
        self.thread.start()

    def _read(self, stream) -> None:
        for line in stream:
            self.lines.append(line)

    def count(self, text: str) -> int:
        return sum(text in line for line in list(self.lines))

    def wait_for(self, text: str, times: int = 1) -> None:
        wait_until(lambda: self.count(text) >= times, f"{text!r} on stderr")

    def text(self) -> str:
        self.thread.join(10)
        return "".join(self.lines)
