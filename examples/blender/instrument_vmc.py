"""Blender add-on: drive your own armature with the instrument's VMC stream, and record it.

Install: Edit > Preferences > Add-ons > Install..., pick this file, tick "Animation: Instrument
VMC receiver". The panel is in the 3D view's sidebar (N), tab "Instrument":
  - Import rest: the T-pose skeleton from `instrument skeleton --out rest.bvh` (metres; the
    scene's frame rate is set to the file's), for a character rigged to it. It works where
    File > Import > BVH fails (Blender 3.4 with Python 3.11, as in Debian: "invalid mode: 'rU'");
  - Import BVH: a walk or recording the instrument wrote, with its motion (same fixes);
  - Armature: the armature to drive, and its bone names (Humanoid = the names in that rest
    file and in VMC, Mixamo, Rigify metarig, VRM/VRoid);
  - Port (39539, where `instrument run` sends VMC by default), Start / Stop;
  - Record: every frame received becomes a key of an Action on the armature, at the scene rate.

The VMC profile sends, per humanoid bone, its rotation relative to a normalised T-pose (Unity
axes). The receiver rebuilds each bone's world rotation from the T-pose, and retargets it to
the armature's own rest: the rest bone swung onto the T-pose direction (arms out, legs down,
spine up; feet and toes only turned to point ahead) is where the T-pose rotation is applied. So
any rest works: a T-pose, an A-pose, any bone roll, or a pose applied as rest. Bones the map
leaves out follow their parents.

Headless (for tests and batch recording; timers never fire in -b mode, so the main thread
polls the socket); the recording is saved when it ends, after --frames, --timeout or Ctrl-C:
    blender -b --factory-startup --python instrument_vmc.py -- --rest rest.bvh --frames 300 \
        --record --save take.blend
or, with PyPI's bpy module (Blender 4.5 LTS, 5.0) in a Python 3.11 environment:
    python instrument_vmc.py -- --rest rest.bvh --frames 300 --record --save take.blend
Tested headless in Blender 3.4 (Debian), 4.5 LTS and 5.0 (PyPI's bpy).
Self-contained: a small OSC decoder is included, so Blender needs no extra Python packages.
"""

import builtins
import math
import queue
import socket
import struct
import threading

import bpy
from bpy_extras.io_utils import ImportHelper
from mathutils import Matrix, Vector

bl_info = {
    "name": "Instrument VMC receiver",
    "author": "instrument",
    "version": (1, 0, 0),
    "blender": (3, 4, 0),
    "location": "View3D > Sidebar > Instrument",
    "description": "Drive an armature from a VMC (Virtual Motion Capture protocol) stream and record it",
    "category": "Animation",
}

PORT = 39539
# Unity (left-handed, Y up, the character facing +Z) -> Blender (Z up, facing -Y)
UNITY_TO_BLENDER = Matrix(((-1, 0, 0), (0, 0, -1), (0, 1, 0)))
FINGERS = ("Thumb", "Index", "Middle", "Ring", "Little")
PHALANGES = ("Proximal", "Intermediate", "Distal")
HUMAN_PARENT = {"Hips": None, "Spine": "Hips", "Chest": "Spine", "UpperChest": "Chest", "Neck": "UpperChest", "Head": "Neck"}
for _side in ("Left", "Right"):
    HUMAN_PARENT.update({
        f"{_side}Shoulder": "UpperChest", f"{_side}UpperArm": f"{_side}Shoulder", f"{_side}LowerArm": f"{_side}UpperArm",
        f"{_side}Hand": f"{_side}LowerArm", f"{_side}UpperLeg": "Hips", f"{_side}LowerLeg": f"{_side}UpperLeg",
        f"{_side}Foot": f"{_side}LowerLeg", f"{_side}Toes": f"{_side}Foot"})
    for _finger in FINGERS:
        for _k, _phalanx in enumerate(PHALANGES):
            HUMAN_PARENT[f"{_side}{_finger}{_phalanx}"] = f"{_side}Hand" if _k == 0 else f"{_side}{_finger}{PHALANGES[_k - 1]}"
# T-pose direction of each bone in Blender's axes (None: only turned to point ahead; missing: follows its parent)
TPOSE_DIRECTION = {b: Vector((0, 0, 1)) for b in ("Hips", "Spine", "Chest", "UpperChest", "Neck", "Head")}
for _side, _x in (("Left", 1), ("Right", -1)):
    TPOSE_DIRECTION.update({f"{_side}{b}": Vector((_x, 0, 0)) for b in ("Shoulder", "UpperArm", "LowerArm", "Hand")})
    TPOSE_DIRECTION.update({f"{_side}{b}": Vector((0, 0, -1)) for b in ("UpperLeg", "LowerLeg")})
    TPOSE_DIRECTION.update({f"{_side}Foot": None, f"{_side}Toes": None})


