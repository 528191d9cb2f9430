"""Training time on every take, the default adaptation against the one-pass MAP it replaced.

    python examples/training_time.py ../shared/data/bandai-walk

Trains three times in one process (one-pass MAP, default, one-pass MAP again) and prints the
wall-clock and CPU seconds of each: on a shared machine compare the ratios, not the seconds.
"""

from __future__ import annotations

import argparse
import time

from instrument.errors import run_script
from instrument.training.adaptation import ONE_PASS_MAP
from instrument.training.build import build_model
from instrument.training.corpus import styled_takes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", help="folder of BVH takes named like dataset-2_walk_<style>_NNN.bvh (searched recursively)")
    args = parser.parse_args()
    pairs = styled_takes([args.data])
    for name, fixed in (("one-pass MAP", ONE_PASS_MAP), ("default", None), ("one-pass MAP", ONE_PASS_MAP)):
        wall, cpu = time.perf_counter(), time.process_time()
        build_model(pairs, adaptation=fixed)
        print(f"{name:<13} {time.perf_counter() - wall:7.1f} s wall-clock, {time.process_time() - cpu:7.1f} s CPU", flush=True)


if __name__ == "__main__":
    run_script(main, __file__)
