"""Styles from little data (issue 30): train on one take per style, judge against the held-out takes.

    python examples/little_data.py ../shared/data/bandai-walk [--taus today,0,4,16,64] [--take 1]
                                   [--seconds 12] [--styles NAME ...] [--json FILE]

For each value of the little-data prior (`--taus`; `today` is the adaptation alone, a number is
`tau` in steps: the style's step durations and swing follow its own take with the weight
n / (n + tau), n its steps, see instrument/training/little.py) a model is trained on the
`--take`-th take of each style (in name order) and each style's 12 s walk at weight 1 is measured
against all the style's other takes, which it never saw:

- recognised: the share of the walk's steps that a classifier trained on the held-out takes
  labels as the style, beside the share of the training take's own steps it labels so (a real
  take it did not see either);
- knee, hip and shoulder range error against the held-out takes' (pooled, as `instrument
  evaluate` measures them), in percent;
- step duration error against the held-out takes' mean step, in percent.

It prints one Markdown table per prior and a summary (means of the absolute errors) and, with
`--json`, writes every figure to FILE.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

from instrument.errors import UserError, run_script
from instrument.evaluation.assessment import SETTLE_SECONDS, model_limbs
from instrument.evaluation.recognition import LinearDiscriminant, step_features
from instrument.motion.bvh import Motion
from instrument.motion.features import extract
from instrument.motion.kinematics import world_positions
from instrument.motion.quality import pooled, take_floors, walk_figures
from instrument.motion.steps import segment_steps
from instrument.synthesis.engine import default_controls, render
from instrument.training.build import build_model
from instrument.training.corpus import TakeFile, make_takes, read_motions, styled_takes

RANGES = ("knee_deg", "hip_deg", "shoulder_deg")


def parse_taus(text: str) -> list[float | None]:
    """--taus: comma-separated `today` (None: the adaptation alone) or tau in steps (>= 0)."""
    parts = [p.strip() for p in text.split(",")]
    if not all(parts):
        raise UserError(f"--taus: expected 'today' or numbers of steps, comma-separated, not {text!r}")
    out: list[float | None] = []
    for part in parts:
        if part == "today":
            out.append(None)
            continue
        try:
            value = float(part)
        except ValueError:
            raise UserError(f"--taus: {part!r} is neither 'today' nor a number of steps") from None
        if not (math.isfinite(value) and value >= 0):
            raise UserError(f"--taus: {part!r} must be a finite number of steps, 0 or more")
        out.append(value)
    return out


def split(pairs: list[TakeFile], take: int, styles: list[str] | None = None) -> tuple[list[TakeFile], list[TakeFile]]:
    """Per style, its `take`-th walking take (1-based, in name order) trains; the others are held out."""
    walks = [p for p in pairs if p.unit == "walk"]
    names = sorted({p.style for p in walks})
    missing = [s for s in styles or [] if s not in names]
    if missing:
        raise UserError(f"--styles: no walking takes of style {missing[0]!r} (there are {', '.join(names) or 'none'})")
    train, held = [], []
    for style in styles or names:
        mine = sorted((p for p in walks if p.style == style), key=lambda p: p.path.name)
        if len(mine) < take + 1:
            raise UserError(f"style {style!r} has {len(mine)} walking takes: --take {take} needs that one and another to hold out")
        train.append(mine[take - 1])
        held += [p for k, p in enumerate(mine) if k != take - 1]
    return train, held


class HeldOut:
    """The held-out takes read once for every model trained on the same takes (one layout): their
    figures per style, a classifier trained on their steps, and the training takes' own steps."""

    def __init__(self, model, held: list[TakeFile], train: list[TakeFile]):
        self.limbs, self.cm, _ = model_limbs(model)
        layout, dimension = model.layout, model.layout.dimension
        motions = read_motions(held, model.fps)
        takes, _ = make_takes(held, motions, layout)
        positions = [world_positions(m) for m in motions]
        floors = take_floors(positions, self.limbs)  # each take on its own floor, a made walk on their mean
        self.ground, self.sole = floors.mean_ground, floors.mean_sole
        features = [step_features(t.observations[:, :dimension], t.steps) for t in takes]
        self.classifier = LinearDiscriminant(np.vstack(features), [t.style for t, x in zip(takes, features) for _ in x])
        self.real = {style: pooled([walk_figures(m, layout, self.limbs, g, self.cm, f)
                                    for m, p, g, f in zip(motions, held, floors.ground, floors.sole) if p.style == style])
                     for style in {p.style for p in held}}
        own, _ = make_takes(train, read_motions(train, model.fps), layout)
        self.own = {t.style: step_features(t.observations[:, :dimension], t.steps) for t in own}

    def rate(self, features: np.ndarray, style: str) -> float:
        """The share of steps the classifier labels `style`."""
        return float(np.mean([label == style for label in self.classifier.step_labels(features)])) if len(features) else 0.0

    def judge(self, model, seconds: float) -> dict[str, dict[str, float]]:
        """Per style: the walk's figures against the held-out takes' (see the module's docstring)."""
        layout = model.layout
        settle = int(round(SETTLE_SECONDS * model.fps))
        out = {}
        for style in model.style_names:
            real = self.real[style]
            motion = render(model, default_controls(model, {style: 1.0}), settle + int(round(seconds * model.fps)))
            motion = Motion(motion.skeleton, motion.channels[settle:], motion.fps)
            made = walk_figures(motion, layout, self.limbs, self.ground, self.cm, self.sole)
            steps = segment_steps(motion, layout).steps
            row = {"recognised": self.rate(step_features(extract(motion, layout)[0], steps), style),
                   "recognised_real": self.rate(self.own[style], style), "step_s": made["step_s"],
                   "step_s_real": real["step_s"], "step_err_pct": 100.0 * (made["step_s"] / real["step_s"] - 1.0)}
            for key in RANGES:
                row[key] = made[key]
                row[f"{key}_real"] = real[key]
                row[f"{key.split('_')[0]}_err_pct"] = 100.0 * (made[key] / real[key] - 1.0)
            out[style] = row
        return out


