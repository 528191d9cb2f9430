"""`instrument skeleton`: the model's skeleton as a one-frame BVH, for a renderer to rig."""

from __future__ import annotations

import argparse
import sys

import numpy as np

from ..models.modelfile import load_model
from ..motion.bvh import Motion, write_bvh
from ..outputfile import check_output
from ..shipped import default_model_path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("skeleton", help="write the model's skeleton (template pose) as a one-frame BVH")
    p.add_argument("--model", help="model file (default: the shipped default model)")
    p.add_argument("--out", required=True, metavar="REST.bvh")
    p.add_argument("--force", action="store_true", help="overwrite the --out file if it exists (default: refuse)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    check_output(args.out, args.force)
    model = load_model(args.model or default_model_path())
    layout = model.layout
    write_bvh(args.out, Motion(layout.skeleton, np.asarray(layout.template)[None], model.fps))
    print(f"wrote the skeleton of {len(layout.skeleton.joints)} joints to {args.out}", file=sys.stderr)
    return 0
