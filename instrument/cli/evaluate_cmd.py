"""`instrument evaluate`: the figures of a model's walks, beside those of the real takes."""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

from ..errors import UserError
from ..shipped import default_model_path
from .arguments import checked

VARIANT_KINDS = ("one", "x2", "inverted", "pairs")  # as evaluation.assessment names them (imported when run: it is slow to load)

COLUMNS = (  # (figure, heading, scale, format)
    ("step_s", "step s", 1.0, "{:.3f}"),
    ("step_sd_s", "sd", 1.0, "{:.3f}"),
    ("stride_cm", "stride cm", 1.0, "{:.1f}"),
    ("speed_cm_s", "speed cm/s", 1.0, "{:.1f}"),
    ("skate_cm_s", "skate cm/s", 1.0, "{:.1f}"),
    ("under_frac", "under %", 100.0, "{:.1f}"),
    ("under_depth_cm", "depth cm", 1.0, "{:.1f}"),
    ("air_frac", "air %", 100.0, "{:.1f}"),
    ("float_frac", "float %", 100.0, "{:.1f}"),
    ("knee_deg", "knee", 1.0, "{:.0f}"),
    ("hip_deg", "hip", 1.0, "{:.0f}"),
    ("shoulder_deg", "shoulder", 1.0, "{:.0f}"),
    ("jitter_m_s3", "jitter", 1.0, "{:.1f}"),
    ("drift_deg_s", "drift deg/s", 1.0, "{:.2f}"),
    ("recognised", "recognised %", 100.0, "{:.0f}"),
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("evaluate", help="measure a model's walks (skate, floor, ranges, drift, recognisability) against real takes")
    p.add_argument("model", nargs="?", metavar="MODEL", help="model file (default: the shipped default model)")
    p.add_argument("--real", metavar="DIR", action="append",
                   help="folder holding the takes the model was trained on (its provenance names them); "
                        "repeat it for takes in several folders (walks in one, runs, turns and stands in another)")
    p.add_argument("--seconds", type=checked("evaluate --seconds"), default=12.0,
                   help="length of each generated walk, 2 to 600 (default 12)")
    p.add_argument("--styles", nargs="+", metavar="NAME", help="only these styles (default: all)")
    p.add_argument("--variants", type=variant_kinds, default=VARIANT_KINDS,
                   help=f"which weightings, comma-separated from {', '.join(VARIANT_KINDS)} (default: all)")
    p.add_argument("--units", action="store_true",
                   help="also measure the model's other units (run, turns, stand) against their real takes, the stops "
                        "and starts between them, and check issue 25's targets (PASS/FAIL)")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--gestures", action="store_true",
                   help="also each gesture over a walk in each style, against its takes (evaluation/gestures.py)")
    p.set_defaults(run=run)


def variant_kinds(text: str) -> tuple[str, ...]:
    """--variants: some of VARIANT_KINDS, comma-separated (argparse's type=: a bad list is a usage error)."""
    kinds = tuple(k.strip() for k in text.split(",") if k.strip())
    if not kinds or any(k not in VARIANT_KINDS for k in kinds):
        raise argparse.ArgumentTypeError(f"expected some of {', '.join(VARIANT_KINDS)}, comma-separated, not {text!r}")
    return kinds


