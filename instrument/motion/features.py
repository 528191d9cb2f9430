"""The representation the models learn, and its exact inverse.

A frame becomes one vector:

    root.height, root.vx, root.vz, root.yaw_rate, root.tilt.x, root.tilt.z, <joint>(3) per moving joint

The root is described in its heading frame (the root's rotation about the up axis, Y): speeds
in units per second along the heading frame's x and z axes, the yaw rate in radians per second,
and the root's remaining rotation ("tilt", the swing of a swing-twist split, so it has no y
part) as an exponential map. Nothing in it depends on
where the character stands or faces, so a model can learn it from many takes; integrating the
speeds and yaw rate gives the world path back. Every other joint is the exponential map of its
local rotation relative to its rotation in a template frame (so maps stay far from an angle of
pi, where takes would disagree), made continuous over time. Joints that never move are left out; the channels
they and everything else not modelled hold come from a template frame.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property

import numpy as np

from ..errors import UserError
from .bvh import Motion, Skeleton
from .kinematics import channels_from_local, forward_kinematics, local_transforms
from .rotations import (
    axis_angle_matrix,
    continuous_expmap,
    continuous_quaternions,
    euler_to_matrix,
    expmap_to_matrix,
    matrix_to_euler,
    matrix_to_expmap,
    matrix_to_quat,
    quat_to_matrix,
    rotation_angle_between,
)

# tilt has no y part: the heading took all rotation about Y (the swing of a swing-twist split)
ROOT_FEATURES = ("root.height", "root.vx", "root.vz", "root.yaw_rate", "root.tilt.x", "root.tilt.z")
STILL_RADIANS = 1e-4  # a joint whose rotation never strays further than this is left out
DEFAULT_FPS = 30.0
# the rate the settings counted in frames were chosen at (the shipped model's): one that means a
# time or an amount of data counts `frames * fps / REFERENCE_FPS` of a model at `fps` (docs/evaluate.md, "Settings in frames")
REFERENCE_FPS = 30.0

# HTS windows for static, delta and delta-delta features
WINDOWS = (np.array([0.0, 1.0, 0.0]), np.array([-0.5, 0.0, 0.5]), np.array([1.0, -2.0, 1.0]))


@dataclass(frozen=True)
class FeatureLayout:
    """Which joint is the root, which joints are modelled, and the template for the rest."""

    skeleton: Skeleton
    root: int
    joints: tuple[int, ...]
    template: tuple[float, ...]  # one frame of channel values for everything not modelled
    # rotation vector of `heading_reference`; None: models from before issue 30, which read the
    # root's heading and tilt from its own axes
    root_reference: tuple[float, float, float] | None = None

    @cached_property
    def template_pose(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Local rotations (J, 3, 3) and translations (J, 3) of the template frame, and the world
        rotation and position of the root's parent in it (identity at the top)."""
        template = Motion(self.skeleton, np.asarray(self.template)[None], DEFAULT_FPS)
        rotations, translations = local_transforms(template)
        world_rot, world_pos = forward_kinematics(self.skeleton, rotations, translations)
        parent = self.skeleton.joints[self.root].parent
        if parent < 0:
            return rotations[0], translations[0], np.eye(3), np.zeros(3)
        return rotations[0], translations[0], world_rot[0, parent], world_pos[0, parent]

    @cached_property
    def reference(self) -> np.ndarray:
        """(joints, 3, 3) local rotations of the modelled joints in the template frame.

        Joint features are exponential maps relative to these, so they stay small and far from
        an angle of pi, where the equivalent maps of different takes would disagree.
        """
        return self.template_pose[0][list(self.joints)]

    @cached_property
    def heading_reference(self) -> np.ndarray:
        """(3, 3) the root's mean world rotation over the takes with their heading taken out,
        turned so that the takes travel along +Z (`root_reference`; identity without it: older
        models read the root's own axes).

        The root's heading and tilt are read from its rotation relative to this, so they do not
        depend on how the rig orients the root's axes at rest, and the heading frame's +Z is
        where the takes travel. Read from the root's own axes, a rig whose hips are turned at
        rest put the direction of travel between the heading frame's axes, where the mirror
        symmetry of the step models (training/symmetry.py) took part of the forward speed for
        sideways and averaged it away: the same walks with the hips' rest turned by a fixed 40
        degrees swung their hips 18-26% less and slid 1.8-3.8x as much (examples/other_rigs.py,
        set rest-posed). A mean over the takes, not one frame's: the template frame's own lean
        moved the steps' boundaries with the frame the take starts at."""
        if self.root_reference is None:
            return np.eye(3)
        return expmap_to_matrix(np.asarray(self.root_reference, dtype=np.float64))

    @property
    def dimension(self) -> int:
        return len(ROOT_FEATURES) + 3 * len(self.joints)

    @property
    def names(self) -> list[str]:
        joint_names = self.skeleton.names
        axes = ("x", "y", "z")
        return list(ROOT_FEATURES) + [f"{joint_names[j]}.{a}" for j in self.joints for a in axes]

    def to_dict(self) -> dict:
        names = self.skeleton.names
        return {
            "root": names[self.root],
            "joints": [names[j] for j in self.joints],
            "left_out": [n for i, n in enumerate(names) if i != self.root and i not in self.joints],
            "template": list(self.template),
            "names": self.names,
            "up_axis": "Y",
            "root_reference": None if self.root_reference is None else list(self.root_reference),
        }

    @classmethod
    def from_dict(cls, skeleton: Skeleton, data: dict) -> "FeatureLayout":
        index = {n: i for i, n in enumerate(skeleton.names)}
        return cls(skeleton, index[data["root"]], tuple(index[n] for n in data["joints"]), tuple(data["template"]),
                   None if data.get("root_reference") is None else tuple(float(v) for v in data["root_reference"]))


