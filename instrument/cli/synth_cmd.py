"""`instrument synth`: write a walk with given style weights as BVH."""

from __future__ import annotations

import argparse
import sys

from ..errors import UserError
from .arguments import value
from ..models.modelfile import default_model_path, load_model
from ..motion.bvh import write_bvh
from ..outputfile import check_output
from ..synthesis.durations import MAX_SPEED, MIN_SPEED
from ..synthesis.interpolation import style_space
from ..motion.features import restore
from ..synthesis.offline import default_controls, synthesize
from ..synthesis.stream import DEFAULT_LOOKAHEAD


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("synth", help="synthesize a walk with given style weights and write it as BVH")
    p.add_argument("--model", help="model file (default: the shipped default model)")
    p.add_argument("--style", action="append", default=[], metavar="NAME=W",
                   help="style weight, repeatable: 1 the style, 2 exaggerated, 0.5 inhibited, -1 inverted")
    p.add_argument("--speed", default="1", help=f"step rate relative to the model's ({MIN_SPEED:g} to {MAX_SPEED:g})")
    p.add_argument("--seconds", default="10", help="length of the walk (default 10)")
    p.add_argument("--out", required=True, metavar="FILE.bvh")
    p.add_argument("--force", action="store_true", help="overwrite OUT if it exists (default: refuse)")
    p.add_argument("--method", choices=("stream", "full"), default="stream",
                   help="stream: frame by frame as live (default); full: one MLPG over the whole walk")
    p.add_argument("--lookahead", default=str(DEFAULT_LOOKAHEAD), metavar="FRAMES", help=f"streaming look-ahead (default {DEFAULT_LOOKAHEAD})")
    p.add_argument("--liveliness", default="0", help="0: mean state durations; 1: durations drawn from the model (seeded)")
    p.add_argument("--seed", default="0", help="seed for liveliness draws (default 0)")
    p.set_defaults(run=run)


def parse_weights(items: list[str], styles: list[str]) -> dict[str, float]:
    weights: dict[str, float] = {}
    for item in items:
        name, sep, text = item.partition("=")
        if not sep:
            raise UserError(f"--style {item!r}: expected NAME=WEIGHT, e.g. elderly=1.5")
        if name not in styles:
            raise UserError(f"--style {item!r}: the model has no style {name!r} (it has {', '.join(styles)})")
        weights[name] = value("synth --style", text, where=f"--style {name}")
    return weights


def run(args: argparse.Namespace) -> int:
    check_output(args.out, args.force)
    model = load_model(args.model or default_model_path())
    weights = parse_weights(args.style, model.style_names)
    speed = value("synth --speed", args.speed)
    seconds = value("synth --seconds", args.seconds)
    lookahead = value("synth --lookahead", args.lookahead)
    liveliness = value("synth --liveliness", args.liveliness)
    seed = value("synth --seed", args.seed)
    frames = max(1, int(round(seconds * model.fps)))
    controls = default_controls(model, weights, speed=speed, liveliness=liveliness)
    static = synthesize(style_space(model), model.layout.dimension, controls, frames, args.method, lookahead, seed)
    write_bvh(args.out, restore(static, model.layout, model.fps))  # from the origin, heading 0
    print(f"wrote {frames} frames ({seconds:g} s) to {args.out}", file=sys.stderr)
    return 0
