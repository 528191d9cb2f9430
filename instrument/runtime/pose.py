"""From generated features to a pose per frame: the root path integrated as the walk goes."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..motion.features import FeatureLayout, restore_local
from ..motion.kinematics import channels_from_local, forward_kinematics
from ..motion.rotations import matrix_to_quat

if TYPE_CHECKING:
    from ..synthesis.contact import FootLock
    from ..synthesis.follow import RootFollow


@dataclass
class Pose:
    """One frame of the character, in the model's space (right-handed, Y up, the model's units)."""

    index: int
    time: float  # seconds of performance time (index / fps)
    rotations: np.ndarray  # (J, 3, 3) local joint rotations
    translations: np.ndarray  # (J, 3) local joint translations
    world_rotations: np.ndarray  # (J, 3, 3)
    world_positions: np.ndarray  # (J, 3)


def quaternions(rotations: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) as quaternions (x, y, z, w) with w >= 0 (one sign for receivers)."""
    quats = matrix_to_quat(rotations)
    return np.where(quats[..., 3:4] < 0, -quats, quats)


class PoseStream:
    """Turns each frame of static features into a Pose, carrying the root's path across frames."""

    def __init__(self, layout: FeatureLayout, fps: float, lock: FootLock | None = None):
        self.layout, self.fps = layout, fps
        self.lock = lock  # plants the feet when the frame says how surely each is planted
        self.follow: RootFollow | None = None  # the body follows its stance foot
        if lock is not None:
            from ..synthesis.follow import RootFollow  # here: synthesis imports this module

            self.follow = RootFollow()
        self.position = np.zeros(3)
        self.heading = 0.0
        self.index = 0

    def next(self, static: np.ndarray, contact_shares: np.ndarray | None = None, follow_strength: float | None = None) -> Pose:
        """The frame's pose; with the feet planted when `contact_shares` (2,) says how surely
        each is planted, the body taking `follow_strength` of a planted foot's slide (default
        follow.STRENGTH)."""
        rotations, translations, (self.position, self.heading) = restore_local(
            static[None], self.layout, self.fps, self.position, self.heading
        )
        if self.lock is not None and contact_shares is not None:
            translations = self._follow(rotations, translations, follow_strength)
            pose = Pose(self.index, self.index / self.fps, *self.lock.apply(rotations[0], translations[0], contact_shares))
        else:
            world_rot, world_pos = forward_kinematics(self.layout.skeleton, rotations, translations)
            pose = Pose(self.index, self.index / self.fps, rotations[0], translations[0], world_rot[0], world_pos[0])
        self.index += 1
        return pose

    def _follow(self, rotations: np.ndarray, translations: np.ndarray, strength: float | None) -> np.ndarray:
        """The frame's translations with the body moved after its stance foot (follow.py), by
        the lock's blend of each foot so far."""
        from ..synthesis.follow import STRENGTH

        world_pos = forward_kinematics(self.layout.skeleton, rotations, translations)[1][0]
        strengths = np.array([STRENGTH if strength is None else strength])
        offset = self.follow.step(world_pos[self.lock.pivot][None], self.lock.weight[None], strengths)[0]
        moved = translations.copy()
        moved[0, self.layout.root] += offset @ self.lock.parent_rot  # world to the root's parent's frame
        return moved


def pose_channels(skeleton, pose: Pose) -> np.ndarray:
    """BVH channel values of a pose (for recording)."""
    return channels_from_local(skeleton, pose.rotations[None], pose.translations[None])[0]
