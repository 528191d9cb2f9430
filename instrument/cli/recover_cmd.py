"""`instrument recover`: repair a recording left by a killed run."""

from __future__ import annotations

import argparse


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("recover", help="repair the frame count of a BVH recording left by a killed run")
    p.add_argument("bvh", metavar="FILE.bvh", help="the recording (its FILE.bvh.part, if the run was killed before the first frame)")
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    from ..motion.bvh import read_bvh  # (numpy: loaded when run, not for --help)
    from ..output.recorder import recover

    before, after, path, cut, inside = recover(args.bvh)
    if after == 0:
        print(f"{path}: the run was stopped before its first frame: nothing was recorded; removed it")
        return 0
    read_bvh(path)  # proves the result reads
    cut_lines = f"; cut {cut} line{'s' if cut > 1 else ''} that {'were' if cut > 1 else 'was'} not a whole frame" if cut else ""
    if inside:  # not where a kill cuts: the frames after it come a frame earlier (said, so the user can look)
        cut_lines += (f" ({'lines ' + ', '.join(map(str, inside)) if len(inside) > 1 else f'line {inside[0]}'} among the frames: "
                      "the frames after it come a frame earlier; a killed run cuts only the end)")
    if before == after and not cut:
        print(f"{path}: {after} frames, as the header says; left as it is")
    elif before == after:
        print(f"{path}: {after} frames, as the header says{cut_lines}")
    else:
        print(f"{path}: {after} frames (the header said {before}){cut_lines}")
    return 0
