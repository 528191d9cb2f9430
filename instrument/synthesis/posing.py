"""From generated features to a pose per frame: the root path integrated as the walk goes, the
feet planted; for one character (`PoseStream`) or a crowd in one compiled call (`CrowdPoses`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from ..motion.features import FeatureLayout
from ..motion.kinematics import _compose
from ..motion.restore_frame import FrameRestorer
from ..motion.rotations import matrix_to_quat
from .cores import over_cores, parts
from .follow import STRENGTH, RootFollow

if TYPE_CHECKING:
    from .footlock import FootLock


@dataclass
class Pose:
    """One frame of the character, in the model's space (right-handed, Y up, the model's units)."""

    index: int
    time: float  # seconds of performance time (index / fps)
    rotations: np.ndarray  # (J, 3, 3) local joint rotations
    translations: np.ndarray  # (J, 3) local joint translations
    world_rotations: np.ndarray  # (J, 3, 3)
    world_positions: np.ndarray  # (J, 3)


@dataclass
class CrowdPose:
    """One frame of N characters: `Pose`'s arrays with a leading character axis."""

    index: int
    time: float
    rotations: np.ndarray  # (N, J, 3, 3)
    translations: np.ndarray  # (N, J, 3)
    world_rotations: np.ndarray  # (N, J, 3, 3)
    world_positions: np.ndarray  # (N, J, 3)

    def character(self, n: int) -> Pose:
        return Pose(self.index, self.time, self.rotations[n], self.translations[n], self.world_rotations[n],
                    self.world_positions[n])


@dataclass
class Frame:
    """What the live loop hands every sink once a frame: every character's pose and every control
    value, so no sink reads the control state (and a sink sees the values the frame was made with)."""

    index: int
    time: float  # seconds of performance time
    crowd: CrowdPose  # every character's pose (one character: a crowd of one)
    values: dict[str, float]  # every target's value (control/values.all_values; NaN: a part weight that follows its style)
    echo: dict[str, float]  # the values a control surface shows (ControlState.echo)
    footfalls: list = field(default_factory=list)  # the feet that landed in this frame (footfalls.Footfall)

    def pose(self, character: int = 0) -> Pose:
        return self.crowd.character(character)


