"""The whole-sequence MLPG kernel against a dense solve, against the windowed kernel (`_solve`,
which streaming uses), and under repeated and concurrent calls (its work arrays are kept)."""

import os
import threading
import time

import numpy as np
import pytest

from instrument.models.modelfile import default_model_path, load_model
from instrument.motion.features import WINDOWS
from instrument.synthesis.interpolation import interpolate, style_space
from instrument.synthesis.mlpg import mlpg, mlpg_continued
from instrument.synthesis.stream import Controls, Crowd
from walks import tune


def dense_mlpg(means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """c = (W'PW)^-1 W'P mu with W built row by row from the windows (zero precision for dynamic
    windows that reach past either end), solved densely: the definition, not an algorithm."""
    frames, width = means.shape
    dim = width // 3
    out = np.empty((frames, dim))
    for d in range(dim):
        rows, weights, targets = [], [], []
        for k, window in enumerate(WINDOWS):
            for t in range(frames):
                row = np.zeros(frames)
                inside = True
                for offset, coefficient in zip((-1, 0, 1), window):
                    if coefficient != 0.0:
                        if not 0 <= t + offset < frames:
                            inside = False
                        else:
                            row[t + offset] = coefficient
                rows.append(row)
                weights.append(1.0 / variances[t, k * dim + d] if inside or k == 0 else 0.0)
                targets.append(means[t, k * dim + d])
        w, p, mu = np.array(rows), np.array(weights), np.array(targets)
        out[:, d] = np.linalg.solve(w.T @ (p[:, None] * w), w.T @ (p * mu))
    return out


def random_input(frames: int, dim: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(size=(frames, 3 * dim)), rng.uniform(0.01, 3.0, size=(frames, 3 * dim))


def windowed_kernel(means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """The solve `mlpg` used before it had a kernel of its own (and streaming still uses)."""
    return mlpg_continued(means[None], variances[None], np.zeros((1, 0, means.shape[1] // 3)), as_variance=True)[0]


@pytest.mark.parametrize("frames", [1, 2, 3, 4, 5, 6, 9, 40])
def test_mlpg_equals_the_dense_solve(frames):
    means, variances = random_input(frames, 5, frames)
    expected = dense_mlpg(means, variances)
    np.testing.assert_allclose(mlpg(means, variances), expected, rtol=0, atol=1e-10 * np.abs(expected).max())


@pytest.fixture(scope="module")
def model_input():
    """A 3,000-frame state plan of the shipped model with all styles mixed, as `instrument bench` builds."""
    model = load_model(default_model_path())
    space = style_space(model)
    controls = Controls(np.full(len(model.style_names), 1.5 / len(model.style_names)))
    planner = Crowd(space)
    tune(planner, [controls])
    ids = planner.state_plan(3000)
    lam = interpolate(space, controls.weights)
    return lam.means[ids], 1.0 / lam.precisions[ids]


def test_mlpg_equals_the_windowed_kernel_on_the_shipped_model(model_input):
    means, variances = model_input
    before = windowed_kernel(means, variances)
    now = mlpg(means, variances)
    scale = np.abs(before).max(axis=0)  # per dimension: features differ in size by orders of magnitude
    assert np.all(np.abs(now - before) <= 1e-10 * scale)


def test_mlpg_equals_the_windowed_kernel_on_random_input():
    for frames, dim in ((2, 1), (7, 3), (500, 66)):
        means, variances = random_input(frames, dim, frames * dim)
        before = windowed_kernel(means, variances)
        np.testing.assert_allclose(mlpg(means, variances), before, rtol=0, atol=1e-10 * np.abs(before).max())


def test_mlpg_equals_the_windowed_kernel_on_variances_of_many_sizes():
    """The sequence kernel keeps no pivots, only their inverses (pivot = diag - m1 u1 - m2 a2): on
    variances spread over eight orders of magnitude it still agrees with the windowed kernel,
    which keeps both, per dimension."""
    rng = np.random.default_rng(8)
    for frames, dim in ((300, 7), (1000, 67)):
        means = rng.normal(size=(frames, 3 * dim)) * 10.0 ** rng.uniform(-3, 3, size=3 * dim)
        variances = 10.0 ** rng.uniform(-4, 4, size=(frames, 3 * dim))
        before = windowed_kernel(means, variances)
        scale = np.abs(before).max(axis=0)
        assert np.all(np.abs(mlpg(means, variances) - before) <= 1e-10 * scale)


def test_kept_work_arrays_leave_no_trace_between_calls_of_other_sizes():
    inputs = [random_input(frames, dim, frames + dim) for frames, dim in ((800, 9), (30, 9), (30, 4), (1200, 2), (3, 9))]
    first = [mlpg(m, v) for m, v in inputs]
    again = [mlpg(m, v) for m, v in reversed(inputs)][::-1]
    for a, b, (m, v) in zip(first, again, inputs):
        np.testing.assert_array_equal(a, b)
        expected = windowed_kernel(m, v)
        np.testing.assert_allclose(a, expected, rtol=0, atol=1e-10 * np.abs(expected).max())


def test_threads_solving_at_once_each_get_their_own_answer():
    inputs = [random_input(2000 + 100 * k, 12, k) for k in range(4)]
    expected = [mlpg(m, v) for m, v in inputs]
    results: dict[int, list[np.ndarray]] = {k: [] for k in range(len(inputs))}
    start = threading.Barrier(len(inputs))

    def solve(k: int) -> None:
        start.wait()
        for _ in range(20):
            results[k].append(mlpg(*inputs[k]))

    threads = [threading.Thread(target=solve, args=(k,)) for k in range(len(inputs))]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for k, runs in results.items():
        assert len(runs) == 20
        for run in runs:
            np.testing.assert_array_equal(run, expected[k])


def test_mlpg_takes_any_float_layout():
    means, variances = random_input(60, 4, 3)
    expected = mlpg(means, variances)
    np.testing.assert_array_equal(mlpg(np.asfortranarray(means), np.asfortranarray(variances)), expected)
    np.testing.assert_array_equal(mlpg(means[:, ::-1][:, ::-1], variances), expected)
    np.testing.assert_array_equal(mlpg(means.tolist(), variances.tolist()), expected)


def test_bench_names_the_machine_its_figures_came_from():
    from instrument.cli.benchmarks import machine

    figures = machine()
    assert figures["cores"] == os.cpu_count()
    with open("/proc/cpuinfo", encoding="utf-8") as info:
        models = {line.split(":", 1)[1].strip() for line in info if line.startswith("model name")}
    assert figures["cpu"] in models
    assert figures["load_1min"] >= 0


def test_bench_sets_each_figure_against_the_yardstick_of_the_same_turn(monkeypatch):
    """A shared machine's speed moves within seconds (a window solve 27 us, then 44, then 27 in one
    process): each figure is divided by the yardstick timed in the same turn. Here the machine is a
    clock whose speed changes from turn to turn (1x to 2x) and a work costs twice the yardstick
    (another half of it): the ratios are exactly 2 and 0.5 whatever the speeds."""
    from instrument.cli import benchmarks

    now, speed = [0.0], [1.0]
    speeds = iter(np.random.default_rng(3).uniform(1.0, 2.0, 100))
    monkeypatch.setattr(benchmarks.time, "perf_counter", lambda: now[0])

    def costing(units):
        def work():
            now[0] += units * speed[0]
        return work

    def yardstick():  # the last of a turn: the machine's speed changes after it
        now[0] += speed[0]
        speed[0] = next(speeds)

    seconds, ratios, solve = benchmarks.against_yardstick({"double": costing(2.0), "half": costing(0.5)}, yardstick, 15)
    assert ratios == pytest.approx({"double": 2.0, "half": 0.5}, rel=1e-12)
    assert 1.0 < solve < 2.0 and seconds["double"] > seconds["half"]
    _, speedups = benchmarks.turn_about([costing(8.0), yardstick], 15)  # MLPG's: how many times faster than the last
    assert speedups == pytest.approx([0.125, 1.0], rel=1e-12)


def test_mlpg_keeps_variances_whose_product_leaves_the_doubles():
    """The kernel takes a frame's three precisions from one division, 1 / (v0 v1 v2); where that
    product would overflow or underflow (variances beyond 1e100 or below 1e-100) it divides one by
    one: the answer agrees with the windowed kernel, which always does."""
    rng = np.random.default_rng(11)
    frames, dim = 200, 9
    means = rng.normal(size=(frames, 3 * dim))
    variances = rng.uniform(0.5, 2.0, size=(frames, 3 * dim))
    variances[50:60] = 1e-110  # v0 v1 v2 underflows
    variances[120:130, dim:] = 1e160  # v0 v1 v2 overflows
    variances[170, [3, dim + 3, 2 * dim + 3]] = 1e-200
    before = windowed_kernel(means, variances)
    now = mlpg(means, variances)
    assert np.all(np.isfinite(now))
    scale = np.abs(before).max(axis=0)
    assert np.all(np.abs(now - before) <= 1e-10 * scale)


def test_a_solve_shared_among_threads_equals_one_solved_alone(model_input):
    means, variances = model_input
    alone = mlpg(means, variances, threads=1)
    scale = np.abs(alone).max(axis=0)
    for threads in (2, 3, 5, 100):
        shared = mlpg(means, variances, threads=threads)
        assert np.all(np.abs(shared - alone) <= 1e-12 * scale), threads


def test_empty_inputs_give_empty_trajectories():
    assert mlpg(np.zeros((0, 6)), np.ones((0, 6))).shape == (0, 2)
    assert mlpg(np.zeros((5, 0)), np.ones((5, 0))).shape == (5, 0)


@pytest.mark.parametrize("loadavg, cores, free", [
    ("0.31 0.52 0.70 1/140 9999\n", 2, 2),  # only the caller runs: both cores free
    ("4.10 4.52 4.71 3/140 9999\n", 2, 1),  # two other threads want the cores: none to share with
    ("1.90 1.20 0.90 2/140 9999\n", 4, 3),
    ("garbled", 2, 2),  # unreadable: every core, as before
])
def test_a_long_solve_is_shared_only_with_cores_no_other_thread_wants(monkeypatch, loadavg, cores, free):
    """On a shared machine a part handed to a busy core waits for another program's time slice,
    and the caller for it: `mlpg` shares a long solve among the free cores only (the count of
    runnable threads in /proc/loadavg, which the calling thread is one of)."""
    import io

    from instrument.synthesis import mlpg as module

    monkeypatch.setattr(module, "_cores", lambda: cores)
    monkeypatch.setattr(module, "open", lambda path, *a, **k: io.StringIO(loadavg), raising=False)
    assert module._free_cores() == free
    assert module.mlpg_threads(8 * cores, 100_000) == free
    assert module.mlpg_threads(8 * cores, 10) == 1  # a short solve is never shared


def test_parts_cover_every_dimension_once_on_line_bounds():
    from instrument.synthesis.mlpg import _parts

    for dim in (1, 7, 8, 9, 33, 66, 67, 200):
        for threads in (1, 2, 3, 4, 16):
            parts = _parts(dim, threads)
            assert parts[0][0] == 0 and parts[-1][1] == dim
            assert all(hi == lo for (_, hi), (lo, _) in zip(parts, parts[1:]))
            assert all(lo % 8 == 0 and hi > lo for lo, hi in parts)
            assert len(parts) <= max(1, threads)


def test_a_part_no_helper_takes_is_solved_by_the_caller(model_input):
    """With every helper thread busy, the caller does not wait for one: it takes the waiting part
    back and solves it itself (as after a fork, where the pool's threads are gone)."""
    from instrument.synthesis.mlpg import _cores, _pool

    means, variances = model_input
    alone = mlpg(means, variances, threads=1)
    release = threading.Event()
    blockers = [_pool().submit(release.wait, 60) for _ in range(max(_cores() - 1, 1))]
    try:
        shared = mlpg(means, variances, threads=2)
        assert not any(b.done() for b in blockers)  # the helpers were busy throughout
    finally:
        release.set()
    scale = np.abs(alone).max(axis=0)
    assert np.all(np.abs(shared - alone) <= 1e-12 * scale)


def test_shared_solves_of_every_length_equal_the_windowed_kernel():
    """Short sequences end inside the six-row unrolled sweep at every offset; a second part starts
    at a dimension other than 0 and is not a multiple of the vector width long."""
    for frames in range(1, 14):
        means, variances = random_input(frames, 17, frames)
        expected = windowed_kernel(means, variances)
        scale = np.abs(expected).max(axis=0)
        for threads in (1, 2):
            assert np.all(np.abs(mlpg(means, variances, threads=threads) - expected) <= 1e-10 * scale), (frames, threads)


@pytest.mark.filterwarnings("ignore::DeprecationWarning")  # Python 3.12 warns of forking with threads running
def test_a_forked_child_solves_with_threads_of_its_own(model_input):
    """A fork takes none of the pool's threads along: the child makes its own, and its shared
    solves finish with the right answer (the parent used the pool before forking)."""
    means, variances = model_input
    expected = mlpg(means, variances, threads=2)
    child = os.fork()
    if child == 0:  # pragma: no cover - runs in the child
        try:
            ok = all(np.array_equal(mlpg(means, variances, threads=2), expected) for _ in range(3))
            from instrument.synthesis.mlpg import _pool

            # nothing handed over is left behind: a part the caller took back (its helper not yet
            # run, on a busy machine) leaves the queue when a helper of the child's own comes to
            # it; a pool whose threads stayed in the parent would keep it for ever
            deadline = time.monotonic() + 60
            while _pool()._work_queue.qsize() and time.monotonic() < deadline:
                time.sleep(0.01)
            ok = ok and _pool()._work_queue.qsize() == 0
        finally:
            os._exit(0 if ok else 1)
    _, status = os.waitpid(child, 0)
    assert os.waitstatus_to_exitcode(status) == 0


def test_mlpg_names_inputs_of_the_wrong_shape():
    with pytest.raises(ValueError, match=r"\(T, 3D\), not \(5, 6\) and \(4, 6\)"):
        mlpg(np.zeros((5, 6)), np.ones((4, 6)))
    with pytest.raises(ValueError, match="not \\(5, 7\\)"):
        mlpg(np.zeros((5, 7)), np.ones((5, 7)))
