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
    p.add_argument("--real", metavar="DIR", help="folder holding the takes the model was trained on (its provenance names them)")
    p.add_argument("--seconds", type=checked("evaluate --seconds"), default=12.0,
                   help="length of each generated walk, 2 to 600 (default 12)")
    p.add_argument("--styles", nargs="+", metavar="NAME", help="only these styles (default: all)")
    p.add_argument("--variants", type=variant_kinds, default=VARIANT_KINDS,
                   help=f"which weightings, comma-separated from {', '.join(VARIANT_KINDS)} (default: all)")
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
    from ..evaluation.assessment import assess

    progress = None if args.json else (lambda name: print(f"  measured {name}", file=sys.stderr))
    result = assess(model, seconds, Path(args.real) if args.real else None, styles, kinds, progress)
    gestures = None
    if args.gestures:
        from ..evaluation.gestures import assess_gestures, gesture_table

        gestures = assess_gestures(model, seconds, Path(args.real) if args.real else None, styles, progress)
    if args.json:
        print(json.dumps({"model": str(args.model or default_model_path()), "seconds": seconds, "weights": result.weights,
                          "synth": _clean(result.synth), "real": _clean(result.real)}
                         | ({"gestures": {"synth": _clean(gestures.synth), "real": _clean(gestures.real)}} if gestures else {}),
                         indent=1))
    else:
        print(table(result) + (f"\n\n{gesture_table(gestures)}" if gestures else ""))
    return 0


def _clean(figures: dict) -> dict:
    """NaN (a figure a walk has too few steps for) as null, so the JSON is standard."""
    return {k: {f: (None if isinstance(v, float) and math.isnan(v) else v) for f, v in d.items()} for k, d in figures.items()}


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
