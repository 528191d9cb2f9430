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
