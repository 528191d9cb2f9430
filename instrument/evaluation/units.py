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
    part-way     for PARTWAY_STYLES of the styles at 1, x2 and -1, a stop called off and a start
                 stopped, swept over when the second command comes (transitions.partway_figures),
                 and per gait and weighting the worst against the steady gait and the real takes
                 (`partway_summary`): figures, not targets (issue 25 sets none for them)

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
from ..motion.quality import AIR_CM, mean_turn_rate, pooled, stride_headings, walk_figures
from ..motion.standing import pieces, still_frames
from ..motion.steps import Step, segment_steps
from ..synthesis.engine import Engine, default_controls, render
from ..synthesis.parameters import GAITS
from ..training.corpus import Take, TakeFile, make_takes, read_motions
from .assessment import SETTLE_SECONDS, _cross_validated, model_limbs, _model_ground, real_pairs
from .recognition import LinearDiscriminant, step_features
from .sequence import horizontal_speed, velocity_jumps
from .transitions import transition_figures

UNIT_SECONDS = 8.0  # length of each generated run, turn and stand (after the settling half second)
WEIGHTINGS = (("", 1.0), (" x2", 2.0), (" -1", -1.0))  # the variants of a style: name suffix, weight
SIDES = ((1, "left"), (-1, "right"))  # turn's sign, and the turning unit's side
SECTIONS = ("run", "turn", "stand", "transitions")
PARTWAY_STYLES = 3  # styles swept for changes part-way: spread evenly over those measured (the first, middle, last)


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
    # (gait, change, style, weight): ("walk", "stop called off", "active", 2.0) -> the sweep's worst
    partway: dict[tuple[str, str, str, float], dict[str, float]] = field(default_factory=dict)
    real_jumps: dict[str, dict[str, float]] = field(default_factory=dict)  # unit -> style or "all" -> largest jump of its real takes, cm/frame^2

    def partway_by_name(self) -> dict[str, dict[str, float]]:
        """`partway` keyed as the JSON has it: "walk stop called off active x2"."""
        return {f"{gait} {change} {style}{weight_suffix(weight)}": figures
                for (gait, change, style, weight), figures in self.partway.items()}


def weight_suffix(weight: float) -> str:
    """A weight of WEIGHTINGS as a walk's name ends with it: "" (1), " x2", " -1"."""
    return next(suffix for suffix, w in WEIGHTINGS if w == weight)


def load_real_units(model: Model, folders: list[Path], cm: float) -> dict[str, RealUnit]:
    """Every take the model lists that is in `folders`, by unit (walks, runs, turns, stands), as
    training took it: a turning take by the way it turns, one that does not turn left out."""
    files = real_pairs(model, folders, units=None)
    motions = read_motions(files, model.fps)
    out: dict[str, RealUnit] = {}
    for file, motion in zip(files, motions):
        takes, _ = make_takes([file], [motion], model.layout, states=model.states)
        if file.unit.startswith("turn-") and not takes:
            continue
        file = file._replace(unit=takes[0].unit) if takes else file
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
    limbs, cm, template = model_limbs(model)
    reals = load_real_units(model, real, cm) if real else {}
    walks = reals.get("walk")
    ground = clearance([p / cm for p in walks.positions], limbs) if walks else _model_ground(model, limbs, template)
    work = _Assessor(model, _Measure(model, limbs, cm, ground), reals, styles or model.style_names, seconds, progress)
    for unit, takes in reals.items():
        work.result.real_jumps[unit] = takes.largest_jumps()
    if walks:  # what the transitions of a walk are held to (its skate, its flight)
        work.result.real["walk"] = work.real_figures(walks, work.measure.moving)
    if "run" in model.units and "run" in sections:
        work.gait("run", work.measure.moving, lambda motion: segment_steps(motion, model.layout).steps)
    if "turn" in sections:
        work.turns()
    if "stand" in model.units and "stand" in sections:
        def whole(motion: Motion, positions: np.ndarray) -> dict[str, float]:  # a generated stand stands throughout
            return work.measure.standing(motion, positions, np.ones(motion.frames, dtype=bool))

        work.gait("stand", whole, lambda motion: _pieces(0, motion.frames, model.fps), posture=True,
                  real=lambda motion, positions: work.measure.standing(motion, positions, still_frames(motion, model.layout)))
    if "stand" in model.units and "transitions" in sections:
        work.transitions()
    return work.result


