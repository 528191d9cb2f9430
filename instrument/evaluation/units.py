"""`instrument evaluate --units`: each motion unit against its own real takes, and the transitions.

    run     gait run, each style at weight 1, x2 and -1, against the style's run takes: the walk's
            figures (speed, step, skate, flight share `air_frac`), the largest joint velocity
            jump, and recognition by a classifier trained on the real runs (as the walk's)
    turn    a full `turn` each way (the model's turning rate, so every step is a turning one) at
            weight 1, against the style's turning takes that way: turn rate (deg/s), radius, skate
    stand   gait stand at weight 1, x2 and -1, against the still frames of the standing takes
            (motion/standing.py): the hips' horizontal speed, the feet's, and the posture
            recognised by a classifier trained on those still frames
    transitions  walk and run -> stand -> walk and run, each style at 1, x2 and -1 (transitions.py)

Every motion comes from the engine as `synth` makes it; every figure is measured from the
skeleton's geometry (motion/quality.py), in cm, s and degrees.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.features import extract, heading_angle
from ..motion.kinematics import forward_kinematics, local_transforms, world_positions
from ..motion.limbs import Limbs, clearance
from ..motion.quality import AIR_CM, pooled, stride_headings, walk_figures
from ..motion.standing import pieces, still_frames
from ..motion.steps import Step, segment_steps
from ..synthesis.engine import Engine, default_controls, render
from ..synthesis.parameters import GAITS
from ..training.corpus import Take, TakeFile, make_takes, read_motions
from .assessment import SETTLE_SECONDS, _cross_validated, _limbs, _model_ground, real_pairs
from .recognition import LinearDiscriminant, step_features
from .sequence import horizontal_speed, velocity_jumps
from .transitions import transition_figures

UNIT_SECONDS = 8.0  # length of each generated run, turn and stand (after the settling half second)
WEIGHTINGS = (("", 1.0), (" x2", 2.0), (" -1", -1.0))  # the variants of a style: name suffix, weight
SIDES = ((1, "left"), (-1, "right"))  # turn's sign, and the turning unit's side
SECTIONS = ("run", "turn", "stand", "transitions")


@dataclass
class RealUnit:
    """A unit's real takes: each file, its motion, its world positions (cm) and its steps (None:
    none found, as training leaves it out)."""

    files: list[TakeFile] = field(default_factory=list)
    motions: list[Motion] = field(default_factory=list)
    positions: list[np.ndarray] = field(default_factory=list)
    takes: list[Take | None] = field(default_factory=list)

    def of_style(self, style: str) -> list[int]:
        return [k for k, f in enumerate(self.files) if f.style == style]

    def largest_jumps(self) -> dict[str, float]:
        """The largest joint velocity jump (cm/frame^2) over these takes ("all") and each style's."""
        largest = [float(velocity_jumps(p).max()) for p in self.positions]
        out = {"all": max(largest)} if largest else {}
        for style in dict.fromkeys(f.style for f in self.files):
            out[style] = max(largest[k] for k in self.of_style(style))
        return out


@dataclass
class UnitAssessment:
    weights: dict[str, dict[str, float]] = field(default_factory=dict)  # walk name -> style weights
    synth: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)  # section -> walk name -> figures
    real: dict[str, dict[str, dict[str, float]]] = field(default_factory=dict)  # section -> style (turn: "style left") -> figures
    transitions: dict[str, dict[str, float]] = field(default_factory=dict)  # "walk->stand active x2" -> figures
    real_jumps: dict[str, dict[str, float]] = field(default_factory=dict)  # unit -> style or "all" -> largest jump of its real takes, cm/frame^2


def load_real_units(model: Model, folders: list[Path], cm: float) -> dict[str, RealUnit]:
    """Every take the model lists that is in `folders`, by unit (walks, runs, turns, stands)."""
    files = real_pairs(model, folders, units=None)
    motions = read_motions(files, model.fps)
    out: dict[str, RealUnit] = {}
    for file, motion in zip(files, motions):
        takes, _ = make_takes([file], [motion], model.layout, states=model.states)
        unit = out.setdefault(file.unit, RealUnit())
        unit.files.append(file)
        unit.motions.append(motion)
        unit.positions.append(world_positions(motion) * cm)
        unit.takes.append(takes[0] if takes else None)
    return out


