"""Run inside Blender: drive armatures that are not ours with the VMC add-on, and report.

    blender -b --factory-startup --python-exit-code 1 --python vmc_addon_check.py -- \\
        ADDON.py REST.bvh PORT FRAMES SCALE REPORT.json SAVED.blend
    (or `python vmc_addon_check.py -- ...` with PyPI's bpy)

One Blender run drives several rigs from the same stream, each an import of the rest skeleton:

- one per name preset of the add-on (MIXAMO, RIGIFY, VRM): made into someone else's rig with the
  preset's bone names from the add-on's PRESETS table (Mixamo's inside its `mixamorig:`
  namespace, as Mixamo exports them), every bone scaled by SCALE, the arms lowered 40 degrees
  into an A-pose, the feet turned out 15 degrees, every bone's roll changed;
- APPLIED: the rest as imported (Humanoid names, scale 1), posed in Pose mode (arms 40 degrees
  down, spine 10 degrees forward) and that pose applied as its rest (Pose > Apply > Apply Pose
  as Rest Pose).

Each rig records an Action until FRAMES frames came in, and the scene is saved to SAVED.blend
(blend_check.py reads the keys and the last frame's pose back from it). The report holds the
last frame's messages as received and, per rig, its object, its bone names, its last recorded
frame and how its rest differs from the sent one.
"""

import importlib.util
import json
import math
import random
import sys

import bpy
from mathutils import Matrix

addon_path, rest, port, frames, scale, report, saved = sys.argv[sys.argv.index("--") + 1 :]
port, frames, scale = int(port), int(frames), float(scale)
spec = importlib.util.spec_from_file_location("instrument_vmc", addon_path)
addon = importlib.util.module_from_spec(spec)
spec.loader.exec_module(addon)
addon.register()
NAMESPACE = {"MIXAMO": "mixamorig:"}


def imported() -> bpy.types.Object:
    """A fresh import of the rest skeleton, the only object selected and active."""
    armature = addon.import_rest(rest)
    for other in bpy.context.view_layer.objects:
        other.select_set(other is armature)
    bpy.context.view_layer.objects.active = armature
    return armature


def someone_elses_rig(preset: str, seed: int) -> tuple[bpy.types.Object, dict[str, str]]:
    """The rest, resized, A-posed, feet out, rolls changed and bones renamed to `preset`'s names."""
    armature = imported()
    names = {human: NAMESPACE.get(preset, "") + name for human, name in addon.PRESETS[preset].items()}
    rng = random.Random(seed)
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
    for bone in list(edit):
        if bone.name in names:
            bone.name = names[bone.name]
    bpy.ops.object.mode_set(mode="OBJECT")
    renamed = {human: name for human, name in names.items() if name in armature.data.bones}
    return armature, renamed


def turn_about_head(pose_bone, axis: str, degrees: float) -> None:
    """Rotate a pose bone about a world axis through its head (Pose mode), children following."""
    head = pose_bone.head.copy()
    turn = Matrix.Translation(head) @ Matrix.Rotation(math.radians(degrees), 4, axis) @ Matrix.Translation(-head)
    pose_bone.matrix = turn @ pose_bone.matrix
    bpy.context.view_layer.update()  # the children's matrices follow before they are turned in turn


def pose_applied_as_rest() -> tuple[bpy.types.Object, dict[str, str]]:
    """The rest with arms 40 deg down and the spine 10 deg forward, applied as its rest pose."""
    armature = imported()
    bpy.ops.object.mode_set(mode="POSE")
    bones = armature.pose.bones
    turn_about_head(bones["Spine"], "X", 10.0)  # forward: the character faces -Y
    turn_about_head(bones["LeftUpperArm"], "Y", 40.0)  # down: +X towards -Z
    turn_about_head(bones["RightUpperArm"], "Y", -40.0)
    assert bpy.ops.pose.armature_apply() == {"FINISHED"}
    bpy.ops.object.mode_set(mode="OBJECT")
    names = {human: name for human, name in addon.PRESETS["HUMANOID"].items() if name in armature.data.bones}
    return armature, names


rigs = {}  # rig name -> (armature, preset, scale, humanoid bone -> bone name)
for seed, preset in enumerate(("MIXAMO", "RIGIFY", "VRM")):
    armature, names = someone_elses_rig(preset, seed + 5)
    rigs[preset] = (armature, preset, scale, names)
armature, names = pose_applied_as_rest()
rigs["APPLIED"] = (armature, "HUMANOID", 1.0, names)
fps = bpy.context.scene.render.fps / bpy.context.scene.render.fps_base
drivers = {rig: addon.VmcDriver(armature, preset, rig_scale, record=True)
           for rig, (armature, preset, rig_scale, _) in rigs.items()}


class Fanout:
    """Every message to every rig's driver; keeps the messages of the last applied frame."""

    def __init__(self) -> None:
        self.pending, self.last = [], []

    @property
    def count(self) -> int:
        return min(driver.count for driver in drivers.values())

    def handle(self, address, args) -> bool:
        self.pending.append([address, list(args)])
        applied = [driver.handle(address, args) for driver in drivers.values()]
        if any(applied):
            self.last, self.pending = self.pending, []
        return any(applied)


fanout = Fanout()
addon.run_headless(fanout, port, frames, 120.0)
last_frames = {driver.last_frame for driver in drivers.values()}
if len(last_frames) == 1 and None not in last_frames:
    bpy.context.scene.frame_set(last_frames.pop())  # the recordings, read back at the last frame
bpy.context.view_layer.update()

results = {}
for rig, (armature, preset, rig_scale, names) in rigs.items():
    # the panel's operators: Start listens with the scene's settings, Stop closes the socket
    scene = bpy.context.scene
    scene.instrument_armature, scene.instrument_preset, scene.instrument_port = armature, preset, port
    started = bpy.ops.instrument.start() == {"FINISHED"} and "state" in addon._running
    stopped = bpy.ops.instrument.stop() == {"FINISHED"} and "state" not in addon._running
    rest_of = {human: armature.data.bones[name].matrix_local.to_3x3().col[1] for human, name in names.items()}
    results[rig] = {
        "rest_arm_drop": math.degrees(math.asin(-rest_of["LeftUpperArm"].normalized().z)),
        "rest_spine_lean": math.degrees(math.asin(-rest_of["Spine"].normalized().y)),
        "preset": preset, "scale": rig_scale, "count": drivers[rig].count, "names": names,
        "object": armature.name, "last_frame": drivers[rig].last_frame, "operators": started and stopped}
addon.unregister()
bpy.ops.wm.save_as_mainfile(filepath=saved)
with open(report, "w") as f:
    json.dump({"fps": fps, "messages": fanout.last, "rigs": results}, f)
print(f"applied {fanout.count} frames to {len(rigs)} rigs", flush=True)