def _preset(names: dict[str, str], fingers) -> dict[str, str]:
    out = dict(names)
    for side in ("Left", "Right"):
        for finger in FINGERS:
            for k, phalanx in enumerate(PHALANGES):
                out[f"{side}{finger}{phalanx}"] = fingers(side, finger, k + 1)
    return out


def _sided(pattern: dict[str, str], left: str, right: str) -> dict[str, str]:
    out = {}
    for bone, name in pattern.items():
        if "{s}" in bone:
            out[bone.format(s="Left")] = name.format(s=left)
            out[bone.format(s="Right")] = name.format(s=right)
        else:
            out[bone] = name
    return out


MIXAMO_FINGER = {"Thumb": "Thumb", "Index": "Index", "Middle": "Middle", "Ring": "Ring", "Little": "Pinky"}
RIGIFY_FINGER = {"Thumb": "thumb", "Index": "f_index", "Middle": "f_middle", "Ring": "f_ring", "Little": "f_pinky"}
PRESETS = {
    "HUMANOID": {b: b for b in HUMAN_PARENT},
    "MIXAMO": _preset(_sided({
        "Hips": "Hips", "Spine": "Spine", "Chest": "Spine1", "UpperChest": "Spine2", "Neck": "Neck", "Head": "Head",
        "{s}Shoulder": "{s}Shoulder", "{s}UpperArm": "{s}Arm", "{s}LowerArm": "{s}ForeArm", "{s}Hand": "{s}Hand",
        "{s}UpperLeg": "{s}UpLeg", "{s}LowerLeg": "{s}Leg", "{s}Foot": "{s}Foot", "{s}Toes": "{s}ToeBase"}, "Left", "Right"),
        lambda side, finger, k: f"{side}Hand{MIXAMO_FINGER[finger]}{k}"),
    "RIGIFY": _preset(_sided({
        "Hips": "spine", "Spine": "spine.001", "Chest": "spine.002", "UpperChest": "spine.003", "Neck": "spine.004",
        "Head": "spine.006", "{s}Shoulder": "shoulder.{s}", "{s}UpperArm": "upper_arm.{s}", "{s}LowerArm": "forearm.{s}",
        "{s}Hand": "hand.{s}", "{s}UpperLeg": "thigh.{s}", "{s}LowerLeg": "shin.{s}", "{s}Foot": "foot.{s}",
        "{s}Toes": "toe.{s}"}, "L", "R"),
        lambda side, finger, k: f"{RIGIFY_FINGER[finger]}.0{k}.{side[0]}"),
    "VRM": _preset(_sided({
        "Hips": "J_Bip_C_Hips", "Spine": "J_Bip_C_Spine", "Chest": "J_Bip_C_Chest", "UpperChest": "J_Bip_C_UpperChest",
        "Neck": "J_Bip_C_Neck", "Head": "J_Bip_C_Head", "{s}Shoulder": "J_Bip_{s}_Shoulder", "{s}UpperArm": "J_Bip_{s}_UpperArm",
        "{s}LowerArm": "J_Bip_{s}_LowerArm", "{s}Hand": "J_Bip_{s}_Hand", "{s}UpperLeg": "J_Bip_{s}_UpperLeg",
        "{s}LowerLeg": "J_Bip_{s}_LowerLeg", "{s}Foot": "J_Bip_{s}_Foot", "{s}Toes": "J_Bip_{s}_ToeBase"}, "L", "R"),
        lambda side, finger, k: f"J_Bip_{side[0]}_{finger}{k}"),
}


