"""Issue 25's targets on a model (default: the shipped one), each measured value against its bound.

    python examples/units_figures.py [MODEL] [--json OUT.json]

Measures every unit beyond the walk against its real takes and every stop and start
(`instrument evaluate --units` does the same beside the walk's table; docs/evaluate.md), then
prints one row per target and walk, PASS or FAIL, and a summary per target. The real takes are
read from ../shared/data/bandai-walk and ../shared/data/bandai-motions beside the repository.
It takes a few minutes (about 90 motions of 8 to 12 s through the engine, 421 takes read).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from instrument.evaluation.targets import check, summary, table
from instrument.cli.evaluate_cmd import partway_table
from instrument.evaluation.units import assess_units, partway_summary
from instrument.models.modelfile import default_model_path, load_model

DATA = REPO.parent / "shared" / "data"
FOLDERS = [DATA / "bandai-walk", DATA / "bandai-motions"]


def _plain(value):
    """NaN as None, numpy scalars as Python numbers, so the JSON is standard."""
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    if hasattr(value, "item"):
        value = value.item()
    return None if isinstance(value, float) and math.isnan(value) else value


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", nargs="?", default=str(default_model_path()))
    parser.add_argument("--json", metavar="OUT", help="also write every figure and target row to this JSON file")
    args = parser.parse_args()
    model = load_model(args.model)
    began = time.time()
    result = assess_units(model, FOLDERS, progress=lambda name: print(f"  measured {name} ({time.time() - began:.0f} s)",
                                                                      file=sys.stderr))
    rows = check(result)
    print(table(rows))
    print("\n" + partway_table(partway_summary(result)))
    failed = sum(not r.passed for r in rows)
    print(f"\n{len(rows) - failed} of {len(rows)} target rows pass; "
          f"{sum(ok == total for _, ok, total, _ in summary(rows))} of {len(summary(rows))} targets pass in full")
    if args.json:
        Path(args.json).write_text(json.dumps(_plain({
            "model": args.model, "weights": result.weights, "synth": result.synth, "real": result.real,
            "transitions": result.transitions, "real_jumps": result.real_jumps, "partway": result.partway_by_name(),
            "partway_summary": partway_summary(result), "targets": [vars(r) for r in rows]}), indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