def run(args: argparse.Namespace) -> int:
    from ..models.modelfile import load_model  # (numpy, scipy, numba: loaded when run, not for --help)

    model = load_model(args.model or default_model_path())
    seconds = args.seconds
    styles = args.styles or model.style_names
    unknown = [s for s in styles if s not in model.style_names]
    if unknown:
        raise UserError(f"--styles: the model has no style {unknown[0]!r} (it has {', '.join(model.style_names)})")
    styles = [s for s in model.style_names if s in styles]  # the model's order, whatever the command line's
    kinds = args.variants
    from ..evaluation.assessment import assess, missing_takes

    progress = None if args.json else (lambda name: print(f"  measured {name}", file=sys.stderr))
    real = [Path(folder) for folder in args.real] if args.real else None
    result = assess(model, seconds, real, styles, kinds, progress)
    if real is not None:
        for line in missing_takes(model, real, None if args.units else ("walk",)):
            print(f"warning: --real: {line}", file=sys.stderr)
    units = None
    if args.units:
        from ..evaluation.targets import check
        from ..evaluation.units import assess_units, partway_summary

        units = assess_units(model, real, styles, seconds, progress)
        targets = check(units)
    gestures = None
    if args.gestures:
        from ..evaluation.gestures import assess_gestures, gesture_table

        gestures = assess_gestures(model, seconds, real, styles, progress)
    if args.json:
        report = {"model": str(args.model or default_model_path()), "seconds": seconds, "weights": result.weights,
                  "synth": _clean(result.synth), "real": _clean(result.real)}
        if units is not None:
            report["units"] = {"weights": units.weights, "synth": {k: _clean(v) for k, v in units.synth.items()},
                               "real": {k: _clean(v) for k, v in units.real.items()},
                               "transitions": _clean(units.transitions), "real_jumps": units.real_jumps,
                               "partway": _clean(units.partway_by_name()), "partway_summary": _clean(partway_summary(units)),
                               "targets": [vars(t) | {"measured": _number(t.measured)} for t in targets]}
        if gestures is not None:
            report["gestures"] = {"synth": _clean(gestures.synth), "real": _clean(gestures.real)}
        print(json.dumps(report, indent=1))
    else:
        print(table(result))
        if units is not None:
            from ..evaluation.targets import table as target_table

            print(unit_tables(units) or "\nthe model has no units but the walk: no runs, turns, stands or stops to measure")
            print("\n" + target_table(targets))
        if gestures is not None:
            print(f"\n{gesture_table(gestures)}")
    return 0


def _number(value):
    return None if isinstance(value, float) and math.isnan(value) else value


def _clean(figures: dict) -> dict:
    """NaN (a figure a walk has too few steps for) as null, so the JSON is standard."""
    return {k: {f: _number(v) for f, v in d.items()} for k, d in figures.items()}


def _row(name: str, figures: dict) -> str:
    cells = []
    for key, _, scale, fmt in COLUMNS:
        value = figures.get(key, float("nan"))
        cells.append("-" if value is None or math.isnan(value) else fmt.format(value * scale))
    return "| " + " | ".join([name] + cells) + " |"


def table(result) -> str:
    """A Markdown table of an `Assessment`: for each style with real takes, the real row first."""
    lines = ["| walk | " + " | ".join(h for _, h, _, _ in COLUMNS) + " |", "|---" * (len(COLUMNS) + 1) + "|"]
    for style, figures in result.real.items():
        lines.append(_row(f"{style} (real)", figures))
        if style in result.synth:
            lines.append(_row(style, result.synth[style]))
    lines += [_row(name, figures) for name, figures in result.synth.items() if name not in result.real]
    return "\n".join(lines)


UNIT_COLUMNS = {  # section -> (figure, heading, scale, format)
    "run": (("step_s", "step s", 1.0, "{:.3f}"), ("speed_cm_s", "speed cm/s", 1.0, "{:.1f}"),
            ("stance_skate_cm_s", "stance skate cm/s", 1.0, "{:.1f}"), ("air_frac", "air %", 100.0, "{:.1f}"),
            ("knee_deg", "knee", 1.0, "{:.0f}"), ("jump_cm_f2", "jump cm/f^2", 1.0, "{:.1f}"),
            ("recognised", "recognised %", 100.0, "{:.0f}")),
    "turn": (("turn_deg_s", "turn deg/s", 1.0, "{:.1f}"), ("radius_cm", "radius cm", 1.0, "{:.0f}"),
             ("speed_cm_s", "speed cm/s", 1.0, "{:.1f}"), ("step_s", "step s", 1.0, "{:.3f}"),
             ("skate_cm_s", "skate cm/s", 1.0, "{:.1f}"), ("jump_cm_f2", "jump cm/f^2", 1.0, "{:.1f}")),
    "stand": (("hips_cm_s", "hips cm/s", 1.0, "{:.2f}"), ("hips_min_cm_s", "takes' least", 1.0, "{:.2f}"),
              ("hips_max_cm_s", "takes' most", 1.0, "{:.2f}"), ("feet_cm_s", "feet cm/s", 1.0, "{:.2f}"),
              ("jump_cm_f2", "jump cm/f^2", 1.0, "{:.1f}"), ("recognised", "recognised %", 100.0, "{:.0f}")),
}
TRANSITION_COLUMNS = (
    ("steady_cm_s", "steady cm/s", 1.0, "{:.1f}"), ("stop_s", "stop s", 1.0, "{:.2f}"),
    ("stop_steps", "stop steps", 1.0, "{:.0f}"), ("speed_s", "to speed s", 1.0, "{:.2f}"),
    ("speed_steps", "to speed steps", 1.0, "{:.0f}"), ("slide_cm_s", "slide cm/s", 1.0, "{:.1f}"),
    ("jump_cm_f2", "jump cm/f^2", 1.0, "{:.1f}"), ("jump_joint", "joint", None, "{}"),
    ("gait_jump_cm_f2", "gait's jump cm/f^2", 1.0, "{:.1f}"), ("air_frames", "air frames", 1.0, "{:.0f}"),
)
PARTWAY_COLUMNS = (  # of evaluation.units.partway_summary
    ("jump_cm_f2", "worst jump cm/f^2", 1.0, "{:.1f}"), ("x_steady", "x its steady gait's", 1.0, "{:.2f}"),
    ("x_real", "x real takes'", 1.0, "{:.2f}"), ("walk", "of", None, "{}"), ("jump_joint", "joint", None, "{}"),
    ("delay_frames", "2nd command after (frames)", 1.0, "{:.0f}"), ("slide_cm_s", "worst slide cm/s", 1.0, "{:.1f}"),
    ("slide_x_real", "x real stance skate", 1.0, "{:.2f}"), ("slide_walk", "of", None, "{}"),
)


