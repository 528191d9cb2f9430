"""Where a walk at turn = 0 turns: the generated features, before any pose is made.

    python examples/straight_walks.py [MODEL] [--seconds 12]

For each style at weight 1, x2 and -1: the step length the durations plan (frames), the frames
the planner gave the first right and left steps, the heading each kind of step turns on
average, the drift of the heading the yaw-rate feature integrates to (deg/s, a line fitted
to every stride's mean heading, as `instrument evaluate` measures the finished walk) and the
range those stride means cover (deg: a walk that weaves one way and back drifts little over
a long time but covers a wide range). The root
path is integrated from exactly this feature (motion/features.py restore_local), so a drift
here is a drift of the walk.
"""

from __future__ import annotations

import argparse

import numpy as np

from instrument.models.modelfile import default_model_path, load_model
from instrument.synthesis.durations import state_durations
from instrument.synthesis.interpolation import interpolate, style_space
from instrument.synthesis.engine import default_controls, walk_features

SETTLE_FRAMES = 15  # as instrument evaluate: the first half second is left out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("model", nargs="?", default=str(default_model_path()))
    parser.add_argument("--seconds", type=float, default=12.0)
    args = parser.parse_args()
    model = load_model(args.model)
    space, fps, states = style_space(model), model.fps, model.states
    frames = SETTLE_FRAMES + int(round(args.seconds * fps))
    print("| walk | planned step | right steps | left steps | turn per right / left step deg | drift deg/s | heading range deg |")
    print("|---|---|---|---|---|---|---|")
    for weight in (1.0, 2.0, -1.0):
        for style in model.style_names:
            controls = default_controls(model, {style: weight})
            static, ids = walk_features(model, controls, frames)
            static, label = static[SETTLE_FRAMES:], ids[SETTLE_FRAMES:] // states
            starts = np.flatnonzero(np.diff(label)) + 1
            yaw = np.degrees(np.concatenate([[0.0], np.cumsum(static[:, 3]) / fps]))
            lengths, kinds = np.diff(starts), label[starts[:-1]]
            turns = yaw[starts[1:]] - yaw[starts[:-1]]
            strides = list(zip(starts[:-2], starts[2:]))
            times = np.array([(a + b - 1) / 2.0 for a, b in strides]) / fps
            means = np.array([yaw[a:b].mean() for a, b in strides])
            drift = abs(np.polyfit(times, means, 1)[0])
            lam = interpolate(space, controls.weights)
            planned = state_durations(lam.duration_means, lam.duration_variances)[0].sum()
            name = style if weight == 1.0 else f"{style} {'x2' if weight == 2.0 else '-1'}"
            print(f"| {name} | {planned:.2f} | {' '.join(map(str, lengths[kinds == 0][:6]))} | "
                  f"{' '.join(map(str, lengths[kinds == 1][:6]))} | {turns[kinds == 0].mean():+.2f} / "
                  f"{turns[kinds == 1].mean():+.2f} | {drift:.2f} | {np.ptp(means):.1f} |")


if __name__ == "__main__":
    main()
