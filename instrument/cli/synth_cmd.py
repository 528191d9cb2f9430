"""`instrument synth`: write a walk (or a stand, a run, a turning walk) with given style weights as BVH."""

from __future__ import annotations

import argparse
import sys
from typing import TYPE_CHECKING

from ..errors import UserError
from ..outputfile import check_output
from ..shipped import default_model_path
from ..synthesis.parameters import DEFAULT_LOOKAHEAD, GROUPS, MAX_SPEED, MIN_SPEED
from ..control.options import value

if TYPE_CHECKING:
    import numpy as np


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("synth", help="synthesize a walk with given style weights and write it as BVH")
    p.add_argument("--model", help="model file (default: the shipped default model)")
    p.add_argument("--style", action="append", default=[], metavar="NAME[.PART]=W",
                   help="style weight, repeatable: 1 the style, 2 exaggerated, 0.5 inhibited, -1 inverted; "
                        f"NAME.PART=W sets it for one body part ({', '.join(GROUPS)}), e.g. elderly.legs=1")
    p.add_argument("--speed", default="1", help=f"step rate relative to the model's ({MIN_SPEED:g} to {MAX_SPEED:g})")
    p.add_argument("--gait", default="walk", help="stand, walk or run (or 0, 1, 2; default walk); a sequence that "
                                                  "stops, stands and runs is a score, played by `run --fast --bvh`")
    p.add_argument("--turn", default="0", help="steering in rad/s, positive turns left (turning steps where the model "
                                               "has them; default 0)")
    p.add_argument("--seconds", default="10", help="length of the walk (default 10)")
    p.add_argument("--gesture", action="append", default=[], metavar="NAME@SECONDS",
                   help="a gesture (wave, raise) started at SECONDS, repeatable; it plays as its takes do")
    p.add_argument("--out", required=True, metavar="FILE.bvh", help="the walk's file: .bvh, or .glb for binary glTF 2.0")
    p.add_argument("--force", action="store_true", help="overwrite the --out file if it exists (default: refuse)")
    p.add_argument("--method", choices=("stream", "full"), default="stream",
                   help="stream: frame by frame as live (default); full: one MLPG over the whole walk")
    p.add_argument("--lookahead", default=None, metavar="FRAMES",
                   help=f"streaming look-ahead (default {DEFAULT_LOOKAHEAD} at 30 fps: as long in the model's frames)")
    p.add_argument("--liveliness", default="0", help="0: mean state durations; 1: durations drawn from the model (seeded)")
    p.add_argument("--seed", default="0", help="seed for liveliness draws (default 0)")
    p.set_defaults(run=run)


def parse_weights(items: list[str], styles: list[str]) -> tuple[dict[str, float], np.ndarray | None]:
    """Whole-body weights by style, and per-part weights (styles, parts; NaN: as the whole body) if any."""
    import numpy as np

    weights: dict[str, float] = {}
    parts = np.full((len(styles), len(GROUPS)), np.nan)
    for item in items:
        key, sep, text = item.partition("=")
        name, dot, part = key.partition(".")
        if not sep:
            raise UserError(f"--style {item!r}: expected NAME=WEIGHT or NAME.PART=WEIGHT, e.g. elderly=1.5")
        if name not in styles:
            raise UserError(f"--style {item!r}: the model has no style {name!r} (it has {', '.join(styles)})")
        if dot and part not in GROUPS:
            raise UserError(f"--style {item!r}: no body part {part!r} (the parts are {', '.join(GROUPS)})")
        weight = value("synth --style", text, where=f"--style {key}")
        if dot:
            parts[styles.index(name), GROUPS.index(part)] = weight
        else:
            weights[name] = weight
    return weights, (None if np.isnan(parts).all() else parts)


def parse_gestures(items: list[str], model) -> list[tuple[str, float]]:
    """--gesture NAME@SECONDS items as (name, seconds); an error names the item at fault."""
    from ..models.gestures import gesture_labels

    known = list(gesture_labels(model.metadata))
    out = []
    for item in items:
        name, sep, text = item.partition("@")
        if not sep:
            raise UserError(f"--gesture {item!r}: expected NAME@SECONDS, e.g. wave@2")
        if name not in known:
            raise UserError(f"--gesture {item!r}: the model has no gesture {name!r} "
                            f"({'it has ' + ', '.join(known) if known else 'it was trained without gesture takes'})")
        out.append((name, value("synth --gesture", text, where=f"--gesture {item}")))
    return out


def run(args: argparse.Namespace) -> int:
    # the synthesizer's code (numpy, scipy, numba): loaded when run, not for --help
    from ..models.modelfile import load_model
    from ..output.export import motion_format, write_motion
    from ..synthesis.engine import default_controls, render
    from ..synthesis.parameters import GAITS
    from ..synthesis.stream import gait_index
    from ..synthesis.units import UnitChooser

    motion_format(args.out)  # an extension it cannot write is refused before any work
    check_output(args.out, args.force)
    model = load_model(args.model or default_model_path())
    weights, part_weights = parse_weights(args.style, model.style_names)
    speed = value("synth --speed", args.speed)
    gait = gait_index(value("synth --gait", args.gait))
    turn = value("synth --turn", args.turn)
    seconds = value("synth --seconds", args.seconds)
    lookahead = None if args.lookahead is None else value("synth --lookahead", args.lookahead)
    liveliness = value("synth --liveliness", args.liveliness)
    seed = value("synth --seed", args.seed)
    frames = max(1, int(round(seconds * model.fps)))
    if GAITS[gait] not in model.units:  # said, not refused, as `run` says it: the walk is written
        print(f"--gait {GAITS[gait]}: this model has no {GAITS[gait]} unit (it has {', '.join(model.units)}); "
              "it walks", file=sys.stderr)
    missing_turn = UnitChooser(model, 1).unsteered(gait, turn)
    if missing_turn:  # said, as a gait it lacks is: the walk is steered all the same
        print(f"--turn {turn:g}: this model has no {missing_turn} unit (it has {', '.join(model.units)}); "
              "its walk is steered without turning steps", file=sys.stderr)
    gestures = parse_gestures(args.gesture, model)
    for (name, start), item in zip(gestures, args.gesture):
        if start >= frames / model.fps:
            raise UserError(f"--gesture {item}: starts after the walk ends ({seconds:g} s; give a longer --seconds)")
    controls = default_controls(model, weights, part_weights=part_weights, speed=speed, liveliness=liveliness, gait=gait,
                                turn=turn)
    # the engine as `run` plays it, without a clock: the feet planted, from the origin, heading 0
    write_motion(args.out, render(model, controls, frames, args.method, lookahead, seed, gestures))
    print(f"wrote {frames} frames ({seconds:g} s) to {args.out}", file=sys.stderr)
    return 0
