"""Run inside Blender: open saved .blend files and report their armatures' keys and pose.

    blender -b --factory-startup --python-exit-code 1 --python blend_check.py -- REPORT.json FILE.blend...
    (or `python blend_check.py -- ...` with PyPI's bpy)

Per file: the scene's frame rate and, per armature object, the frames keyed on each bone's
rotation (its first quaternion curve) and, at its last keyed frame, each bone's head and tail in
world space.
"""

import json
import os
import sys

import bpy

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from actions import rotation_keys  # the module beside this script


def armature_report(obj) -> dict:
    keys = rotation_keys(obj)
    last = max((frames[-1] for frames in keys.values() if frames), default=None)
    if last is not None:
        bpy.context.scene.frame_set(round(last))
        bpy.context.view_layer.update()
    bones = obj.pose.bones
    return {"keys": keys, "frame": last,
            "heads": {b.name: list(obj.matrix_world @ b.head) for b in bones},
            "tails": {b.name: list(obj.matrix_world @ b.tail) for b in bones}}


report_path, *files = sys.argv[sys.argv.index("--") + 1 :]
report = {}
for path in files:
    bpy.ops.wm.open_mainfile(filepath=path)
    scene = bpy.context.scene
    report[path] = {"fps": scene.render.fps / scene.render.fps_base,
                    "armatures": {obj.name: armature_report(obj) for obj in scene.objects if obj.type == "ARMATURE"}}
with open(report_path, "w") as f:
    json.dump(report, f)
