"""The pose a VMC stream describes, rebuilt from received messages on the rest skeleton that
`instrument skeleton` writes (independently of any receiver's code), for the renderer tests."""

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from instrument.motion.bvh import read_bvh


def sent_pose(rest_path: Path, messages: list) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Joint and End Site positions (Unity metres) of the rest skeleton posed the VMC way by the messages."""
    skeleton = read_bvh(rest_path).skeleton
    bones = {args[0]: (np.array(args[1:4]), Rotation.from_quat(args[4:8]).as_matrix())
             for address, args in messages if address == "/VMC/Ext/Bone/Pos"}
    root_args = next(args for address, args in messages if address == "/VMC/Ext/Root/Pos")
    root_pos, root_rot = np.array(root_args[1:4]), Rotation.from_quat(root_args[4:8]).as_matrix()
    mirror = np.array([-1.0, 1.0, 1.0]) * 0.01  # the rest file: centimetres, right-handed, facing +Z
    world_rot, world_pos = {}, {}
    for j, joint in enumerate(skeleton.joints):
        parent = joint.parent
        if parent < 0:
            world_rot[j], world_pos[j] = root_rot, root_pos
            continue
        local = bones[joint.name][1] if joint.name in bones else np.eye(3)
        world_rot[j] = world_rot[parent] @ local
        if joint.name == "Hips":
            world_pos[j] = root_pos + root_rot @ bones["Hips"][0]
        else:
            world_pos[j] = world_pos[parent] + world_rot[parent] @ (np.array(joint.offset) * mirror)
    positions = {joint.name: world_pos[j] for j, joint in enumerate(skeleton.joints)}
    ends = {joint.name: world_pos[j] + world_rot[j] @ (np.array(joint.end_site) * mirror)
            for j, joint in enumerate(skeleton.joints) if joint.end_site is not None}
    return positions, ends