def choose_layout(motions: list[Motion]) -> FeatureLayout:
    """Pick the root and the moving joints from all the motions (which share one skeleton)."""
    skeleton = motions[0].skeleton
    rotations = [local_transforms(m)[0] for m in motions]
    moving_position = np.zeros(len(skeleton.joints), dtype=bool)
    for m in motions:
        for j, (joint, start) in enumerate(zip(skeleton.joints, skeleton.channel_start())):
            cols = [start + k for k, c in enumerate(joint.channels) if c.endswith("position")]
            if cols and np.ptp(m.channels[:, cols], axis=0).max() > 1e-6:
                moving_position[j] = True
    candidates = np.flatnonzero(moving_position)
    root = int(candidates[0]) if len(candidates) else 0
    first = rotations[0][0]
    still = np.ones(len(skeleton.joints), dtype=bool)
    for rot in rotations:
        still &= rotation_angle_between(rot, first[None]).max(axis=0) < STILL_RADIANS
    below_root = _descendants(skeleton, root)
    joints = tuple(j for j in below_root if not still[j])
    if still[root] and joints:  # e.g. a floor 'Reference' joint moving the hips, which turn below it
        raise UserError(f"joint {skeleton.names[root]!r} carries the body's position but never turns, while "
                        f"{skeleton.names[joints[0]]!r} below it does: the walk's heading is read from the joint "
                        "that moves, so export the takes with one joint carrying both (the hips as the root)")
    layout = FeatureLayout(skeleton, root, joints, tuple(float(v) for v in motions[0].channels[0]))
    return replace(layout, root_reference=_root_reference(motions, root))


def _root_reference(motions: list[Motion], root: int) -> tuple[float, float, float]:
    """`FeatureLayout.heading_reference` of takes, as a rotation vector: the mean of the root's
    world rotation in its heading frame (the heading read relative to the previous guess, from
    the first frame's rotation without its twist on), turned about the vertical so that the
    mean velocity in the heading frame points along +Z (not turned for takes that stay put)."""
    turns, steps = [], []
    for motion in motions:
        world_rot, world_pos = forward_kinematics(motion.skeleton, *local_transforms(motion))
        turns.append(world_rot[:, root])
        steps.append(np.diff(world_pos[:, root], axis=0))
    first = turns[0][0]
    reference = axis_angle_matrix("y", heading_angle(first[None]))[0].T @ first
    for _ in range(2):
        headings = [axis_angle_matrix("y", heading_angle(r, reference)) for r in turns]
        u, _, vt = np.linalg.svd(sum(np.einsum("tji,tjk->ik", h, r) for h, r in zip(headings, turns)))
        reference = u @ np.diag([1.0, 1.0, np.linalg.det(u @ vt)]) @ vt  # the nearest rotation to the mean
    headings = [axis_angle_matrix("y", heading_angle(r, reference)) for r in turns]
    travel = sum(np.einsum("tji,tj->i", h[:-1], d) for h, d in zip(headings, steps))
    if np.hypot(travel[0], travel[2]) > 1e-9:
        reference = axis_angle_matrix("y", np.array([-np.arctan2(travel[0], travel[2])]))[0] @ reference
    return tuple(float(v) for v in matrix_to_expmap(reference))


