"""Per-frame cost and size of the VMC profile's output over a recorded walk (a benchmark, not a test).

    python examples/vmc_cost.py [--old OLD_VMC.py]

`--old` times another version of instrument/output/vmc.py (e.g. `git show a14495b:instrument/output/vmc.py
> /tmp/old_vmc.py`) in the same run, so the figures can be read as ratios on a busy machine.
"""

from __future__ import annotations

import argparse
import importlib.util
import time
from pathlib import Path

from instrument.models.modelfile import load_model
from instrument.motion.bvh import read_bvh
from instrument.motion.kinematics import forward_kinematics, local_transforms
from instrument.output.humanoid import guess_humanoid
from instrument.output.outputs import make_profile
from instrument.synthesis.posing import Pose
from instrument.shipped import default_model_path

WALK = Path(__file__).resolve().parent / "data" / "dataset-2_walk_normal_001.bvh"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--old", help="another vmc.py to time alongside")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()
    model = load_model(default_model_path())
    motion = read_bvh(WALK)
    rotations, translations = local_transforms(motion)
    world_rot, world_pos = forward_kinematics(motion.skeleton, rotations, translations)
    poses = [Pose(t, t / motion.fps, rotations[t], translations[t], world_rot[t], world_pos[t]) for t in range(motion.frames)]
    profiles = {"hips, relaxed hands (default)": make_profile("vmc", model),
                "path, relaxed hands": make_profile("vmc", model, vmc_root="path"),
                "hips, no finger bones": make_profile("vmc", model, fingers=False)}
    if args.old:
        spec = importlib.util.spec_from_file_location("instrument.output.old_vmc", args.old)
        old = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(old)
        means = model.average.means[..., : model.layout.dimension]
        profiles["old"] = old.VmcProfile(model.layout, guess_humanoid(model.layout.skeleton), old.forward_direction(means))
    for name, profile in profiles.items():
        best = float("inf")
        for _ in range(args.repeat):
            start = time.perf_counter()
            for pose in poses:
                datagrams = profile.datagrams(pose, {})
            best = min(best, (time.perf_counter() - start) / len(poses))
        print(f"{name}: {best * 1e6:.0f} us/frame (best of {args.repeat}), {len(datagrams)} bundles, "
              f"largest {max(map(len, datagrams))} bytes, {sum(map(len, datagrams))} bytes per frame")


if __name__ == "__main__":
    main()
