"""From BVH takes to a complete Model: corpus, average model, style models, metadata."""

from __future__ import annotations

import platform
import time
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from .. import __version__
from ..errors import UserError
from ..models.modelfile import Model
from ..motion.features import ROOT_FEATURES, WINDOWS
from ..motion.gestures import PHASES
from ..motion.standing import PIECE_SECONDS
from ..motion.steps import LABELS
from ..synthesis.interpolation import body_groups
from ..synthesis.parameters import GROUPS
from .adaptation import DEFAULT, Settings, adapt_styles
from .average import TrainingReport, train_average, variance_floors
from .contact import train_contact
from .corpus import Take, load_corpus, segments_by_label
from .gestures import gesture_metadata, gesture_segments, model_gestures
from .height import stand_on_the_floor
from .little import LITTLE_TAU, keep_own_steps
from .symmetry import symmetric_models
from .units import held_posture, mirrored_pairs, model_units
from .widen import calibrate_range, train_range

UNSPECIFIED_LICENCE = "unspecified: the licence of the training data applies"

# a stand's "steps" are pieces of still standing (motion/standing.py): "no left step" said nothing a user could act on
STAND_TOO_LITTLE = ("unit 'stand': its takes hold too little still standing with the arms down for a right and a left piece "
                    "of {states} frames or more (one still stretch of {seconds:g} s gives both, before or after the gesture): ")


