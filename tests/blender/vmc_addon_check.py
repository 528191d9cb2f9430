"""Run inside Blender: drive an armature that is not ours with the VMC add-on, and report.

    blender -b --factory-startup --python-exit-code 1 --python vmc_addon_check.py -- \\
        ADDON.py REST.bvh PORT FRAMES SCALE REPORT.json

The rest skeleton is imported, then made into someone else's rig: Mixamo names, every bone
scaled by SCALE, the arms lowered 40 degrees into an A-pose, the feet turned out 15 degrees,
every bone's roll changed. The
add-on's Mixamo map drives it (recording an Action) until FRAMES frames came in; the report
holds the last frame's messages as received, the bones' heads and the recorded keys.
"""

import importlib.util
import json
import math
import random
import sys

import bpy
from mathutils import Matrix

addon_path, rest, port, frames, scale, report = sys.argv[sys.argv.index("--") + 1 :]
port, frames, scale = int(port), int(frames), float(scale)
spec = importlib.util.spec_from_file_location("instrument_vmc", addon_path)
addon = importlib.util.module_from_spec(spec)
spec.loader.exec_module(addon)
addon.register()
armature = addon.import_rest(rest)
fps = bpy.context.scene.render.fps / bpy.context.scene.render.fps_base

mixamo = {human: f"mixamorig:{name}" for human, name in addon.PRESETS["MIXAMO"].items()}
rng = random.Random(5)
bpy.ops.object.mode_set(mode="EDIT")
edit = armature.data.edit_bones
for bone in edit:
    bone.head, bone.tail = bone.head * scale, bone.tail * scale
for side, angle in (("Left", 40.0), ("Right", -40.0)):
    pivot = edit[f"{side}UpperArm"].head.copy()
    turn = Matrix.Rotation(math.radians(angle), 3, "Y")
    for name in (f"{side}UpperArm", f"{side}LowerArm", f"{side}Hand"):
        bone = edit[name]
        bone.head, bone.tail = pivot + turn @ (bone.head - pivot), pivot + turn @ (bone.tail - pivot)
for side, angle in (("Left", 15.0), ("Right", -15.0)):  # the feet turned out at rest
    pivot = edit[f"{side}Foot"].head.copy()
    turn = Matrix.Rotation(math.radians(angle), 3, "Z")
    for name in (f"{side}Foot", f"{side}Toes"):
        bone = edit[name]
        bone.head, bone.tail = pivot + turn @ (bone.head - pivot), pivot + turn @ (bone.tail - pivot)
for bone in edit:
    bone.roll += math.radians(rng.uniform(-120.0, 120.0))
    if bone.name in mixamo:
        bone.name = mixamo[bone.name]
bpy.ops.object.mode_set(mode="OBJECT")

driver = addon.VmcDriver(armature, "MIXAMO", scale, record=True)
pending, last = [], {}
handle = driver.handle


def capture(address, args):
    pending.append([address, list(args)])
    applied = handle(address, args)
    if applied:
        last["messages"] = list(pending)
        pending.clear()
    return applied


driver.handle = capture
addon.run_headless(driver, port, frames, 120.0)
if driver.last_frame is not None:
    bpy.context.scene.frame_set(driver.last_frame)  # the recording, read back at the last frame
bpy.context.view_layer.update()
human_of = {name: human for human, name in mixamo.items()}
heads = {human_of[b.name]: list(armature.matrix_world @ b.head) for b in armature.pose.bones if b.name in human_of}
tails = {human_of[b.name]: list(armature.matrix_world @ b.tail) for b in armature.pose.bones
         if b.name in human_of and not b.children}
action = armature.animation_data.action if armature.animation_data else None
keys = {}
if action is not None:
    for curve in action.fcurves:
        if curve.data_path.endswith("rotation_quaternion") and curve.array_index == 0:
            keys[curve.group.name if curve.group else curve.data_path] = [k.co.x for k in curve.keyframe_points]
# the panel's operators: Start listens with the scene's settings, Stop closes the socket
scene = bpy.context.scene
scene.instrument_armature, scene.instrument_preset, scene.instrument_port = armature, "MIXAMO", port
started = bpy.ops.instrument.start() == {"FINISHED"} and "state" in addon._running
stopped = bpy.ops.instrument.stop() == {"FINISHED"} and "state" not in addon._running
addon.unregister()
with open(report, "w") as f:
    json.dump({"count": driver.count, "fps": fps, "messages": last.get("messages", []), "heads": heads, "tails": tails,
               "keys": keys, "action": action.name if action else None, "operators": started and stopped}, f)
print(f"applied {driver.count} frames", flush=True)
