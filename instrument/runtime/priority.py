"""Realtime scheduling for the frame loop, so frames do not wait behind ordinary programs.

On a busy machine (a renderer, a browser, JACK on the same cores) an ordinary process can be
kept off the CPU for a millisecond or more right when a frame is due. The loop asks for
SCHED_FIFO at a modest priority: above every ordinary process, below JACK's audio threads
(JACK's own default priority is 10 and its clients run near it). Linux users with JACK set up
usually may do this already (the `audio` group's rtprio limit); otherwise the instrument runs
at normal priority and says so.
"""

from __future__ import annotations

import os

PRIORITY = 5


def realtime_scheduling() -> str | None:
    """Switch the calling thread to SCHED_FIFO; None when done, else why not."""
    if not hasattr(os, "sched_setscheduler"):
        return "not available on this system"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(PRIORITY))
    except PermissionError:
        return "not permitted for this user (on Linux, an rtprio limit such as JACK's audio group grants it)"
    except OSError as error:
        return error.strerror or str(error)
    return None
