"""`instrument recover`: repair a recording left by a killed run."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("recover", help="repair the frame count of a BVH recording left by a killed run")
    p.add_argument("bvh", metavar="FILE.bvh")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..motion.bvh import read_bvh  # (numpy: loaded when run, not for --help)
    from ..output.recorder import recover

    before, after = recover(args.bvh)
    read_bvh(args.bvh)  # proves the result reads
    if before == after:
        print(f"{args.bvh}: {after} frames, as the header says; left as it is")
    else:
        print(f"{args.bvh}: {after} frames (the header said {before})")
    return 0
