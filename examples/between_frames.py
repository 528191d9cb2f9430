"""How smooth, and how dear, the poses between the model's frames are (synthesis/between.py), with
the rules they are measured against (a benchmark, not a test).

    python examples/between_frames.py [--seconds 10] [--cost]

Jitter: each style of the shipped model at weight 1, played at 30, 60 and 120 fps through
`Engine.frame`, the mean magnitude of the third difference of every joint's world position
(m/s^3, `evaluate`'s figure) from 1 s on, with the knots between model frames made four ways:
the lerp (the rule before), Catmull-Rom's three-point tangent, the five-point tangent (the
engine's), and a natural cubic spline through the same 30 fps frames made with the whole walk
known (offline only: the floor a curve through these frames can reach).

`--cost`: the engine's work per model frame at 120 fps (one output frame making a model frame,
three between), lerped and on the curve, and at 30 fps, for one character and per character of a
crowd of 100 (all styles mixed, spread 0.5), each as a ratio to the window solve timed turn about
in the same run (`instrument bench`'s yardstick).
"""

from __future__ import annotations

import argparse

import numpy as np
from scipy.interpolate import CubicSpline

from instrument.cli.benchmarks import SOLVES, _walk_of_all_styles, against_yardstick, window_solves
from instrument.models.modelfile import load_model
from instrument.shipped import default_model_path
from instrument.synthesis.between import Knots
from instrument.synthesis.engine import Engine, default_controls
from instrument.synthesis.parameters import default_lookahead


class Lerp(Knots):
    """The rule before: a straight line between the two newest frames."""

    def at(self, fraction: float) -> np.ndarray:
        if fraction >= 1.0 - 1e-9 or len(self.frames) == 1:
            return self.frames[-1]
        return self.frames[-2] + (self.frames[-1] - self.frames[-2]) * fraction


class ThreePoint(Knots):
    """Catmull-Rom: the tangent from one provisional frame."""

    def add(self, frame: np.ndarray, forward: np.ndarray | None) -> None:
        super().add(frame, None if forward is None else np.ascontiguousarray(forward[:, :1]))


class Spline(Knots):
    """A natural cubic spline through the walk's frames, all known beforehand (`frames`)."""

    def __init__(self, frames: np.ndarray):
        super().__init__()
        self.spline, self.newest = CubicSpline(np.arange(len(frames)), frames, axis=0), -1

    def add(self, frame: np.ndarray, forward: np.ndarray | None) -> None:
        self.newest += 1
        super().add(frame, forward)

    def at(self, fraction: float) -> np.ndarray:
        if fraction >= 1.0 - 1e-9 or len(self.frames) == 1:
            return self.frames[-1]
        return self.spline(self.newest - 1 + fraction)


def jitter(model, controls, fps: float, seconds: float, knots: Knots | None = None) -> float:
    engine = Engine(model, fps=fps)
    if knots is not None:
        engine.knots = knots
    positions = np.array([engine.frame(k / fps, controls).world_positions[0] for k in range(int(seconds * fps))])
    positions = positions[int(fps):]
    return float(np.linalg.norm(np.diff(positions, 3, axis=0), axis=2).mean() * fps**3 / 100.0)


def jitter_table(seconds: float) -> None:
    model = load_model(default_model_path())
    print("style | 30 fps | 60: lerp / three / five / spline | 120: lerp / three / five / spline")
    for style in model.style_names:
        controls = default_controls(model, {style: 1.0})
        made = Engine(model)
        frames = np.array([made.sample(k / model.fps, controls) for k in range(int(seconds * model.fps) + 2)])
        row = [f"{jitter(model, controls, model.fps, seconds):.1f}"]
        for fps in (2 * model.fps, 4 * model.fps):
            row.append(" / ".join(f"{jitter(model, controls, fps, seconds, knots):.1f}"
                                  for knots in (Lerp(), ThreePoint(), Knots(), Spline(frames))))
        print(f"{style} | " + " | ".join(row), flush=True)


def cost_table() -> None:
    model, controls, lam, ids = _walk_of_all_styles(None)
    frames = 30
    solves = window_solves(lam, ids, frames, default_lookahead(model.fps))

    def player(count: int, fps: float, lerp: bool, pose: bool):
        engine = Engine(model, count, fps)
        if lerp:  # the rule before: no forward differences made, a lerp between the frames
            engine.knots = Lerp()
            engine._forward = lambda ahead, solved: None
        clock = [0]

        def work() -> None:
            for _ in range(frames * round(fps / model.fps)):
                t = clock[0] / fps
                engine.frame(t, controls, 0.5) if pose else engine.sample(t, controls, 0.5)
                clock[0] += 1

        return work

    for count in (1, 100):
        works = {f"{'posed' if pose else 'engine'}, {name}": player(count, fps, lerp, pose) for pose in (False, True)
                 for name, fps, lerp in (("30 fps", model.fps, False), ("120 fps lerp", 4 * model.fps, True),
                                         ("120 fps curve", 4 * model.fps, False))}
        _, ratios, solve = against_yardstick(works, solves, 9)
        print(f"{count} character(s): window solves per model frame per character (a solve {1e6 * solve / frames:.1f} us)")
        for name, ratio in ratios.items():
            print(f"  {name}: {ratio / count:.2f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=10.0)
    parser.add_argument("--cost", action="store_true", help="the cost table instead of the jitter table")
    args = parser.parse_args()
    cost_table() if args.cost else jitter_table(args.seconds)


if __name__ == "__main__":
    main()
