"""Styles from a single take: train on the first take of each style, judge against all the others.

    python examples/one_take.py ../shared/data/bandai-walk [--walks 4] [--seconds 20]

Two models are trained on the same seven takes: the default adaptation (re-aligned EM, shared
transforms over a regression class tree, MAP on top, settings chosen by held-out likelihood)
and the one-pass MAP adaptation that came before it. For each it prints

- the held-out log-likelihood per frame of every style's other takes under its own model and
  under the average model;
- how often walks synthesised at weight 1 for each style are recognised as that style by a
  linear discriminant trained on the other takes (style_fidelity.py's classifier), next to how
  often the real training takes themselves are; the target is >= 0.9 x the real takes' rate.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from style_fidelity import LinearDiscriminant, step_features  # noqa: E402

from instrument.errors import UserError, run_script  # noqa: E402
from instrument.training.adaptation import ONE_PASS_MAP  # noqa: E402
from instrument.training.build import build_model  # noqa: E402
from instrument.training.corpus import make_takes, read_motions, styled_takes  # noqa: E402
from instrument.evaluation.heldout import heldout_table  # noqa: E402
from instrument.motion.features import extract  # noqa: E402
from instrument.motion.steps import segment_steps  # noqa: E402
from instrument.synthesis.engine import default_controls, render  # noqa: E402


def recognised(classifier: LinearDiscriminant, model, style: str, walks: int, seconds: float) -> tuple[list[bool], list[bool]]:
    """(per walk, per step) whether synthesised walks of `style` are labelled `style`."""
    takes, steps = [], []
    for seed in range(walks):
        controls = default_controls(model, {style: 1.0}, liveliness=1.0 if seed else 0.0)
        motion = render(model, controls, int(seconds * model.fps), seed=seed)  # as synth writes it
        again, _, _ = extract(motion, model.layout)  # the walk as the classifier sees real takes
        x = step_features(again, segment_steps(motion, model.layout).steps)
        takes.append(classifier.take_label(x) == style)
        steps += [label == style for label in classifier.step_labels(x)]
    return takes, steps


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", help="folder of BVH takes named like dataset-2_walk_<style>_NNN.bvh (searched recursively)")
    parser.add_argument("--walks", type=int, default=4, help="synthesised walks per style (different seeds)")
    parser.add_argument("--seconds", type=float, default=20.0, help="length of each synthesised walk")
    args = parser.parse_args()
    if args.walks < 1 or not args.seconds > 0:
        raise UserError(f"--walks must be at least 1 and --seconds above 0 (got {args.walks}, {args.seconds})")
    pairs = styled_takes([args.data])
    first = [next(p for p in pairs if p[1] == s) for s in sorted({s for _, s in pairs})]
    others = [p for p in pairs if p not in first]
    if not others:
        raise UserError(f"{args.data}: one take per style: no other takes to judge the models against")

    results = {}
    for name, fixed in (("re-aligned, transforms + MAP", None), ("one-pass MAP (before)", ONE_PASS_MAP)):
        started = time.perf_counter()
        model, _, train_takes = build_model(first, adaptation=fixed)
        seconds = time.perf_counter() - started
        results[name] = (model, train_takes, seconds)

    model, train_takes, _ = next(iter(results.values()))
    dimension = model.layout.dimension
    other_takes, _ = make_takes(others, read_motions(others, model.fps), model.layout)
    classifier = LinearDiscriminant(np.vstack([step_features(t.observations[:, :dimension], t.steps) for t in other_takes]),
                                    [t.style for t in other_takes for _ in t.steps])
    real_takes, real_steps = [], []
    for t in train_takes:
        x = step_features(t.observations[:, :dimension], t.steps)
        real_takes.append(classifier.take_label(x) == t.style)
        real_steps += [label == t.style for label in classifier.step_labels(x)]
    print(f"trained on {len(first)} takes (the first of each style); classifier and held-out scores on the other {len(others)}")
    print(f"real training takes recognised: takes {sum(real_takes)}/{len(real_takes)}, "
          f"steps {100 * np.mean(real_steps):.0f}% of {len(real_steps)}")

    for name, (model, _, seconds) in results.items():
        table = heldout_table(model, others)
        print(f"\n{name} (trained in {seconds:.1f} s)")
        print("  style       own model  average  own - average  shortest state (frames)  walks recognised  steps recognised")
        all_walks, all_steps = [], []
        for style in model.style_names:
            walks, steps = recognised(classifier, model, style, args.walks, args.seconds)
            all_walks += walks
            all_steps += steps
            row = table[style]
            shortest = model.style(style).duration_means.min()
            print(f"  {style:<10} {row[style]:10.1f} {row['(average)']:8.1f} {row[style] - row['(average)']:14.1f} "
                  f"{shortest:24.2f} {sum(walks):11d}/{len(walks)} {100 * np.mean(steps):16.0f}%")
        ratio = np.mean(all_steps) / max(np.mean(real_steps), 1e-9)
        print(f"  all: walks {sum(all_walks)}/{len(all_walks)}, steps {100 * np.mean(all_steps):.0f}% "
              f"= {ratio:.2f} x the real takes' step rate; own model beats average on "
              f"{sum(table[s][s] > table[s]['(average)'] for s in model.style_names)}/{len(model.style_names)} styles")


if __name__ == "__main__":
    run_script(main, __file__)
