"""Run inside Blender: import a BVH with Blender's own importer and print joint positions.

    blender -b --factory-startup --python-exit-code 1 --python import_bvh_check.py -- HOW FILE.bvh FRAME...
    (or `python import_bvh_check.py -- ...` with PyPI's bpy)

HOW is `plain` (File > Import > Motion Capture, as a user would, in the file's units) or the
path of the add-on examples/blender/instrument_vmc.py, whose `import_bvh` (metres) is the way
round Blender 3.4's importer on Python 3.11. Prints one JSON line: {"frames": [start, end],
"bones": [...], "positions": {frame: {bone: [x, y, z]}}}, positions in the file's units.
"""

import importlib.util
import json
import sys

import bpy

how, path, *frames = sys.argv[sys.argv.index("--") + 1 :]
frames = [int(f) for f in frames]
if how == "plain":
    bpy.ops.import_anim.bvh(filepath=path, global_scale=1.0, frame_start=1, use_fps_scale=False, rotate_mode="NATIVE")
    scale = 1.0
else:
    spec = importlib.util.spec_from_file_location("instrument_vmc", how)
    addon = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(addon)
    addon.import_bvh(path)
    scale = 0.01  # the add-on imports centimetres as metres
armature = next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")
action = armature.animation_data.action
positions = {}
for frame in frames:
    bpy.context.scene.frame_set(frame + 1)
    positions[frame] = {b.name: list(armature.matrix_world @ b.head / scale) for b in armature.pose.bones}
print(json.dumps({"frames": list(action.frame_range), "bones": [b.name for b in armature.pose.bones], "positions": positions}))