def parse_osc(data: bytes) -> list[tuple[str, list]]:
    """Messages of an OSC packet (bundles unpacked); f, i, s and d arguments."""
    if data.startswith(b"#bundle\0"):
        out, pos = [], 16
        while pos + 4 <= len(data):
            (size,) = struct.unpack(">i", data[pos : pos + 4])
            out += parse_osc(data[pos + 4 : pos + 4 + size])
            pos += 4 + size
        return out

    def string(pos: int) -> tuple[str, int]:
        end = data.index(b"\0", pos)
        return data[pos:end].decode("utf-8"), pos + ((end - pos) // 4 + 1) * 4

    address, pos = string(0)
    tags, pos = string(pos)
    args = []
    for tag in tags[1:]:
        if tag in "fi":
            args.append(struct.unpack(">" + tag, data[pos : pos + 4])[0])
            pos += 4
        elif tag == "d":
            args.append(struct.unpack(">d", data[pos : pos + 8])[0])
            pos += 8
        elif tag == "s":
            value, pos = string(pos)
            args.append(value)
    return [(address, args)]


def import_bvh(path: str, keep_motion: bool = True):
    """A BVH file written by the instrument (a recording, a walk, the rest skeleton) as an
    armature in metres, its motion as an Action unless `keep_motion` is false; the scene takes the
    file's frame rate. Blender's own importer, with what it gets wrong for these files put right:
    Blender 3.4 opens files with mode 'rU', which Python 3.11 (Debian 12's) rejects ("invalid
    mode: 'rU'"), and reads 30 fps as 30.00003 from the frame time's six decimals."""
    import io_anim_bvh.import_bvh as importer

    importer.open = lambda p, mode="r", *a, **k: builtins.open(p, mode.replace("U", ""), *a, **k)
    try:  # (Blender 4.5 and 5.0 open with 'r': the same call)
        bpy.ops.import_anim.bvh(filepath=path, global_scale=0.01, rotate_mode="QUATERNION", update_scene_fps=True,
                                update_scene_duration=keep_motion)
    finally:
        del importer.open
    render = bpy.context.scene.render
    rate = render.fps / render.fps_base
    if abs(rate - round(rate)) < 1e-3:
        render.fps, render.fps_base = round(rate), 1.0
    armature = bpy.context.active_object
    if not keep_motion:
        armature.animation_data_clear()  # the rest frame's keys: recording makes an Action of its own
    return armature


def import_rest(path: str):
    """The rest skeleton as an armature in metres, without keys, its hips free to move."""
    armature = import_bvh(path, keep_motion=False)
    bpy.ops.object.mode_set(mode="EDIT")
    for bone in armature.data.edit_bones:  # the importer connects the hips to the root joint's tail: they could not move
        if bone.name == "Hips":
            bone.use_connect = False
    bpy.ops.object.mode_set(mode="OBJECT")
    return armature


def find_bone(armature, name: str):
    """A bone by name, allowing a namespace (mixamorig:Hips) or Rigify's DEF- prefix."""
    bones = armature.data.bones
    if name in bones:
        return bones[name]
    for bone in bones:
        if bone.name.split(":")[-1] == name or bone.name == f"DEF-{name}":
            return bone
    return None


def swing(source: Vector, target: Vector) -> Matrix:
    return source.normalized().rotation_difference(target.normalized()).to_matrix()


class VmcDriver:
    """Poses one armature from VMC messages; applies a frame when /VMC/Ext/T (sent last) arrives."""

    def __init__(self, armature, preset: str = "HUMANOID", scale: float = 0.0, record: bool = False):
        self.armature = armature
        self.scale, self.record = scale, record
        self.targets = {}  # humanoid bone -> armature bone name
        for human, name in PRESETS[preset].items():
            bone = find_bone(armature, name)
            if bone is not None:
                self.targets[human] = bone.name
        if "Hips" not in self.targets:
            raise ValueError(f"armature {armature.name!r} has no hips bone for the {preset} names ({PRESETS[preset]['Hips']})")
        if armature.data.bones[self.targets["Hips"]].use_connect:
            raise ValueError(f"the hips bone {self.targets['Hips']!r} is connected to its parent, so it cannot move: "
                             "disconnect it (Edit Mode, Bone properties, Relations)")
        self.human_of = {name: human for human, name in self.targets.items()}
        self.rest = {b.name: b.matrix_local.copy() for b in armature.data.bones}
        self.tpose = self._tpose_rotations()
        self.order = [b.name for b in armature.data.bones]  # Blender lists parents first
        for pose_bone in armature.pose.bones:
            pose_bone.rotation_mode = "QUATERNION"
        self.bones: dict[str, tuple[Vector, Matrix]] = {}
        self.root = (Vector((0, 0, 0)), Matrix.Identity(3))
        self.count, self.first_time, self.first_frame = 0, None, bpy.context.scene.frame_current
        self.last_frame = None

    def _tpose_rotations(self) -> dict[str, Matrix]:
        """Per mapped bone, its armature-space rotation when the armature stands in the T-pose."""
        swings: dict[str, Matrix] = {}
        out = {}
        for human, parent in HUMAN_PARENT.items():  # parents first
            if human not in self.targets:
                swings[human] = swings.get(parent, Matrix.Identity(3)) if parent else Matrix.Identity(3)
                continue
            rest = self.rest[self.targets[human]].to_3x3()
            along = rest @ Vector((0, 1, 0))
            if human in TPOSE_DIRECTION and TPOSE_DIRECTION[human] is not None:
                swings[human] = swing(along, TPOSE_DIRECTION[human])
            elif human in TPOSE_DIRECTION:  # feet and toes: only turned to point ahead (-Y)
                ahead = along.xy.length > 1e-6
                swings[human] = Matrix.Rotation(-math.atan2(along.x, -along.y), 3, "Z") if ahead else Matrix.Identity(3)
            else:
                swings[human] = swings.get(parent, Matrix.Identity(3)) if parent else Matrix.Identity(3)
            out[human] = swings[human] @ rest
        return out

    def handle(self, address: str, args: list) -> bool:
        """Take one message; True when a frame was applied."""
        if address == "/VMC/Ext/Bone/Pos" and len(args) >= 8:
            self.bones[args[0]] = (Vector(args[1:4]), _rotation(args[4:8]))
        elif address == "/VMC/Ext/Root/Pos" and len(args) >= 8:
            self.root = (Vector(args[1:4]), _rotation(args[4:8]))
        elif address == "/VMC/Ext/T" and args:
            self.apply(float(args[0]))
            return True
        return False

    def world_rotations(self) -> dict[str, Matrix]:
        """Each humanoid bone's rotation from the T-pose, in Blender's axes."""
        convert = UNITY_TO_BLENDER
        world = {}
        for human, parent in HUMAN_PARENT.items():
            local = self.bones[human][1] if human in self.bones else Matrix.Identity(3)
            above = world[parent] if parent else convert @ self.root[1] @ convert.transposed()
            world[human] = above @ convert @ local @ convert.transposed()
        return world

    def hips_position(self) -> Vector:
        root_position, root_rotation = self.root
        hips = self.bones["Hips"][0] if "Hips" in self.bones else Vector((0, 0, 0))
        unity = root_position + root_rotation @ hips
        if self.scale <= 0:  # auto: the armature's hips height over the sender's first hips height
            self.scale = self.rest[self.targets["Hips"]].translation.z / max(unity.y, 1e-6)
        return UNITY_TO_BLENDER @ unity * self.scale

    def apply(self, time: float) -> None:
        world = self.world_rotations()
        posed: dict[str, Matrix] = {}  # armature-space matrix of every bone
        for name in self.order:
            bone = self.armature.data.bones[name]
            rest = self.rest[name]
            parent = bone.parent.name if bone.parent else None
            follow = (posed[parent] @ self.rest[parent].inverted() @ rest) if parent else rest.copy()
            human = self.human_of.get(name)
            if human is None:
                matrix = follow
            else:
                rotation = (world[human] @ self.tpose[human]).to_4x4()
                position = self.hips_position() if human == "Hips" else follow.translation
                matrix = Matrix.Translation(position) @ rotation
            posed[name] = matrix
            self.armature.pose.bones[name].matrix_basis = follow.inverted() @ matrix
        self.count += 1
        if self.first_time is None:
            self.first_time = time
        if self.record:
            scene = bpy.context.scene
            frame = self.first_frame + round((time - self.first_time) * scene.render.fps / scene.render.fps_base)
            for name in self.targets.values():
                pose_bone = self.armature.pose.bones[name]
                pose_bone.keyframe_insert("rotation_quaternion", frame=frame, group=name)
                if name == self.targets["Hips"]:
                    pose_bone.keyframe_insert("location", frame=frame, group=name)
            self.last_frame = frame


def _rotation(quaternion) -> Matrix:
    from mathutils import Quaternion

    x, y, z, w = quaternion
    return Quaternion((w, x, y, z)).normalized().to_matrix()


def open_socket(port: int) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", port))
    return sock


# --- the UI: a socket thread feeds a queue that a timer drains on the main thread -------------

_running: dict = {}


def _drain() -> float | None:
    state = _running.get("state")
    if state is None:
        return None
    inbox, driver = state["inbox"], state["driver"]
    while not inbox.empty():
        for address, args in parse_osc(inbox.get_nowait()):
            try:
                driver.handle(address, args)
            except (KeyError, ValueError, TypeError, ReferenceError) as error:  # a bad message or a deleted armature
                print(f"instrument receiver: skipped {address}: {error}")
    return 0.005


def start(armature, port: int, preset: str, scale: float, record: bool) -> None:
    stop()
    driver = VmcDriver(armature, preset, scale, record)
    sock = open_socket(port)
    sock.settimeout(0.1)
    inbox: queue.Queue = queue.Queue()
    stopping = threading.Event()

    def listen() -> None:
        """Until Stop: a socket closed under a blocked recv would stay bound, so this thread closes it."""
        with sock:
            while not stopping.is_set():
                try:
                    inbox.put(sock.recv(65536))
                except socket.timeout:
                    continue
                except OSError:
                    return

    thread = threading.Thread(target=listen, daemon=True)
    thread.start()
    _running["state"] = {"thread": thread, "stopping": stopping, "inbox": inbox, "driver": driver}
    if not bpy.app.timers.is_registered(_drain):
        bpy.app.timers.register(_drain, persistent=True)


def stop() -> None:
    state = _running.pop("state", None)
    if state is not None:
        state["stopping"].set()
        state["thread"].join()  # the port is free again when Stop returns
    if bpy.app.timers.is_registered(_drain):  # nothing left behind (a timer left at exit hangs PyPI's bpy)
        bpy.app.timers.unregister(_drain)


class _PickBvh(ImportHelper):
    """A file browser for .bvh files (Blender's ImportHelper: `filepath`, and invoke opens the browser)."""

    filename_ext = ".bvh"
    filter_glob: bpy.props.StringProperty(default="*.bvh", options={"HIDDEN"})


class INSTRUMENT_OT_import_rest(bpy.types.Operator, _PickBvh):
    bl_idname = "instrument.import_rest"
    bl_label = "Import rest"
    bl_description = "Import the T-pose skeleton written by `instrument skeleton` (metres, the scene at its frame rate)"

    def execute(self, context):
        context.scene.instrument_armature = import_rest(self.filepath)
        return {"FINISHED"}


class INSTRUMENT_OT_import_motion(bpy.types.Operator, _PickBvh):
    bl_idname = "instrument.import_motion"
    bl_label = "Import BVH"
    bl_description = ("Import a walk or recording written by the instrument (metres, the scene at its frame rate); "
                      "works where File > Import > BVH fails (Blender 3.4 with Python 3.11)")

    def execute(self, context):
        import_bvh(self.filepath)
        return {"FINISHED"}


class INSTRUMENT_OT_start(bpy.types.Operator):
    bl_idname = "instrument.start"
    bl_label = "Start"
    bl_description = "Listen for VMC on 127.0.0.1 and drive the armature"

    def execute(self, context):
        scene = context.scene
        if scene.instrument_armature is None or scene.instrument_armature.type != "ARMATURE":
            self.report({"ERROR"}, "choose an armature first")
            return {"CANCELLED"}
        try:
            start(scene.instrument_armature, scene.instrument_port, scene.instrument_preset, scene.instrument_scale,
                  scene.instrument_record)
        except (OSError, ValueError) as error:
            self.report({"ERROR"}, str(error))
            return {"CANCELLED"}
        return {"FINISHED"}


class INSTRUMENT_OT_stop(bpy.types.Operator):
    bl_idname = "instrument.stop"
    bl_label = "Stop"

    def execute(self, context):
        stop()
        return {"FINISHED"}


class INSTRUMENT_PT_panel(bpy.types.Panel):
    bl_label = "Instrument VMC"
    bl_space_type = "VIEW_3D"
    bl_region_type = "UI"
    bl_category = "Instrument"

    def draw(self, context):
        scene, layout = context.scene, self.layout
        row = layout.row()
        row.operator("instrument.import_rest")
        row.operator("instrument.import_motion")
        layout.prop(scene, "instrument_armature")
        layout.prop(scene, "instrument_preset")
        layout.prop(scene, "instrument_port")
        layout.prop(scene, "instrument_scale")
        layout.prop(scene, "instrument_record")
        state = _running.get("state")
        row = layout.row()
        row.operator("instrument.start")
        row.operator("instrument.stop")
        layout.label(text=f"received {state['driver'].count} frames" if state else "stopped")


CLASSES = (INSTRUMENT_OT_import_rest, INSTRUMENT_OT_import_motion, INSTRUMENT_OT_start, INSTRUMENT_OT_stop, INSTRUMENT_PT_panel)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    scene = bpy.types.Scene
    scene.instrument_port = bpy.props.IntProperty(name="Port", default=PORT, min=1, max=65535)
    scene.instrument_armature = bpy.props.PointerProperty(name="Armature", type=bpy.types.Object,
                                                           poll=lambda self, obj: obj.type == "ARMATURE")
    scene.instrument_preset = bpy.props.EnumProperty(name="Bone names", items=[
        ("HUMANOID", "Humanoid", "Unity/VMC names, as in `instrument skeleton`'s rest"),
        ("MIXAMO", "Mixamo", "mixamorig:Hips, LeftArm, LeftForeArm, ..."),
        ("RIGIFY", "Rigify metarig", "spine, upper_arm.L, forearm.L, ... (or their DEF- bones)"),
        ("VRM", "VRM (VRoid)", "J_Bip_C_Hips, J_Bip_L_UpperArm, ...")])
    scene.instrument_scale = bpy.props.FloatProperty(name="Scale", default=0.0, min=0.0,
                                                     description="sent metres to armature units (0: from the hips' height)")
    scene.instrument_record = bpy.props.BoolProperty(name="Record", default=False,
                                                     description="key every received frame into the armature's Action")


def unregister() -> None:
    stop()
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
    for name in ("instrument_port", "instrument_armature", "instrument_preset", "instrument_scale", "instrument_record"):
        delattr(bpy.types.Scene, name)


def run_headless(driver: VmcDriver, port: int, frames: int, timeout: float) -> None:
    """Poll the socket on the main thread until `frames` frames were applied, `timeout` seconds
    passed or Ctrl-C; the caller saves what was recorded in every case."""
    import time

    sock = open_socket(port)
    sock.settimeout(0.05)
    print(f"listening on 127.0.0.1:{port}", flush=True)
    deadline = time.monotonic() + timeout
    try:
        while driver.count < frames and time.monotonic() < deadline:
            try:
                data = sock.recv(65536)
            except socket.timeout:
                continue
            for address, args in parse_osc(data):
                driver.handle(address, args)
    except KeyboardInterrupt:
        print(f"interrupted after {driver.count} frames", flush=True)
    finally:
        sock.close()


def save_path(save: str | None, force: bool) -> str:
    """Where a batch recording is saved: --save, else the .blend Blender opened; checked before
    listening, so a recording is never made that cannot be kept."""
    import os

    path = save or bpy.data.filepath
    if not path:
        raise SystemExit("instrument_vmc.py: --record in the background needs --save FILE.blend (or a .blend to open)")
    path = os.path.abspath(path)
    if save and os.path.exists(path) and not force:
        raise SystemExit(f"instrument_vmc.py: {path} already exists; give --force to overwrite it")
    if not os.path.isdir(os.path.dirname(path)):
        raise SystemExit(f"instrument_vmc.py: {path}: the folder does not exist")
    return path


def main(argv: list[str]) -> None:
    """blender [-b] --python instrument_vmc.py -- --rest rest.bvh ... (or python instrument_vmc.py -- ...
    with PyPI's bpy): register the add-on; with --rest, import it and, headless, drive it."""
    import argparse

    parser = argparse.ArgumentParser(prog="instrument_vmc.py")
    parser.add_argument("--rest", help="import this rest skeleton and drive it")
    parser.add_argument("--port", type=int, default=PORT)
    parser.add_argument("--frames", type=int, default=60, help="headless: stop after this many frames")
    parser.add_argument("--timeout", type=float, default=60.0, help="headless: stop after this many seconds")
    parser.add_argument("--record", action="store_true", help="key every received frame into an Action")
    parser.add_argument("--save", metavar="FILE.blend", help="headless --record: save the recording here when it ends")
    parser.add_argument("--force", action="store_true", help="let --save overwrite an existing file")
    options = parser.parse_args(argv)
    headless = bpy.app.background and options.rest
    target = save_path(options.save, options.force) if headless and options.record else None
    register()
    if options.rest:
        bpy.context.scene.instrument_armature = import_rest(options.rest)
    if headless:
        driver = VmcDriver(bpy.context.scene.instrument_armature, record=options.record)
        try:
            run_headless(driver, options.port, options.frames, options.timeout)
        finally:  # whatever ended it, what was recorded is kept
            if target:
                bpy.ops.wm.save_as_mainfile(filepath=target)
                print(f"saved {driver.count} recorded frames to {target}", flush=True)
            unregister()  # PyPI's bpy hangs at exit while an add-on's classes are registered


if __name__ == "__main__":  # run as a script: blender [-b] --python instrument_vmc.py -- --rest rest.bvh ...
    import sys

    main(sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else [])
