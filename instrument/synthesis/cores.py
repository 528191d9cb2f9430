"""A crowd's frame spread over the cores: every batched stage works character by character, so
its characters are cut into one part per core, each part run by the stage's own compiled kernel
(which releases the GIL) or numpy (which does too for large arrays) on a thread of its own.

Each character's numbers do not depend on which part it falls in, so a crowd's walk is the same
bit for bit on one core or many. A crowd too small to repay a hand-over (some tens of
microseconds) stays in the calling thread.
"""

from __future__ import annotations

from typing import Callable

from .mlpg import _cores, _pool

LEAST_PER_PART = 16  # characters: below this a part is not worth a thread's hand-over
# ... for a stage of about a microsecond a character (the duration tables, `_tune`), which a
# hand-over's cost to the calling thread outweighs in a smaller crowd (docs/crowds.md)
LEAST_PER_LIGHT_PART = 256


def parts(count: int, least: int = LEAST_PER_PART) -> list[tuple[int, int]]:
    """[start, stop) ranges of about equal size covering `count` characters, one per core at most."""
    if count < 2 * least:  # the common case of one character: no need to ask how many cores
        return [(0, count)]
    share = max(1, min(_cores(), count // max(least, 1)))
    bounds = [count * k // share for k in range(share + 1)]
    return list(zip(bounds[:-1], bounds[1:]))


def over_cores(kernel: Callable[..., object], arguments: list[tuple]) -> None:
    """Runs `kernel(*arguments[k])` for each part k (from `parts`): the first in this thread, the
    others on the pool's. The arguments are made by the caller, so a helper thread goes straight
    into the kernel (no Python of its own to wait for the GIL with). Returns when all are done;
    an error in any is raised."""
    try:
        others = [_pool().submit(kernel, *args) for args in arguments[1:]]
    except RuntimeError:  # the interpreter is shutting down: this thread does them all
        others = []
        for args in arguments[1:]:
            kernel(*args)
    kernel(*arguments[0])
    for other in others:
        other.result()