def _descendants(skeleton: Skeleton, joint: int) -> list[int]:
    out, parents = [], skeleton.parents
    for j in range(len(parents)):
        p = parents[j]
        while p >= 0 and p != joint:
            p = parents[p]
        if p == joint:
            out.append(j)
    return out


def heading_angle(world_rotation: np.ndarray, reference: np.ndarray | None = None) -> np.ndarray:
    """Unwrapped yaw (radians) of rotations (T, 3, 3): the twist about Y in a swing-twist split,
    of the rotation relative to `reference` (a root's: FeatureLayout.heading_reference) when given."""
    if reference is not None:
        world_rotation = world_rotation @ reference.T
    quat = continuous_quaternions(matrix_to_quat(world_rotation))
    return np.unwrap(2.0 * np.arctan2(quat[:, 1], quat[:, 3]))


def travel_direction(heading: np.ndarray, velocity: np.ndarray) -> np.ndarray:
    """(T, 3) the way a take goes, in world space frame by frame: the median of the root's
    horizontal velocity (T, 3) in its heading frame (T, 3, 3), turned back by each frame's
    heading (+Z of the heading frame for a take that stays put). Finding the feet (steps.py) and
    measuring the limbs' swing (quality.py) read forward and back along it."""
    direction = np.median(np.einsum("tji,tj->ti", heading, velocity), axis=0) * np.array([1.0, 0.0, 1.0])
    norm = np.linalg.norm(direction)
    return heading @ (direction / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0]))


def extract(motion: Motion, layout: FeatureLayout) -> tuple[np.ndarray, np.ndarray, float]:
    """Features (T, D) of a motion, with the root's start position and heading for `restore`."""
    rotations, translations = local_transforms(motion)
    world_rot, world_pos = forward_kinematics(motion.skeleton, rotations, translations)
    root_rot, root_pos = world_rot[:, layout.root], world_pos[:, layout.root]
    fps = motion.fps
    yaw = heading_angle(root_rot, layout.heading_reference)
    heading = axis_angle_matrix("y", yaw)
    step = np.diff(root_pos, axis=0)
    local_step = np.einsum("tji,tj->ti", heading[:-1], step) * fps  # heading^T @ step
    yaw_rate = np.diff(yaw) * fps
    if len(step) == 0:
        local_step, yaw_rate = np.zeros((1, 3)), np.zeros(1)
    else:
        local_step = np.vstack([local_step, local_step[-1:]])
        yaw_rate = np.append(yaw_rate, yaw_rate[-1])
    tilt = continuous_expmap(matrix_to_expmap(np.einsum("tji,tjk->tik", heading, root_rot @ layout.heading_reference.T)))
    relative = np.einsum("jki,tjkl->tjil", layout.reference, rotations[:, list(layout.joints)])  # ref^T @ R
    joints = continuous_expmap(matrix_to_expmap(relative))
    features = np.hstack(
        [root_pos[:, 1:2], local_step[:, 0:1], local_step[:, 2:3], yaw_rate[:, None], tilt[:, [0, 2]], joints.reshape(motion.frames, -1)]
    )
    return features, root_pos[0], float(yaw[0])


def restore_local(
    features: np.ndarray,
    layout: FeatureLayout,
    fps: float,
    start: np.ndarray | None = None,
    start_heading: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, tuple[np.ndarray, float]]:
    """Local joint rotations (T, J, 3, 3) and translations (T, J, 3) from features, integrating
    the root path from `start` and `start_heading`; also where the root would be one frame
    after the last (so a stream can continue the path frame by frame)."""
    features = np.asarray(features, dtype=np.float64)
    frames = features.shape[0]
    yaw = start_heading + np.concatenate([[0.0], np.cumsum(features[:, 3]) / fps])  # one longer: the next frame too
    heading = axis_angle_matrix("y", yaw)
    local_step = np.zeros((frames, 3))
    local_step[:, 0], local_step[:, 2] = features[:, 1], features[:, 2]
    world_step = np.einsum("tij,tj->ti", heading[:-1], local_step) / fps
    origin = np.zeros(3) if start is None else np.asarray(start, dtype=np.float64)
    path = origin + np.concatenate([np.zeros((1, 3)), np.cumsum(world_step, axis=0)])
    root_pos = path[:-1].copy()
    root_pos[:, 1] = features[:, 0]
    expmaps = np.zeros((frames, 1 + len(layout.joints), 3))  # the root's tilt, then every joint's
    expmaps[:, 0, 0], expmaps[:, 0, 2] = features[:, 4], features[:, 5]
    expmaps[:, 1:] = features[:, len(ROOT_FEATURES) :].reshape(frames, len(layout.joints), 3)
    matrices = expmap_to_matrix(expmaps)
    root_rot = heading[:-1] @ matrices[:, 0] @ layout.heading_reference

    template_rot, template_trans, parent_rot, parent_pos = layout.template_pose
    rotations = np.broadcast_to(template_rot, (frames,) + template_rot.shape).copy()
    translations = np.broadcast_to(template_trans, (frames,) + template_trans.shape).copy()
    rotations[:, layout.root] = parent_rot.T @ root_rot
    translations[:, layout.root] = (root_pos - parent_pos) @ parent_rot
    rotations[:, list(layout.joints)] = layout.reference @ matrices[:, 1:]
    return rotations, translations, (path[-1], float(yaw[-1]))