def build_model(
    pairs: list[tuple],
    fps: float = 30.0,
    states: int = 5,
    command: str = "",
    licence: str = UNSPECIFIED_LICENCE,
    attribution: str = "",
    progress: Callable[[int, int, str], None] | None = None,
    on_iteration: Callable[[int, float], None] | None = None,
    adaptation: Settings | None = None,
    little_tau: float | None = LITTLE_TAU,
) -> tuple[Model, TrainingReport, list[Take]]:
    """`adaptation` fixes the style adaptation's settings (for comparisons); None chooses them per
    style by held-out likelihood. `little_tau` (steps) is the prior of a style's own step
    durations and swing (training/little.py); None leaves them as the adaptation and the range
    filter make them alone."""
    started = time.perf_counter()
    layout, takes, warnings, rates = load_corpus(pairs, fps, progress, states)
    report = TrainingReport(warnings=list(warnings), capture_rates=rates)
    units = model_units({t.unit for t in takes})
    gestures = model_gestures(takes)  # their labels after the units' (models/gestures.py)

    def labelled(chosen: list[Take]) -> list[list[np.ndarray]]:
        return segments_by_label(chosen, states, units) + gesture_segments(chosen, states, gestures)

    segments = labelled(takes)
    # a label no take has a segment of has no average to train (nor to keep): its unit or gesture
    # is left out, and the gait plays the walk as on a model trained without it
    lacking = {unit: foot for k, unit in enumerate(units) for f, foot in enumerate(LABELS) if not segments[2 * k + f]}
    if "walk" in lacking:
        raise UserError(f"the walking takes hold no {lacking['walk']} step long enough for {states} states: "
                        "a model needs both feet's steps (longer or more walks)")
    lacking_phase = {g: phase for k, g in enumerate(gestures) for p, phase in enumerate(PHASES)
                     if not segments[2 * len(units) + len(PHASES) * k + p]}
    if lacking or lacking_phase:
        report.warnings += [(STAND_TOO_LITTLE.format(states=states, seconds=2 * PIECE_SECONDS) if unit == "stand" else
                             f"unit {unit!r}: no {foot} step long enough for {states} states in any take: ")
                            + "left out (its gait plays the walk)" for unit, foot in lacking.items()]
        report.warnings += [f"gesture {g!r}: no {phase} long enough for {states} states in any take: left out"
                            for g, phase in lacking_phase.items()]
        units = [u for u in units if u not in lacking]
        gestures = [g for g in gestures if g not in lacking_phase]
        segments = labelled(takes)
    floors = variance_floors(segments)
    average = train_average(segments, states, floors, report=report, on_iteration=on_iteration)
    style_names = sorted({t.style for t in takes})
    per_style = {s: [(t.unit, labelled([t])) for t in takes if t.style == s] for s in style_names}
    styles, adapted = adapt_styles(average, per_style, floors, report.warnings, adaptation, fps, units)
    data_weights = {}
    if little_tau is not None:  # each unit's step durations toward the style's own (training/little.py)
        mine = [labelled([t for t in takes if t.style == style]) for style in style_names]
        styles, by_index = keep_own_steps(average, styles, mine, units, little_tau, (adaptation or DEFAULT).floor_share,
                                            fps)
        data_weights = {style_names[s]: w for s, w in by_index.items()}
    contact, contact_metadata = train_contact(layout, takes, average, styles, style_names, fps, states, units)
    pairs_mirrored = mirrored_pairs(units)  # straight at turn = 0 (the turns keep their turn)
    average, styles = symmetric_models(average, styles, layout.dimension, pairs_mirrored)
    if "stand" in units:  # the stand's arms held in the style's posture (training/units.py)
        stand = 2 * units.index("stand")
        arms = np.flatnonzero(body_groups(layout)[GROUPS.index("upper")])
        travel = tuple(w * layout.dimension + ROOT_FEATURES.index(f) for w in range(3)
                       for f in ("root.vx", "root.vz", "root.yaw_rate"))
        average = held_posture(average, [stand, stand + 1], arms, layout.dimension, travel)
        styles = held_posture(styles, [stand, stand + 1], arms, layout.dimension, travel)
    walks = [t for t in takes if t.unit == "walk"]
    for k, style in enumerate(style_names):  # the shortest state as the shipped model has it (mirroring shares durations)
        adapted[style].min_duration = float(styles.duration_means[k].min())
    dimension = layout.dimension
    step_max = np.max([np.abs(np.diff(t.observations[:, :dimension], axis=0)).max(axis=0) for t in takes], axis=0)
    static_std = np.vstack([t.observations[:, :dimension] for t in takes]).std(axis=0)
    metadata = {
        "fps": fps,
        "states": states,
        "labels": ([f"{unit}/{foot}" for unit in units for foot in LABELS] if units != ["walk"] or gestures else list(LABELS))
        + [f"gesture/{g}/{phase}" for g in gestures for phase in PHASES],
        "units": units,
        "styles": style_names,
        "skeleton": layout.skeleton.to_dict(),
        "features": layout.to_dict(),
        "windows": [w.tolist() for w in WINDOWS],
        "licence": licence,
        "attribution": attribution,
        "training": {
            "command": command,
            "states": states,
            "fps": fps,
            "iterations": len(report.loglik_per_frame),
            "loglik_per_frame": report.loglik_per_frame,
            "variance_floor_ratio": 0.01,
            "adaptation": {style: r.to_dict() for style, r in adapted.items()},
            "mirror_image_steps": True,
            "little_data": {"tau_steps": little_tau, "walk_weights": data_weights},
            "seconds": round(time.perf_counter() - started, 1),
            "instrument_version": __version__,
            "python": platform.python_version(),
            "numpy": np.__version__,
        },
        "data": [
            {"file": t.path.name, "style": t.style, "unit": t.unit, "frames": t.frames, "steps": len(t.steps),
             "sha256": t.sha256} | ({"gesture": t.gesture} if t.gesture else {}) for t in takes
        ],
        "mean_step_frames": {  # of the walk (the model card reads it); a style with no walking step has none
            # (its walk comes from its other units through the shared transform): not NaN, which no model loads
            s: float(np.mean(frames)) for s in style_names
            if (frames := [st.frames for t in walks if t.style == s for st in t.steps])
        },
        "warnings": report.warnings,
    }
    if contact_metadata:
        metadata["contact"] = contact_metadata
    if gestures:
        metadata["gestures"] = gesture_metadata(takes, gestures, 2 * len(units))
    model = Model(metadata, average, styles, static_std, step_max, contact)
    return ranged_and_standing(model, walks, little_tau), report, takes


def ranged_and_standing(model: Model, walks: list[Take], little_tau: float | None = LITTLE_TAU) -> Model:
    """`model` (its contact statistics trained) with its range factors, its body's height and
    then its limbs' calibration (knees, hips, shoulders), in that order: the height shift is
    measured on the walk the features and their ranges make, feet not locked; the limbs are
    calibrated on the walk as played, feet locked on the floor, which is only the takes' once the
    body stands on it (the calibration run first fitted a raised capture's knees to a walk the
    shift then moved)."""
    model = replace(model, extras=dict(model.extras or {}) | train_range(model, walks))
    model = stand_on_the_floor(model, walks)
    return replace(model, extras=dict(model.extras) | calibrate_range(model, walks, little_tau))
