"""A crowd in the live instrument: N walkers around the performed walk (docs/crowds.md).

Character 0 walks exactly as performed, as a run of one character does. Every other character
k has, drawn once from its own seed (the run's seed + k, so a replay is exact):

- a style offset of its own: a style mix (a Dirichlet draw over the styles: mostly one or two
  of them) minus the even mix, so its weights add up to 0. The `spread` control scales it: a
  character's weights are the performed ones plus `spread` times its offset (0: all as
  performed; 1: each its own mix around the performed one). The offsets change no total: a
  walk inside the styles' blends stays near them. Part weights set for a body part move the
  same way; those that follow the overall weights keep following;
- a start phase: the step and state it starts in, so the crowd does not step in unison;
- its own liveliness draws (the walker's generator, seeded the same way).

On the floor the characters stand in a grid, character 0 at the origin, the others in rows
beside it (across the direction of travel) and behind it, `spacing` metres apart.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.features import FeatureLayout
from ..motion.kinematics import forward_kinematics, local_transforms
from ..output.vmc import forward_direction, units_to_metres
from ..synthesis.stream import LABEL, STATE, Controls, Crowd
from .pose import Pose, PoseStream

DEFAULT_SPACING = 1.5  # metres between neighbours on the floor
MIX_CONCENTRATION = 0.5  # of the Dirichlet draw: below 1 a character's own mix leans on one or two styles
MIX_STREAM = 1  # the draws of a character's mix and phase come from seed sequence (seed, MIX_STREAM)


@dataclass(frozen=True)
class Cast:
    """Who is in the crowd: per character its seed, own style mix and start phase."""

    seeds: list[int]
    offsets: np.ndarray  # (N, styles) each character's style offset at spread 1; row 0 zeros (the performance itself)
    phases: np.ndarray  # (N, 2): label (which foot steps) and state it starts in; row 0 zeros

    @property
    def count(self) -> int:
        return len(self.seeds)


def make_cast(count: int, styles: int, states: int, seed: int = 0) -> Cast:
    seeds = [seed + k for k in range(count)]
    offsets = np.zeros((count, styles))
    phases = np.zeros((count, 2), dtype=np.int64)
    for k in range(1, count):
        rng = np.random.default_rng([seeds[k], MIX_STREAM])
        offsets[k] = rng.dirichlet(np.full(styles, MIX_CONCENTRATION)) - 1.0 / styles
        phases[k] = rng.integers(0, 2), rng.integers(0, states)
    return Cast(seeds, offsets, phases)


def start_phases(walker: Crowd, cast: Cast) -> None:
    """Put each character of a fresh walker at its start phase (before its first frame)."""
    walker.counters[:, LABEL] = cast.phases[:, 0]
    walker.counters[:, STATE] = cast.phases[:, 1]


class CastControls:
    """Each character's Controls from the performed ones and the spread.

    The same objects are handed out while neither the performed controls (what lambda* depends
    on) nor the spread change, so the walkers do not recompute lambda* every frame."""

    def __init__(self, cast: Cast):
        self.offsets = cast.offsets
        self._key: tuple | None = None
        self._others: list[Controls] = []

    def __call__(self, controls: Controls, spread: float) -> list[Controls]:
        if self.offsets.shape[0] == 1:
            return [controls]
        key = (controls.key(), float(spread))
        if key != self._key:
            self._key = key
            self._others = [spread_controls(controls, offset, spread) for offset in self.offsets[1:]]
        return [controls] + self._others


def spread_controls(controls: Controls, offset: np.ndarray, spread: float) -> Controls:
    """`controls` with `spread` times `offset` added to the style weights (and to the part
    weights set for a body part; NaN, following the overall weights, stays NaN)."""
    weights = controls.weights + spread * offset
    parts = None
    if controls.part_weights is not None:
        parts = controls.part_weights + spread * offset[:, None]
    return Controls(weights, parts, controls.speed, controls.state_scale, controls.liveliness, controls.turn)


def metres_to_units(layout: FeatureLayout) -> float:
    """Model units per metre, from the template pose's hip height (as the VMC profile guesses)."""
    template = Motion(layout.skeleton, np.asarray(layout.template)[None], 30.0)
    positions = forward_kinematics(layout.skeleton, *local_transforms(template))[1][0]
    return 1.0 / units_to_metres(float(positions[layout.root][1] - positions[:, 1].min()))


def floor_positions(model: Model, count: int, spacing_m: float = DEFAULT_SPACING) -> np.ndarray:
    """(N, 3) where each character starts, in model units: a grid of ceil(sqrt(N)) columns
    across the direction of travel, rows behind one another, character 0 at the origin."""
    layout = model.layout
    forward = forward_direction(model.average.means[..., : layout.dimension])
    forward = forward / max(np.linalg.norm(forward), 1e-12)
    across = np.cross(np.array([0.0, 1.0, 0.0]), forward)
    columns = int(np.ceil(np.sqrt(count)))
    k = np.arange(count)
    step = spacing_m * metres_to_units(layout)
    return step * ((k % columns)[:, None] * across - (k // columns)[:, None] * forward) + 0.0  # + 0.0: no -0.0


@dataclass
class CrowdPose:
    """One frame of N characters: `Pose`'s arrays with a leading character axis (the same
    fields as the batched pose path's CrowdPose on branch lockfast)."""

    index: int
    time: float
    rotations: np.ndarray  # (N, J, 3, 3)
    translations: np.ndarray  # (N, J, 3)
    world_rotations: np.ndarray  # (N, J, 3, 3)
    world_positions: np.ndarray  # (N, J, 3)

    def character(self, n: int) -> Pose:
        return Pose(self.index, self.time, self.rotations[n], self.translations[n], self.world_rotations[n],
                    self.world_positions[n])


class LoopedPoses:
    """Features to poses for N characters, one PoseStream each, started at `positions` (N, 3).

    The swap point for the batched pose path (`CrowdPoses` in runtime/pose.py on branch
    lockfast, which takes the same frames and returns the same CrowdPose in one compiled call):
    `perform` makes this in one line."""

    def __init__(self, layout: FeatureLayout, fps: float, positions: np.ndarray, lock_factory):
        self.streams = [PoseStream(layout, fps, lock_factory()) for _ in range(len(positions))]
        for stream, position in zip(self.streams, positions):
            stream.position = np.array(position, dtype=np.float64)

    def next(self, static: np.ndarray, shares: np.ndarray | None = None) -> CrowdPose:
        """The poses of static features (N, D); `shares` (N, 2) how surely each character's state
        has each foot planted (None: the feet are not planted)."""
        poses = [stream.next(frame, None if shares is None else shares[n]) for n, (stream, frame) in enumerate(zip(self.streams, static))]
        first = poses[0]
        return CrowdPose(first.index, first.time, *(np.stack([getattr(p, name) for p in poses]) for name in
                                                     ("rotations", "translations", "world_rotations", "world_positions")))
