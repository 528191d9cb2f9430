"""`instrument bench`: the speed figures the project promises, measured on this machine."""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from ..motion.bvh import Motion, Skeleton, bvh_text, parse_bvh
from ..motion.features import choose_layout, extract


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("bench", help="measure parsing and synthesis speed on this machine")
    p.add_argument("--json", action="store_true", help="print one JSON object")
    p.add_argument("--repeat", type=int, default=20, help="timed repetitions per figure (the median is reported)")
    p.set_defaults(run=run)


def _median_seconds(work, repeat: int) -> float:
    work()  # warm up
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        work()
        times.append(time.perf_counter() - start)
    return float(np.median(times))


def benchmark_walk(frames: int = 500, joints: int = 22) -> str:
    """BVH text of a `frames`-long chain of `joints` 6-channel joints with smooth random motion."""
    from ..motion.bvh import Joint

    skeleton = Skeleton(
        tuple(
            Joint(f"J{k}", k - 1, (0.0, 10.0, 0.0), ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation"))
            for k in range(joints)
        )
    )
    rng = np.random.default_rng(0)
    channels = np.cumsum(rng.normal(0, 1.0, (frames, skeleton.channel_count)), axis=0)
    return bvh_text(Motion(skeleton, channels, 30.0))


def measure(repeat: int) -> dict:
    text = benchmark_walk()
    motion = parse_bvh(text)
    layout = choose_layout([motion])
    return {
        "bvh_parse_ms_500x22": 1000 * _median_seconds(lambda: parse_bvh(text), repeat),
        "features_ms_500x22": 1000 * _median_seconds(lambda: extract(motion, layout), repeat),
    }


def run(args: argparse.Namespace) -> int:
    figures = measure(max(1, args.repeat))
    if args.json:
        print(json.dumps(figures, indent=1))
    else:
        print(f"BVH parse, 500 frames x 22 joints: {figures['bvh_parse_ms_500x22']:.1f} ms")
        print(f"feature extraction, same file:      {figures['features_ms_500x22']:.1f} ms")
    return 0
