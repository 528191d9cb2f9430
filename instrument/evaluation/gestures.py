"""`instrument evaluate --gestures`: each gesture of a model, played over a walk in each style,
measured against the real gesture takes it learnt from.

For each style at weight 1 and each gesture: a walk of `seconds` with the gesture tapped at
START_SECONDS (the engine as `synth --gesture` plays it), and the same walk (same seed) without
it. Figures:

- `over_head_cm`: the hands' highest point above the head's top joint over the gesture (negative:
  below it), `reach_cm` the hands' farthest horizontal reach from the root, `up_s` how long after
  the press the hands are highest, `duration_s` how long the gesture has any of the upper body;
- `speed_ratio`, `skate_ratio`: the walk's speed and foot skate over the gesture (motion/quality.py's
  figures) over the same stretch of the walk without it;
- `recognised`: the share of the gesture's repeat half cycles a linear discriminant trained on the
  real takes' half cycles (upper body only: the takes stand, the walk walks) labels with the style,
  beside the share of the real takes' own half cycles it labels right when each take is left out;
- `cost_ratio`: a frame's time (the whole engine, posing included; the median over the gesture)
  with the gesture over the same frame's without it; `solve_ratio` the gesture's stage over the
  gait's stream stage (its window solve) while it plays.

The takes' rows have the same figures where they mean something (over the head, reach, duration
from raise to lower, recognised).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..models.gestures import gesture_labels
from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.features import extract
from ..motion.kinematics import ChannelStream, world_positions
from ..motion.quality import walk_figures
from ..motion.standing import hand_joints
from ..motion.steps import Step
from ..synthesis.engine import Engine, default_controls
from ..synthesis.interpolation import body_groups
from ..synthesis.parameters import GROUPS
from ..training.corpus import make_takes, read_motions
from .assessment import model_limbs, real_pairs
from .recognition import LinearDiscriminant, step_features

START_SECONDS = 2.0


@dataclass
class GestureAssessment:
    synth: dict[str, dict[str, float]] = field(default_factory=dict)  # "wave elderly" -> figures
    real: dict[str, dict[str, float]] = field(default_factory=dict)  # "wave elderly" -> figures of its takes


class Body:
    """Where a model's hands and head are, and how to measure a pose sequence in centimetres."""

    def __init__(self, model: Model):
        self.layout = model.layout
        self.limbs, self.cm, template = model_limbs(model)
        parents = self.layout.skeleton.parents
        self.hands = hand_joints(parents, self.limbs, template)
        leaves = [j for j in range(len(parents)) if not (parents == j).any()]
        self.head = max(leaves, key=lambda j: template[j, 1])
        self.upper = np.flatnonzero(body_groups(self.layout)[GROUPS.index("upper")])

    def figures(self, positions: np.ndarray, fps: float) -> dict[str, float]:
        """Over the head, reach and when the hands are highest, of positions (frames, joints, 3)."""
        pos = positions * self.cm
        over = pos[:, self.hands, 1].max(axis=1) - pos[:, self.head, 1]
        reach = np.linalg.norm((pos[:, self.hands] - pos[:, [self.limbs.root]])[..., [0, 2]], axis=-1).max(axis=1)
        return {"over_head_cm": float(over.max()), "reach_cm": float(reach.max()), "up_s": float(np.argmax(over) / fps)}


def play(model: Model, weights: dict[str, float], frames: int, gesture: str | None, seed: int = 0):
    """A walk with `gesture` tapped at START_SECONDS: (Motion, the gesture's share of the upper
    body per frame, the gesture's label per frame (-1 none), each frame's seconds (the whole
    engine: stream, stages, posing), the stream's and the gesture's stage seconds while it plays)."""
    engine = Engine(model, seed=seed)
    controls = default_controls(model, weights)
    channels = ChannelStream(model.layout.skeleton)
    start = int(round(START_SECONDS * engine.fps))
    rows, shares, labels, seconds = [], np.zeros(frames), np.full(frames, -1), np.zeros(frames)
    stages = {"stream": 0.0, "gestures": 0.0}
    for k in range(frames):
        engine.stage_seconds = {} if gesture and k > start else None
        begun = time.perf_counter()
        pose = engine.frame(k / engine.fps, replace(controls, gestures=(gesture,) if gesture and k == start else ()))
        seconds[k] = time.perf_counter() - begun
        rows.append(channels.next(pose.rotations[0], pose.translations[0]))
        layer = engine.gestures
        shares[k] = layer.weights[0] if layer.playing else 0.0
        if layer.playing:
            labels[k] = layer.crowd.history_ids[0, 1] // model.states
            for stage in stages:
                stages[stage] += (engine.stage_seconds or {}).get(stage, 0.0)
    return Motion(model.layout.skeleton, np.array(rows), model.fps), shares, labels, seconds, stages


def _runs(labels: np.ndarray, wanted: list[int]) -> list[Step]:
    """The stretches of frames with one label of `wanted` each, as Steps."""
    steps, start = [], 0
    for k in range(1, len(labels) + 1):
        if k == len(labels) or labels[k] != labels[start]:
            if labels[start] in wanted and k - start >= 2:
                steps.append(Step(f"{labels[start]}", start, k))
            start = k
    return steps


