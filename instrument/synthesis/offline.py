"""Whole walks at once: streaming or full-sequence generation with constant controls."""

from __future__ import annotations

import numpy as np

from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.features import restore
from ..motion.kinematics import channels_from_local
from ..runtime.pose import PoseStream
from .contact import contact_space
from .follow import strength
from .footlock import FootLock
from .interpolation import StyleSpace
from .mlpg import mlpg
from .stream import DEFAULT_LOOKAHEAD, Controls, Crowd
from .widen import RangeSpace, Widen, range_space

ROOT_RATES = slice(1, 4)  # root.vx, root.vz, root.yaw_rate in the static features


def drive(static: np.ndarray, cadence: float | np.ndarray, turn: float | np.ndarray) -> np.ndarray:
    """Root speeds scaled by the cadence (a step taken faster covers the same ground sooner, so
    the feet do not slide) and the steering added to the yaw rate."""
    out = np.array(static, dtype=np.float64)
    out[..., ROOT_RATES] *= np.asarray(cadence)[..., None] if np.ndim(cadence) else cadence
    out[..., 3] += turn
    return out


def synthesize(
    space: StyleSpace,
    dimension: int,
    controls: Controls,
    frames: int,
    method: str = "stream",
    lookahead: int = DEFAULT_LOOKAHEAD,
    seed: int = 0,
    widen: RangeSpace | None = None,
) -> np.ndarray:
    """Static features (frames, D) of a walk with constant controls, root speeds driven."""
    return generate_with_states(space, dimension, controls, frames, method, lookahead, seed, widen)[0]


def generate_with_states(space: StyleSpace, dimension: int, controls: Controls, frames: int, method: str, lookahead: int,
                         seed: int, widen: RangeSpace | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Driven static features (frames, D) and the (label * states + state) of each frame, their
    swing scaled to the data's frame by frame as live when `widen` is given."""
    walker = Crowd(space, 1, lookahead, seeds=[seed])
    if method == "full":
        ids = walker.state_plan(controls, frames)
        lam = walker.lams[0]
        static = mlpg(lam.means[ids], 1.0 / lam.precisions[ids])
        if widen is not None:
            scale = Widen(widen)
            static = np.array([scale.next(row, walker, controls) for row in static])
    else:
        rows, ids = [], []
        scale = None if widen is None else Widen(widen)
        for _ in range(frames):
            row = walker.step([controls])[0]
            rows.append(row if scale is None else scale.next(row, walker, controls))
            ids.append(walker.history_ids[0, 1])
        static, ids = np.vstack(rows), np.asarray(ids)
    return drive(static, walker.cadence[0], controls.turn), ids


def default_controls(model: Model, weights: dict[str, float] | None = None, **kwargs) -> Controls:
    vector = np.zeros(len(model.style_names))
    for name, value in (weights or {}).items():
        vector[model.style_names.index(name)] = value
    return Controls(vector, **kwargs)


def synthesize_motion(model: Model, space: StyleSpace, controls: Controls, frames: int, method: str = "stream",
                      lookahead: int = DEFAULT_LOOKAHEAD, seed: int = 0) -> Motion:
    """A walk as a Motion on the model's skeleton, from the origin, heading 0, its feet planted
    frame by frame as live when the model has contact statistics."""
    static, ids = generate_with_states(space, model.layout.dimension, controls, frames, method, lookahead, seed,
                                       range_space(model))
    contact = contact_space(model)
    if contact is None:
        return restore(static, model.layout, model.fps)
    shares = contact.shares(controls.weights, controls.part_weights)[ids]
    poses = PoseStream(model.layout, model.fps, FootLock(model.layout, contact.clearance, model.fps))
    follow = strength(contact.leg_weights(controls.weights, controls.part_weights))
    frames_out = [poses.next(row, frame_shares, follow) for row, frame_shares in zip(static, shares)]
    rotations = np.stack([p.rotations for p in frames_out])
    translations = np.stack([p.translations for p in frames_out])
    return Motion(model.layout.skeleton, channels_from_local(model.layout.skeleton, rotations, translations), model.fps)
