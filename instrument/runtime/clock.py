"""One clock owns time: frames fall due on absolute deadlines of the monotonic clock."""

from __future__ import annotations

import time


class FrameClock:
    """Deadlines start + n / fps, so sleep errors never accumulate (no drift over an hour).

    A frame finished after the next one was due counts as late. When the loop falls more than a
    frame behind, the missed slots are dropped and the schedule moves on from now: the walk
    carries on at its own pace instead of bursting through the backlog.
    """

    def __init__(self, fps: float, realtime: bool = True, now=time.monotonic, sleep=time.sleep):
        self.period = 1.0 / fps
        self.realtime = realtime
        self.now, self.sleep = now, sleep
        self.start = now()
        self.frame = 0  # index of the next frame to make
        self.late = 0
        self.dropped = 0

    def restart(self) -> None:
        """Anchor the schedule so that the current frame is due now."""
        self.start = self.now() - self.frame * self.period

    def deadline(self, frame: int | None = None) -> float:
        return self.start + (self.frame if frame is None else frame) * self.period

    def wait(self) -> float:
        """Block until the next frame is due; returns how late the wake-up was (seconds)."""
        if not self.realtime:
            self.frame += 1
            return 0.0
        self.frame += 1
        due = self.deadline()
        now = self.now()
        if now > due + self.period:  # more than a whole frame behind: drop the missed slots
            missed = int((now - due) / self.period) + 1  # so the next deadline is ahead again
            self.late += 1
            self.dropped += missed
            self.start += missed * self.period
            due = self.deadline()
        elif now > due:
            self.late += 1
        while True:
            remaining = due - self.now()
            if remaining <= 0:
                break
            self.sleep(remaining if remaining > 0.002 else remaining / 2)
        return self.now() - due
