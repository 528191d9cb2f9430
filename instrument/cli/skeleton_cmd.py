"""`instrument skeleton`: the model's skeleton as a one-frame BVH, for a renderer to rig."""

from __future__ import annotations

import argparse
import sys

from ..errors import UserError
from ..outputfile import check_output
from ..shipped import default_model_path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("skeleton", help="write the model's skeleton as a one-frame BVH (or .glb): a T-pose rest to rig, or the template")
    p.add_argument("--model", help="model file (default: the shipped default model)")
    p.add_argument("--out", required=True, metavar="REST.bvh", help="the skeleton's file: .bvh, or .glb for binary glTF 2.0")
    p.add_argument("--force", action="store_true", help="overwrite the --out file if it exists (default: refuse)")
    p.add_argument("--template", action="store_true",
                   help="the model's own skeleton in its template pose (for the flat-profile receiver), not the T-pose rest")
    p.add_argument("--humanoid", metavar="BONES.toml", help="joint-to-humanoid-bone map (default: guessed from the names)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np  # (with the model's code: loaded when run, not for --help)

    from ..models.modelfile import load_model
    from ..motion.bvh import Motion
    from ..output.export import motion_format, write_motion

    if args.template and args.humanoid:
        raise UserError("--humanoid maps the joints for the T-pose rest; --template writes the model's own skeleton as it "
                        "is: give one of them")
    motion_format(args.out)  # an extension it cannot write is refused before any work
    check_output(args.out, args.force)
    model = load_model(args.model or default_model_path())
    layout = model.layout
    if args.template:
        write_motion(args.out, Motion(layout.skeleton, np.asarray(layout.template)[None], model.fps))
        print(f"wrote the skeleton of {len(layout.skeleton.joints)} joints (template pose) to {args.out}", file=sys.stderr)
    else:
        from ..output.rest import tpose_rest

        write_motion(args.out, tpose_rest(model, args.humanoid))
        print(f"wrote the skeleton of {len(layout.skeleton.joints)} joints (T-pose rest, facing +Z, at {model.fps:g} fps) "
              f"to {args.out}", file=sys.stderr)
    return 0
