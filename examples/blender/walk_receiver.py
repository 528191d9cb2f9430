"""Blender receiver for the instrument's flat OSC profile: the walk, live, on an armature.

1. Write the skeleton:      instrument skeleton --template --out rest.bvh
2. In Blender's UI:         blender --python examples/blender/walk_receiver.py -- --rest rest.bvh
   (or open this file in the Text Editor, set REST below, and Run Script)
3. Start the instrument:    instrument run --osc 127.0.0.1:9000/flat

Headless (no UI; the main thread polls the socket, as timers never fire in -b mode):

    blender -b --factory-startup --python-exit-code 1 --python walk_receiver.py -- \\
        --rest rest.bvh --frames 60 --report applied.json

Self-contained: a small OSC decoder is included, so Blender needs no extra Python packages.
The armature comes from Blender's own BVH importer; every frame, each bone gets the local
rotation the instrument sent, expressed in the bone's rest frame exactly as the importer does
for animation (rest^-1 @ R @ rest), and the root bone its location.
"""

from __future__ import annotations

import argparse
import builtins
import json
import queue
import socket
import struct
import sys
import threading
import time

import bpy
from mathutils import Matrix, Quaternion, Vector

REST = ""  # path of rest.bvh when run from the Text Editor
PORT = 9000
AXIS = Matrix(((1, 0, 0), (0, 0, -1), (0, 1, 0)))  # the importer's default: BVH Y-up -> Blender Z-up


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
        if tag == "f":
            args.append(struct.unpack(">f", data[pos : pos + 4])[0]); pos += 4
        elif tag == "i":
            args.append(struct.unpack(">i", data[pos : pos + 4])[0]); pos += 4
        elif tag == "d":
            args.append(struct.unpack(">d", data[pos : pos + 8])[0]); pos += 8
        elif tag == "s":
            value, pos = string(pos); args.append(value)
    return [(address, args)]


def import_rest(path: str):
    import io_anim_bvh.import_bvh as import_bvh

    # Blender 3.4's importer opens files with mode 'rU', which Python 3.11 rejects
    import_bvh.open = lambda p, mode="r", *a, **k: builtins.open(p, mode.replace("U", ""), *a, **k)
    bpy.ops.import_anim.bvh(filepath=path, global_scale=1.0, rotate_mode="QUATERNION", update_scene_fps=True)
    render = bpy.context.scene.render
    if abs(render.fps / render.fps_base - round(render.fps / render.fps_base)) < 1e-3:  # 0.0333333 s reads as 30.00003 fps
        render.fps, render.fps_base = round(render.fps / render.fps_base), 1.0
    return next(o for o in bpy.context.scene.objects if o.type == "ARMATURE")


class WalkApplier:
    """Collects one frame's values and applies them when /walk/frame (sent last) arrives."""

    def __init__(self, armature, root_name: str | None = None):
        self.armature = armature
        self.rest = {}  # bone -> its rest rotation in BVH space (importer's bone_rest_matrix)
        for bone in armature.data.bones:
            self.rest[bone.name] = AXIS.transposed() @ bone.matrix_local.to_3x3()
            armature.pose.bones[bone.name].rotation_mode = "QUATERNION"
        self.offsets = {b.name: Vector(b.head_local) for b in armature.data.bones}
        self.root = root_name
        self.pending: dict[str, list] = {}
        self.root_local: list | None = None
        self.applied = -1
        self.count = 0
        self.last: dict = {}

    def handle(self, address: str, args: list) -> None:
        if address.startswith("/walk/bone/") and address.endswith("/quat"):
            self.pending[address[len("/walk/bone/") : -len("/quat")]] = args
        elif address == "/walk/root/local":
            self.root_local = args
        elif address == "/walk/frame":
            self.apply(int(args[0]))

    def apply(self, index: int) -> None:
        bones = self.armature.pose.bones
        applied = {}
        for name, (x, y, z, w) in self.pending.items():
            if name not in bones:
                continue
            rest = self.rest[name]
            rotation = Quaternion((w, x, y, z)).to_matrix()
            bones[name].rotation_quaternion = (rest.inverted() @ rotation @ rest).to_quaternion()
            applied[name] = [x, y, z, w]
        local = self.root_local
        if local is not None and self.root in bones:
            rest = self.rest[self.root]
            head = AXIS.transposed() @ self.offsets[self.root]
            bones[self.root].location = rest.inverted() @ (Vector(local) - head)
        self.last = {"frame": index, "sent": applied, "applied": {
            name: list(self._bvh_rotation(name)) for name in applied}}
        self.applied = index
        self.count += 1
        self.pending = {}

    def _bvh_rotation(self, name: str):
        """The bone's rotation as Blender now holds it, turned back into BVH space (x, y, z, w)."""
        rest = self.rest[name]
        q = (rest @ self.armature.pose.bones[name].rotation_quaternion.to_matrix() @ rest.inverted()).to_quaternion()
        return (q.x, q.y, q.z, q.w)


def open_socket(port: int) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", port))
    return sock


def run_headless(applier: WalkApplier, port: int, frames: int, timeout: float, report: str | None) -> None:
    sock = open_socket(port)
    sock.setblocking(False)
    print(f"listening on 127.0.0.1:{port}", flush=True)
    deadline = time.monotonic() + timeout
    while applier.count < frames and time.monotonic() < deadline:
        try:
            data = sock.recv(65536)
        except BlockingIOError:
            time.sleep(0.001)
            continue
        for address, args in parse_osc(data):
            applier.handle(address, args)
    bpy.context.view_layer.update()
    print(f"applied {applier.count} frames, last {applier.applied}", flush=True)
    applier.last["heads"] = {b.name: list(applier.armature.matrix_world @ b.head) for b in applier.armature.pose.bones}
    if report:
        with builtins.open(report, "w") as f:
            json.dump(applier.last, f)


def run_in_ui(applier: WalkApplier, port: int) -> None:
    """A socket thread feeds a queue; a timer on the main thread drains it (Blender data is
    only touched on the main thread)."""
    inbox: queue.Queue = queue.Queue()
    sock = open_socket(port)

    def listen() -> None:
        while True:
            inbox.put(sock.recv(65536))

    threading.Thread(target=listen, daemon=True).start()

    def drain() -> float:
        while not inbox.empty():
            for address, args in parse_osc(inbox.get_nowait()):
                applier.handle(address, args)
        return 0.005

    bpy.app.timers.register(drain, persistent=True)
    print(f"walk receiver listening on 127.0.0.1:{port}")


def main() -> None:
    argv = sys.argv[sys.argv.index("--") + 1 :] if "--" in sys.argv else []
    parser = argparse.ArgumentParser(prog="walk_receiver.py")
    parser.add_argument("--rest", default=REST, help="skeleton written by `instrument skeleton --out rest.bvh`")
    parser.add_argument("--port", type=int, default=PORT)
    parser.add_argument("--root", default="Hips", help="the joint whose position the walk moves")
    parser.add_argument("--frames", type=int, default=0, help="headless: stop after this many frames")
    parser.add_argument("--timeout", type=float, default=60.0)
    parser.add_argument("--report", help="headless: write the last frame's sent and applied rotations as JSON")
    args = parser.parse_args(argv)
    armature = import_rest(args.rest)
    applier = WalkApplier(armature, args.root)
    if bpy.app.background:
        run_headless(applier, args.port, args.frames or 1, args.timeout, args.report)
    else:
        run_in_ui(applier, args.port)


main()
