"""Feet that stay planted: contact learnt per state from the data, enforced frame by frame.

Training labels each foot of each frame as in contact when its lowest joint is within
CONTACT_CM of its ground clearance and moves slower than CONTACT_SPEED_CM_S horizontally, and
stores per (label, state) the share of frames in contact, for the average model and each style
(aligned by each model's own state posteriors). Live, the probabilities move with the style
weights like every other parameter (offsets from the average, so they blend and extrapolate)
and a foot counts as planted in a state whose share is at least PLANTED, or at least POSSIBLE
when the generated foot is on the floor and nearly still (as the data was labelled).

`FootLock` enforces it causally, one frame at a time, on the pose the features give:
- when a foot lands, the point it lands on (its lowest joint, horizontally) is locked;
- each leg is solved by analytic two-bone IK (law of cosines for the knee, bent about its own
  hinge; then the hip swings the leg), the foot keeping its generated world orientation, towards: the lock
  horizontally, its lowest joint on the floor vertically; the lock blends in and out over
  BLEND_FRAMES frames, so nothing pops;
- no foot joint goes below its clearance, planted or not, and a swinging foot keeps up to
  SWING_CM above it (all of it on a bent knee, none on a straight one reaching to land);
- a released foot rises as generated (only the horizontal pull blends out);
- a walk always has a foot on the floor: when no state plants either, the likelier one is;
- where a planted leg is too short to reach the floor below it (an exaggerated style can lift
  the hips), the body comes down by the difference, eased over BLEND_FRAMES frames.
Nothing looks ahead beyond what the frame's state already says, so live and `synth` agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..models.hsmm import HSMM, forward_backward, pad_segments
from ..motion.features import FeatureLayout, restore_local
from ..motion.kinematics import forward_kinematics
from ..motion.limbs import Limbs, centimetres_per_unit, clearance, find_limbs

CONTACT_CM = 2.0
CONTACT_SPEED_CM_S = 30.0
BLEND_FRAMES = 4
SWING_CM = 2.0  # a foot in the air keeps its lowest joint this far above its clearance
PLANTED = 0.5  # a state this sure of a foot's contact plants it
POSSIBLE = 0.2  # a state this sure plants a foot that is on the floor and still
NEARLY_STRAIGHT = np.radians(10.0)  # a knee bent less than this may be bent the wrong way (see _leg_swings)
SWING_BENT = np.radians(30.0)  # a swinging foot gets its full SWING_CM once its knee is bent this far


def EASE(x: float) -> float:
    return x * x * (3.0 - 2.0 * x)  # smoothstep: the lock starts and ends with zero speed


def _swing_share(world_pos: np.ndarray, leg) -> float:
    """How much of SWING_CM a swinging foot keeps: all of it on a bent knee (mid-swing, where
    an exaggerated style would drag it along the floor), none on a straight one (reaching for
    the floor to land: lifting it there bends the knee the data straightens and flexes the hip)."""
    thigh, shin = world_pos[leg.knee] - world_pos[leg.hip], world_pos[leg.ankle] - world_pos[leg.knee]
    cos = thigh @ shin / (np.linalg.norm(thigh) * np.linalg.norm(shin) + 1e-12)
    return min(1.0, float(np.arccos(min(max(cos, -1.0), 1.0))) / SWING_BENT)


# ---- training -------------------------------------------------------------------------------

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
                  states: int) -> tuple[dict[str, np.ndarray], dict]:
    """Model-file arrays `contact_average` (labels, states, 2) and `contact_styles` (styles,
    labels, states, 2), and the metadata entry describing them; empty when the skeleton has no
    two legs."""
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    if limbs is None:
        return {}, {}
    positions = [_take_positions(t.observations[:, : layout.dimension], layout, fps) for t in takes]
    cm = centimetres_per_unit(layout, positions[0][0])
    ground = clearance(positions, limbs)
    labels = [contact_labels(p, limbs, ground, cm, fps) for p in positions]

    def split(chosen):
        segs = [[], []]
        flags = [[], []]
        for k in chosen:
            for step in takes[k].steps:
                if step.frames >= states:
                    index = 0 if step.label == "right" else 1
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


# ---- generation -----------------------------------------------------------------------------

@dataclass(frozen=True)
class ContactSpace:
    """Contact probabilities as lambda 0 plus style offsets, flattened over (label, state)."""

    base: np.ndarray  # (labels * states, 2)
    offsets: np.ndarray  # (styles, labels * states, 2)
    clearance: np.ndarray  # (2, foot joints)
    legs: int  # index of the legs' body group in per-part weights

    def shares(self, weights: np.ndarray, part_weights: np.ndarray | None = None) -> np.ndarray:
        """(labels * states, 2): how surely each foot is planted in each state at these weights
        (the legs' own weights when given per body part), 0 to 1."""
        return np.clip(self.base + np.einsum("s,sif->if", self.leg_weights(weights, part_weights), self.offsets), 0.0, 1.0)

    def leg_weights(self, weights: np.ndarray, part_weights: np.ndarray | None = None) -> np.ndarray:
        """The style weights the legs walk with: their own where given per body part."""
        weights = np.asarray(weights, dtype=np.float64)
        if part_weights is not None:
            legs = np.asarray(part_weights, dtype=np.float64)[:, self.legs]
            weights = np.where(np.isnan(legs), weights, legs)
        return weights


def contact_space(model) -> ContactSpace | None:
    """None for a model trained without contact statistics (it then runs as before)."""
    from .interpolation import GROUPS

    extras = getattr(model, "extras", {}) or {}
    base, styles = extras.get("contact_average"), extras.get("contact_styles")
    stored = model.metadata.get("contact", {}).get("clearance")
    layout = model.layout
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    labels, states = len(model.labels), model.states
    if base is None or styles is None or stored is None or limbs is None:
        return None
    if base.shape != (labels, states, 2) or styles.shape != (len(model.style_names), labels, states, 2):
        return None
    flat = base.reshape(-1, 2)
    return ContactSpace(flat, styles.reshape(len(model.style_names), -1, 2) - flat, np.asarray(stored), GROUPS.index("legs"))


@njit(cache=True)
def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """The smallest rotation taking direction a to direction b (Rodrigues)."""
    a = a / np.sqrt(np.sum(a * a))
    b = b / np.sqrt(np.sum(b * b))
    axis = np.cross(a, b)
    s = np.sqrt(np.sum(axis * axis))
    c = np.sum(a * b)
    if s < 1e-12:
        return np.eye(3)
    k = axis / s
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


@njit(cache=True)
def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:  # pragma: no cover - compiled
    k = axis / np.sqrt(np.sum(axis * axis))
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


@njit(cache=True)
def _leg_swings(hip, knee, ankle, target, toes):  # pragma: no cover - compiled
    """Two-bone IK, as world rotations of the thigh (about the hip) and the shin (about the
    knee, applied after the thigh's) that take the ankle to `target`, or as near as the leg
    allows: the knee bends about its own hinge (the axis across its generated bend; for a
    straight leg, across the line to the toes) to the angle the law of cosines gives, then the
    hip swings the leg onto the target. A generated leg bent a little backwards (less than
    NEARLY_STRAIGHT, the toes' side telling which way is forward) is bent forward through
    straight, not further back, so a leg shortened from nearly straight never folds the wrong
    way and flips back a frame later; a clearer bend is the knee's own (a swinging foot's toes
    may point anywhere)."""
    thigh_vector, shin_vector = knee - hip, ankle - knee
    upper = np.sqrt(np.sum(thigh_vector**2))
    lower = np.sqrt(np.sum(shin_vector**2))
    reach = target - hip
    distance = min(max(np.sqrt(np.sum(reach * reach)), abs(upper - lower) + 1e-6), (upper + lower) * 0.9999)
    forward = np.cross(toes, thigh_vector)  # the axis a knee bends forward about (the shin back, the knee towards the toes)
    hinge = np.cross(thigh_vector, shin_vector)
    now = np.arccos(min(max(np.sum(thigh_vector * shin_vector) / (upper * lower), -1.0), 1.0))  # 0: straight
    if np.sqrt(np.sum(hinge * hinge)) < 1e-3 * upper * lower:  # straight: the knee bends forward
        hinge, now = forward, 0.0
    elif now < NEARLY_STRAIGHT and np.sum(hinge * forward) < 0.0:  # bent a little backwards: bent forward through straight
        hinge, now = -hinge, -now
    if np.sqrt(np.sum(hinge * hinge)) < 1e-12:
        return np.eye(3), np.eye(3)
    cos_new = min(max((upper**2 + lower**2 - distance**2) / (2.0 * upper * lower), -1.0), 1.0)
    bend = _axis_rotation(hinge, np.pi - np.arccos(cos_new) - now)
    swing = _rotation_between(thigh_vector + bend @ shin_vector, reach)
    return swing, swing @ bend @ swing.T


class FootLock:
    """One character's planted feet, carried from frame to frame (see the module's docstring)."""

    def __init__(self, layout: FeatureLayout, ground: np.ndarray, fps: float):
        self.layout, self.fps = layout, fps
        self.limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
        self.ground = np.asarray(ground, dtype=np.float64)
        self.parents = layout.skeleton.parents
        self.weight = np.zeros(2)  # how far each foot's lock is blended in
        self.lock = np.full((2, 3), np.nan)  # world point each foot is locked to
        self.drop = 0.0  # how far the body is lowered for a planted leg to reach the floor
        self.parent_rot = layout.template_pose[2]  # the root's parent's world rotation
        self.pivot = [int(foot[-1]) for foot in self.limbs.feet]  # the joint whose landing point is locked
        template = forward_kinematics(layout.skeleton, layout.template_pose[0][None], layout.template_pose[1][None])[1][0]
        self.cm = centimetres_per_unit(layout, template)
        self.swing_lift = SWING_CM / self.cm  # in the skeleton's units
        self.previous = np.full((2, 3), np.nan)  # each pivot's generated position in the frame before

    def apply(self, rotations: np.ndarray, translations: np.ndarray, shares: np.ndarray) -> tuple[np.ndarray, ...]:
        """Local rotations (J, 3, 3) of one frame, adjusted, the translations (J, 3), and their
        world rotations and positions; `shares` (2,) says how surely each foot is planted in
        the frame's state."""
        rotations = rotations.copy()
        world_rot, world_pos = forward_kinematics(self.layout.skeleton, rotations[None], translations[None])
        world_rot, world_pos = world_rot[0], world_pos[0]
        planted = self._planted(shares, world_pos)
        step = 1.0 / BLEND_FRAMES
        for f in range(2):
            if planted[f] and self.weight[f] == 0.0:
                self.lock[f] = world_pos[self.pivot[f]]
            self.weight[f] = min(1.0, self.weight[f] + step) if planted[f] else max(0.0, self.weight[f] - step)
        targets = [self._target(f, leg, world_pos, planted[f]) for f, leg in enumerate(self.limbs.legs)]
        # a planted leg too short for the floor below it (an exaggerated style can lift the
        # hips): the body comes down, eased over a few frames so it does not bob
        need = 0.0
        for f, leg in enumerate(self.limbs.legs):
            if planted[f]:
                below = world_pos[leg.hip] - np.array([world_pos[leg.ankle][0], targets[f][1], world_pos[leg.ankle][2]])
                need = max(need, np.linalg.norm(below) - 0.98 * (leg.thigh + leg.shin))
        self.drop += (max(need, 0.0) - self.drop) / BLEND_FRAMES
        if self.drop > 1e-9:
            translations = translations.copy()
            translations[self.layout.root] -= np.array([0.0, self.drop, 0.0]) @ self.parent_rot
            world_pos = world_pos - np.array([0.0, self.drop, 0.0])
            targets = [self._target(f, leg, world_pos, planted[f]) for f, leg in enumerate(self.limbs.legs)]
        for f, leg in enumerate(self.limbs.legs):
            target = targets[f]
            if np.linalg.norm(target - world_pos[leg.ankle]) > 1e-9:
                self._solve(leg, rotations, world_rot, world_pos, target)
        world_rot, world_pos = forward_kinematics(self.layout.skeleton, rotations[None], translations[None])
        return rotations, translations, world_rot[0], world_pos[0]

    def _planted(self, shares: np.ndarray, world_pos: np.ndarray) -> np.ndarray:
        """A foot is planted where its state says so, or where the state allows it and the
        generated foot is on the floor and nearly still (as the data's contact was labelled)."""
        planted = shares >= PLANTED
        pivots = world_pos[self.pivot]
        speed = np.hypot(*(pivots - self.previous)[:, [0, 2]].T) * self.fps * self.cm
        self.previous = pivots
        for f, leg in enumerate(self.limbs.legs):
            if not planted[f] and shares[f] >= POSSIBLE:
                lift = np.min(world_pos[list(leg.foot), 1] - self.ground[f]) * self.cm
                planted[f] = lift < CONTACT_CM and speed[f] < CONTACT_SPEED_CM_S  # NaN speed (first frame): False
        if not planted.any() and shares.max() > 0.0:  # a walk has a foot on the floor: the likelier one
            planted[int(np.argmax(shares))] = True
        return planted

    def _target(self, f: int, leg, world_pos: np.ndarray, planted: bool) -> np.ndarray:
        """Where the ankle should be: the lock blended in horizontally, the lowest foot joint on
        the floor while planted, never below it, and a little above it while swinging."""
        lift = np.min(world_pos[list(leg.foot), 1] - self.ground[f])
        target = world_pos[leg.ankle].copy()
        w = EASE(self.weight[f])
        down = w * lift if planted else 0.0  # a released foot rises as generated (held down, the knee straightens at toe-off)
        if w > 0:
            pull = self.lock[f] - world_pos[self.pivot[f]]
            target[[0, 2]] += w * pull[[0, 2]]
            target[1] -= down
        lowest_after = lift - down
        floor = 0.0 if planted else (1.0 - w) * self.swing_lift * _swing_share(world_pos, leg)
        if lowest_after < floor:
            target[1] += floor - lowest_after
        return target

    def _solve(self, leg, rotations: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray, target: np.ndarray) -> None:
        """Leg IK in place on the local rotations: hip and knee swung, the ankle keeping its world rotation."""
        toes = world_pos[leg.foot[-1]] - world_pos[leg.ankle]
        thigh, shin = _leg_swings(world_pos[leg.hip], world_pos[leg.knee], world_pos[leg.ankle], target, toes)
        # the hip is the knee's parent and the knee the ankle's (limbs.py): below the hip everything
        # turns with the thigh, below the knee also with the shin
        hip_world = thigh @ world_rot[leg.hip]
        knee_world = shin @ thigh @ world_rot[leg.knee]
        rotations[leg.hip] = self._parent_world(leg.hip, world_rot).T @ hip_world
        rotations[leg.knee] = hip_world.T @ knee_world
        rotations[leg.ankle] = knee_world.T @ world_rot[leg.ankle]

    def _parent_world(self, joint: int, world_rot: np.ndarray) -> np.ndarray:
        parent = int(self.parents[joint])
        return world_rot[parent] if parent >= 0 else np.eye(3)