def assess_units(model: Model, real: list[Path] | None = None, styles: list[str] | None = None,
                 seconds: float = UNIT_SECONDS, progress=None, sections: tuple[str, ...] = SECTIONS) -> UnitAssessment:
    """The figures of every unit the model has beyond the walk, and of its transitions (see the
    module's text), of the `sections` asked for; with `real`, the same of the real takes beside them."""
    styles = styles or model.style_names
    limbs, cm, template = _limbs(model)
    layout = model.layout
    result = UnitAssessment()
    reals = load_real_units(model, real, cm) if real else {}
    walks = reals.get("walk")
    ground = clearance([p / cm for p in walks.positions], limbs) if walks else _model_ground(model, limbs, template)
    measure = _Measure(model, limbs, cm, ground)
    for unit, takes in reals.items():
        result.real_jumps[unit] = takes.largest_jumps()
    if walks:  # what the transitions of a walk are held to (its skate, its flight)
        result.real["walk"] = {style: _pooled([measure.moving(walks.motions[k], walks.positions[k]) for k in walks.of_style(style)])
                               for style in styles if walks.of_style(style)}
    settle = int(round(SETTLE_SECONDS * model.fps))
    frames = settle + max(1, int(round(seconds * model.fps)))

    def note(name: str) -> None:
        if progress:
            progress(name)

    if "run" in model.units and "run" in sections:
        runs = reals.get("run")
        classifier = None
        real_runs = result.real.setdefault("run", {})
        if runs:
            classifier, recognised = _recogniser([t for t in runs.takes if t is not None], layout.dimension)
            for style in styles:
                mine = [measure.moving(runs.motions[k], runs.positions[k]) for k in runs.of_style(style)]
                if mine:
                    real_runs[style] = _pooled(mine) | {"recognised": recognised.get(style, float("nan"))}
        section = result.synth.setdefault("run", {})
        for style in styles:
            for suffix, weight in WEIGHTINGS:
                name = f"{style}{suffix}"
                result.weights[name] = {style: weight}
                motion = _settled(render(model, default_controls(model, {style: weight}, gait=GAITS.index("run")), frames), settle)
                figures = measure.moving(motion, world_positions(motion) * cm)
                if classifier is not None and weight > 0:
                    figures["recognised"] = _recognised(classifier, motion, layout, segment_steps(motion, layout).steps, style)
                section[name] = figures
                note(f"run {name}")

    turning = [(sign, side) for sign, side in SIDES if f"turn-{side}" in model.units]
    if turning and "turn" in sections:
        rates = Engine(model).units.turn_rates
        section, real_turns = result.synth.setdefault("turn", {}), result.real.setdefault("turn", {})
        for sign, side in turning:
            takes = reals.get(f"turn-{side}")
            for style in styles:
                if takes:
                    mine = [measure.turning(takes.motions[k], takes.positions[k]) for k in takes.of_style(style)]
                    if mine:
                        real_turns[f"{style} {side}"] = _pooled(mine)
                name = f"{style} {side}"
                result.weights[name] = {style: 1.0}
                controls = default_controls(model, {style: 1.0}, turn=sign * rates[sign])
                motion = _settled(render(model, controls, frames), settle)
                section[name] = measure.turning(motion, world_positions(motion) * cm) | {"turn_asked_deg_s": float(np.degrees(sign * rates[sign]))}
                note(f"turn {name}")

    if "stand" in model.units and "stand" in sections:
        stands = reals.get("stand")
        classifier = None
        real_stands = result.real.setdefault("stand", {})
        if stands:
            classifier, recognised = _recogniser([t for t in stands.takes if t is not None], layout.dimension, posture=True)
            for style in styles:
                mine = [measure.standing(stands.motions[k], stands.positions[k], still_frames(stands.motions[k], layout))
                        for k in stands.of_style(style)]
                mine = [m for m in mine if m["seconds"] > 0]
                if mine:
                    hips = [m["hips_cm_s"] for m in mine]
                    real_stands[style] = _pooled(mine) | {"recognised": recognised.get(style, float("nan")),
                                                          "hips_min_cm_s": min(hips), "hips_max_cm_s": max(hips)}
        section = result.synth.setdefault("stand", {})
        for style in styles:
            for suffix, weight in WEIGHTINGS:
                name = f"{style}{suffix}"
                result.weights[name] = {style: weight}
                motion = _settled(render(model, default_controls(model, {style: weight}, gait=GAITS.index("stand")), frames), settle)
                figures = measure.standing(motion, world_positions(motion) * cm, np.ones(motion.frames, dtype=bool))
                if classifier is not None and weight > 0:
                    figures["recognised"] = _recognised(classifier, motion, layout, _pieces(0, motion.frames, model.fps), style, posture=True)
                section[name] = figures
                note(f"stand {name}")
    if "stand" in model.units and "transitions" in sections:
        for gait in ("walk", "run"):
            if gait not in model.units:
                continue
            for style in styles:
                for suffix, weight in WEIGHTINGS:
                    name = f"{style}{suffix}"
                    result.weights[name] = {style: weight}
                    for kind, figures in transition_figures(model, gait, {style: weight}, measure).items():
                        result.transitions[f"{kind} {name}"] = figures
                    note(f"{gait}->stand->{gait} {name}")
    return result


