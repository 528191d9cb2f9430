"""A sink's sending on a thread of its own, so the live loop's thread is free for the next frame.

A large crowd's flat frame is some 2,200 datagrams for 1,000 characters: the kernel's work for
them (each copied, routed and, to a local receiver, delivered) is some 6 ms of CPU however few
system calls carry them (docs/crowds.md). Made on the loop's thread, it came after the deadline
and before the next frame's work could start, so the frame's work and the sending had to fit
one after the other in a frame's time. On a thread of its own it runs beside the next frame's
work, on the other core.

One frame at a time: `hand` gives the thread a frame's sending and returns; `wait` returns when
that sending is done (a sink calls it before writing the next frame into the buffer the last one
is sent from). An error the sending raised is raised by the next `wait`, so the loop counts it
against the sink as it counts an error of a sending made in its own thread.
"""

from __future__ import annotations

import threading
from typing import Callable

BEGIN_WAIT = 0.001  # seconds `hand` waits at most for the thread to begin (when no core is free for it)


class Background:
    """One thread that runs the sendings handed to it, one at a time, in order.

    The thread is started by the first `hand`, so it is made by the thread that plays the show
    after that thread's scheduling is set (a thread takes its maker's: realtime_scheduling)."""

    def __init__(self, name: str):
        self.name = name
        self._wake = threading.Condition()
        self._job: Callable[[], object] | None = None  # the sending handed over, not yet done
        self._idle = threading.Event()
        self._idle.set()
        self._begun = threading.Event()  # the thread has taken the job handed over
        self._error: BaseException | None = None
        self._closing = False
        self._thread: threading.Thread | None = None

    def hand(self, job: Callable[[], object]) -> None:
        """Run `job` on the thread, and return once the thread has begun it, or after BEGIN_WAIT
        (the one handed before is waited for first). Waiting for it to begin costs the caller a
        thread's wake-up (some 0.06 ms): without it, a caller going on with Python work held the
        interpreter's lock, and the sending began only when the caller next let it go (0.3 to
        0.6 ms later in the live loop, which goes on to its status and its next frame). At most
        BEGIN_WAIT: when no core is free for the thread (another program's realtime thread, the
        host), the caller goes on rather than wait with it (once 9 ms in 360 frames)."""
        self.wait()
        if self._thread is None:
            self._thread = threading.Thread(target=self._run, name=self.name, daemon=True)
            self._thread.start()
        with self._wake:
            self._idle.clear()
            self._begun.clear()
            self._job = job
            self._wake.notify()
        self._begun.wait(BEGIN_WAIT)

    def wait(self) -> None:
        """Return once the last job handed over is done; raise what it raised, if anything."""
        self._idle.wait()
        error, self._error = self._error, None
        if error is not None:
            raise error

    def close(self) -> None:
        """The last job done (its error, if any, raised), then the thread ended."""
        try:
            self.wait()
        finally:
            with self._wake:
                self._closing = True
                self._wake.notify()
            if self._thread is not None:
                self._thread.join()
            self._thread, self._closing = None, False  # a later `hand` starts a thread again (a profile shared by shows)

    def _run(self) -> None:
        while True:
            with self._wake:
                while self._job is None and not self._closing:
                    self._wake.wait()
                if self._job is None:
                    return
                job, self._job = self._job, None
            self._begun.set()
            try:
                job()
            except BaseException as error:  # handed back to the loop's thread by `wait`
                self._error = error
            finally:
                self._idle.set()
