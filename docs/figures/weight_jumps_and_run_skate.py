"""The figures of docs/evaluate.md, "Style weights flicked every frame; x4 runs' skate".

    python docs/figures/weight_jumps_and_run_skate.py [jumps] [skate]

jumps: scores that set a style weight every frame (or once, or ramped) rendered by `instrument
run --score --fast --bvh`, read back with tests/bvh_independent.py: the largest second
difference of any joint's world position (cm/frame^2); then the same flick in-process, each
frame's stream output against the stream's rate limit (`max_step`).
skate: runs at x1..x4 measured as `evaluate --units` measures a run; where the skate is (the
lock's weights, the state's contact shares); the planted foot as the model makes it (no lock).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests"))
from bvh_independent import world_positions  # noqa: E402

from instrument.evaluation import units as U  # noqa: E402
from instrument.evaluation.assessment import model_limbs, _model_ground  # noqa: E402
from instrument.models.modelfile import default_model_path, load_model  # noqa: E402
from instrument.synthesis.contact import PLANTED  # noqa: E402
from instrument.synthesis.engine import Engine, default_controls  # noqa: E402
from instrument.synthesis.posing import CrowdPoses  # noqa: E402

FPS = 30.0


def second_differences(positions: np.ndarray) -> np.ndarray:
    """(frames, joints) |x(t) - 2 x(t-1) + x(t-2)| (0 for the first two frames)."""
    jumps = np.zeros(positions.shape[:2])
    jumps[2:] = np.linalg.norm(np.diff(positions, 2, axis=0), axis=-1)
    return jumps


def recorded_jumps(score: str, folder: Path, hips: bool = False) -> tuple[list[str], np.ndarray]:
    """Joint names and (frames, joints) jumps of the score as `run --fast --bvh` records it
    (`hips`: of the joints' positions relative to the hips, the hips' own in their column)."""
    (folder / "s.toml").write_text(score)
    done = subprocess.run([sys.executable, "-m", "instrument", "run", "--score", "s.toml", "--fast", "--no-osc",
                           "--quiet", "--bvh", "s.bvh", "--force"], capture_output=True, text=True, cwd=folder)
    assert done.returncode == 0, done.stderr
    names, positions, _ = world_positions(folder / "s.bvh")
    if hips:
        k = names.index("Hips")
        relative = positions - positions[:, k:k + 1]
        relative[:, k] = positions[:, k]
        positions = relative
    return names, second_differences(positions)


def flick(style: str, values: list[float], start: float = 3.0, seconds: float = 4.0) -> str:
    cues = [f'[[cue]]\nat = {start + k / FPS:.6f}\nramp = {{ "style/{style}" = {values[k % len(values)]} }}\n'
            for k in range(int(seconds * FPS))]
    return "\n".join(cues + [f'[[cue]]\nat = {start + seconds:.6f}\nramp = {{ "style/{style}" = 1.0 }}\n', "[[cue]]\nhold = 3\n"])


def jumps(folder: Path) -> None:
    for style, values in (("active", [4, -2, 1]), ("active", [4, -2]), ("active", [1, 0]), ("normal", [4, -2, 1])):
        names, j = recorded_jumps(flick(style, values), folder)
        window = j[int(3 * FPS):int(7 * FPS) + 2]
        print(f"{style} {values} a value a frame: {window.max():.1f} ({names[window.max(axis=0).argmax()]})")
        if values == [4, -2, 1] and style == "active":
            names, j = recorded_jumps(flick(style, values), folder, hips=True)
            window, k = j[int(3 * FPS):int(7 * FPS) + 2], names.index("Hips")
            print(f"  relative to the hips {np.delete(window, k, axis=1).max():.1f}, the hips' own {window[:, k].max():.1f}")
    for over in (0.0, 0.2):
        worst = []
        for k in range(0, 16, 2):  # the jump at 8 points of the step
            at = 4 + k / FPS
            score = (f'[[cue]]\nat = 1\nramp = {{ "style/active" = 4 }}\nover = 1\n[[cue]]\nat = {at:.6f}\n'
                     f'ramp = {{ "style/active" = -2 }}\nover = {over}\n[[cue]]\nhold = 2\n')
            a = int(round(at * FPS))
            worst.append(recorded_jumps(score, folder)[1][a:a + int(1.5 * FPS)].max())
        print(f"active 4 -> -2 over {over} s at 8 phases: " + ", ".join(f"{x:.1f}" for x in worst))
    for style in ("active", "normal"):
        for weight in (4, -2, 1):
            j = recorded_jumps(f'[[cue]]\nramp = {{ "style/{style}" = {weight} }}\n[[cue]]\nhold = 10\n', folder)[1]
            print(f"steady {style} x{weight}: {j[int(2 * FPS):].max():.1f}")
    # in-process: the stream's frames against its limit through the same flick
    model = load_model(default_model_path())
    engine = Engine(model)
    controls = {w: default_controls(model, {"active": w}) for w in (4.0, -2.0, 1.0)}
    sent, bound, binding = [], engine.space.max_step, []
    for k in range(200):
        before = engine.stream.history[0, 1].copy()
        engine.next_features(controls[1.0] if k < 90 else controls[(4.0, -2.0, 1.0)[(k - 90) % 3]])
        after = engine.stream.history[0, 1].copy()
        sent.append(after)
        if k >= 90:
            binding.append(int((np.abs(after - before) >= 0.999 * bound)[bound > 0].sum()))
    second = np.abs(np.diff(np.array(sent[88:]), 2, axis=0)) / np.maximum(bound, 1e-12)
    print(f"in-process: features at the limit a frame {min(binding)} to {max(binding)} of {len(bound)}; "
          f"largest change of a feature's velocity {second.max():.2f}x its max_step")


def skate() -> None:
    model = load_model(default_model_path())
    limbs, cm, template = model_limbs(model)
    measure = U._Measure(model, limbs, cm, _model_ground(model, limbs, template))
    work = U._Assessor(model, measure, {}, model.style_names, U.UNIT_SECONDS, None)
    for style in model.style_names:
        row = []
        for weight in (1, 2, 3, 4):
            figures = measure.moving(*work.made(f"{style}{weight}", {style: weight}, gait=2))
            row.append(f"{figures['stance_skate_cm_s']:.1f} ({figures['speed_cm_s']:.0f})")
        print(f"| {style} | " + " | ".join(row) + " |")
    feet = list(limbs.feet[0] + limbs.feet[1])
    for style, weight in (("active", 1), ("active", 4), ("elderly", 1), ("elderly", 4)):
        engine = Engine(model)
        controls = default_controls(model, {style: weight}, gait=2)
        rows, weights = [], []
        for k in range(360):
            rows.append(engine.frame(k / model.fps, controls).world_positions[0][feet] * cm)
            weights.append(engine.poses.lock_state.weights[0].max())
        positions, held = np.array(rows)[60:], np.array(weights)[60:]
        clearance = np.concatenate(engine.poses.lock.ground) * cm
        lift = positions[:, :, 1] - clearance
        lowest = np.argmin(lift, axis=1)
        speed = (np.linalg.norm(np.gradient(positions[:, :, [0, 2]], axis=0), axis=2) * model.fps)[np.arange(len(lift)), lowest]
        half = len(limbs.feet[0])
        ground = ~((lift[:, :half].min(axis=1) > 3) & (lift[:, half:].min(axis=1) > 3))
        for name, which in (("locked", held > 0.99), ("blending", (held > 0.01) & (held <= 0.99)), ("no lock", held <= 0.01)):
            frames = which & ground
            print(f"{style} x{weight} {name}: {frames.mean() * 100:.0f}% of frames, "
                  f"{speed[frames].mean() if frames.any() else float('nan'):.1f} cm/s")
        engine, bare = Engine(model), CrowdPoses(model.layout, model.fps, 1, None)
        rows, shares = [], []
        for k in range(360):
            rows.append(bare.next(engine.next_features(controls)).world_positions[0] * cm)
            shares.append(engine.contact_shares[0].copy())
        positions, shares = np.array(rows)[60:], np.array(shares)[60:]
        moving = []
        for side, foot in enumerate(limbs.feet):
            low = np.argmin(positions[:, list(foot), 1], axis=1)
            v = np.linalg.norm(np.gradient(positions[:, list(foot)][:, :, [0, 2]], axis=0), axis=2)[np.arange(len(low)), low]
            moving.append(v[shares[:, side] >= PLANTED] * model.fps)
        print(f"{style} x{weight}: the planted foot as made (no lock) {np.concatenate(moving).mean():.1f} cm/s")


if __name__ == "__main__":
    asked = sys.argv[1:] or ["jumps", "skate"]
    if "jumps" in asked:
        with tempfile.TemporaryDirectory() as folder:
            jumps(Path(folder))
    if "skate" in asked:
        skate()
