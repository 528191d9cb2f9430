"""Maximum-likelihood parameter generation (Tokuda 2000), with a banded solver compiled by numba.

For each static dimension, c = (W' P W)^-1 W' P mu, where W stacks the static, delta and
delta-delta windows (each reaching one frame either side). W' P W is symmetric pentadiagonal,
so an LDL' factorisation solves it in O(T). The bands are formed on the fly inside the same
sweep over time, all dimensions at once, so nothing of size T x D x 3 is built in between. At
the edges of a sequence the delta and delta-delta precisions are zero, as in HTS and nnmnkwii.

LAPACK's banded Cholesky (dpbsv) pays two BLAS calls per unknown and is 3 times slower than
nnmnkwii here; numpy cannot run a recurrence over time without a Python loop. numba compiles
this one loop, which is why it is a dependency.

The same routine (`_solve`) continues a trajectory: frames already sent enter as fixed values,
and only the frames after them are solved for, so a streamed walk has no jump where windows meet.

A whole sequence from variances (`mlpg`, what `instrument bench` sets against nnmnkwii and
`synth --method full` solves) has a kernel of its own, `_solve_sequence`: the same elimination
without the row table and the fixed frames, its work arrays kept between calls (fresh ones came
back from the allocator as fresh pages), its dimensions shared among the cores (each thread a
range of them). How it was made fast, each step measured (docs/mlpg.md): the frame's precisions
in a loop of their own from one division (`_sequence_precisions`) and the elimination with one
division and no pivot kept (`_sequence_row`), both vectorised and inlined; rows taken as views
that own nothing (`_part`) and the forward sweep unrolled so the ring rows it uses are
constants, which spares the compiler's run-time overlap checks; the back substitution's row
index hidden from the compiler (`_opaque`), whose one overlap check for the whole sweep always
failed; and both sweeps asking for their rows ahead of time (`_prefetch`, llvm.prefetch through
a numba intrinsic), since the loads of the next rows were issued late behind long chains of
dependent arithmetic.
"""

from __future__ import annotations

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic
from numba.np.arrayobj import populate_array

from ..motion.features import WINDOWS

