"""Full MLPG, the whole-sequence kernel against the windowed one and nnmnkwii (docs/mlpg.md).

The bench's input (the shipped model, all styles mixed, 10,000 frames) solved four ways, timed
turn about in one process so all see the same load: `mlpg` (the whole-sequence kernel) on one
thread and shared among the cores as it runs by default, the windowed kernel `mlpg` used before
(`mlpg_continued` on variances, no fixed frames: the same call the old `mlpg` made) and nnmnkwii.
Two memory floors are timed in the same turns: one compiled pass reading the means and
variances (what any solve must read), and one that also writes three (T, D) arrays (what the
forward sweep of ours writes). Prints medians of wall and CPU time (the calling thread's: none
for the shared solve) and the median of the per-turn ratios, with the machine and its load.

    python examples/mlpg_speed.py [--turns 31] [--frames 10000]
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from numba import njit

from instrument.cli.benchmarks import _nnmnkwii_mlpg, machine
from instrument.models.modelfile import default_model_path, load_model
from instrument.synthesis.interpolation import interpolate, style_space
from instrument.synthesis.mlpg import mlpg, mlpg_continued
from instrument.synthesis.engine import Engine
from instrument.synthesis.stream import Controls


@njit(nogil=True, fastmath=True, error_model="numpy")
def read_floor(means: np.ndarray, variances: np.ndarray) -> float:
    """One pass reading both inputs, vectorised: the least a solve can cost in memory traffic."""
    total = 0.0
    for t in range(means.shape[0]):
        for j in range(means.shape[1]):
            total += means[t, j] + variances[t, j]
    return total


@njit(nogil=True, fastmath=True, error_model="numpy")
def read_write_floor(means: np.ndarray, variances: np.ndarray, a: np.ndarray, b: np.ndarray, c: np.ndarray) -> None:
    """One pass reading both inputs and writing three (T, D) arrays, as the forward sweep does."""
    dim = a.shape[1]
    for t in range(means.shape[0]):
        for d in range(dim):
            a[t, d] = means[t, d] + variances[t, d] + means[t, dim + d]
            b[t, d] = variances[t, dim + d] + means[t, 2 * dim + d]
            c[t, d] = variances[t, 2 * dim + d]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--turns", type=int, default=31)
    parser.add_argument("--frames", type=int, default=10_000)
    args = parser.parse_args()
    model = load_model(default_model_path())
    space = style_space(model)
    controls = Controls(np.full(len(model.style_names), 1.5 / len(model.style_names)))
    planner = Engine(model)
    planner.retune(controls)
    ids = planner.stream.state_plan(args.frames)
    lam = interpolate(space, controls.weights)
    means, variances = lam.means[ids], 1.0 / lam.precisions[ids]
    dim = means.shape[1] // 3
    solvers = {
        "whole, 1 thread": lambda: mlpg(means, variances, threads=1),
        "windowed": lambda: mlpg_continued(means[None], variances[None], np.zeros((1, 0, dim)), as_variance=True)[0],
        "whole, shared": lambda: mlpg(means, variances),
    }
    reference = _nnmnkwii_mlpg()
    if reference:
        solvers["nnmnkwii"] = lambda: reference(means, variances)
    written = np.empty((3, args.frames, dim))
    solvers["floor: read"] = lambda: read_floor(means, variances)
    solvers["floor: read+write"] = lambda: read_write_floor(means, variances, *written)
    for solve in solvers.values():
        solve()  # compile, warm up
    wall = np.empty((args.turns, len(solvers)))
    cpu = np.empty((args.turns, len(solvers)))
    for k in range(args.turns):
        for j, solve in enumerate(solvers.values()):
            start, start_cpu = time.perf_counter(), time.thread_time()
            solve()
            cpu[k, j], wall[k, j] = time.thread_time() - start_cpu, time.perf_counter() - start
    m = machine()
    print(f"{m['cores']} cores, {m['cpu']}, load {m['load_1min']:.1f}; {args.frames} frames x {dim} dims, {args.turns} turns")
    names = list(solvers)
    nnmnkwii = names.index("nnmnkwii") if reference else None
    for j, name in enumerate(names):
        line = f"{name:17s} wall {1e3 * np.median(wall[:, j]):7.1f} ms  cpu {1e3 * np.median(cpu[:, j]):7.1f} ms  per turn: "
        if name.startswith("floor"):
            line += f"the whole-sequence kernel on one thread takes x{np.median(wall[:, 0] / wall[:, j]):.2f} this time"
        else:
            shared = name == "whole, shared"  # its threads' cpu time is not the calling thread's
            cpu_ratio = "n/a" if shared else f"x{np.median(cpu[:, 1] / cpu[:, j]):.2f}"
            line += f"x{np.median(wall[:, 1] / wall[:, j]):.2f} the windowed kernel (cpu {cpu_ratio})"
            if nnmnkwii is not None:
                line += f", x{np.median(wall[:, nnmnkwii] / wall[:, j]):.2f} nnmnkwii"
        print(line)


if __name__ == "__main__":
    main()