class _Assessor:
    """One `assess_units` call's work: the model, how to measure, the real takes, the result."""

    def __init__(self, model: Model, measure: _Measure, reals: dict[str, RealUnit], styles: list[str],
                 seconds: float, progress):
        self.model, self.measure, self.reals, self.styles, self.progress = model, measure, reals, styles, progress
        self.settle = int(round(SETTLE_SECONDS * model.fps))
        self.frames = self.settle + max(1, int(round(seconds * model.fps)))
        self.result = UnitAssessment()

    def made(self, name: str, weights: dict[str, float], **controls) -> tuple[Motion, np.ndarray]:
        """A steady motion of these weights and controls (the settling left out) and its world positions (cm)."""
        self.result.weights[name] = weights
        motion = render(self.model, default_controls(self.model, weights, **controls), self.frames)
        motion = Motion(motion.skeleton, motion.channels[self.settle:], motion.fps)
        return motion, world_positions(motion) * self.measure.cm

    def real_figures(self, takes: RealUnit, figures_of, key=lambda style: style) -> dict[str, dict[str, float]]:
        """Each style's takes measured with `figures_of(motion, positions)` and pooled (takes
        with nothing to measure, as a standing take without still frames, left out)."""
        out = {}
        for style in self.styles:
            mine = [figures_of(takes.motions[k], takes.positions[k]) for k in takes.of_style(style)]
            mine = [m for m in mine if m["seconds"] > 0]
            if mine:
                out[key(style)] = _pooled(mine)
                if "hips_cm_s" in mine[0]:  # a stand: how much the quietest and the most restless take sway
                    hips = [m["hips_cm_s"] for m in mine]
                    out[key(style)] |= {"hips_min_cm_s": min(hips), "hips_max_cm_s": max(hips)}
        return out

    def gait(self, gait: str, figures_of, cut, posture: bool = False, real=None) -> None:
        """A gait's section: its real takes (measured with `real`, else `figures_of`), and each
        style at 1, x2 and -1, recognised (at a positive weight) on the pieces `cut(motion)` gives."""
        takes = self.reals.get(gait)
        classifier = None
        if takes:
            classifier, recognised = _recogniser([t for t in takes.takes if t is not None], self.model.layout.dimension, posture)
            self.result.real[gait] = {style: figures | {"recognised": recognised.get(style, float("nan"))}
                                      for style, figures in self.real_figures(takes, real or figures_of).items()}
        section = self.result.synth.setdefault(gait, {})
        for style in self.styles:
            for suffix, weight in WEIGHTINGS:
                name = f"{style}{suffix}"
                motion, positions = self.made(name, {style: weight}, gait=GAITS.index(gait))
                figures = figures_of(motion, positions)
                if classifier is not None and weight > 0:
                    figures["recognised"] = _recognised(classifier, motion, self.model.layout, cut(motion), style, posture)
                section[name] = figures
                self.note(f"{gait} {name}")

    def turns(self) -> None:
        """Each side's full turn, each style at 1, against the style's takes turning that way."""
        turning = [(sign, side) for sign, side in SIDES if f"turn-{side}" in self.model.units]
        if not turning:
            return
        engine = Engine(self.model)  # each style's own full turn (its turning steps' rate): every step turns
        section = self.result.synth.setdefault("turn", {})
        for sign, side in turning:
            takes = self.reals.get(f"turn-{side}")
            if takes:
                self.result.real.setdefault("turn", {}).update(
                    self.real_figures(takes, self.measure.turning, key=lambda style: f"{style} {side}"))
            for style in self.styles:
                name = f"{style} {side}"
                engine.retune(default_controls(self.model, {style: 1.0}))
                turn = sign * float(engine.units.turn_rates[sign][0])
                motion, positions = self.made(name, {style: 1.0}, turn=turn)
                section[name] = self.measure.turning(motion, positions) | {"turn_asked_deg_s": float(np.degrees(turn))}
                self.note(f"turn {name}")

    def transitions(self) -> None:
        """walk -> stand -> walk and run -> stand -> run, each style at 1, x2 and -1; for
        PARTWAY_STYLES of them, the sweep of changes part-way forked from the same sequence."""
        swept = partway_styles(self.styles)
        for gait in ("walk", "run"):
            if gait not in self.model.units:
                continue
            for style in self.styles:
                for suffix, weight in WEIGHTINGS:
                    name = f"{style}{suffix}"
                    self.result.weights[name] = {style: weight}
                    transitions, partway = transition_figures(self.model, gait, {style: weight}, self.measure,
                                                              partway=style in swept)
                    self.result.transitions.update({f"{kind} {name}": figures for kind, figures in transitions.items()})
                    self.result.partway.update({(gait, change, style, weight): figures for change, figures in partway.items()})
                    self.note(f"{gait}->stand->{gait} {name}")

    def note(self, name: str) -> None:
        if self.progress:
            self.progress(name)


