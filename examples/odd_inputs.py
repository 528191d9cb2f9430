"""Odd but valid BVH captures, end to end, as a check on data we have never seen would try them
(issue 30): for each variant, a few shared walks re-rigged (`other_rigs.rerig`), then `instrument
train`, `synth`, `evaluate --real` and the live path (`run --fast`, recording BVH and sending
VMC, whose bones are guessed from the joint names) on them.

    python examples/odd_inputs.py ../shared/data/bandai-walk [--out /tmp/odd-inputs] [--variants NAME,...]
                                  [--styles elderly,active] [--takes 2]

Prints one row per variant: each command's outcome (`ok`, or the one line it printed on
failure; a traceback is a failure of its own), the humanoid bones VMC could not guess from the
joint names (UpperChest, which few skeletons have, and toes a skeleton lacks, aside) and, where evaluate ran, the made
walk's knee, hip and skate against the takes'. Exit status 1 when any command failed with a traceback or a
variant that should work did not, or a bone was not guessed.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from instrument.errors import UserError, run_script
from instrument.models.modelfile import load_model
from instrument.output.humanoid import HUMAN_BONES, guess_humanoid
from instrument.motion.bvh import Motion, read_bvh, write_bvh
from other_rigs import Rig, chosen_takes, rerig, rest_turns

VARIANTS: dict[str, Rig] = {
    "orders-zxy-xyz-yxz": Rig(30.0, 1.0, "YXZ", keep_root=False),
    "positions-everywhere": Rig(30.0, 1.0, "XYZ", keep_root=False, positions=True),
    "mixamo-names": Rig(30.0, 1.0, "ZXY", "mixamo", keep_root=False),
    "asf-names-lhumerus": Rig(120.0, 1.0, "ZYX", "asf", keep_root=False),
    "blender-names-z-up": Rig(24.0, 0.01, "XYZ", "blender", keep_root=False, up="Z"),
    "z-up-rest-pose": Rig(60.0, 1.0, "ZXY", "suit", keep_root=False, up="Z", rest_pose=True),
    "fps-24": Rig(24.0, 1.0, "ZXY"),
    "fps-60-inches": Rig(60.0, 1 / 2.54, "ZXY", keep_root=False),
    "fps-120-metres": Rig(120.0, 0.01, "ZXY", keep_root=False),
    "no-toes": Rig(30.0, 1.0, "ZXY", keep_root=False, drop=("Toes_L", "Toes_R")),
    "suit23-60": Rig(60.0, 1.0, "ZXY", "suit", keep_root=False, split=("Chest", 3), rest_pose=True),
    "floor-below-origin-metres": Rig(30.0, 0.01, "ZXY", keep_root=False, lift=-70.0),
    "short-takes": Rig(30.0, 1.0, "ZXY", keep_root=False, frames=45),
    # HumanIK's prefixed names (upper arms and shins were unguessed), millimetres (guessed as an unknown
    # unit: hips made 0.95 m, figures 9.6% long), Z up, 100 fps
    "humanik-mm-z-up-100": Rig(100.0, 10.0, "YXZ", "humanik", keep_root=False, up="Z"),
}

EXTRA = ["turning-take", "tiny-take"]  # the plain walks with a turning take, or a take of 8 frames, among them
PLAIN = Rig(30.0, 1.0, "ZXY")


def build(takes: list[Path], rig: Rig, folder: Path) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    rest = rest_turns(read_bvh(takes[0]), rig) if rig.rest_pose else None
    for path in takes:
        write_bvh(folder / path.name, rerig(read_bvh(path), rig, rest))


def turning(data: Path, folder: Path, rig: Rig) -> None:
    """A walk that turns: a turning take of the shared motions (beside them), named as a walk."""
    for path in sorted(data.parent.glob("bandai-motions/dataset-2_walk-turn-left_elderly_00*.bvh"))[:1]:
        write_bvh(folder / "dataset-2_walk_elderly_009.bvh", rerig(read_bvh(path), rig))


def tiny(folder: Path, rig: Rig, source: Path) -> None:
    """A take of 8 frames (a quarter of a second) among the others."""
    motion = rerig(read_bvh(source), rig)
    write_bvh(folder / "dataset-2_walk_elderly_010.bvh", Motion(motion.skeleton, motion.channels[:8], motion.fps))


def run(*args: str) -> tuple[str, subprocess.CompletedProcess]:
    result = subprocess.run([sys.executable, "-m", "instrument", *args], capture_output=True, text=True, timeout=900)
    if "Traceback" in result.stderr:
        return "TRACEBACK: " + result.stderr.strip().splitlines()[-1], result
    if result.returncode != 0:
        lines = result.stderr.strip().splitlines()
        return "error: " + (lines[-1] if lines else f"status {result.returncode}"), result
    return "ok", result


def check(folder: Path, out: Path) -> dict:
    model = out / f"{folder.name}.npz"
    row: dict = {}
    row["train"], _ = run("train", str(folder), "--out", str(model), "--force", "--quiet")
    if row["train"] != "ok":
        return row
    styles = json.loads(run("info", str(model), "--json")[1].stdout or "{}").get("styles", [])
    style = styles[0] if styles else "elderly"
    row["synth"], _ = run("synth", "--model", str(model), "--style", f"{style}=1", "--seconds", "4",
                          "--out", str(out / f"{folder.name}.bvh"), "--force")
    row["evaluate"], result = run("evaluate", str(model), "--real", str(folder), "--variants", "one", "--seconds", "8",
                                  "--json")
    if row["evaluate"] == "ok":
        figures = json.loads(result.stdout)
        row["figures"] = {s: {k: (figures["real"][s].get(k), figures["synth"][s].get(k))
                              for k in ("knee_deg", "hip_deg", "shoulder_deg", "skate_cm_s", "float_frac")}
                          for s in figures["real"]}
    skeleton = load_model(model).layout.skeleton
    absent = {"UpperChest"} | ({"LeftToes", "RightToes"} if not any("toe" in n.lower() for n in skeleton.names) else set())
    row["vmc_unguessed"] = [b for b in HUMAN_BONES if b not in guess_humanoid(skeleton).values() and b not in absent]
    row["live"], _ = run("run", "--model", str(model), "--fast", "--seconds", "3", "--quiet", "--force",
                         "--bvh", str(out / f"{folder.name}-live.bvh"), "--osc", "127.0.0.1:59991/vmc")
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", help="folder of walks (named like dataset-2_walk_<style>_NNN.bvh)")
    parser.add_argument("--out", default="/tmp/odd-inputs", help="folder for the variants and models")
    parser.add_argument("--variants", default=",".join(list(VARIANTS) + EXTRA))
    parser.add_argument("--styles", default="elderly,active")
    parser.add_argument("--takes", type=int, default=2)
    args = parser.parse_args()
    names = [v.strip() for v in args.variants.split(",") if v.strip()]
    unknown = [n for n in names if n not in VARIANTS and n not in EXTRA]
    if unknown:
        raise UserError(f"--variants: no variant {unknown[0]!r} (there are {', '.join(list(VARIANTS) + EXTRA)})")
    out = Path(args.out)
    takes = chosen_takes(Path(args.data), [s.strip() for s in args.styles.split(",")], args.takes)
    bad = 0
    for name in names:
        folder = out / name
        if name in EXTRA:
            build(takes, PLAIN, folder)
            if name == "turning-take":
                turning(Path(args.data), folder, PLAIN)
            else:
                tiny(folder, PLAIN, takes[0])
        else:
            build(takes, VARIANTS[name], folder)
        row = check(folder, out)
        bad += any(str(v).startswith("TRACEBACK") or str(v).startswith("error") for v in row.values())
        bad += bool(row.get("vmc_unguessed"))
        print(json.dumps({name: row}), flush=True)
    print(f"{bad} variant(s) with a failure")
    sys.exit(1 if bad else 0)


if __name__ == "__main__":
    run_script(main, "odd_inputs.py")