class _Measure:
    """The figures of one motion (real or generated), with the model's limbs, scale and ground."""

    def __init__(self, model: Model, limbs: Limbs, cm: float, ground: np.ndarray):
        self.layout, self.limbs, self.cm, self.ground = model.layout, limbs, cm, ground

    def moving(self, motion: Motion, positions: np.ndarray) -> dict[str, float]:
        """The walk's figures, the skate over the frames a foot is on the ground (`stance_skate_cm_s`:
        a run's flight is no skate) and the largest joint velocity jump (cm/frame^2)."""
        ground = ~self.air(positions)
        stance = self.skate(positions, motion.fps)[ground]
        return walk_figures(motion, self.layout, self.limbs, self.ground, self.cm) | {
            "stance_skate_cm_s": float(stance.mean()) if len(stance) else float("nan"),
            "jump_cm_f2": float(velocity_jumps(positions).max()), "finite": float(np.isfinite(motion.channels).all())}

    def turning(self, motion: Motion, positions: np.ndarray) -> dict[str, float]:
        """The walk's figures and the turn (stride_headings: each stride's mean heading):
        `turn_deg_s` the mean rate, first stride to last (+ to the left), `turn_peak_deg_s` the rate
        through the middle half of the heading's change (a take that walks in and out of its
        turn turns faster in it than on average; a steady turn has both the same), and
        `radius_cm`, the speed over the mean rate."""
        figures = self.moving(motion, positions)
        world_rot = forward_kinematics(motion.skeleton, *local_transforms(motion))[0]
        yaw = heading_angle(world_rot[:, self.layout.root])
        times, headings = stride_headings(yaw, segment_steps(motion, self.layout).steps, motion.fps)
        rate = peak = float("nan")
        if len(times) >= 2 and times[-1] > times[0]:
            total = headings[-1] - headings[0]
            rate = total / (times[-1] - times[0])
            turned = (headings - headings[0]) * np.sign(total or 1.0)  # rising, give or take the sway
            quarter, three = (np.interp(share * abs(total), np.maximum.accumulate(turned), times) for share in (0.25, 0.75))
            peak = 0.5 * abs(total) / max(three - quarter, 1.0 / motion.fps)
        figures["turn_signed_deg_s"] = rate
        figures["turn_deg_s"] = abs(rate)
        figures["turn_peak_deg_s"] = peak
        figures["radius_cm"] = figures["speed_cm_s"] / max(np.radians(abs(rate)), 1e-9)
        return figures

    def air(self, positions: np.ndarray) -> np.ndarray:
        """(frames,) bool: both feet more than AIR_CM above their clearance."""
        lifts = [(positions[:, list(foot), 1] - self.ground[f] * self.cm).min(axis=1) for f, foot in enumerate(self.limbs.feet)]
        return (np.array(lifts) > AIR_CM).all(axis=0)

    def skate(self, positions: np.ndarray, fps: float) -> np.ndarray:
        """(frames,) horizontal speed of the lowest foot joint (cm/s), as walk_figures' skate."""
        feet = list(self.limbs.feet[0] + self.limbs.feet[1])
        lowest = np.argmin(positions[:, feet, 1], axis=1)
        moving = np.linalg.norm(np.gradient(positions[:, feet][:, :, [0, 2]], axis=0), axis=2) * fps
        return moving[np.arange(len(positions)), lowest]

    def standing(self, motion: Motion, positions: np.ndarray, still: np.ndarray) -> dict[str, float]:
        """Over the `still` frames: the hips' (root's) horizontal speed and the feet's (every foot
        joint's, averaged), cm/s, and the largest joint velocity jump."""
        fps = motion.fps
        root = horizontal_speed(positions[:, self.layout.root], fps)
        feet = [j for foot in self.limbs.feet for j in foot]
        foot = np.mean([horizontal_speed(positions[:, j], fps) for j in feet], axis=0)
        if not still.any():
            return {"hips_cm_s": float("nan"), "feet_cm_s": float("nan"), "seconds": 0.0}
        return {"hips_cm_s": float(root[still].mean()), "feet_cm_s": float(foot[still].mean()),
                "jump_cm_f2": float(velocity_jumps(positions).max()), "finite": float(np.isfinite(motion.channels).all()),
                "seconds": float(still.sum() / fps)}