def summary(rows: dict[str, dict[str, float]]) -> dict[str, float]:
    """Means over the styles: absolute errors, recognition rates and their ratio."""
    keys = ("step_err_pct", "knee_err_pct", "hip_err_pct", "shoulder_err_pct")
    out = {f"mean_abs_{k}": float(np.mean([abs(r[k]) for r in rows.values()])) for k in keys}
    synth = float(np.mean([r["recognised"] for r in rows.values()]))
    real = float(np.mean([r["recognised_real"] for r in rows.values()]))
    return out | {"recognised": synth, "recognised_real": real, "recognised_ratio": synth / real if real else float("nan")}


def table(name: str, rows: dict[str, dict[str, float]]) -> str:
    lines = [f"prior {name}", "",
             "| style | recognised made / real take | step s made / held-out (err) | knee err | hip err | shoulder err |",
             "|---|---|---|---|---|---|"]
    for style, r in rows.items():
        lines.append(f"| {style} | {r['recognised']:.2f} / {r['recognised_real']:.2f} | {r['step_s']:.3f} / "
                     f"{r['step_s_real']:.3f} ({r['step_err_pct']:+.1f}%) | {r['knee_err_pct']:+.1f}% | "
                     f"{r['hip_err_pct']:+.1f}% | {r['shoulder_err_pct']:+.1f}% |")
    s = summary(rows)
    lines.append(f"\nmean |error|: step {s['mean_abs_step_err_pct']:.1f}%, knee {s['mean_abs_knee_err_pct']:.1f}%, "
                 f"hip {s['mean_abs_hip_err_pct']:.1f}%, shoulder {s['mean_abs_shoulder_err_pct']:.1f}%; recognised "
                 f"{s['recognised']:.2f} against the real takes' {s['recognised_real']:.2f} ({s['recognised_ratio']:.2f}x)")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("data", nargs="+", help="folders of BVH takes named like dataset-2_walk_<style>_NNN.bvh")
    parser.add_argument("--taus", default="today,0,4,16,64", help="priors to compare: 'today' or tau in steps, comma-separated")
    parser.add_argument("--take", type=int, default=1, help="which take of each style trains (1-based, name order)")
    parser.add_argument("--seconds", type=float, default=12.0, help="length of each synthesised walk")
    parser.add_argument("--styles", nargs="+", metavar="NAME", help="only these styles (default: all)")
    parser.add_argument("--json", metavar="FILE", help="write every figure to FILE")
    args = parser.parse_args()
    taus = parse_taus(args.taus)
    if args.take < 1:
        raise UserError(f"--take must be 1 or more (got {args.take})")
    if not (math.isfinite(args.seconds) and 2.0 <= args.seconds <= 600.0):
        raise UserError(f"--seconds must be 2 to 600 (got {args.seconds})")
    for folder in args.data:
        if not Path(folder).exists():
            raise UserError(f"{folder}: no such file or folder")
    train, held = split(styled_takes(args.data), args.take, args.styles)
    results, held_out = {}, None
    for tau in taus:
        name = "today" if tau is None else f"tau {tau:g}"
        model, _, _ = build_model(train, little_tau=tau)
        held_out = held_out or HeldOut(model, held, train)
        rows = held_out.judge(model, args.seconds)
        results[name] = {"tau": tau, "styles": rows, "summary": summary(rows),
                         "weights": model.metadata["training"].get("little_data", {})}
        print(table(name, rows) + "\n", flush=True)
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    sys.exit(run_script(main, __file__))
