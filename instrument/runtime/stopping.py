"""Ctrl-C and SIGTERM ask the show to stop; they never interrupt it mid-step.

Both signals only set a flag, which the start-up and the frame loop look at between steps. No
KeyboardInterrupt is raised, so a stop never lands between a BVH frame and its header update,
and none can be swallowed by a library callback during start-up (the flag stays set). Before
anything is opened (the show checked, a first run's kernels compiled: `ending_at_once`), there
is nothing to close, and a signal ends the process at once.
"""

from __future__ import annotations

import os
import signal
import threading
from collections.abc import Iterator
from contextlib import contextmanager

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

    @contextmanager
    def ending_at_once(self, command: str) -> Iterator[None]:
        """While nothing is open or written yet: Ctrl-C or SIGTERM ends the process at once with one
        line and status 130 or 143 (as while the command line loads: cli/main.py), instead of
        setting the flag. A first run compiles the kernels for half a minute in one call that
        looks at no flag, and a Ctrl-C then waited for it to end. A signal that set the flag
        before ends the process too. Only in the main thread (signals are handled there)."""
        if threading.current_thread() is not threading.main_thread():
            yield
            return

        def end(signum: int, _frame=None) -> None:
            line = f"{command}: stopped by {signal.Signals(signum).name} before anything was opened\n".encode()
            # written from a thread, waited for a second at most: a stderr nobody reads never holds the exit
            writer = threading.Thread(target=_write_stderr, args=(line,), daemon=True)
            writer.start()
            writer.join(1.0)
            os._exit(128 + signum)

        before = {signum: signal.signal(signum, end) for signum in SIGNALS}
        try:
            if self.requested and self.by in signal.Signals.__members__:
                end(signal.Signals[self.by])
            yield
        finally:
            for signum, handler in before.items():
                signal.signal(signum, handler)

    def __enter__(self) -> "StopFlag":
        return self.install()

    def __exit__(self, *exc) -> None:
        self.restore()


def _write_stderr(data: bytes) -> None:
    try:
        os.write(2, data)
    except OSError:  # no stderr: the exit status says it
        pass
