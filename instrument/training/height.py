"""The body's height, set so that the walk a model makes stands on the floor its takes stand on.

A state's joint rotations and the body's height are learnt (averaged) each on its own. Where the
takes disagree (a crouching take and an upright one: the public CMU walk, tests/data/cmu-131,
bends its knees through 113 degrees in one take and 51 in the other), the leg of the averaged
angles reaches further down than the takes' legs do on average (the cosines of a mean angle
exceed the mean of the cosines), and the range filter, straightening the stance knee further,
more so: that model's walk planted its feet 5-12 cm below the floor, the foot lock lifted them
onto it by bending the stance knee, and the played knee swung 14% less than the takes' (hip
10%). So, for the average and for each style, the walk the model makes (feet not locked) is
measured against its takes: how high the lower foot's lowest joint stands above its clearance
(the foot that carries the body), the median over the frames; the body's height is moved by
the difference (every state's mean), so the made walk's feet stand where the takes' do.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..motion.bvh import Motion
from ..motion.features import ROOT_FEATURES, restore_local
from ..motion.kinematics import forward_kinematics, world_positions
from ..motion.limbs import Limbs, centimetres_per_unit, find_limbs
from ..motion.quality import take_floors
from ..synthesis.engine import render
from ..synthesis.stream import Controls
from .widen import settle_frames

SECONDS = 12.0  # of each made walk measured


def standing_height(positions: np.ndarray, limbs: Limbs, ground: np.ndarray) -> float:
    """Median over the frames of the lower foot's height above the floor (each foot's lowest
    joint above that joint's clearance `ground` (2, foot joints)), in the positions' units."""
    lifts = [(positions[:, list(foot), 1] - ground[f]).min(axis=1) for f, foot in enumerate(limbs.feet)]
    return float(np.median(np.minimum(*lifts)))


def _unlocked(model):
    """The model without its contact statistics: its walk as the features make it, feet not locked."""
    return replace(model, extras={k: v for k, v in (model.extras or {}).items() if not k.startswith("contact_")})


def stand_on_the_floor(model, takes):
    """`model` with the body's height of the average and of each style moved so that the walk
    each makes at its own weights stands on its takes' floor (see the module's text). A model
    without two legs or without walking takes is returned as it is."""
    layout = model.layout
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    stored = model.metadata.get("contact", {}).get("clearance")
    chosen = [t for t in takes if t.steps]
    if limbs is None or stored is None or not chosen:
        return model
    ground = np.asarray(stored, dtype=np.float64)
    dimension = layout.dimension
    positions = [forward_kinematics(layout.skeleton, *restore_local(t.observations[:, :dimension], layout, model.fps)[:2])[1]
                 for t in chosen]
    floors = take_floors(positions, limbs)
    real = {t.style: [] for t in chosen}
    for take, p, g in zip(chosen, positions, floors.ground):
        real[take.style].append((standing_height(p, limbs, g), take.frames))
    unlocked = _unlocked(model)
    names = model.style_names
    column = ROOT_FEATURES.index("root.height")

    def offset(weights: np.ndarray, heights: list[tuple[float, int]]) -> float:
        settle = settle_frames(model.fps)  # from rest
        made = render(unlocked, Controls(weights), settle + int(round(SECONDS * model.fps)))
        made = world_positions(Motion(made.skeleton, made.channels[settle:], made.fps))
        shift = np.average([h for h, _ in heights], weights=[n for _, n in heights]) - standing_height(made, limbs, ground)
        return float(shift) if np.isfinite(shift) else 0.0

    everything = [h for style in real.values() for h in style]
    average_shift = offset(np.zeros(len(names)), everything)
    style_shifts = np.array([offset(np.eye(len(names))[s], real[name]) if real.get(name) else average_shift
                             for s, name in enumerate(names)])
    average_means = model.average.means.copy()
    average_means[..., column] += average_shift
    style_means = model.styles.means.copy()
    style_means[..., column] += style_shifts[:, None, None]
    metadata = dict(model.metadata)
    cm = centimetres_per_unit(layout, positions[0][0])
    metadata["training"] = dict(metadata.get("training", {}), standing_shift_cm={
        "average": round(average_shift * cm, 2), **{n: round(float(d) * cm, 2) for n, d in zip(names, style_shifts)}})
    return replace(model, metadata=metadata, average=replace(model.average, means=average_means),
                   styles=replace(model.styles, means=style_means))
