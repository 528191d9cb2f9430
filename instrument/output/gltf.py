"""Binary glTF 2.0 (.glb): a motion's skeleton and its animation, for animators and game engines.

Animators and game developers import glTF more readily than BVH (Blender, Godot, Unity, Unreal
and three.js read it natively). The file holds:

- one node per joint, in the skeleton's hierarchy, named as in the BVH; its rest is the joint's
  offset (no rotation), converted to metres (the unit guessed from the hips' height, as the VMC
  profile does). glTF is Y up and right-handed, as the instrument's BVH files are, so positions
  need no change of axes;
- a skin whose joints are those nodes (inverse bind matrices from the rest), so an importer makes
  an armature of them and a mesh can be bound to it later ("skinned-ready": there is no mesh);
- one animation with, per joint, one rotation and one translation channel keyed at every frame
  of the motion's frame rate (LINEAR interpolation; quaternions kept on one side of the sphere
  from frame to frame so nothing spins the long way between keys).

Written with numpy, struct and json only; checked by the Khronos glTF-Validator in the tests.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from ..errors import UserError
from ..motion.bvh import Motion
from ..motion.kinematics import local_transforms, world_positions
from ..motion.rotations import continuous_quaternions, matrix_to_quat
from ..motion.limbs import units_to_metres

FLOAT = 5126  # componentType of float32 accessors
FLOAT_MAX = float(np.finfo(np.float32).max)
GLB_MAGIC, GLB_VERSION = b"glTF", 2
JSON_CHUNK, BIN_CHUNK = b"JSON", b"BIN\0"


def motion_scale(motion: Motion) -> float:
    """Metres per file unit, guessed from the first frame's hips height above its lowest joint;
    the hips are the first joint the body branches at (the spine and the legs), as the root may be
    a joint on the floor."""
    skeleton = motion.skeleton
    positions = world_positions(Motion(skeleton, motion.channels[:1], motion.fps))[0]
    hips = next((j for j in range(len(skeleton.joints)) if len(skeleton.children(j)) > 1), 0)
    return units_to_metres(float(positions[hips, 1] - positions[:, 1].min()))


class _Buffer:
    """The binary chunk: float32 blocks, each with its buffer view and accessor."""

    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def add(self, values: np.ndarray, kind: str, bounds: bool = False) -> int:
        """Append a float32 array (count, components...) as one accessor of `kind` (SCALAR, VEC3,
        VEC4, MAT4); `bounds` adds the min and max glTF requires of animation inputs."""
        largest = float(np.abs(values).max(initial=0.0))
        if not largest <= FLOAT_MAX:  # the validator refuses Infinity: one line, not a broken file
            raise UserError(f"a value is too large for glTF's 32-bit floats ({largest:.3g}; at most {FLOAT_MAX:.2g})")
        values = np.ascontiguousarray(values, dtype="<f4")
        self.views.append({"buffer": 0, "byteOffset": len(self.data), "byteLength": values.nbytes})
        self.data += values.tobytes()
        accessor = {"bufferView": len(self.views) - 1, "componentType": FLOAT, "count": int(values.shape[0]), "type": kind}
        if bounds:
            flat = values.reshape(values.shape[0], -1)
            accessor["min"], accessor["max"] = flat.min(axis=0).tolist(), flat.max(axis=0).tolist()
        self.accessors.append(accessor)
        return len(self.accessors) - 1


def glb_bytes(motion: Motion, scale: float | None = None) -> bytes:
    """The motion as a binary glTF file; `scale`: metres per file unit (None: guessed)."""
    if motion.frames == 0:
        raise UserError("the motion has no frames: glTF needs at least one")
    skeleton = motion.skeleton
    scale = motion_scale(motion) if scale is None else scale
    rotations, translations = local_transforms(motion)
    quats = np.transpose(continuous_quaternions(matrix_to_quat(rotations)), (1, 0, 2))  # (J, T, 4) x, y, z, w
    quats /= np.linalg.norm(quats, axis=-1, keepdims=True)
    translations = np.transpose(translations, (1, 0, 2)) * scale  # (J, T, 3)
    rest = skeleton.offsets * scale
    rest_world = np.zeros_like(rest)
    for j, parent in enumerate(skeleton.parents):  # parents come first in a BVH
        rest_world[j] = rest[j] + (rest_world[parent] if parent >= 0 else 0.0)

    buffer = _Buffer()
    times = buffer.add(np.arange(motion.frames) / motion.fps, "SCALAR", bounds=True)
    inverse_bind = np.tile(np.eye(4), (len(rest), 1, 1))
    inverse_bind[:, 3, :3] = -rest_world  # column-major: the translation is the last column
    binds = buffer.add(inverse_bind, "MAT4")
    samplers, channels = [], []
    for j in range(len(skeleton.joints)):
        for path, values, kind in (("rotation", quats[j], "VEC4"), ("translation", translations[j], "VEC3")):
            samplers.append({"input": times, "output": buffer.add(values, kind), "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": j, "path": path}})

    nodes = []
    for j, joint in enumerate(skeleton.joints):
        node: dict = {"name": joint.name, "translation": rest[j].tolist()}
        children = skeleton.children(j)
        if children:
            node["children"] = children
        nodes.append(node)
    roots = [j for j, parent in enumerate(skeleton.parents) if parent < 0]
    document = {
        "asset": {"version": "2.0", "generator": "instrument"},
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "skins": [{"joints": list(range(len(nodes))), "skeleton": roots[0], "inverseBindMatrices": binds}],
        "animations": [{"name": "walk", "samplers": samplers, "channels": channels}],
        "accessors": buffer.accessors,
        "bufferViews": buffer.views,
        "buffers": [{"byteLength": len(buffer.data)}],
    }
    return _glb(json.dumps(document, separators=(",", ":")).encode("utf-8"), bytes(buffer.data))


def _glb(document: bytes, binary: bytes) -> bytes:
    """The GLB container: a 12-byte header, the JSON chunk padded with spaces, the binary chunk
    padded with zeros (chunks are 4-byte aligned)."""
    document += b" " * (-len(document) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<I4s", len(document), JSON_CHUNK) + document + struct.pack("<I4s", len(binary), BIN_CHUNK) + binary
    return struct.pack("<4sII", GLB_MAGIC, GLB_VERSION, 12 + len(chunks)) + chunks
