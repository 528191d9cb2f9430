"""Run inside Blender: import a binary glTF with Blender's own importer and report what it made.

    python import_gltf_check.py -- FPS FILE.glb REPORT.json FRAME...   (PyPI's bpy 4.5 or 5.0)

glTF keys are in seconds; the scene is set to FPS first so that the importer puts each key on a
frame. Reports the armature's bones, the frames keyed on each bone's rotation, and each bone's
head (world space, metres) at the given frames counted from the first key.
"""

import json
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from actions import rotation_keys  # the module beside this script

fps, path, report, *frames = sys.argv[sys.argv.index("--") + 1 :]
scene = bpy.context.scene
scene.render.fps, scene.render.fps_base = int(fps), 1.0
bpy.ops.import_scene.gltf(filepath=path)
(armature,) = [o for o in scene.objects if o.type == "ARMATURE"]
keys = rotation_keys(armature)
first = min(frames_keyed[0] for frames_keyed in keys.values())
heads = {}
for frame in map(int, frames):
    scene.frame_set(round(first) + frame)
    bpy.context.view_layer.update()
    heads[frame] = {b.name: list(armature.matrix_world @ b.head) for b in armature.pose.bones}
with open(report, "w") as f:
    json.dump({"bones": [b.name for b in armature.data.bones], "keys": keys, "heads": heads}, f)
