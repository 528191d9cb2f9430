"""Held-out log-likelihood per frame: train on ~80% of each style's takes, score the rest.

    python examples/heldout_likelihood.py ../shared/data/bandai-walk [--json] [--one-pass-map]

Each row is a style's held-out takes; each column a model. A style's own model should score its
takes better than the average model and the other styles' models do. --one-pass-map trains the
styles with the one-pass MAP adaptation the default replaced, for the baseline column.
"""

from __future__ import annotations

import argparse
import json
import time

from instrument.errors import run_script
from instrument.training.adaptation import ONE_PASS_MAP
from instrument.training.build import build_model
from instrument.training.corpus import styled_takes
from instrument.evaluation.heldout import format_table, heldout_table, split_holdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", help="folder of BVH takes named like dataset-2_walk_<style>_NNN.bvh")
    parser.add_argument("--json", action="store_true")
    parser.add_argument("--one-pass-map", action="store_true", help="adapt the styles by one-pass MAP (the old way)")
    args = parser.parse_args()
    pairs = styled_takes([args.data])
    train, held = split_holdout(pairs)
    started = time.perf_counter()
    model, _, _ = build_model(train, adaptation=ONE_PASS_MAP if args.one_pass_map else None)
    print(f"trained on {len(train)} takes in {time.perf_counter() - started:.1f} s; scoring {len(held)} held-out takes")
    table = heldout_table(model, held)
    print(json.dumps(table, indent=1) if args.json else format_table(table))


if __name__ == "__main__":
    run_script(main, __file__)