def partway_styles(styles: list[str]) -> list[str]:
    """PARTWAY_STYLES of `styles` spread evenly over them (all of them, when as few)."""
    if len(styles) <= PARTWAY_STYLES:
        return list(styles)
    return [styles[round(k * (len(styles) - 1) / (PARTWAY_STYLES - 1))] for k in range(PARTWAY_STYLES)]


def partway_summary(result: UnitAssessment) -> dict[str, dict[str, float | str]]:
    """Per change, gait and weighting ("walk stop called off 1", "run start stopped x2"): of the
    styles swept, the one whose worst jump is the largest multiple of its own steady gait's at
    those weights (`x_steady`: transitions.steady_jump), not the one with the largest jump in
    cm/frame^2 (a livelier style's steady gait jumps more: its larger jump may stand out less),
    with that style's jump (`jump_cm_f2`), name (`walk`), joint and delay, and the jump as a
    multiple of the real takes' largest (`x_real`: the style's own at weight 1, every style's at
    x2 and -1, as the transition targets take it); and, apart, the style whose worst slide is the
    largest multiple of the real takes' stance skate (`slide_x_real`: the style's at 1, the
    largest style's at x2 and -1), with its slide (`slide_cm_s`) and name (`slide_walk`)."""
    out: dict[str, dict[str, float | str]] = {}
    for (gait, kind, style, weight), made in result.partway.items():
        suffix = weight_suffix(weight)
        walk = f"{style}{suffix}"
        jumps, reals = result.real_jumps.get(gait, {}), result.real.get(gait, {})
        real_jump = jumps.get(style if weight == 1.0 else "all", float("nan"))
        skates = [f["stance_skate_cm_s"] for f in reals.values()]
        real_skate = (reals[style]["stance_skate_cm_s"] if weight == 1.0 and style in reals
                      else max(skates) if skates else float("nan"))
        row = {"jump_cm_f2": made["jump_cm_f2"], "x_steady": made["jump_cm_f2"] / made["gait_jump_cm_f2"],
               "x_real": made["jump_cm_f2"] / real_jump, "walk": walk, "jump_joint": made.get("jump_joint", ""),
               "delay_frames": made.get("delay_frames", float("nan")), "slide_cm_s": made["slide_cm_s"],
               "slide_x_real": made["slide_cm_s"] / real_skate, "slide_walk": walk}
        key = f"{gait} {kind} {suffix.strip() or '1'}"
        if key not in out:
            out[key] = row
            continue
        mine = out[key]
        if not row["x_steady"] <= mine["x_steady"]:
            mine |= {k: row[k] for k in ("jump_cm_f2", "x_steady", "x_real", "walk", "jump_joint", "delay_frames")}
        if not row["slide_x_real"] <= mine["slide_x_real"] and not np.isnan(row["slide_x_real"]):
            mine |= {"slide_cm_s": row["slide_cm_s"], "slide_x_real": row["slide_x_real"], "slide_walk": walk}
    return out


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
        """The walk's figures and the turn: `turn_deg_s` the mean rate (quality.mean_turn_rate:
        the mean heading over the last stride less that over the first, over the time between:
        the mean of the yaw rate a turning unit learns from its takes; + to the left), `turn_peak_deg_s`
        the rate through the middle half of the heading's change, from each stride's mean
        heading (a take walks into and out of its turn and turns faster in it than on average;
        a steady turn has both the same), and `radius_cm`, the speed over the mean rate."""
        figures = self.moving(motion, positions)
        world_rot = forward_kinematics(motion.skeleton, *local_transforms(motion))[0]
        yaw = np.degrees(heading_angle(world_rot[:, self.layout.root], self.layout.heading_reference))
        steps = segment_steps(motion, self.layout).steps
        rate, peak = mean_turn_rate(yaw, steps, motion.fps), float("nan")
        times, headings = stride_headings(np.radians(yaw), steps, motion.fps)
        if len(times) >= 2 and headings[-1] != headings[0]:
            total = headings[-1] - headings[0]
            turned = np.maximum.accumulate((headings - headings[0]) * np.sign(total))  # rising, the sway aside
            quarter, three = (np.interp(share * abs(total), turned, times) for share in (0.25, 0.75))
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
