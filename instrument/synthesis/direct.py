"""A compiled kernel called straight through the machine code of one argument signature.

Every call of a numba kernel goes through its dispatcher, which first works out the type of each
argument to choose the compiled version. For a record (a NamedTuple of arrays, as the stream's
`StreamTables` and `WindowWork`) that means typing every array in it, each call. A frame's record
is made again only when its tables change (stream.py keeps it), so the compiled entry point is
chosen once per record here and called directly. When a record is made again (a fader moved the
style), its arrays are new but of the same kinds, so the entry point is looked up by a cheap
description of the arguments (each array's dtype, rank, layout and writability) rather than by
numba's `typeof`, which cost a style change's frame more than the rest of its work
(docs/mlpg.md, "A style change's frame").

What is kept is keyed on the identity of the `held` objects the caller names (the records); every
other argument must keep its type from call to call (the caller's promise: a Python int, a bool,
a float64 C array of fixed rank), since the entry point does not check types as the dispatcher
does.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numba import typeof


def _kind(value: Any) -> Any:
    """What decides `value`'s numba type, cheaply: for an array its dtype, rank, layout, whether
    it can be written and whether it is aligned; for a tuple (a record) its class and its items'
    kinds; for anything else its Python type."""
    if isinstance(value, np.ndarray):
        flags = value.flags
        return value.dtype, value.ndim, flags.c_contiguous, flags.f_contiguous, flags.writeable, flags.aligned
    if isinstance(value, tuple):
        return type(value), tuple(_kind(item) for item in value)
    return type(value)


class DirectCall:
    """`kernel(*arguments)` through the compiled entry point for the arguments' types, looked up
    again only when one of the `held` objects is another than at the last call."""

    def __init__(self, kernel: Any):
        self.kernel = kernel
        self._held: tuple = ()  # the objects the entry point was chosen for (kept, so their ids stay theirs)
        self._entry: Any = None
        self._entries: dict[Any, Any] = {}  # the arguments' kinds -> the entry point for their types

    def __call__(self, held: tuple, *arguments: Any) -> Any:
        if self._entry is None or len(held) != len(self._held):
            return self._choose(held, arguments)
        for a, b in zip(held, self._held):  # (a loop: a generator's any() cost a frame 0.3 us)
            if a is not b:
                return self._choose(held, arguments)
        return self._entry(*arguments)

    def _choose(self, held: tuple, arguments: tuple) -> Any:
        """The entry point for `arguments`' kinds, kept for the objects `held`; called."""
        kinds = tuple(_kind(a) for a in arguments)
        entry = self._entries.get(kinds)
        if entry is None:
            entry = self._entries[kinds] = entry_point(self.kernel, arguments)
        self._entry, self._held = entry, held
        return entry(*arguments)


def entry_point(kernel: Any, arguments: tuple, *last: Any) -> Any:
    """The compiled entry point of `kernel` for the types of `arguments` (compiled if need be):
    called with arguments of those same types, it skips the dispatcher's typing of each. `last`:
    the numba types of arguments after those, given as types (an array of any layout, say, where
    the caller checks what it passes: gestures.py's frames)."""
    types = tuple(typeof(a) for a in arguments) + last
    if types not in kernel.overloads:
        kernel.compile(types)
    return kernel.overloads[types].entry_point
