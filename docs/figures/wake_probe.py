"""A lone SCHED_FIFO thread at the live loop's priority, sleeping 2 ms at a time, in a process of
its own: how often and how late the OS wakes it, and whether it waited on the run queue meanwhile
(/proc/thread-self/schedstat). Run beside `examples/midi_latency.py` with the loop traced
(docs/figures/loop_trace.patch): a late wake-up of the loop that this thread shares, off the run
queue, is the machine's (the host's), not the loop's own (it shares no interpreter lock).

    sudo python docs/figures/wake_probe.py SECONDS OUT.json    # (SCHED_FIFO needs the right)
"""

import json
import os
import sys
import time

PRIORITY = 5  # instrument/runtime/priority.py


def run_queue_seconds() -> float:
    with open("/proc/thread-self/schedstat") as f:
        return int(f.read().split()[1]) * 1e-9


def main() -> None:
    seconds, out = float(sys.argv[1]), sys.argv[2]
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(PRIORITY))
    late, sleeps = [], 0
    start = time.monotonic()
    while time.monotonic() < start + seconds:
        queued, due = run_queue_seconds(), time.monotonic() + 0.002
        time.sleep(0.002)
        over, sleeps = time.monotonic() - due, sleeps + 1
        if over > 0.001:
            late.append((due, over, run_queue_seconds() - queued))  # (due, how late, of it on the run queue)
    with open(out, "w") as f:
        json.dump({"start": start, "end": time.monotonic(), "sleeps": sleeps, "late": late}, f)


if __name__ == "__main__":
    main()
