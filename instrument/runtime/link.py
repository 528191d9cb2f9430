"""An Ableton Link session as a tempo source (`run --sync link`; the optional extra `[link]`).

Link (PyPI LinkPython-extern, which bundles Ableton's Link library under the GPL, version 2 or
later) shares a beat timeline between the music programs of a local network. Installing the
extra and distributing the instrument with it makes the combined work GPL: the instrument itself
does not import it unless `--sync link` is asked for. Link's clock is the system's monotonic
clock in microseconds, so its beats and the frames' deadlines (`time.monotonic()`)
are compared after one subtraction. Link joins a session by multicast on the local network's interfaces (that
is what Link is); alone, it keeps its own timeline at the tempo it started with.

Link's clock is not `time.monotonic()`'s on Linux (it reads CLOCK_MONOTONIC_RAW, which the
system's clock adjustments do not slew: here they were 0.1 s apart), so a moment is moved onto
Link's clock by their difference, read anew at each question.
"""

from __future__ import annotations

import time

from ..errors import UserError

QUANTUM = 4.0  # beats per bar, Link's phase unit
START_BPM = 120.0  # the tempo a session begun by the instrument starts at


class LinkTempo:
    """The Link session's tempo and beats, read from an app session state capture each time.

    Start/stop sync is on: the session's transport (any peer's play and stop) is `running`, so
    a stopped session keeps the walk at its last speed and a start locks it again. A session
    whose transport has never played (peers that do not share start/stop) is followed by its
    timeline, which never stops."""

    def __init__(self, bpm: float = START_BPM):
        try:
            import link
        except ImportError:
            raise UserError("--sync link needs Ableton Link: pip install 'instrument[link]' "
                            "(LinkPython-extern, GPL: see docs/tempo.md)") from None
        self.link = link.Link(bpm)
        self.link.startStopSyncEnabled = True
        self.link.enabled = True
        self.played = False  # the session's transport has played since we joined

    @property
    def running(self) -> bool:
        """The session plays (or its transport never has: its timeline is followed)."""
        playing = self.link.captureAppSessionState().isPlaying()
        self.played = self.played or playing
        return playing or not self.played

    def period(self) -> float:
        return 60.0 / self.link.captureAppSessionState().tempo()

    def beat_at(self, moment: float) -> float:
        on_link = moment + self.link.clock().micros() * 1e-6 - time.monotonic()
        return self.link.captureAppSessionState().beatAtTime(int(on_link * 1e6), QUANTUM)

    def peers(self) -> int:
        return self.link.numPeers()

    def close(self) -> None:
        self.link.enabled = False
