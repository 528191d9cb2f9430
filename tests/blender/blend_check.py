"""Run inside Blender: open saved .blend files and report their armatures' keys and pose.

    blender -b --factory-startup --python-exit-code 1 --python blend_check.py -- REPORT.json FILE.blend...
    (or `python blend_check.py -- ...` with PyPI's bpy)

Per file: the scene's frame rate and, per armature object, the frames keyed on each bone's
rotation (its first quaternion curve) and, at its last keyed frame, each bone's head and tail in
world space. Reads Actions both ways Blender has stored them: the curves of the Action itself
(3.4) and the curves of the object's slot in a layered Action (4.4 and later; 5.0 has no other).
"""

import json
import re
import sys

import bpy

BONE_PATH = re.compile(r'pose\.bones\["(.+)"\]\.rotation_quaternion')


def fcurves(obj) -> list:
    """The F-curves animating `obj`, wherever this Blender keeps them."""
    data = obj.animation_data
    if data is None or data.action is None:
        return []
    slot = getattr(data, "action_slot", None)
    if slot is not None:
        from bpy_extras.anim_utils import action_get_channelbag_for_slot

        channelbag = action_get_channelbag_for_slot(data.action, slot)
        return list(channelbag.fcurves) if channelbag is not None else []
    return list(data.action.fcurves)


def armature_report(obj) -> dict:
    keys = {}
    for curve in fcurves(obj):
        match = BONE_PATH.fullmatch(curve.data_path)
        if match and curve.array_index == 0:
            keys[match.group(1)] = [point.co.x for point in curve.keyframe_points]
    last = max((frames[-1] for frames in keys.values() if frames), default=None)
    if last is not None:
        bpy.context.scene.frame_set(int(round(last)))
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
