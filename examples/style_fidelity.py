"""Style fidelity: do synthesized walks look like their style to a classifier trained on real takes?

    python examples/style_fidelity.py ../shared/data/bandai-walk [--seconds 20]

A linear discriminant (shared, shrunk covariance) learns per-step features of real training
takes: the mean and spread of every static feature over the step, and the step's length. It
then labels (a) held-out real takes and (b) walks synthesized at weight 1 for each style by a
model trained on the same training takes. A take is labelled by the summed scores of its steps.
"""

from __future__ import annotations

import argparse

import numpy as np

from instrument.errors import UserError, run_script
from instrument.training.build import build_model
from instrument.training.corpus import make_takes, read_motions, styled_takes
from instrument.evaluation.heldout import split_holdout
from instrument.evaluation.recognition import LinearDiscriminant, step_features
from instrument.motion.features import extract
from instrument.motion.steps import segment_steps
from instrument.synthesis.engine import default_controls, render


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data")
    parser.add_argument("--seconds", type=float, default=20.0, help="length of each synthesized walk")
    parser.add_argument("--walks", type=int, default=4, help="synthesized walks per style (different seeds, liveliness 1)")
    args = parser.parse_args()
    if args.walks < 1 or not args.seconds > 0:
        raise UserError(f"--walks must be at least 1 and --seconds above 0 (got {args.walks}, {args.seconds})")
    pairs = styled_takes([args.data])
    train, held = split_holdout(pairs)
    model, _, train_takes = build_model(train)
    dimension = model.layout.dimension
    train_x = np.vstack([step_features(t.observations[:, :dimension], t.steps) for t in train_takes])
    train_y = [t.style for t in train_takes for _ in t.steps]
    classifier = LinearDiscriminant(train_x, train_y)

    held_takes, _ = make_takes(held, read_motions(held, model.fps), model.layout)
    real_hits, real_steps = [], []
    for t in held_takes:
        x = step_features(t.observations[:, :dimension], t.steps)
        real_hits.append(classifier.take_label(x) == t.style)
        real_steps += [label == t.style for label in classifier.step_labels(x)]

    frames = int(args.seconds * model.fps)
    synth_hits: dict[str, list[bool]] = {}
    synth_steps: list[bool] = []
    for style in model.style_names:
        for seed in range(args.walks):
            controls = default_controls(model, {style: 1.0}, liveliness=1.0 if seed else 0.0)
            motion = render(model, controls, frames, seed=seed)  # as synth writes it
            again, _, _ = extract(motion, model.layout)  # the walk as the classifier sees real takes
            steps = segment_steps(motion, model.layout).steps
            x = step_features(again, steps)
            synth_hits.setdefault(style, []).append(classifier.take_label(x) == style)
            synth_steps += [label == style for label in classifier.step_labels(x)]
    print(f"held-out real takes recognised: {sum(real_hits)}/{len(real_hits)} ({100 * np.mean(real_hits):.0f}%), "
          f"single steps {100 * np.mean(real_steps):.0f}% of {len(real_steps)}")
    total = [h for hits in synth_hits.values() for h in hits]
    print(f"synthesized walks recognised:   {sum(total)}/{len(total)} ({100 * np.mean(total):.0f}%), "
          f"single steps {100 * np.mean(synth_steps):.0f}% of {len(synth_steps)}")
    for style, hits in synth_hits.items():
        print(f"  {style:<10} {sum(hits)}/{len(hits)}")


if __name__ == "__main__":
    run_script(main, __file__)
