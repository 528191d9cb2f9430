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
import sys

PRIORITY = 5


def realtime_scheduling() -> str | None:
    """Switch the calling thread to SCHED_FIFO, and the helper threads a crowd's frame is shared
    with (synthesis/cores.py) as well; None when done, else why not.

    A helper started before this call (by an earlier long MLPG solve: `instrument bench` solves
    one before its crowd trials) kept normal scheduling, and a frame waits for its helper, so the
    realtime loop waited behind ordinary programs after all (docs/crowds.md). Threads started
    later take the caller's scheduling by themselves."""
    if not hasattr(os, "sched_setscheduler"):
        return "not available on this system"
    # helpers exist only once the solver is loaded (looked up, not imported: `run --help` and a
    # process that never solves stay without numba)
    solver = sys.modules.get("instrument.synthesis.mlpg")
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(PRIORITY))
        for helper in solver.helper_thread_ids() if solver else []:
            try:
                os.sched_setscheduler(helper, os.SCHED_FIFO, os.sched_param(PRIORITY))
            except ProcessLookupError:  # a helper that has ended (at exit): nothing to move
                pass
    except PermissionError:
        return "not permitted for this user (on Linux, an rtprio limit such as JACK's audio group grants it)"
    except OSError as error:
        return error.strerror or str(error)
    return None