def assess_gestures(model: Model, seconds: float = 12.0, real: Path | list[Path] | None = None, styles: list[str] | None = None,
                    progress=None) -> GestureAssessment:
    styles = styles or model.style_names
    body = Body(model)
    result = GestureAssessment()
    gestures = gesture_labels(model.metadata)
    classifiers: dict[str, LinearDiscriminant] = {}
    if real is not None and gestures:
        pairs = real_pairs(model, real, units=("stand",))
        motions = read_motions(pairs, model.fps)
        takes, _ = make_takes(pairs, motions, body.layout, states=model.states)
        for gesture in gestures:
            mine = [(t, m) for t, m in zip(takes, motions) if t.gesture == gesture and t.phases]
            features = [step_features(t.observations[:, body.upper], [s for s in t.phases if s.label.startswith("repeat")])
                        for t, _ in mine]
            kept = [(t, m, f) for (t, m), f in zip(mine, features) if len(f)]
            if len({t.style for t, _, _ in kept}) < 2:
                continue
            classifiers[gesture] = LinearDiscriminant(np.vstack([f for _, _, f in kept]),
                                                      [t.style for t, _, f in kept for _ in f])
            right = _left_out(kept)
            for style in styles:
                own = [(t, m) for t, m, _ in kept if t.style == style] or [(t, m) for t, m in mine if t.style == style]
                if not own:
                    continue
                figures = [body.figures(world_positions(m)[t.phases[0].start:t.phases[-1].end], m.fps) for t, m in own]
                row = {key: float(np.mean([f[key] for f in figures])) for key in ("over_head_cm", "reach_cm")}
                row["duration_s"] = float(np.mean([(t.phases[-1].end - t.phases[0].start) / m.fps for t, m in own]))
                row["recognised"] = right.get(style, float("nan"))
                result.real[f"{gesture} {style}"] = row
    frames = max(1, int(round(seconds * model.fps)))
    for gesture, labels in gestures.items():
        for style in styles:
            weights = {style: 1.0}
            motion, shares, played, seconds_with, stages = play(model, weights, frames, gesture)
            plain, _, _, seconds_without, _ = play(model, weights, frames, None)
            on = np.flatnonzero(shares > 0)
            if not len(on):
                result.synth[f"{gesture} {style}"] = {"duration_s": 0.0}
                continue
            a, b = int(on[0]), int(on[-1]) + 1
            positions = world_positions(motion)
            row = body.figures(positions[a:b], model.fps)
            row["up_s"] += a / model.fps - START_SECONDS
            row["duration_s"] = (b - a) / model.fps
            cut = lambda m: Motion(m.skeleton, m.channels[a:b], m.fps)  # noqa: E731
            ground = np.zeros(2)
            with_it, without = (walk_figures(cut(m), body.layout, body.limbs, ground, body.cm) for m in (motion, plain))
            row["speed_ratio"] = with_it["speed_cm_s"] / max(without["speed_cm_s"], 1e-9)
            row["skate_ratio"] = with_it["skate_cm_s"] / max(without["skate_cm_s"], 1e-9)
            row["cost_ratio"] = float(np.median(seconds_with[a + 1:b]) / max(np.median(seconds_without[a + 1:b]), 1e-12))
            row["solve_ratio"] = stages["gestures"] / max(stages["stream"], 1e-12)
            row["recognised"] = float("nan")
            if gesture in classifiers:
                steps = _runs(played, labels[2:4])  # the repeat's halves
                if steps:
                    static = extract(motion, body.layout)[0]
                    guesses = classifiers[gesture].step_labels(step_features(static[:, body.upper], steps))
                    row["recognised"] = float(np.mean([g == style for g in guesses]))
            result.synth[f"{gesture} {style}"] = row
            if progress:
                progress(f"{gesture} {style}")
    return result


def _left_out(kept) -> dict[str, float]:
    """Per style: the share of its takes' repeat half cycles labelled right by a classifier trained
    on the other takes."""
    hits: dict[str, list[bool]] = {}
    for k, (take, _, features) in enumerate(kept):
        others = [(t, f) for j, (t, _, f) in enumerate(kept) if j != k]
        if len({t.style for t, _ in others}) < 2:
            continue
        classifier = LinearDiscriminant(np.vstack([f for _, f in others]), [t.style for t, f in others for _ in f])
        hits.setdefault(take.style, []).extend(g == take.style for g in classifier.step_labels(features))
    return {style: float(np.mean(h)) for style, h in hits.items()}


COLUMNS = (("over_head_cm", "hands over head cm", "{:.1f}"), ("reach_cm", "reach cm", "{:.1f}"),
           ("up_s", "highest at s", "{:.2f}"), ("duration_s", "duration s", "{:.2f}"),
           ("speed_ratio", "speed x", "{:.2f}"), ("skate_ratio", "skate x", "{:.2f}"),
           ("recognised", "recognised", "{:.2f}"), ("cost_ratio", "frame cost x", "{:.2f}"),
           ("solve_ratio", "gesture / solve", "{:.2f}"))


def gesture_table(result: GestureAssessment) -> str:
    """A Markdown table: for each gesture and style, its takes' row first."""
    def row(name: str, figures: dict) -> str:
        cells = [fmt.format(figures[key]) if key in figures and np.isfinite(figures[key]) else "-"
                 for key, _, fmt in COLUMNS]
        return "| " + " | ".join([name] + cells) + " |"

    lines = ["| gesture | " + " | ".join(h for _, h, _ in COLUMNS) + " |", "|---" * (len(COLUMNS) + 1) + "|"]
    for name, figures in result.synth.items():
        if name in result.real:
            lines.append(row(f"{name} (real)", result.real[name]))
        lines.append(row(name, figures))
    return "\n".join(lines)
