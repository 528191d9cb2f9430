"""Each late frame of a traced live loop given one cause (docs/crowds.md, "the late frames of one
character, traced").

The trace comes from `instrument run` (or `examples/midi_latency.py`, whose run inherits the
variable) with docs/figures/loop_trace.patch applied and INSTRUMENT_LOOP_TRACE=OUT.json set: per
frame the planned wake-up, the wake-up, the ends of its input, engine and outputs, the hold, the
send, and what ran after it (health, status, the collector); every look while waiting; every
collection, retune and import; the loop thread's run-queue time. The optional probe is
docs/figures/wake_probe.py's output from the same minutes.

    python docs/figures/loop_trace_causes.py [--probe=PROBE.json] [-v] TRACE.json...
"""

from __future__ import annotations

import json
import sys

LATE = 0.0001  # seconds after its deadline a frame counts as late (instrument/runtime/clock.py)


def collections(events: list) -> list[tuple[float, float, int]]:
    """(start, stop, generation) of each collection, from gc.callbacks' start and stop events."""
    spans, started = [], None
    for is_start, t, generation in events:
        if is_start:
            started = (t, generation)
        elif started is not None:
            spans.append((started[0], t, started[1]))
            started = None
    return spans


def cause(trace: dict, k: int, stalls: list | None) -> str:
    """Why frame k (of trace["frames"], k >= 2) was late: a late wake-up (and what delayed it) when
    that is more than half its lateness, else what made its work longer than the lead."""
    frames, r = trace["frames"], trace["frames"][k]
    prev = frames[k - 1]
    lateness, woke_late = r["hold"] - r["deadline"], r["wake"] - r["planned"]
    work, cpu = r["hold"] - r["wake"], r["cpu1"] - r["cpu0"]
    lead = r["deadline"] - r["planned"]
    if woke_late > lateness / 2:
        looks = [i for i in trace["idles"] if prev["gc"] <= i[0] < r["wake"]]  # (start, stop, retuned, wake, cpu)
        last = looks[-1] if looks else None
        if prev["gc"] > r["planned"]:
            if prev["hold"] - prev["deadline"] > LATE:
                return "wake: the frame before was late (cascade)"
            after = {"send": prev["sent"] - prev["hold"], "health": prev["health"] - prev["sent"],
                     "status": prev["status"] - prev["health"], "collector": prev["gc"] - prev["status"]}
            return f"wake: the frame before's work after its deadline ({max(after, key=after.get)})"
        # a look that began before the wake-up and took most of the delay itself (one that began
        # late came after a sleep that returned late: that sleep is the cause, below)
        if last is not None and last[0] < r["planned"] and last[1] - last[0] > woke_late / 2:
            if last[4] > 0.5 * (last[1] - last[0]):
                return "wake: a look while waiting ran past the wake-up (" + ("retune ahead" if last[2] else "input") + ")"
            return "wake: kept off the CPU in a look while waiting"
        if r["runq"] - prev["runq_after"] > 0.5 * woke_late:
            return "wake: the sleep returned late, waiting for a core (run queue)"
        if stalls is not None and any(s[0] - 0.0005 < r["wake"] and s[0] + s[1] > r["planned"] for s in stalls):
            return "wake: the sleep returned late, off the run queue; the probe stalled too (the machine)"
        return "wake: the sleep returned late, off the run queue"
    collected = [c for c in collections(trace["gc"]) if r["wake"] <= c[1] and c[0] < r["hold"]]
    if collected:
        return "work: a collection in the frame"
    if work - cpu > 0.0003 and work - cpu > 0.5 * (work - lead):
        return "work: kept off the CPU (wall time over CPU time)"
    if r["nret1"] > r["nret0"]:
        return "work: a retune in the frame (" + ("a change taken at the frame" if r["rev1"] != r["rev0"] else
                                                  "a change taken while waiting, too late to retune ahead") + ")"
    parts = {"input": r["live"] - r["wake"], "engine": r["engine"] - r["live"], "outputs": r["hold"] - r["engine"]}
    return f"work: longer than the lead ({max(parts, key=parts.get)})"


def causes(trace: dict, stalls: list | None = None, verbose: bool = False) -> dict[str, int]:
    """Late frames by cause (the first frame, which compiles and warms up, and the one after it left out)."""
    counts: dict[str, int] = {}
    for k in range(2, len(trace["frames"])):
        r = trace["frames"][k]
        if r["hold"] - r["deadline"] <= LATE:
            continue
        why = cause(trace, k, stalls)
        counts[why] = counts.get(why, 0) + 1
        if verbose:
            print(f"  frame {r['i']}: late {(r['hold'] - r['deadline']) * 1e3:.2f} ms, woke "
                  f"{(r['wake'] - r['planned']) * 1e3:.2f} ms late, work {(r['hold'] - r['wake']) * 1e3:.2f} ms "
                  f"(CPU {(r['cpu1'] - r['cpu0']) * 1e3:.2f}): {why}")
    return counts


def main() -> None:
    args = sys.argv[1:]
    verbose = "-v" in args
    stalls = None
    for arg in args:
        if arg.startswith("--probe="):
            with open(arg.split("=", 1)[1]) as f:
                stalls = [s for s in json.load(f)["late"] if s[2] < 0.5 * s[1]]  # off the run queue only
    for path in (a for a in args if not a.startswith("-")):
        with open(path) as f:
            trace = json.load(f)
        counts = causes(trace, stalls, verbose)
        retuned = sum(1 for r in trace["frames"][1:] if r["nret1"] > r["nret0"])
        print(f"{path}: {len(trace['frames']) - 1} frames, {sum(counts.values())} late; retunes in frames {retuned}, "
              f"ahead {sum(1 for i in trace['idles'] if i[2])}")
        for why, n in sorted(counts.items(), key=lambda item: -item[1]):
            print(f"  {n:4d}  {why}")


if __name__ == "__main__":
    main()
