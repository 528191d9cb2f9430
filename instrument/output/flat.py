"""The flat OSC profile: one address per value group, for TouchDesigner, Max, Pd, Blender add-ons.

Per frame, in bundles of at most 1,400 bytes, in this order:

    /walk/bone/<Joint>/quat  f f f f   local rotation of every joint (x, y, z, w), BVH joint names
    /walk/bone/<Joint>/pos   f f f     world position of every joint (model units)
    /walk/root/pos           f f f     world position of the root joint
    /walk/root/quat          f f f f   world rotation of the root joint (x, y, z, w)
    /walk/root/local         f f f     local translation of the root joint (its BVH position channels)
    /walk/style/<name>       f         echo of every style weight
    /walk/speed, /walk/turn, /walk/liveliness   f   echo of the other controls
    /walk/frame              i f       frame index and performance time in seconds; sent last,
                                       so a receiver can apply the frame when it arrives

Coordinates are the model's: right-handed, Y up, the units of the training data (centimetres
for the shipped model).
"""

from __future__ import annotations

import numpy as np

from ..runtime.pose import Pose, quaternions
from .osc import bundles, float_messages, float_prefix, message


class FlatProfile:
    def __init__(self, joint_names: list[str], root: int):
        self.names = joint_names
        self.root = root
        self.quat_prefixes = [float_prefix(f"/walk/bone/{n}/quat", 4) for n in joint_names]
        self.pos_prefixes = [float_prefix(f"/walk/bone/{n}/pos", 3) for n in joint_names]

    def datagrams(self, pose: Pose, echo: dict[str, float]) -> list[bytes]:
        quats = quaternions(np.concatenate([pose.rotations, pose.world_rotations[self.root][None]]))  # local, then the root's world
        messages = float_messages(self.quat_prefixes, quats[:-1])
        messages += float_messages(self.pos_prefixes, pose.world_positions)
        messages.append(message("/walk/root/pos", *pose.world_positions[self.root].tolist()))
        messages.append(message("/walk/root/quat", *quats[-1].tolist()))
        messages.append(message("/walk/root/local", *pose.translations[self.root].tolist()))
        messages += [message(f"/walk/{name}", value) for name, value in echo.items()]
        messages.append(message("/walk/frame", int(pose.index), float(pose.time)))
        return bundles(messages)
