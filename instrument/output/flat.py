"""The flat OSC profile: one address per value group, for TouchDesigner, Max, Pd, Blender add-ons.

Per frame, in bundles of at most 1,400 bytes, in this order:

    /walk/bone/<Joint>/quat  f f f f   local rotation of every joint (x, y, z, w), BVH joint names
    /walk/bone/<Joint>/pos   f f f     world position of every joint (model units)
    /walk/root/pos           f f f     world position of the root joint
    /walk/root/quat          f f f f   world rotation of the root joint (x, y, z, w)
    /walk/root/local         f f f     local translation of the root joint (its BVH position channels)
    /walk/style/<name>       f         echo of every style weight
    /walk/speed, /walk/turn, /walk/liveliness, /walk/spread   f   echo of the other controls
    /walk/frame              i f       frame index and performance time in seconds; sent last,
                                       so a receiver can apply the frame when it arrives

and, in a bundle of their own before the frame's, one message per foot that landed in the frame:

    /walk/footfall           s i f f   side ("left" or "right"), character, performance time in
                                       seconds, the foot's speed at impact in metres per second

Coordinates are the model's: right-handed, Y up, the units of the training data (centimetres
for the shipped model).

A crowd (`run --characters N`): character 0 is sent at the addresses above, exactly as a single
character; character K (1 to N-1) at the same bone and root addresses under
/walk/character/K/ (/walk/character/K/bone/<Joint>/quat, /walk/character/K/root/pos, ...),
after character 0's root and before the echo. The echo and /walk/frame are sent once, last.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..synthesis.footfalls import SIDES, Footfall
from ..synthesis.posing import Pose, quaternions
from .osc import bundles, float_prefix, message


def character_prefix(k: int) -> str:
    """Where character k's bone and root addresses start: /walk for character 0 (a crowd's
    first character is sent as a single one is), /walk/character/k for the others."""
    return "/walk" if k == 0 else f"/walk/character/{k}"


@dataclass(frozen=True)
class FrameTemplate:
    """A frame's bundles with every value left as a slot: every message of the profile has a
    fixed size, so the bundles are cut the same way every frame, and a frame is the template
    with its float32 values (and the frame index) written in by one numpy scatter."""

    data: np.ndarray  # uint8: every datagram of a frame, back to back
    float_slots: np.ndarray  # (values, 4) byte positions of each float32, in message order
    index_slot: np.ndarray  # (4,) byte positions of /walk/frame's int32
    bounds: list[tuple[int, int]]  # each datagram's start and end in `data`

    @classmethod
    def build(cls, prefixes: list[bytes], widths: list[int]) -> FrameTemplate:
        """For messages of `widths[k]` float32 values after `prefixes[k]`, then /walk/frame."""
        frame = message("/walk/frame", 0, 0.0)
        datagrams = bundles([p + bytes(4 * w) for p, w in zip(prefixes, widths)] + [frame])
        starts, bounds, base = [], [], 0
        for datagram in datagrams:  # where each message landed: "#bundle\0", time tag, then (size, message)...
            at = 16
            while at < len(datagram):
                size = int.from_bytes(datagram[at : at + 4], "big", signed=True)
                starts.append(base + at + 4)
                at += 4 + size
            bounds.append((base, base + len(datagram)))
            base += len(datagram)
        lanes = np.arange(4)
        floats = [start + len(p) + 4 * i for start, p, w in zip(starts, prefixes, widths) for i in range(w)]
        frame_values = starts[-1] + len(frame) - 8  # the int32 index, then the float32 time
        floats.append(frame_values + 4)
        return cls(np.frombuffer(b"".join(datagrams), dtype=np.uint8).copy(), np.array(floats)[:, None] + lanes,
                   frame_values + lanes, bounds)

    def fill(self, values: np.ndarray, index: int) -> list[bytes]:
        data = self.data.copy()
        data[self.float_slots] = np.ascontiguousarray(values, dtype=">f4").view(np.uint8).reshape(-1, 4)
        data[self.index_slot] = np.array([index], dtype=">i4").view(np.uint8)
        raw = data.tobytes()
        return [raw[a:b] for a, b in self.bounds]


class FlatProfile:
    def __init__(self, joint_names: list[str], root: int, characters: int = 1):
        self.names = joint_names
        self.root = root
        self.whole_crowd = characters > 1  # datagrams() takes every character's pose (a CrowdPose)
        joints = len(joint_names)
        # per character, in the order sent: a quaternion per joint, a position per joint, the root's position,
        # world rotation and local translation
        self.prefixes, self.widths = [], []
        for head in (character_prefix(k) for k in range(characters)):
            self.prefixes += [float_prefix(f"{head}/bone/{n}/quat", 4) for n in joint_names]
            self.prefixes += [float_prefix(f"{head}/bone/{n}/pos", 3) for n in joint_names]
            self.prefixes += [float_prefix(f"{head}/root/{kind}", width)
                              for kind, width in (("pos", 3), ("quat", 4), ("local", 3))]
            self.widths += [4] * joints + [3] * joints + [3, 4, 3]
        self._template: tuple[tuple[str, ...], FrameTemplate] | None = None  # for the echo's names

    def datagrams(self, pose: Pose, echo: dict[str, float]) -> list[bytes]:
        """One frame's bundles: of one character (a Pose), or of a crowd (a CrowdPose: the same
        arrays with a leading character axis)."""
        arrays = (pose.rotations, pose.world_rotations, pose.world_positions, pose.translations)
        if pose.rotations.ndim == 3:  # one character: a crowd of one
            arrays = tuple(a[None] for a in arrays)
        rotations, world_rotations, world_positions, translations = arrays
        root, count = self.root, rotations.shape[0]
        quats = quaternions(np.concatenate([rotations, world_rotations[:, root, None]], axis=1))  # local, then the root's world
        values = np.concatenate([quats[:, :-1].reshape(count, -1), world_positions.reshape(count, -1), world_positions[:, root],
                                 quats[:, -1], translations[:, root]], axis=1)
        names = tuple(echo)
        if self._template is None or self._template[0] != names:
            echo_prefixes = [float_prefix(f"/walk/{name}", 1) for name in names]
            self._template = names, FrameTemplate.build(self.prefixes + echo_prefixes, self.widths + [1] * len(names))
        everything = np.concatenate([values.ravel(), np.fromiter(echo.values(), float, len(names)), [float(pose.time)]])
        return self._template[1].fill(everything, int(pose.index))


def footfall_datagrams(footfalls: list[Footfall], characters: range) -> list[bytes]:
    """The /walk/footfall messages of a frame's footfalls of `characters`, bundled (none: [])."""
    messages = [message("/walk/footfall", SIDES[f.side], f.character, f.time, f.speed)
                for f in footfalls if f.character in characters]
    return bundles(messages) if messages else []
