"""An independent reader of the BVH files the instrument writes: the `bvh` package (PyPI) parses
the text and scipy's Rotation composes the joints, so a figure measured here does not go through
the instrument's own parser or kinematics.

Position channels replace a joint's offset (the usual reading); Euler channels compose in the
order written (BVH's Z X Y means R = Rz Rx Ry acting on column vectors: scipy's intrinsic 'ZXY').
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from bvh import Bvh
from scipy.spatial.transform import Rotation


def world_positions(path: str | Path) -> tuple[list[str], np.ndarray, float]:
    """Joint names, world positions (frames, joints, 3) and frames per second of a BVH file."""
    mocap = Bvh(Path(path).read_text())
    names = mocap.get_joints_names()
    frames = mocap.nframes
    values = np.array(mocap.frames, dtype=np.float64)  # (frames, channels)
    world_rot = np.zeros((frames, len(names), 3, 3))
    world_pos = np.zeros((frames, len(names), 3))
    column = 0
    for j, name in enumerate(names):
        channels = mocap.joint_channels(name)
        local = values[:, column:column + len(channels)]
        column += len(channels)
        translation = np.broadcast_to(np.array(mocap.joint_offset(name), dtype=np.float64), (frames, 3)).copy()
        order = ""
        angles = []
        for k, channel in enumerate(channels):
            if channel.endswith("position"):
                translation[:, "XYZ".index(channel[0])] = local[:, k]
            else:
                order += channel[0]
                angles.append(local[:, k])
        rotation = (Rotation.from_euler(order, np.stack(angles, axis=1), degrees=True).as_matrix() if order
                    else np.broadcast_to(np.eye(3), (frames, 3, 3)))
        parent = mocap.joint_parent_index(name)
        if parent < 0:
            world_rot[:, j], world_pos[:, j] = rotation, translation
        else:
            world_rot[:, j] = world_rot[:, parent] @ rotation
            world_pos[:, j] = world_pos[:, parent] + np.einsum("fij,fj->fi", world_rot[:, parent], translation)
    return names, world_pos, 1.0 / mocap.frame_time


def foot_skate(path: str | Path, joints: list[str]) -> tuple[float, float]:
    """The feet as a viewer judges them: for each foot joint, the frames in the lowest 20% of its
    heights count as contact; the mean horizontal speed of the joints in contact (cm/s, the file
    in cm), and the share of frames in which a joint is more than 1 cm below its contact height
    (the median of those lowest frames): a foot under the floor."""
    names, positions, fps = world_positions(path)
    speeds, under = [], []
    for name in joints:
        track = positions[:, names.index(name)]
        height = track[:, 1]
        contact = height <= np.percentile(height, 20)
        velocity = np.linalg.norm(np.diff(track[:, [0, 2]], axis=0), axis=1) * fps
        speeds.append(velocity[contact[1:] & contact[:-1]])
        under.append(height < np.median(height[contact]) - 1.0)
    return float(np.mean(np.concatenate(speeds))), float(np.mean(np.concatenate(under)))