def _settled(motion: Motion, settle: int) -> Motion:
    return Motion(motion.skeleton, motion.channels[settle:], motion.fps)


def _pooled(figures: list[dict[str, float]]) -> dict[str, float]:
    """`pooled` over every key the figures share (weighted by length), and the largest jump as a maximum."""
    out = pooled(figures) if "step_s" in figures[0] else {}
    weights = np.array([f["seconds"] for f in figures])
    for key in figures[0]:
        if key in out or key == "seconds":
            continue
        values = np.array([f[key] for f in figures])
        ok = np.isfinite(values)
        if key == "jump_cm_f2":
            out[key] = float(values[ok].max()) if ok.any() else float("nan")
        else:
            out[key] = float(np.average(values[ok], weights=weights[ok])) if ok.any() and weights[ok].sum() > 0 else float("nan")
    if "radius_cm" in out:  # the radius of the pooled speed and rate, not the mean of each take's (a straight take's is huge)
        out["radius_cm"] = out["speed_cm_s"] / max(np.radians(out["turn_deg_s"]), 1e-9)
    out["seconds"] = float(weights.sum())
    return out


def _recogniser(takes: list[Take], dimension: int, posture: bool = False) -> tuple[LinearDiscriminant, dict[str, float]]:
    """A style classifier on the takes' steps (as the walk's), and the takes' own cross-validated
    recognition. A `posture` classifier sees only each piece's mean features (the pose held),
    not their spread over it: a stand's sway is measured apart (hips and feet speeds), and the
    stand unit holds its arms still by design (training/units.py), which the spread would count
    against it."""
    features = [_described(t.observations[:, :dimension], t.steps, posture) for t in takes]
    classifier = LinearDiscriminant(np.vstack(features), [t.style for t, x in zip(takes, features) for _ in x])
    return classifier, _cross_validated(takes, features)


def _described(static: np.ndarray, steps: list[Step], posture: bool) -> np.ndarray:
    features = step_features(static, steps)
    return features[:, :static.shape[1]] if posture else features


def _recognised(classifier: LinearDiscriminant, motion: Motion, layout, steps: list[Step], style: str,
                posture: bool = False) -> float:
    """The share of `steps` of `motion` the classifier labels `style`."""
    if not steps:
        return float("nan")
    static, _, _ = extract(motion, layout)
    return float(np.mean([label == style for label in classifier.step_labels(_described(static, steps, posture))]))


def _pieces(start: int, end: int, fps: float) -> list[Step]:
    """A stretch of standing cut as training cuts the standing takes' still stretches."""
    return [Step("right" if k % 2 == 0 else "left", a, b) for k, (a, b) in enumerate(pieces(start, end, fps))]
