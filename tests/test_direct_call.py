"""synthesis/direct.py: a compiled kernel called through its entry point gives what the
dispatcher gives, and works its types out again for a new record."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from instrument.synthesis.direct import DirectCall


class Pair(NamedTuple):
    a: np.ndarray
    b: np.ndarray


@njit(cache=False)
def _weighted_sum(pair, weight, out):
    for k in range(out.shape[0]):
        out[k] = pair.a[k] + weight * pair.b[k]
    return out.sum()


def test_a_direct_call_equals_the_dispatchers_and_follows_a_new_records_types():
    call = DirectCall(_weighted_sum)
    floats = Pair(np.arange(5.0), np.linspace(0.0, 1.0, 5))
    out, expected = np.zeros(5), np.zeros(5)
    assert call((floats,), floats, 2.0, out) == _weighted_sum(floats, 2.0, expected)
    assert np.array_equal(out, expected)
    floats.a[:] += 1.0  # the same record, written in place: the kept entry point reads it
    assert call((floats,), floats, 2.0, out) == _weighted_sum(floats, 2.0, expected)
    integers = Pair(np.arange(5, dtype=np.int64) * 3, np.arange(5, dtype=np.int32))  # another record, other types
    assert call((integers,), integers, 0.5, out) == float(np.sum(np.arange(5) * 3 + 0.5 * np.arange(5)))
    assert len(_weighted_sum.overloads) == 2  # one compiled version per record type


def test_a_new_record_of_the_same_kinds_takes_the_kept_entry_point_and_other_layouts_get_their_own(monkeypatch):
    """A fader's move makes the stream's record again, with new arrays of the same kinds: the entry
    point is found by their kinds, without numba's typing (what made a style change's frame dear).
    A record whose arrays differ in layout or writability is typed and compiled for its own."""
    import instrument.synthesis.direct as direct

    call = DirectCall(_weighted_sum)
    out = np.zeros(5)
    first = Pair(np.arange(5.0), np.ones(5))
    assert call((first,), first, 1.0, out) == 15.0
    typed = []
    monkeypatch.setattr(direct, "typeof", lambda value: typed.append(value) or __import__("numba").typeof(value))
    again = Pair(np.arange(5.0) * 2, np.ones(5))  # new arrays, same kinds
    assert call((again,), again, 1.0, out) == 25.0
    assert typed == []  # found by kind, not typed again
    strided = Pair(np.arange(10.0)[::2], np.ones(5))  # a non-contiguous array: numba's layout "A"
    assert call((strided,), strided, 1.0, out) == float(np.arange(10.0)[::2].sum() + 5)
    readonly = np.arange(5.0)
    readonly.flags.writeable = False
    frozen = Pair(readonly, np.ones(5))
    assert call((frozen,), frozen, 1.0, out) == 15.0
    assert len(typed) == 2 * 3  # each new kind typed once (its three arguments)
    assert call((Pair(np.arange(10.0)[::2], np.ones(5)),), Pair(np.arange(10.0)[::2], np.ones(5)), 1.0, out) == 25.0
    assert len(typed) == 6  # the strided kind again: kept
