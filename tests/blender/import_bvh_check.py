"""Run inside Blender: import a BVH with Blender's own importer and print joint positions.

    blender -b --factory-startup --python-exit-code 1 --python import_bvh_check.py -- FILE.bvh FRAME...

Prints one JSON line: {"frames": [start, end], "bones": [...], "positions": {frame: {bone: [x, y, z]}}}.
"""

import builtins
import json
import sys

import bpy
import io_anim_bvh.import_bvh as import_bvh

# Blender 3.4's importer opens with mode 'rU', which Python 3.11 rejects
import_bvh.open = lambda path, mode="r", *a, **k: builtins.open(path, mode.replace("U", ""), *a, **k)

args = sys.argv[sys.argv.index("--") + 1 :]
path, frames = args[0], [int(f) for f in args[1:]]
bpy.ops.import_anim.bvh(filepath=path, global_scale=1.0, frame_start=1, use_fps_scale=False, rotate_mode="NATIVE")
armature = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
action = armature.animation_data.action
positions = {}
for frame in frames:
    bpy.context.scene.frame_set(frame + 1)
    positions[frame] = {b.name: list(armature.matrix_world @ b.head) for b in armature.pose.bones}
print(json.dumps({"frames": list(action.frame_range), "bones": [b.name for b in armature.pose.bones], "positions": positions}))