def quaternions(rotations: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) as quaternions (x, y, z, w) with w >= 0 (one sign for receivers)."""
    quats = matrix_to_quat(rotations)
    return np.where(quats[..., 3:4] < 0, -quats, quats)


class CrowdPoses:
    """Turns each frame of static features of N characters into their poses in one compiled
    pass (restore, forward kinematics, the foot lock), carrying each character's root path
    (`positions` (N, 3), `headings` (N,) radians about Y) and lock state (`lock_state`) across
    frames. Without a `lock` (a model without contact statistics) the feet are left as made."""

    def __init__(self, layout: FeatureLayout, fps: float, count: int, lock: FootLock | None = None,
                 positions: np.ndarray | None = None, headings: np.ndarray | None = None):
        self.layout, self.fps, self.count, self.lock = layout, float(fps), int(count), lock
        self.positions = np.zeros((count, 3)) if positions is None else np.array(positions, dtype=np.float64).reshape(count, 3)
        self.headings = np.zeros(count) if headings is None else np.array(headings, dtype=np.float64).reshape(count)
        self.lock_state = None if lock is None else lock.start(count)
        self.follow = None if lock is None else RootFollow(count)  # the body follows its stance foot
        self._none_standing = np.zeros(count, dtype=np.bool_)  # a frame's `standing` when it is not told (made once)
        self.index = 0
        self._restorer = FrameRestorer(layout, fps)
        self._parents = np.asarray(layout.skeleton.parents, dtype=np.int64)
        self._shape = np.asarray(layout.template_pose[1]).shape  # (J, 3)

    def place(self, n: int, position: np.ndarray, heading: float) -> None:
        """Puts character n at `position` (3,) facing `heading` (radians about Y) from its next
        frame on, its feet unlocked (a planted foot is not dragged back to where it was)."""
        self.positions[n], self.headings[n] = position, heading
        if self.lock_state is not None:
            self.lock_state.release(n)
            self.follow.release(n)

    def next(self, static: np.ndarray, shares: np.ndarray | None = None, follow: np.ndarray | None = None,
             standing: np.ndarray | None = None) -> CrowdPose:
        """The poses of static features (N, D); `shares` (N, 2) says how surely each character's
        state has each foot planted (None: the feet are not planted this frame); `follow` (N,)
        how much of a planted foot's slide each body takes (default follow.STRENGTH); `standing`
        (N,) bool: which characters' frames are of a stand (its feet close up: FootLock.apply)."""
        static = np.asarray(static, dtype=np.float64)
        if static.shape != (self.count, self.layout.dimension) or (shares is not None and np.shape(shares) != (self.count, 2)):
            # the kernels do not check their bounds: a wrong shape would read past the arrays
            raise ValueError(f"CrowdPoses.next: static {static.shape} and shares {np.shape(shares)} for "
                             f"{self.count} characters of {self.layout.dimension} features")
        joints = self._shape[0]
        rotations = np.empty((self.count, joints, 3, 3))
        translations = np.empty((self.count, joints, 3))
        world_rot, world_pos = np.empty_like(rotations), np.empty_like(translations)
        static = np.ascontiguousarray(static)
        cut = parts(self.count)
        if len(cut) == 1:  # one core's worth (one character): no parts to cut
            self._made(static, self.positions, self.headings, rotations, translations, world_rot, world_pos)
        else:
            over_cores(self._made, [(static[a:b], self.positions[a:b], self.headings[a:b], rotations[a:b],
                                     translations[a:b], world_rot[a:b], world_pos[a:b]) for a, b in cut])
        if self.lock is not None and shares is not None:
            self._follow(translations, world_rot, world_pos, np.full(self.count, STRENGTH) if follow is None else follow)
            standing = self._none_standing if standing is None else np.asarray(standing, dtype=np.bool_)
            if len(cut) == 1:
                self.lock.apply(self.lock_state, rotations, translations, shares, world_rot, world_pos, standing)
            else:
                shares = np.ascontiguousarray(shares, dtype=np.float64)
                over_cores(self.lock.apply, [(self.lock_state.part(a, b), rotations[a:b], translations[a:b], shares[a:b],
                                              world_rot[a:b], world_pos[a:b], standing[a:b]) for a, b in cut])
        elif self.lock is not None:  # no feet planted this frame: the body stays where following took it
            self._shift(translations, world_pos, self.follow.offset)
        pose = CrowdPose(self.index, self.index / self.fps, rotations, translations, world_rot, world_pos)
        self.index += 1
        return pose

    def _made(self, static: np.ndarray, positions: np.ndarray, headings: np.ndarray, rotations: np.ndarray,
              translations: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray) -> None:
        """Some characters' poses as made (before the lock): restored, then their world transforms."""
        self._restorer.next(static, positions, headings, rotations, translations)
        _compose(self._parents, rotations, translations, world_rot, world_pos)

    def _follow(self, translations: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray, strengths: np.ndarray) -> None:
        """Moves each body after its stance foot (follow.py) in place, by the lock's blend of each
        foot so far: the root's translation and, as the whole skeleton hangs from the root,
        every joint's world position."""
        pivots = self.lock.pivots(world_rot, world_pos)  # (N, 2, 3) in the generated pose
        self._shift(translations, world_pos, self.follow.step(pivots, self.lock_state.weights,
                                                              np.asarray(strengths, dtype=np.float64)))

    def _shift(self, translations: np.ndarray, world_pos: np.ndarray, offset: np.ndarray) -> None:
        """Moves each body by its world offset (N, 3) in place."""
        translations[:, self.layout.root] += offset @ self.lock.parent_rot  # world to the root's parent's frame
        world_pos += offset[:, None, :]


class PoseStream:
    """One character's `CrowdPoses`: each frame of static features (D,) becomes a `Pose`."""

    def __init__(self, layout: FeatureLayout, fps: float, lock: FootLock | None = None,
                 position: np.ndarray | None = None, heading: float = 0.0):
        self.crowd = CrowdPoses(layout, fps, 1, lock, None if position is None else [position], [heading])

    @property
    def lock_weights(self) -> np.ndarray:
        """(2,) how far each foot's lock is blended in (0..1)."""
        return np.zeros(2) if self.crowd.lock_state is None else self.crowd.lock_state.weights[0]

    def next(self, static: np.ndarray, contact_shares: np.ndarray | None = None, follow_strength: float | None = None) -> Pose:
        """The frame's pose; the feet planted when `contact_shares` (2,) says how surely each is,
        the body taking `follow_strength` of a planted foot's slide (default follow.STRENGTH)."""
        shares = None if contact_shares is None else np.asarray(contact_shares, dtype=np.float64)[None]
        follow = None if follow_strength is None else np.array([follow_strength], dtype=np.float64)
        return self.crowd.next(np.asarray(static)[None], shares, follow).character(0)

