"""Ctrl-C and SIGTERM ask the show to stop; they never interrupt it mid-step.

Both signals only set a flag, which the start-up and the frame loop look at between steps. No
KeyboardInterrupt is raised, so a stop never lands between a BVH frame and its header update,
and none can be swallowed by a library callback during start-up (the flag stays set).
"""

from __future__ import annotations

import signal
import threading

SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopFlag:
    def __init__(self):
        self.requested = False
        self.by: str | None = None  # name of the signal that asked
        self.previous: dict[int, object] = {}

    def __bool__(self) -> bool:
        return self.requested

    def request(self, signum: int | None = None, _frame=None) -> None:
        self.requested = True
        self.by = signal.Signals(signum).name if signum else "request"

    def install(self) -> "StopFlag":
        """Take over SIGINT and SIGTERM; `restore` gives them back. Only the main thread can
        (a show run in another thread is stopped by `request`)."""
        if threading.current_thread() is not threading.main_thread():
            return self
        for signum in SIGNALS:
            self.previous[signum] = signal.signal(signum, self.request)
        return self

    def restore(self) -> None:
        for signum, handler in self.previous.items():
            signal.signal(signum, handler)
        self.previous.clear()

    def __enter__(self) -> "StopFlag":
        return self.install()

    def __exit__(self, *exc) -> None:
        self.restore()
