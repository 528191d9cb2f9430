"""Training's half of the foot lock: which foot is planted in each state, learnt from the takes.

Each foot of each frame of a take is labelled as in contact when its lowest joint is within
CONTACT_CM of its ground clearance and moves slower than CONTACT_SPEED_CM_S horizontally; the
share of contact frames in each (label, state) is stored for the average model and for each
style, the frames aligned by each model's own state posteriors. How the instrument uses these
shares live is described in `instrument.synthesis.contact`.
"""

from __future__ import annotations

import numpy as np

from ..models.hsmm import HSMM, forward_backward, pad_segments
from ..motion.features import FeatureLayout, restore_local
from ..motion.kinematics import forward_kinematics
from ..motion.limbs import Limbs, centimetres_per_unit, find_limbs
from ..motion.quality import take_floors
from ..synthesis.contact import CONTACT_CM, CONTACT_SPEED_CM_S


def _take_positions(static: np.ndarray, layout: FeatureLayout, fps: float) -> np.ndarray:
    rotations, translations, _ = restore_local(static, layout, fps)
    return forward_kinematics(layout.skeleton, rotations, translations)[1]


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


def _state_contact(model: HSMM, segments: list[list[np.ndarray]], flags: list[list[np.ndarray]], fallback: np.ndarray) -> np.ndarray:
    """(labels, states, 2): posterior-weighted share of contact frames in each state."""
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
    positions = [_take_positions(t.observations[:, : layout.dimension], layout, fps) for t in takes]
    cm = centimetres_per_unit(layout, positions[0][0])
    floors = take_floors(positions, limbs)  # each take on its own floor (a capture's is not always level)
    labels = [contact_labels(p, limbs, g, cm, fps) for p, g in zip(positions, floors.ground)]
    ground = floors.mean_ground  # the lock's: the floor of the walk the model learnt from them all

    units = units or ["walk"]

    def split(chosen):
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
    per_style = []
    for s, name in enumerate(style_names):
        model = HSMM(*(getattr(styles, p)[s] for p in ("means", "variances", "duration_means", "duration_variances")))
        per_style.append(_state_contact(model, *split([k for k, t in enumerate(takes) if t.style == name]), base))
    names = layout.skeleton.names
    metadata = {
        "feet": [[names[j] for j in foot] for foot in limbs.feet],
        "clearance": ground.tolist(),
        "contact_cm": CONTACT_CM,
        "contact_speed_cm_s": CONTACT_SPEED_CM_S,
    }
    return {"contact_average": base, "contact_styles": np.stack(per_style)}, metadata