D_PREV, D_NEXT = float(WINDOWS[1][0]), float(WINDOWS[1][2])
A_PREV, A_MID, A_NEXT = (float(v) for v in WINDOWS[2])
# the whole-sequence kernel's rows are written out for these windows (the windowed one takes any
# delta and delta-delta windows reaching one frame either side)
assert tuple(WINDOWS[0]) == (0.0, 1.0, 0.0) and tuple(WINDOWS[1]) == (-0.5, 0.0, 0.5) and tuple(WINDOWS[2]) == (1.0, -2.0, 1.0)


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _precision_row(second, k, as_variance, rows, r, lo, solved):  # pragma: no cover - compiled
    """Table row k's precisions of the dimensions lo to lo + solved into row r of `rows`, each
    window's side by side (views of the rows: `_solve`'s means say why)."""
    dim = second.shape[1] // 3
    for w in range(3):
        source, target = _part(second, k, w * dim + lo, solved), _part(rows, r, w * solved, solved)
        for j in range(solved):
            target[j] = 1.0 / source[j] if as_variance else source[j]


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _solve(means, second, rows, as_variance, fixed, count, out, l1, l2, lo):  # pragma: no cover - compiled
    """means and `second` (precisions, or variances when as_variance): (N, R, 3D) tables whose
    rows[n, t] is frame t of window n (rows: (N, M), so a stream reads its model's few state rows
    in place instead of copying a window); fixed: (N, max(F, 1), D) holding F = count known
    frames; out: (N, M - F, D); l1, l2: (M, D) work. lo: the first of the D static dimensions solved
    (the tables may hold more: a gesture's stream solves only the upper body's, synthesis/gestures.py).

    One forward sweep forms row t of W'PW (from the windows centred on t-1, t and t+1) and
    eliminates it at once (LDL'); one backward sweep substitutes. Precisions and pivots live in
    three-row rolling buffers, so nothing the size of the input is allocated; the branches are
    per frame, so the loop over dimensions is straight-line code the compiler can vectorise.
    """
    n_seq, frames = rows.shape
    width = means.shape[2]
    dim = width // 3  # the tables'
    solved = out.shape[2]  # the dimensions solved: lo to lo + solved
    prec_rows = np.empty((3, 3 * solved))
    pivots = np.ones((3, solved))
    inverses = np.ones((3, solved))
    last_fixed = max(count - 1, 0)
    for n in range(n_seq):
        z = out[n]  # the forward sweep's values, overwritten by the solution
        mu = means[n]
        row = rows[n]
        # the ring's first rows, then one ahead a frame
        _precision_row(second[n], row[max(count - 1, 0)], as_variance, prec_rows, max(count - 1, 0) % 3, lo, solved)
        _precision_row(second[n], row[count], as_variance, prec_rows, count % 3, lo, solved)
        for t in range(count, frames):
            tp, tn, tpp = max(t - 1, 0), min(t + 1, frames - 1), max(t - 2, 0)
            if t + 1 < frames:
                _precision_row(second[n], row[t + 1], as_variance, prec_rows, (t + 1) % 3, lo, solved)
            # dynamic windows centred on the first or last frame have zero precision
            w_here = 1.0 if 0 < t < frames - 1 else 0.0
            w_prev = 1.0 if 0 < t - 1 else 0.0
            w_next = 1.0 if t + 1 < frames - 1 else 0.0
            # couplings to unknown frames stay in the matrix; to known frames they move to the rhs
            unknown1 = 1.0 if t - 1 >= count else 0.0
            unknown2 = 1.0 if t - 2 >= count else 0.0
            known1 = 1.0 if (t >= 1 and t - 1 < count) else 0.0
            known2 = 1.0 if (t >= 2 and t - 2 < count) else 0.0
            fp, fpp = min(tp, last_fixed), min(tpp, last_fixed)
            rt, rp, rn = t % 3, tp % 3, tn % 3  # rows of the rolling precision buffer
            qt, qp, qpp = t % 3, tp % 3, tpp % 3  # rows of the rolling pivot buffers
            zt, zp, zpp = t - count, max(tp - count, 0), max(tpp - count, 0)
            mt, mp, mn = row[t], row[tp], row[tn]  # the table rows of frames t, t - 1, t + 1
            # their means of the dimensions solved, as views (an offset index `lo + d` of unknown sign
            # kept the loop below from being vectorised: a gesture's solve of 36 of 66 dimensions cost a full one)
            mu0_t, mu2_t = _part(mu, mt, lo, solved), _part(mu, mt, 2 * dim + lo, solved)
            mu1_n, mu2_n = _part(mu, mn, dim + lo, solved), _part(mu, mn, 2 * dim + lo, solved)
            mu1_p, mu2_p = _part(mu, mp, dim + lo, solved), _part(mu, mp, 2 * dim + lo, solved)
            for d in range(solved):
                p0 = prec_rows[rt, d]
                p2_here = prec_rows[rt, 2 * solved + d] * w_here
                p1_prev = prec_rows[rp, solved + d] * w_prev
                p2_prev = prec_rows[rp, 2 * solved + d] * w_prev
                p1_next = prec_rows[rn, solved + d] * w_next
                p2_next = prec_rows[rn, 2 * solved + d] * w_next
                diag = (p0 + D_PREV * D_PREV * p1_next + D_NEXT * D_NEXT * p1_prev
                        + A_PREV * A_PREV * p2_next + A_MID * A_MID * p2_here + A_NEXT * A_NEXT * p2_prev)
                rhs = (p0 * mu0_t[d] + A_MID * p2_here * mu2_t[d]
                       + D_PREV * p1_next * mu1_n[d] + A_PREV * p2_next * mu2_n[d]
                       + D_NEXT * p1_prev * mu1_p[d] + A_NEXT * p2_prev * mu2_p[d])
                a1 = A_PREV * A_MID * p2_here + A_MID * A_NEXT * p2_prev  # A[t-1, t]
                a2 = D_PREV * D_NEXT * p1_prev + A_PREV * A_NEXT * p2_prev  # A[t-2, t]
                rhs -= known1 * a1 * fixed[n, fp, d] + known2 * a2 * fixed[n, fpp, d]
                a1 *= unknown1
                a2 *= unknown2
                m2 = a2 * inverses[qpp, d]
                m1 = (a1 - m2 * pivots[qpp, d] * l1[tp, d]) * inverses[qp, d]
                pivot = diag - m1 * m1 * pivots[qp, d] - m2 * m2 * pivots[qpp, d]
                inverse = 1.0 / pivot
                # forward substitution, kept as y = z / pivot (z of earlier rows is y * pivot)
                y = (rhs - m1 * pivots[qp, d] * z[zp, d] - m2 * pivots[qpp, d] * z[zpp, d]) * inverse
                pivots[qt, d] = pivot
                inverses[qt, d] = inverse
                l1[t, d] = m1
                l2[t, d] = m2
                z[zt, d] = y
        for t in range(frames - 1, count - 1, -1):
            has1 = 1.0 if t + 1 < frames else 0.0
            has2 = 1.0 if t + 2 < frames else 0.0
            z1, z2 = min(t + 1, frames - 1) - count, min(t + 2, frames - 1) - count
            r1, r2 = min(t + 1, frames - 1), min(t + 2, frames - 1)
            for d in range(solved):
                z[t - count, d] = z[t - count, d] - has1 * l1[r1, d] * z[z1, d] - has2 * l2[r2, d] * z[z2, d]


