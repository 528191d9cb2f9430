"""One clock owns time: frames fall due on absolute deadlines of the monotonic clock."""

from __future__ import annotations

import time
from typing import Callable

SPIN = 0.0005  # the last half millisecond before a deadline is spun, not slept (sleep overshoots)
IDLE_EVERY = 0.002  # seconds between two calls of the idle work while waiting for a frame
IDLE_UNTIL = 0.001  # idle work stops this long before waking, so it never delays the wake-up
LATE = 0.0001  # a frame sent more than this after its deadline counts as late


class FrameClock:
    """Deadlines start + n / fps, so sleep errors never accumulate (no drift over an hour).

    The loop wakes a little before each deadline (`lead`, about what making a frame takes),
    makes the frame, then `hold`s until the deadline and sends it, so frames leave on time.
    While it waits it can run small `idle` work (reading devices), never into the wake-up.
    A frame not ready by its deadline counts as late. When the loop falls more than a frame
    behind, the missed slots are dropped and the schedule moves on from now: the walk carries
    on at its own pace instead of bursting through the backlog.
    """

    def __init__(self, fps: float, realtime: bool = True, now=time.monotonic, sleep=time.sleep):
        self.period = 1.0 / fps
        self.realtime = realtime
        self.now, self.sleep = now, sleep
        self.start = now()
        self.frame = 0  # index of the frame being made
        self.late = 0
        self.dropped = 0

    def restart(self) -> None:
        """Anchor the schedule so that the current frame is due now."""
        self.start = self.now() - self.frame * self.period

    def deadline(self, frame: int | None = None) -> float:
        return self.start + (self.frame if frame is None else frame) * self.period

    def advance(self, lead: float = 0.0, idle: Callable[[], None] | None = None) -> None:
        """Move to the next frame and sleep until `lead` seconds before its deadline, calling
        `idle` about every IDLE_EVERY seconds meanwhile (up to IDLE_UNTIL before waking)."""
        self.frame += 1
        if not self.realtime:
            return
        now = self.now()
        due = self.deadline()
        if now > due + self.period:  # more than a whole frame behind: drop the missed slots
            missed = int((now - due) / self.period) + 1  # so the next deadline is ahead again
            self.dropped += missed
            self.start += missed * self.period
        self._until(self.deadline() - lead, idle)

    def hold(self) -> float:
        """Wait for the current frame's deadline; returns how late it is (0 if on time)."""
        if not self.realtime:
            return 0.0
        due = self.deadline()
        lateness = self.now() - due
        if lateness > 0:
            self.late += lateness > LATE
            return lateness
        self._until(due)
        return 0.0

    def _until(self, moment: float, idle: Callable[[], None] | None = None) -> None:
        if idle is not None:
            while (remaining := moment - IDLE_UNTIL - self.now()) > 0:
                self.sleep(min(remaining, IDLE_EVERY))
                idle()
        while True:
            remaining = moment - self.now()
            if remaining <= 0:
                return
            if remaining > SPIN:
                self.sleep(remaining - SPIN)
            # else: spin
