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

Coordinates are the model's: right-handed, Y up, the units of the training data (centimetres
for the shipped model).

A crowd (`run --characters N`): character 0 is sent at the addresses above, exactly as a single
character; character K (1 to N-1) at the same bone and root addresses under
/walk/character/K/ (/walk/character/K/bone/<Joint>/quat, /walk/character/K/root/pos, ...),
after character 0's root and before the echo. The echo and /walk/frame are sent once, last.
"""

from __future__ import annotations

import numpy as np

from ..runtime.pose import Pose, quaternions
from .osc import bundles, float_messages, float_prefix, message


def character_prefix(k: int) -> str:
    """Where character k's bone and root addresses start: /walk for character 0 (a crowd's
    first character is sent as a single one is), /walk/character/k for the others."""
    return "/walk" if k == 0 else f"/walk/character/{k}"


class FlatProfile:
    def __init__(self, joint_names: list[str], root: int, characters: int = 1):
        self.names = joint_names
        self.root = root
        self.whole_crowd = characters > 1  # datagrams() takes every character's pose (a list)
        heads = [character_prefix(k) for k in range(characters)]
        # per character: a quaternion per joint then the root's; a position per joint, the root's world and local
        self.quat_prefixes = [[float_prefix(f"{h}/bone/{n}/quat", 4) for n in joint_names] + [float_prefix(f"{h}/root/quat", 4)]
                              for h in heads]
        self.pos_prefixes = [[float_prefix(f"{h}/bone/{n}/pos", 3) for n in joint_names]
                             + [float_prefix(f"{h}/root/pos", 3), float_prefix(f"{h}/root/local", 3)] for h in heads]

    def datagrams(self, pose: Pose | list[Pose], echo: dict[str, float]) -> list[bytes]:
        """One frame's bundles: of one character, or of a crowd given every character's pose."""
        poses = pose if isinstance(pose, list) else [pose]
        root = self.root
        # local rotations, then the root's world rotation; world positions, then the root's local translation
        quats = quaternions(np.stack([np.concatenate([p.rotations, p.world_rotations[root][None]]) for p in poses]))
        positions = np.stack([np.concatenate([p.world_positions, p.world_positions[root][None], p.translations[root][None]])
                              for p in poses])
        joints = len(self.names)
        messages = []
        for quat_prefixes, pos_prefixes, q, x in zip(self.quat_prefixes, self.pos_prefixes, quats, positions):
            q_messages, x_messages = float_messages(quat_prefixes, q), float_messages(pos_prefixes, x)
            messages += q_messages[:joints] + x_messages[:joints]
            messages += [x_messages[joints], q_messages[joints], x_messages[joints + 1]]  # root pos, quat, local
        messages += [message(f"/walk/{name}", value) for name, value in echo.items()]
        messages.append(message("/walk/frame", int(poses[0].index), float(poses[0].time)))
        return bundles(messages)