def _cells(name: str, figures: dict, columns) -> str:
    cells = []
    for key, _, scale, fmt in columns:
        value = figures.get(key)
        if value is None or (isinstance(value, float) and math.isnan(value)):
            cells.append("-")
        else:
            cells.append(fmt.format(value if scale is None else value * scale))
    return "| " + " | ".join([name] + cells) + " |"


def unit_tables(units) -> str:
    """Markdown tables of a `UnitAssessment`: run, turn and stand (real rows first), then the transitions."""
    parts = []
    for section, columns in UNIT_COLUMNS.items():
        made, real = units.synth.get(section, {}), units.real.get(section, {})
        if not made:
            continue
        lines = [f"| {section} | " + " | ".join(h for _, h, _, _ in columns) + " |", "|---" * (len(columns) + 1) + "|"]
        shown = set()
        for name, figures in made.items():
            key = name.split(" x2")[0].split(" -1")[0]
            if key in real and key not in shown:
                lines.append(_cells(f"{key} (real)", real[key], columns))
                shown.add(key)
            lines.append(_cells(name, figures, columns))
        parts.append("\n".join(lines))
    if units.transitions:
        lines = ["| transition | " + " | ".join(h for _, h, _, _ in TRANSITION_COLUMNS) + " |",
                 "|---" * (len(TRANSITION_COLUMNS) + 1) + "|"]
        lines += [_cells(name, figures, TRANSITION_COLUMNS) for name, figures in units.transitions.items()]
        jumps = ", ".join(f"{unit} {figures['all']:.1f}" for unit, figures in units.real_jumps.items() if "all" in figures)
        if jumps:
            lines.append(f"\nLargest joint velocity jump of the real takes (cm/frame^2): {jumps}")
        parts.append("\n".join(lines))
    if units.partway:
        from ..evaluation.units import partway_summary

        parts.append(partway_table(partway_summary(units)))
    return "\n\n".join([""] + parts) if parts else ""


def partway_table(summary: dict[str, dict[str, float | str]]) -> str:
    """A Markdown table of `evaluation.units.partway_summary`, under a line saying what it is."""
    from ..evaluation.transitions import PARTWAY_STEPS

    lines = ["Changes part-way (figures, not targets): a stop called off and a start stopped, the second command "
             f"swept over the first {PARTWAY_STEPS:g} steps after the first; per gait and weighting, the worst of the styles "
             "swept.", "",
             "| change | " + " | ".join(h for _, h, _, _ in PARTWAY_COLUMNS) + " |", "|---" * (len(PARTWAY_COLUMNS) + 1) + "|"]
    lines += [_cells(name, row, PARTWAY_COLUMNS) for name, row in summary.items()]
    return "\n".join(lines)
