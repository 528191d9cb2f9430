"""A compiled kernel called straight through the machine code of one argument signature.

Every call of a numba kernel goes through its dispatcher, which first works out the type of each
argument to choose the compiled version. For a record (a NamedTuple of arrays, as the stream's
`StreamTables` and `WindowWork`) that means typing every array in it, each call: 12 us of a
one-character frame's stream call against 3 us for unboxing alone (a kernel that does nothing,
two records and three plain arguments, measured 2026-11-26). A frame's record is made again only
when its tables change (stream.py keeps it), so its type is worked out once per record here and
the compiled entry point for it is kept and called directly. For plain arrays the dispatcher is
fast already: the posing kernels called this way were no faster (32.7 against 30.5 us a frame).

What is kept is keyed on the identity of the `held` objects the caller names (the records); every
other argument must keep its type from call to call (the caller's promise: a Python int, a bool,
a float64 C array of fixed rank), since the entry point does not check types as the dispatcher
does.
"""

from __future__ import annotations

from typing import Any

from numba import typeof


class DirectCall:
    """`kernel(*arguments)` through the compiled entry point for the arguments' types, worked out
    again only when one of the `held` objects is another than at the last call."""

    def __init__(self, kernel: Any):
        self.kernel = kernel
        self._held: tuple = ()  # the objects the entry point was chosen for (kept, so their ids stay theirs)
        self._entry: Any = None

    def __call__(self, held: tuple, *arguments: Any) -> Any:
        if self._entry is None or len(held) != len(self._held) or any(a is not b for a, b in zip(held, self._held)):
            types = tuple(typeof(a) for a in arguments)
            if types not in self.kernel.overloads:
                self.kernel.compile(types)
            self._entry, self._held = self.kernel.overloads[types].entry_point, held
        return self._entry(*arguments)
