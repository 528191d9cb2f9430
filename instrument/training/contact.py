"""Training's half of the foot lock: which foot is planted in each state, learnt from the takes.

Each foot of each frame of a take is labelled as in contact when its lowest joint is within
CONTACT_CM of its ground clearance and moves slower than CONTACT_SPEED_CM_S horizontally; the
share of contact frames in each (label, state) is stored for the average model and for each
style, the frames aligned by each model's own state posteriors. For the average model it also
stores each state's share of frames with both feet in the air (`air_labels`), which tells a
run's flight from a walk's states whose feet slide on the floor (`synthesis.contact.flight_states`).
How the instrument uses these shares live is described in `instrument.synthesis.contact`.
"""

from __future__ import annotations

import numpy as np

from ..models.hsmm import HSMM, forward_backward, pad_segments
from ..motion.features import FeatureLayout, restore_local
from ..motion.kinematics import forward_kinematics
from ..motion.limbs import Limbs, centimetres_per_unit, find_limbs, tip_clearance, tip_heights
from ..motion.quality import AIR_CM, take_floors
from ..synthesis.contact import CONTACT_CM, CONTACT_SPEED_CM_S


def _take_world(static: np.ndarray, layout: FeatureLayout, fps: float) -> tuple[np.ndarray, np.ndarray]:
    rotations, translations, _ = restore_local(static, layout, fps)
    return forward_kinematics(layout.skeleton, rotations, translations)


def contact_labels(positions: np.ndarray, limbs: Limbs, ground: np.ndarray, cm: float, fps: float) -> np.ndarray:
    """(frames, 2) 1.0 where a foot is planted: low (near its clearance) and nearly still."""
    out = np.zeros((positions.shape[0], 2))
    for f, foot in enumerate(limbs.feet):
        joints = positions[:, list(foot)] * cm
        lift = joints[..., 1] - ground[f] * cm
        lowest = np.argmin(lift, axis=1)
        rows = np.arange(len(lift))
        speed = np.linalg.norm(np.gradient(joints[..., [0, 2]], axis=0), axis=2)[rows, lowest] * fps
        out[:, f] = (lift[rows, lowest] < CONTACT_CM) & (speed < CONTACT_SPEED_CM_S)
    return out


def air_labels(positions: np.ndarray, limbs: Limbs, ground: np.ndarray, cm: float) -> np.ndarray:
    """(frames, 1) 1.0 where both feet are in the air: each foot's lowest joint more than AIR_CM
    above its clearance, however fast it moves (as `instrument evaluate`'s air counts them). A
    run's flight; not a walk's foot that slides or pivots on the floor, or stands a centimetre or
    two above the floor its take's lowest frames set, which `contact_labels` does not count as
    planted either."""
    lifts = [(positions[:, list(foot), 1] - ground[f]).min(axis=1) * cm for f, foot in enumerate(limbs.feet)]
    return ((lifts[0] > AIR_CM) & (lifts[1] > AIR_CM)).astype(np.float64)[:, None]


def _state_contact(model: HSMM, segments: list[list[np.ndarray]], flags: list[list[np.ndarray]], fallback: np.ndarray) -> np.ndarray:
    """(labels, states, columns of the flags): posterior-weighted share of flagged frames in each
    state (contact per foot, or air)."""
    out = fallback.copy()
    for label, (segs, contact) in enumerate(zip(segments, flags)):
        if not segs:
            continue
        obs, lengths = pad_segments(segs)
        padded, _ = pad_segments(contact)
        _, occupancy, _ = forward_backward(obs, lengths, model.means[label], model.variances[label],
                                           model.duration_means[label], model.duration_variances[label])
        mass = occupancy.sum(axis=(0, 1))
        out[label] = np.einsum("ktn,ktf->nf", occupancy, padded) / np.maximum(mass[:, None], 1e-9)
    return out


def train_contact(layout: FeatureLayout, takes, average: HSMM, styles: HSMM, style_names: list[str], fps: float,
                  states: int, units: list[str] | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """Model-file arrays `contact_average` (labels, states, 2) and `contact_styles` (styles,
    labels, states, 2), and the metadata entry describing them; empty when the skeleton has no
    two legs."""
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    if limbs is None:
        return {}, {}
    positions, tips = [], []  # each take's world positions, and its toe tips' heights (a toe-less foot's)
    for take in takes:
        rotations, world_pos = _take_world(take.observations[:, : layout.dimension], layout, fps)
        positions.append(world_pos)
        tips.append(tip_heights(rotations, world_pos, limbs, layout))
    cm = centimetres_per_unit(layout, positions[0][0])
    floors = take_floors(positions, limbs)  # each take on its own floor (a capture's is not always level)
    labels = [contact_labels(p, limbs, g, cm, fps) for p, g in zip(positions, floors.ground)]
    airs = [air_labels(p, limbs, g, cm) for p, g in zip(positions, floors.ground)]
    ground = floors.mean_ground  # the lock's: the floor of the walk the model learnt from them all

    units = units or ["walk"]

    def split(chosen, labels=labels):
        segs = [[] for _ in range(2 * len(units))]
        flags = [[] for _ in range(2 * len(units))]
        for k in chosen:
            for step in takes[k].steps:
                if step.frames >= states and takes[k].unit in units:
                    index = 2 * units.index(takes[k].unit) + (0 if step.label == "right" else 1)
                    segs[index].append(takes[k].observations[step.start : step.end])
                    flags[index].append(labels[k][step.start : step.end])
        return segs, flags

    everything = split(range(len(takes)))
    neutral = np.full(average.duration_means.shape + (2,), 0.5)
    base = _state_contact(average, *everything, neutral)
    air = _state_contact(average, *split(range(len(takes)), airs), np.zeros(average.duration_means.shape + (1,)))[..., 0]
    per_style = []
    for s, name in enumerate(style_names):
        model = HSMM(*(getattr(styles, p)[s] for p in ("means", "variances", "duration_means", "duration_variances")))
        per_style.append(_state_contact(model, *split([k for k, t in enumerate(takes) if t.style == name]), base))
    names = layout.skeleton.names
    metadata = {
        "feet": [[names[j] for j in foot] for foot in limbs.feet],
        "clearance": ground.tolist(),
        "air": air.tolist(),  # (labels, states) share of frames with both feet off the floor (ContactSpace.flight)
        "contact_cm": CONTACT_CM,
        "contact_speed_cm_s": CONTACT_SPEED_CM_S,
    }
    if tips[0] is not None:  # feet without toe joints, ending in an End Site: the lock's pivot (footlock.FootLock)
        metadata["tip_clearance"] = tip_clearance(tips, [len(p) for p in positions])
    return {"contact_average": base, "contact_styles": np.stack(per_style)}, metadata