def restore(
    features: np.ndarray,
    layout: FeatureLayout,
    fps: float,
    start: np.ndarray | None = None,
    start_heading: float = 0.0,
) -> Motion:
    """Motion from features: integrate the root path, put rotations back, fill the rest."""
    rotations, translations, _ = restore_local(features, layout, fps, start, start_heading)
    return Motion(layout.skeleton, channels_from_local(layout.skeleton, rotations, translations), fps)


def resample(motion: Motion, fps: float = DEFAULT_FPS) -> Motion:
    """The motion at another frame rate: positions and (sign-continuous) quaternions through a
    cubic spline over the frames, the quaternions normalised again.

    Not linearly: a take upsampled linearly (slerp, lerp) moves at constant speed between its own
    frames and turns at each of them, so its accelerations are 0 at the new frames and spikes at
    the old ones. Bandai's 30 fps walks at 60 fps had 5.4-6.3 times their jitter; trained at
    60 fps the delta-delta features' Gaussians learnt that alternation instead of the steps' shape,
    the styles' adaptation chose other weights and active's model came out 1.3% slow (evaluate.md,
    "Walks trained at another rate than their capture's")."""
    if abs(motion.fps - fps) < 1e-9 or motion.frames < 2:
        return motion
    from scipy.interpolate import CubicSpline  # here, not at the top: only a resampled take needs it

    count = int(np.floor((motion.frames - 1) * fps / motion.fps + 1e-9)) + 1
    position = np.minimum(np.arange(count) * (motion.fps / fps), motion.frames - 1)
    frames = np.arange(motion.frames)

    def curve(values: np.ndarray) -> np.ndarray:
        """`values` (frames, ...) at `position`: a cubic spline through them (lines below four frames)."""
        if motion.frames < 4:
            lower = np.minimum(np.floor(position).astype(int), motion.frames - 2)
            frac = (position - lower).reshape((-1,) + (1,) * (values.ndim - 1))
            return values[lower] * (1 - frac) + values[lower + 1] * frac
        return CubicSpline(frames, values, axis=0)(position)

    skeleton = motion.skeleton
    out = np.empty((count, skeleton.channel_count))
    for joint, start in zip(skeleton.joints, skeleton.channel_start()):
        cols = np.arange(start, start + len(joint.channels))
        rot = np.array([c.endswith("rotation") for c in joint.channels])
        pos_cols = cols[~rot]
        if len(pos_cols):
            out[:, pos_cols] = curve(motion.channels[:, pos_cols])
        if rot.any():
            matrices = euler_to_matrix(motion.channels[:, cols[rot]], joint.rotation_order)
            quat = curve(continuous_quaternions(matrix_to_quat(matrices)))
            quat /= np.linalg.norm(quat, axis=-1, keepdims=True)
            out[:, cols[rot]] = matrix_to_euler(quat_to_matrix(quat), joint.rotation_order)
    return Motion(skeleton, out, float(fps), source=motion.source)


def with_deltas(static: np.ndarray) -> np.ndarray:
    """[o, delta o, delta-delta o] with the HTS windows; edges repeat the end frames."""
    padded = np.pad(static, ((1, 1), (0, 0)), mode="edge")
    parts = [w[0] * padded[:-2] + w[1] * padded[1:-1] + w[2] * padded[2:] for w in WINDOWS]
    return np.hstack(parts)


def forward_direction(average_static_means: np.ndarray) -> np.ndarray:
    """The direction of travel in the heading frame, from the model's mean root speeds."""
    vx, vz = average_static_means[..., 1].mean(), average_static_means[..., 2].mean()
    return np.array([vx, 0.0, vz])