def mlpg_continued(means: np.ndarray, precisions: np.ndarray, fixed: np.ndarray, as_variance: bool = False) -> np.ndarray:
    """Static frames for batches of windows: means, precisions (N, M, 3D), fixed (N, F, D).

    The first F frames of each window are known (F = 0 for a whole sequence, 2 to continue a
    stream: windows reach one frame back, so two fixed frames pin the join). Returns the other
    M - F frames, (N, M - F, D). With as_variance, `precisions` holds variances instead.
    """
    means = np.ascontiguousarray(means, dtype=np.float64)
    precisions = np.ascontiguousarray(precisions, dtype=np.float64)
    sequences, frames, width = means.shape
    count = fixed.shape[1]
    if count == 0:  # the kernel reads a fixed row even when it is multiplied by zero
        fixed = np.zeros((sequences, 1, width // 3))
    fixed = np.ascontiguousarray(fixed, dtype=np.float64)
    out = np.zeros((sequences, frames - count, width // 3))
    # work arrays come from numpy, whose allocator reuses memory: fresh pages cost more than the solve
    l1 = np.zeros((frames, width // 3))
    l2 = np.zeros((frames, width // 3))
    rows = np.broadcast_to(np.arange(frames), (sequences, frames))
    _solve(means, precisions, rows, as_variance, fixed, count, out, l1, l2, 0)
    return out


@intrinsic
def _prefetch(typingctx, array, index):  # pragma: no cover - compiled
    """A hint to bring the cache line holding element `index` of `array`, counted in C order from
    its start, into the caches (llvm.prefetch: read, keep in all levels); no load, nothing waits."""

    def codegen(context, builder, signature, args):
        source = context.make_array(signature.args[0])(context, builder, args[0])
        byte_pointer = ir.IntType(8).as_pointer()
        int32 = ir.IntType(32)
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [byte_pointer, int32, int32, int32]), "llvm.prefetch.p0i8")
        address = builder.bitcast(builder.gep(source.data, [args[1]]), byte_pointer)
        builder.call(function, [address, int32(0), int32(3), int32(1)])
        return context.get_dummy_value()

    return types.void(array, index), codegen


@intrinsic
def _part(typingctx, array, row, start, length):  # pragma: no cover - compiled
    """array[row, start:start + length] of a C-contiguous 2-D array, as a 1-D array that owns
    nothing. The sweeps take some twenty views a row; numba's slices normalise their bounds and
    are reference-counted with atomic operations (a sixth of the samples sat on those, though
    removing them alone gained nothing); these are an address and a length, so with the ring rows
    constant (the unrolled sweep) the compiler can tell them apart. The caller holds `array` for
    as long as the view lives, and the bounds are the caller's."""
    result = types.Array(array.dtype, 1, "C")

    def codegen(context, builder, signature, args):
        source = context.make_array(signature.args[0])(context, builder, args[0])
        view = context.make_array(result)(context, builder)
        row, start, length = (context.cast(builder, value, kind, types.intp) for value, kind in zip(args[1:], signature.args[1:]))
        first = builder.add(builder.mul(row, builder.extract_value(source.shape, 1)), start)
        itemsize = context.get_constant(types.intp, context.get_abi_sizeof(context.get_data_type(array.dtype)))
        populate_array(view, data=builder.gep(source.data, [first]), shape=[length], strides=[itemsize],
                       itemsize=itemsize, meminfo=None)
        return view._getvalue()

    return result(array, row, start, length), codegen


@intrinsic
def _opaque(typingctx, value):  # pragma: no cover - compiled
    """`value`, through an empty inline assembly block, so the compiler cannot see how it was
    computed. The back substitution's row index goes through it: seeing rows t, t + 1, t + 2 of
    one array, the compiler otherwise checks the whole range the loop over t sweeps for overlap,
    once, before it, finds that the rows read and the rows written overlap (they are the same
    recurrence), and runs every row scalar; rows it cannot relate to t it checks row by row, and
    those checks pass (docs/mlpg.md, round 4, has the figures)."""

    def codegen(context, builder, signature, args):
        kind = context.get_value_type(signature.args[0])
        return builder.asm(ir.FunctionType(kind, [kind]), "", "=r,0", [args[0]], side_effect=False)

    return value(value), codegen


# How far ahead the forward sweep asks for its input rows, and how far behind the back
# substitution asks for its work rows: the best distances measured (docs/mlpg.md, round 4).
PREFETCH_AHEAD, PREFETCH_BEHIND = 12, 4
SAFE_PRODUCT = (1e-300, 1e300)  # where 1 / (v0 v1 v2) and the precisions taken from it keep full precision


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def _prefetch_row(array, row, start, length):  # pragma: no cover - compiled
    """Prefetch array[row, start:start + length] of a C-contiguous 2-D array, one hint per 64-byte
    line. The hint takes the array's flat index: a reshape to 1-D here would call into numba's
    helpers for every row."""
    first = row * array.shape[1] + start
    for j in range(first, first + length, 8):
        _prefetch(array, j)
    _prefetch(array, first + length - 1)  # the last line, where the range does not start on one


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def _sequence_precisions(v0, v1, v2, dynamic, p0, p1, p2):  # pragma: no cover - compiled
    """One frame's precisions (1 / variance) for the static, delta and delta-delta windows, the
    two dynamic ones times `dynamic` (0 for windows centred on the first or last frame) and the
    delta one also times D_PREV ** 2 (as every row uses it, `_sequence_row`), from one
    division per dimension: r = 1 / (v0 v1 v2), p0 = v1 v2 r, ... Divisions bound this loop (a
    packed one takes as long as a dozen multiplications; docs/mlpg.md has the figures).
    For variances within 1e-100..1e100 each this is exact to rounding; a frame whose product
    leaves 1e-300..1e300 is divided one by one, as before."""
    outside = 0  # counted, not min/max: a running min and max is slower (docs/mlpg.md)
    for d in range(p0.shape[0]):
        v12 = v1[d] * v2[d]
        product = v0[d] * v12
        outside += (product < SAFE_PRODUCT[0]) | (product > SAFE_PRODUCT[1])
        r = 1.0 / product
        p0[d] = v12 * r
        r *= v0[d] * dynamic
        p1[d] = D_PREV * D_PREV * v2[d] * r
        p2[d] = v1[d] * r
    if outside:
        for d in range(p0.shape[0]):
            p0[d] = 1.0 / v0[d]
            p1[d] = D_PREV * D_PREV * dynamic / v1[d]
            p2[d] = dynamic / v2[d]


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def _sequence_row(mu0, mu2, mu1_prev, mu2_prev, mu1_next, mu2_next, p0_here, p2_here, p1_prev, p2_prev, p1_next, p2_next,
                  inverses1, inverses2, z1, z2, l1_last, l1, l2, y):  # pragma: no cover
    """One row t of the whole-sequence solve, formed and eliminated: mu*, p*: the means and
    precisions of the frames t - 1 (prev), t (here: 0 static, 2 delta-delta) and t + 1 (next);
    inverses1, z1: row t - 1's inverse pivot and forward value; inverses2, z2: row t - 2's,
    overwritten by row t's; l1_last: row t - 1's first multiplier, overwritten by row t's; l1, l2,
    y: row t of the multipliers and the forward values. The pivot is eliminated as
    pivot = diag - m1 u1 - m2 a2 (u1 = m1 x pivot of row t - 1, a2 = m2 x pivot of row t - 2), so
    no pivot is kept, only its inverse: the same LDL' factors as `_solve` to rounding."""
    for d in range(y.shape[0]):
        p2h, p2p, p2n = p2_here[d], p2_prev[d], p2_next[d]
        q1p, q1n = p1_prev[d], p1_next[d]  # delta precisions times D_PREV ** 2 (`_sequence_precisions`)
        diag = p0_here[d] + (q1n + q1p) + (p2n + p2p) + 4.0 * p2h
        rhs = (p0_here[d] * mu0[d] + p2n * mu2_next[d] + p2p * mu2_prev[d]
               + 2.0 * (q1p * mu1_prev[d] - q1n * mu1_next[d] - p2h * mu2[d]))
        a1 = -2.0 * (p2h + p2p)  # A[t-1, t]
        a2 = p2p - q1p  # A[t-2, t]
        m2 = a2 * inverses2[d]
        u1 = a1 - a2 * l1_last[d]
        m1 = u1 * inverses1[d]
        inverse = 1.0 / (diag - m1 * u1 - m2 * a2)
        z = rhs - m1 * z1[d] - m2 * z2[d]
        inverses2[d] = inverse
        z2[d] = z
        l1_last[d] = m1
        l1[d] = m1
        l2[d] = m2
        y[d] = z * inverse


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def _sequence_step(t, lo, means, variances, precisions, inverses, forward, l1_last, l1, l2, y,
                   here, before, after, parity):  # pragma: no cover - compiled
    """Row t of the forward sweep: frame t + 1's precisions into rows `after` of `precisions`,
    then row t formed from frames t - 1, t, t + 1 (rows `before`, `here`, `after`) and
    eliminated, row t - 1's inverse pivot and forward value read from row 1 - parity of
    `inverses` and `forward`, row t - 2's replaced by row t's in row `parity`."""
    frames, dim, n = y.shape[0], means.shape[1] // 3, l1.shape[1]
    if t + PREFETCH_AHEAD < frames:
        for start in (lo, dim + lo, 2 * dim + lo):
            _prefetch_row(means, t + PREFETCH_AHEAD, start, n)
            _prefetch_row(variances, t + PREFETCH_AHEAD, start, n)
    dynamic = 1.0 if t + 1 < frames - 1 else 0.0  # windows centred on the last frame have zero precision
    tn, tp = min(t + 1, frames - 1), max(t - 1, 0)
    _sequence_precisions(_part(variances, tn, lo, n), _part(variances, tn, dim + lo, n),
                         _part(variances, tn, 2 * dim + lo, n), dynamic,
                         _part(precisions, after, 0, n), _part(precisions, after + 1, 0, n), _part(precisions, after + 2, 0, n))
    _sequence_row(_part(means, t, lo, n), _part(means, t, 2 * dim + lo, n),
                  _part(means, tp, dim + lo, n), _part(means, tp, 2 * dim + lo, n),
                  _part(means, tn, dim + lo, n), _part(means, tn, 2 * dim + lo, n),
                  _part(precisions, here, 0, n), _part(precisions, here + 2, 0, n),
                  _part(precisions, before + 1, 0, n), _part(precisions, before + 2, 0, n),
                  _part(precisions, after + 1, 0, n), _part(precisions, after + 2, 0, n),
                  _part(inverses, 1 - parity, 0, n), _part(inverses, parity, 0, n),
                  _part(forward, 1 - parity, 0, n), _part(forward, parity, 0, n),
                  l1_last, _part(l1, t, 0, n), _part(l2, t, 0, n), _part(y, t, lo, n))


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _solve_sequence(means, variances, y, l1, l2, lo):  # pragma: no cover - compiled
    """Whole-sequence MLPG from variances for the dimensions [lo, lo + n): means, variances
    (T, 3D), C-contiguous; y (T, D) receives the solution in those columns; l1, l2 (T, n) work,
    any content. The same elimination as `_solve` with no fixed frames and no row table; every
    buffer it reads it has written first.

    The forward sweep is unrolled six rows at a time (frames in a three-row ring, pivots in a
    two-row one): the rows of the rings each step uses are constants, so the compiler can tell
    them apart without checks at run time (1.06-1.13 x). Both sweeps ask for the rows they will
    read a few rows ahead (`_prefetch_row`): the loops keep the core busy with long chains of
    dependent arithmetic, so the loads of the next rows were issued late."""
    frames, width = means.shape
    dim, n = width // 3, l1.shape[1]
    precisions = np.zeros((9, n))  # frame s's in rows 3 (s % 3) + window (static, delta, delta-delta)
    inverses, forward = np.ones((2, n)), np.zeros((2, n))  # inverse pivot and forward value of the last row of each parity
    l1_last = np.zeros(n)
    # frame -1's precisions stay zero; frame 0 has no dynamic ones
    _sequence_precisions(_part(variances, 0, lo, n), _part(variances, 0, dim + lo, n), _part(variances, 0, 2 * dim + lo, n), 0.0,
                         _part(precisions, 0, 0, n), _part(precisions, 1, 0, n), _part(precisions, 2, 0, n))
    t = 0
    while t + 6 <= frames:  # ring rows (here, before, after) = 3 (t, t - 1, t + 1) % 3, parity t % 2
        _sequence_step(t, lo, means, variances, precisions, inverses, forward, l1_last, l1, l2, y, 0, 6, 3, 0)
        _sequence_step(t + 1, lo, means, variances, precisions, inverses, forward, l1_last, l1, l2, y, 3, 0, 6, 1)
        _sequence_step(t + 2, lo, means, variances, precisions, inverses, forward, l1_last, l1, l2, y, 6, 3, 0, 0)
        _sequence_step(t + 3, lo, means, variances, precisions, inverses, forward, l1_last, l1, l2, y, 0, 6, 3, 1)
        _sequence_step(t + 4, lo, means, variances, precisions, inverses, forward, l1_last, l1, l2, y, 3, 0, 6, 0)
        _sequence_step(t + 5, lo, means, variances, precisions, inverses, forward, l1_last, l1, l2, y, 6, 3, 0, 1)
        t += 6
    for t in range(t, frames):
        _sequence_step(t, lo, means, variances, precisions, inverses, forward, l1_last, l1, l2, y,
                       3 * (t % 3), 3 * ((t + 2) % 3), 3 * ((t + 1) % 3), t % 2)
    if frames >= 2:
        for d in range(n):
            y[frames - 2, lo + d] -= l1[frames - 1, d] * y[frames - 1, lo + d]
    for t in range(frames - 3, -1, -1):
        if t >= PREFETCH_BEHIND:
            _prefetch_row(y, t - PREFETCH_BEHIND, lo, n)
            _prefetch_row(l1, t - PREFETCH_BEHIND + 1, 0, n)
            _prefetch_row(l2, t - PREFETCH_BEHIND + 2, 0, n)
        row = _opaque(t)
        _substitute_row(_part(y, row, lo, n), _part(y, row + 1, lo, n), _part(y, row + 2, lo, n),
                        _part(l1, row + 1, 0, n), _part(l2, row + 2, 0, n))


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def _substitute_row(x, x1, x2, l1, l2):  # pragma: no cover - compiled
    """x[t] -= l1[t + 1] x[t + 1] + l2[t + 2] x[t + 2], given rows as vectors: indexed as one (T, D)
    array the compiler cannot tell the row written from the rows read, and the loop stays
    scalar (1.6 times slower)."""
    for d in range(x.shape[0]):
        x[d] = x[d] - l1[d] * x1[d] - l2[d] * x2[d]


_scratch = threading.local()  # per thread: the kernels release the GIL, so threads may solve at once


def _work(frames: int, dim: int) -> tuple[np.ndarray, np.ndarray]:
    """Two (frames, dim) work arrays, kept between calls (growing only: each thread keeps 16 x T x D
    bytes of its largest part of a solve). Fresh arrays of this size came back from the allocator
    as fresh pages, and faulting them in cost a quarter to a third of the solve."""
    size = 2 * frames * dim
    buffer = getattr(_scratch, "buffer", None)
    if buffer is None or buffer.size < size:
        buffer = _scratch.buffer = np.empty(size)
    work = buffer[:size].reshape(2, frames, dim)
    return work[0], work[1]


SHARE_FROM = 100_000  # T x D from which a solve is shared among cores (a hand-over costs some 50 us)
PART_ALIGN = 8  # dimensions per 64-byte line: at a dimension count that is a multiple of 8, parts never share a line


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def _parts(dim: int, threads: int) -> list[tuple[int, int]]:
    """[lo, hi) column ranges of about equal size, their bounds on multiples of PART_ALIGN."""
    threads = max(1, min(threads, dim // PART_ALIGN))
    bounds = sorted({0, dim, *(round(dim * k / threads / PART_ALIGN) * PART_ALIGN for k in range(1, threads))})
    return list(zip(bounds[:-1], bounds[1:]))


def _free_cores() -> int:
    """The cores this process may use that no other thread wants right now: on Linux, from the
    count of runnable threads in /proc/loadavg (the calling thread, running, counts itself); all
    of them where that cannot be read."""
    cores = _cores()
    try:
        with open("/proc/loadavg", encoding="ascii") as loadavg:
            runnable = int(loadavg.read().split()[3].split("/")[0])
    except (OSError, ValueError, IndexError):
        return cores
    return max(1, min(cores, cores - runnable + 1))


def mlpg_threads(dim: int, frames: int) -> int:
    """How many threads `mlpg` shares a solve of `frames` x `dim` among by default: the free
    cores at the call. A part handed to a core another program holds waits for that program's
    time slice, and the caller then waits for the part: on the shared 2-core machine a solve
    shared while both cores were busy took twice as long as on one thread (docs/mlpg.md)."""
    return len(_parts(dim, _free_cores() if frames * dim >= SHARE_FROM else 1))


_helpers: list[ThreadPoolExecutor] = []  # made by the first solve that shares, kept for the process
_helpers_made = threading.Lock()
_helper_ids: list[int] = []  # the pool's threads, as the kernel knows them (`helper_thread_ids`)


def _pool() -> ThreadPoolExecutor:
    """Threads for the parts after the first (the caller solves that one): one fewer than the cores."""
    with _helpers_made:
        if not _helpers:
            _helpers.append(ThreadPoolExecutor(max(_cores() - 1, 1), thread_name_prefix="mlpg", initializer=_started))
        return _helpers[0]


def _started() -> None:
    _helper_ids.append(threading.get_native_id())


def helper_thread_ids() -> list[int]:
    """The native ids of the helper threads started so far (a thread is started when work first
    waits for it). A thread made later takes its maker's scheduling; these may need it set
    (`runtime.priority.realtime_scheduling`)."""
    return list(_helper_ids)


def _forget_pool() -> None:
    """In a forked child: the pool's threads did not come along, and a pool that believes it has
    them would keep every part handed to it (taken back, but never removed from its queue)."""
    global _helpers_made
    _helpers.clear()
    _helper_ids.clear()
    _helpers_made = threading.Lock()


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_forget_pool)


def _solve_part(means: np.ndarray, variances: np.ndarray, out: np.ndarray, lo: int, hi: int) -> None:
    _solve_sequence(means, variances, out, *_work(len(means), hi - lo), lo)


def _handed_over(means: np.ndarray, variances: np.ndarray, out: np.ndarray, parts: list[tuple[int, int]]) -> list:
    """The parts given to the pool's threads, or none when it takes no more work (at exit)."""
    try:
        return [_pool().submit(_solve_part, means, variances, out, lo, hi) for lo, hi in parts]
    except RuntimeError:  # the interpreter is shutting down: the caller solves them all
        return []


def mlpg(means: np.ndarray, variances: np.ndarray, threads: int | None = None) -> np.ndarray:
    """Static trajectories (T, D) from means and variances (T, 3D) of [o, delta o, delta-delta o].

    Dimensions are independent: a long sequence is shared among the cores this process may use,
    each thread solving a range of them (`threads` sets how many; 1 keeps it in this thread).
    The answer depends on the sharing only in rounding (which dimensions go through the vector
    loops and which through their scalar remainders changes with the parts)."""
    means = np.ascontiguousarray(means, dtype=np.float64)
    variances = np.ascontiguousarray(variances, dtype=np.float64)
    if means.ndim != 2 or means.shape != variances.shape or means.shape[1] % 3:
        raise ValueError(f"mlpg: means and variances must both be (T, 3D), not {means.shape} and {variances.shape}")
    frames, width = means.shape
    dim = width // 3
    out = np.empty((frames, dim))
    if frames == 0 or dim == 0:  # nothing to solve (and the kernel reads frame 0 unchecked)
        return out
    first, *rest = _parts(dim, mlpg_threads(dim, frames) if threads is None else threads)
    shared = _handed_over(means, variances, out, rest)
    try:
        _solve_part(means, variances, out, *first)
        for (lo, hi), part in zip(rest, shared or [None] * len(rest)):
            if part is None or part.cancel():  # no helper has taken it (all busy, or at exit): solve it here
                _solve_part(means, variances, out, lo, hi)
            else:
                part.result()
    finally:
        for part in shared:  # after a failure: parts not yet started are not started for nothing
            part.cancel()
    return out
