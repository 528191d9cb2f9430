"""How hard a run sets off from a stand: the hips' peak horizontal acceleration in the start.

    python examples/start_acceleration.py [MODEL] [STYLE:WEIGHT ...]

For each weighting (default: normal x2, active, active x2, feminine x2, masculine x2), the
evaluation's run -> stand -> run sequence (transitions.transition_sequence); the hips' (the
root joint's) horizontal speed over 5 frames (|p[k+5] - p[k]| / 5 frames), and its largest change
from one frame to the next (m/s^2) in the start's first 1.5 s, beside the steady run's (its
first part, 1.5 s on to 1 s before the stop); and the largest joint velocity jump (cm/frame^2,
sequence.velocity_jumps) over the same spans (docs/evaluate.md, "A run sets off over two pushes").
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from instrument.evaluation.sequence import velocity_jumps
from instrument.evaluation.transitions import transition_sequence
from instrument.evaluation.units import model_limbs
from instrument.models.modelfile import default_model_path, load_model
from instrument.motion.kinematics import world_positions

WEIGHTINGS = [("normal", 2.0), ("active", 1.0), ("active", 2.0), ("feminine", 2.0), ("masculine", 2.0)]
SPAN = 5  # frames the speed is taken over
START_SECONDS = 1.5  # the start's span after the command


def main() -> int:
    args = sys.argv[1:]
    model = load_model(args.pop(0) if args and ":" not in args[0] else str(default_model_path()))
    weightings = [(style, float(weight)) for style, weight in (a.split(":") for a in args)] or WEIGHTINGS
    _, cm, _ = model_limbs(model)
    fps = model.fps
    print("| stand->run | hips' peak m/s^2 start / steady | largest jump cm/frame^2 start / steady |")
    print("|---|---|---|")
    for style, weight in weightings:
        sequence = transition_sequence(model, "run", {style: weight})
        positions = world_positions(sequence.motion) * cm
        hips = positions[:, model.layout.root][:, [0, 2]]
        stop_at, start_at = sequence.changes
        speed = np.linalg.norm(hips[SPAN:] - hips[:-SPAN], axis=1) / SPAN * fps / 100.0  # m/s
        change = np.abs(np.diff(speed)) * fps
        jumps = velocity_jumps(positions)
        start, steady = slice(start_at, start_at + int(START_SECONDS * fps)), slice(int(1.5 * fps), stop_at - int(fps))
        print(f"| {style} x{weight:g} | {change[start].max():.1f} / {change[steady].max():.1f} "
              f"| {jumps[start].max():.1f} / {jumps[steady].max():.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
