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

A whole sequence from variances (`mlpg`, what `instrument bench` sets against nnmnkwii) has a
kernel of its own, `_solve_sequence`: the same elimination without the row table and the fixed
frames, its work arrays kept between calls (fresh ones came back from the allocator as fresh
pages). What bound it, measured (docs/mlpg.md): a scalar division takes 1.45 ns here and a
packed one 0.37 ns per value, and the old row loop, scalar, made four per unknown; the compiler
would not vectorise it (it writes 11 arrays and reads 7: too many run-time overlap checks);
where it did vectorise a row, the per-row call with a dozen array arguments and those checks
ate the gain at 66 dimensions; and the loads of the next rows were issued late behind long
chains of dependent arithmetic. So: the three precisions' divisions per unknown in a loop of
their own (`_sequence_precisions`, vectorised), the elimination with one division and no pivot
kept (`_sequence_row`, vectorised), both inlined into the sweep, and both sweeps prefetching
rows a few ahead (`_prefetch`, llvm.prefetch through a numba intrinsic).
"""

from __future__ import annotations

import threading

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.extending import intrinsic

from ..motion.features import WINDOWS

D_PREV, D_NEXT = float(WINDOWS[1][0]), float(WINDOWS[1][2])
A_PREV, A_MID, A_NEXT = (float(v) for v in WINDOWS[2])
assert WINDOWS[1][1] == 0.0 and tuple(WINDOWS[0]) == (0.0, 1.0, 0.0)


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _precision_row(second, k, as_variance, row):  # pragma: no cover - compiled
    for j in range(row.shape[0]):
        row[j] = 1.0 / second[k, j] if as_variance else second[k, j]


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _solve(means, second, rows, as_variance, fixed, count, out, l1, l2):  # pragma: no cover - compiled
    """means and `second` (precisions, or variances when as_variance): (N, R, 3D) tables whose
    rows[n, t] is frame t of window n (rows: (N, M), so a stream reads its model's few state rows
    in place instead of copying a window); fixed: (N, max(F, 1), D) holding F = count known
    frames; out: (N, M - F, D); l1, l2: (M, D) work.

    One forward sweep forms row t of W'PW (from the windows centred on t-1, t and t+1) and
    eliminates it at once (LDL'); one backward sweep substitutes. Precisions and pivots live in
    three-row rolling buffers, so nothing the size of the input is allocated; the branches are
    per frame, so the loop over dimensions is straight-line code the compiler can vectorise.
    """
    n_seq, frames = rows.shape
    width = means.shape[2]
    dim = width // 3
    prec_rows = np.empty((3, width))
    pivots = np.ones((3, dim))
    inverses = np.ones((3, dim))
    last_fixed = max(count - 1, 0)
    for n in range(n_seq):
        z = out[n]  # the forward sweep's values, overwritten by the solution
        mu = means[n]
        row = rows[n]
        _precision_row(second[n], row[max(count - 1, 0)], as_variance, prec_rows[max(count - 1, 0) % 3])
        _precision_row(second[n], row[count], as_variance, prec_rows[count % 3])
        for t in range(count, frames):
            tp, tn, tpp = max(t - 1, 0), min(t + 1, frames - 1), max(t - 2, 0)
            if t + 1 < frames:
                _precision_row(second[n], row[t + 1], as_variance, prec_rows[(t + 1) % 3])
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
            for d in range(dim):
                p0 = prec_rows[rt, d]
                p2_here = prec_rows[rt, 2 * dim + d] * w_here
                p1_prev = prec_rows[rp, dim + d] * w_prev
                p2_prev = prec_rows[rp, 2 * dim + d] * w_prev
                p1_next = prec_rows[rn, dim + d] * w_next
                p2_next = prec_rows[rn, 2 * dim + d] * w_next
                diag = (p0 + D_PREV * D_PREV * p1_next + D_NEXT * D_NEXT * p1_prev
                        + A_PREV * A_PREV * p2_next + A_MID * A_MID * p2_here + A_NEXT * A_NEXT * p2_prev)
                rhs = (p0 * mu[mt, d] + A_MID * p2_here * mu[mt, 2 * dim + d]
                       + D_PREV * p1_next * mu[mn, dim + d] + A_PREV * p2_next * mu[mn, 2 * dim + d]
                       + D_NEXT * p1_prev * mu[mp, dim + d] + A_NEXT * p2_prev * mu[mp, 2 * dim + d])
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
            for d in range(dim):
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
    _solve(means, precisions, rows, as_variance, fixed, count, out, l1, l2)
    return out


@intrinsic
def _prefetch(typingctx, flat, index):  # pragma: no cover - compiled
    """A hint to bring the cache line holding flat[index] into the caches (llvm.prefetch: read,
    keep in all levels); no load, nothing waits for it."""

    def codegen(context, builder, signature, args):
        array = context.make_array(signature.args[0])(context, builder, args[0])
        byte_pointer = ir.IntType(8).as_pointer()
        int32 = ir.IntType(32)
        function = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(ir.VoidType(), [byte_pointer, int32, int32, int32]), "llvm.prefetch.p0i8")
        address = builder.bitcast(builder.gep(array.data, [args[1]]), byte_pointer)
        builder.call(function, [address, int32(0), int32(3), int32(1)])
        return context.get_dummy_value()

    return types.void(flat, index), codegen


PREFETCH_ROWS = 4  # how far ahead (in rows of about 1.5 KB at the shipped model) the sweeps ask for memory


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _prefetch_row(array, row):  # pragma: no cover - compiled
    """Prefetch one row of a C-contiguous 2-D array, one hint per 64-byte line."""
    width = array.shape[1]
    flat = array.reshape(-1)
    for j in range(row * width, (row + 1) * width, 8):
        _prefetch(flat, j)


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def _sequence_precisions(variances, t, dynamic, p0, p1, p2):  # pragma: no cover - compiled
    """Frame t's precisions (1 / variance) for the static, delta and delta-delta windows, the two
    dynamic ones times `dynamic` (0 for windows centred on the first or last frame). A loop of its
    own: with four arrays the compiler vectorises it, and the three divisions per unknown (1.45 ns
    each scalar, 0.37 ns packed, on this machine) were what bound the sweep."""
    dim = p0.shape[0]
    for d in range(dim):
        p0[d] = 1.0 / variances[t, d]
        p1[d] = dynamic / variances[t, dim + d]
        p2[d] = dynamic / variances[t, 2 * dim + d]


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy", inline="always")
def _sequence_row(t, means, before, here, after, inverses1, inverses2, z1, z2, l1_last, l1, l2, y):  # pragma: no cover
    """Row t of the whole-sequence solve, formed and eliminated: before, here, after (3, D) hold the
    precisions of frames t - 1, t, t + 1 (rows: static, delta, delta-delta); inverses1, z1: row
    t - 1's inverse pivot and forward value; inverses2, z2: row t - 2's, overwritten by row t's;
    l1_last: row t - 1's first multiplier, overwritten by row t's. The pivot is eliminated as
    pivot = diag - m1 u1 - m2 a2 (u1 = m1 x pivot of row t - 1, a2 = m2 x pivot of row t - 2), so
    no pivot is kept, only its inverse: the same LDL' factors as `_solve` to rounding."""
    frames = means.shape[0]
    dim = y.shape[1]
    tp, tn = max(t - 1, 0), min(t + 1, frames - 1)
    for d in range(dim):
        p0 = here[0, d]
        p2_here = here[2, d]
        p1_prev = before[1, d]
        p2_prev = before[2, d]
        p1_next = after[1, d]
        p2_next = after[2, d]
        diag = (p0 + D_PREV * D_PREV * p1_next + D_NEXT * D_NEXT * p1_prev
                + A_PREV * A_PREV * p2_next + A_MID * A_MID * p2_here + A_NEXT * A_NEXT * p2_prev)
        rhs = (p0 * means[t, d] + A_MID * p2_here * means[t, 2 * dim + d]
               + D_PREV * p1_next * means[tn, dim + d] + A_PREV * p2_next * means[tn, 2 * dim + d]
               + D_NEXT * p1_prev * means[tp, dim + d] + A_NEXT * p2_prev * means[tp, 2 * dim + d])
        a1 = A_PREV * A_MID * p2_here + A_MID * A_NEXT * p2_prev  # A[t-1, t]
        a2 = D_PREV * D_NEXT * p1_prev + A_PREV * A_NEXT * p2_prev  # A[t-2, t]
        m2 = a2 * inverses2[d]
        u1 = a1 - a2 * l1_last[d]
        m1 = u1 * inverses1[d]
        inverse = 1.0 / (diag - m1 * u1 - m2 * a2)
        z = rhs - m1 * z1[d] - m2 * z2[d]
        inverses2[d] = inverse
        z2[d] = z
        l1_last[d] = m1
        l1[t, d] = m1
        l2[t, d] = m2
        y[t, d] = z * inverse


@njit(cache=True, nogil=True, fastmath=True, error_model="numpy")
def _solve_sequence(means, variances, y, l1, l2):  # pragma: no cover - compiled
    """Whole-sequence MLPG from variances: means, variances (T, 3D), C-contiguous; y (T, D)
    receives the solution; l1, l2 (T, D) work, any content. The same elimination as `_solve` with
    no fixed frames and no row table; every buffer it reads it has written first. Both sweeps ask
    for the rows they will read a few rows ahead (`_prefetch_row`): the loops keep the core busy
    with long chains of dependent arithmetic, so the loads of the next rows were issued late."""
    frames, width = means.shape
    dim = width // 3
    frame_a, frame_b, frame_c = np.zeros((3, dim)), np.zeros((3, dim)), np.zeros((3, dim))
    inverses_a, inverses_b = np.ones(dim), np.ones(dim)
    z_a, z_b = np.zeros(dim), np.zeros(dim)
    l1_last = np.zeros(dim)
    # frame s's precisions live in frame_[abc][s % 3]; frame -1 stays zero; frame 0 has no dynamic ones
    _sequence_precisions(variances, 0, 0.0, frame_a[0], frame_a[1], frame_a[2])
    for t in range(frames):
        if t + PREFETCH_ROWS < frames:
            _prefetch_row(means, t + PREFETCH_ROWS)
            _prefetch_row(variances, t + PREFETCH_ROWS)
        slot = t % 3
        if slot == 0:
            before, here, after = frame_c, frame_a, frame_b
        elif slot == 1:
            before, here, after = frame_a, frame_b, frame_c
        else:
            before, here, after = frame_b, frame_c, frame_a
        dynamic = 1.0 if t + 1 < frames - 1 else 0.0  # windows centred on the last frame have zero precision
        _sequence_precisions(variances, min(t + 1, frames - 1), dynamic, after[0], after[1], after[2])
        if t % 2 == 0:  # row t - 1 in the b buffers; row t - 2 in the a buffers, which row t takes
            _sequence_row(t, means, before, here, after, inverses_b, inverses_a, z_b, z_a, l1_last, l1, l2, y)
        else:
            _sequence_row(t, means, before, here, after, inverses_a, inverses_b, z_a, z_b, l1_last, l1, l2, y)
    if frames >= 2:
        for d in range(dim):
            y[frames - 2, d] -= l1[frames - 1, d] * y[frames - 1, d]
    for t in range(frames - 3, -1, -1):
        if t >= PREFETCH_ROWS:
            _prefetch_row(y, t - PREFETCH_ROWS)
            _prefetch_row(l1, t - PREFETCH_ROWS + 1)
            _prefetch_row(l2, t - PREFETCH_ROWS + 2)
        _substitute_row(y[t], y[t + 1], y[t + 2], l1[t + 1], l2[t + 2])


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
    bytes of its largest solve). Fresh arrays of this size came back from the allocator as fresh
    pages, and faulting them in cost a quarter to a third of the solve."""
    size = 2 * frames * dim
    buffer = getattr(_scratch, "buffer", None)
    if buffer is None or buffer.size < size:
        buffer = _scratch.buffer = np.empty(size)
    work = buffer[:size].reshape(2, frames, dim)
    return work[0], work[1]


def mlpg(means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """Static trajectories (T, D) from means and variances (T, 3D) of [o, delta o, delta-delta o]."""
    means = np.ascontiguousarray(means, dtype=np.float64)
    variances = np.ascontiguousarray(variances, dtype=np.float64)
    frames, width = means.shape
    out = np.empty((frames, width // 3))
    if frames == 0:  # the kernel reads frame 0 unchecked
        return out
    _solve_sequence(means, variances, out, *_work(frames, width // 3))
    return out
