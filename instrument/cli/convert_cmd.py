"""`instrument convert`: a BVH file (a recording, a synthesized walk) to binary glTF or BVH."""

from __future__ import annotations

import argparse
import sys

from ..outputfile import check_output

SUMMARY = "convert a BVH recording to binary glTF (.glb) or BVH, by the --out extension"


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("convert", help=SUMMARY, description=SUMMARY + ": the skeleton in metres, Y up, "
                       "one rotation and translation key per joint and frame at the file's frame rate")
    p.add_argument("bvh", metavar="IN.bvh", help="a BVH file, e.g. a recording of `run --bvh`")
    p.add_argument("--out", required=True, metavar="OUT.glb", help="the file to write: .glb (binary glTF 2.0) or .bvh")
    p.add_argument("--force", action="store_true", help="overwrite the --out file if it exists (default: refuse)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..motion.bvh import read_bvh  # (numpy: loaded when run, not for --help)
    from ..motion.upright import upright_take
    from ..output.export import motion_format, write_motion

    kind = motion_format(args.out)
    check_output(args.out, args.force, inputs=(args.bvh,))
    motion = read_bvh(args.bvh)
    if kind != ".bvh":  # glTF is Y up: a Z-up capture is turned as training reads it (a .bvh is rewritten as it is)
        motion, up = upright_take(motion)
        if up != "+Y":
            print(f"{args.bvh}: {up} is up in this capture: written turned Y up", file=sys.stderr)
    write_motion(args.out, motion)
    print(f"wrote {motion.frames} frames ({motion.duration:g} s at {motion.fps:g} fps) to {args.out}", file=sys.stderr)
    return 0
