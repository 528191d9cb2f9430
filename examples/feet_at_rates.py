"""The feet as users get them at 30 and 120 fps: each style at weight 1, walking and running,
recorded by `instrument run --fast --fps F --bvh` and read back by the independent reader.

    python examples/feet_at_rates.py [--seconds 12] [--out DIR]

Figures (from 1 s on), each at 30 fps, 120 fps and their ratio:
- planted: a planted foot's slide (`tests/test_engine.py`'s `planted_speed`, cm/s);
- skate: the evaluation's (`motion.quality.skate`'s rule: the lowest foot joint of both feet,
  its speed over the floor in every frame, cm/s; a run's flight counts, so runs read 100-200);
- viewer: `bvh_independent.foot_skate` (each foot joint in its lowest 20% of heights, cm/s), and
  the same read on the 120 fps file's every fourth frame (the mean over the four phases): what
  that measure says of the same motion sampled at 30 fps;
- jitter: `tests/test_engine.py`'s `jitter` (every joint's third difference, m/s^3).

docs/evaluate.md, "The feet at 120 fps as recorded: hand-overs and runs".
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from bvh_independent import world_positions  # noqa: E402
from test_engine import jitter, planted_speed  # noqa: E402

STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]
FEET = ["Foot_L", "Toes_L", "Foot_R", "Toes_R"]
RATES = (30, 120)


def skate(names: list[str], positions: np.ndarray, fps: float) -> float:
    """The evaluation's skate (`motion.quality.skate`) on the joints named FEET."""
    feet = [names.index(n) for n in FEET]
    lowest = np.argmin(positions[:, feet, 1], axis=1)
    moving = np.linalg.norm(np.gradient(positions[:, feet][:, :, [0, 2]], axis=0), axis=2) * fps
    return float(moving[np.arange(len(positions)), lowest].mean())


def viewer(names: list[str], positions: np.ndarray, fps: float) -> float:
    """`bvh_independent.foot_skate`'s speed, on positions already read (so a file's every fourth
    frame can be read as well)."""
    speeds = []
    for name in FEET:
        track = positions[:, names.index(name)]
        contact = track[:, 1] <= np.percentile(track[:, 1], 20)
        velocity = np.linalg.norm(np.diff(track[:, [0, 2]], axis=0), axis=1) * fps
        speeds.append(velocity[contact[1:] & contact[:-1]])
    return float(np.mean(np.concatenate(speeds)))


def record(out: Path, style: str, gait: str, fps: int, seconds: float) -> dict[str, float]:
    score = out / f"{style}-{gait}.toml"
    run = ', gait = "run"' if gait == "run" else ""
    score.write_text(f'[[cue]]\nat = 0\nramp = {{ "style/{style}" = 1.0{run} }}\n')
    path = out / f"{style}-{gait}-{fps}.bvh"
    ran = subprocess.run([sys.executable, "-m", "instrument", "run", "--score", str(score), "--fast", "--seconds",
                          str(seconds), "--fps", str(fps), "--no-osc", "--quiet", "--force", "--bvh", str(path)],
                         capture_output=True, text=True, cwd=ROOT)
    if ran.returncode:
        raise SystemExit(ran.stderr)
    names, positions, rate = world_positions(path)
    positions = positions[round(rate):]
    figures = {"planted": planted_speed(path), "skate": skate(names, positions, rate),
               "viewer": viewer(names, positions, rate), "jitter": jitter(path)}
    if fps != RATES[0]:
        step = round(fps / RATES[0])
        figures["viewer_sampled"] = float(np.mean([viewer(names, positions[k::step], rate / step) for k in range(step)]))
    return figures


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=12.0)
    parser.add_argument("--out", type=Path, help="keep the recordings here (default: a temporary folder)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as scratch:
        out = args.out or Path(scratch)
        out.mkdir(parents=True, exist_ok=True)
        jobs = [(style, gait, fps) for gait in ("walk", "run") for style in STYLES for fps in RATES]
        with ThreadPoolExecutor(2) as pool:  # each job is a process of its own
            results = dict(zip(jobs, pool.map(lambda job: record(out, *job, args.seconds), jobs)))
    for gait in ("walk", "run"):
        print(f"\n{gait}: 30 / 120 fps (ratio)\n")
        print("| style | planted cm/s | skate cm/s | viewer cm/s (120 read at 30) | jitter m/s^3 |")
        print("|---|---|---|---|---|")
        for style in STYLES:
            low, high = results[(style, gait, 30)], results[(style, gait, 120)]
            cells = [f"{low[k]:.2f} / {high[k]:.2f} ({high[k] / low[k]:.2f})" for k in ("planted", "skate")]
            cells.append(f"{low['viewer']:.2f} / {high['viewer']:.2f} ({high['viewer_sampled']:.2f})")
            cells.append(f"{low['jitter']:.1f} / {high['jitter']:.1f} ({high['jitter'] / low['jitter']:.2f})")
            print(f"| {style} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
