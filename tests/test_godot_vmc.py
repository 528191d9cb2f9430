"""Godot 3, headless (Debian's godot3-server), poses a humanoid Skeleton from the VMC stream with
the example receiver code in examples/godot.

The Skeleton is built from the rest skeleton `instrument skeleton` writes, changed the way
another character differs: Mixamo names, 1.3 times the size, arms lowered 40 degrees into an
A-pose, the feet turned out, every bone's rest frame turned arbitrarily (Godot bones have no direction of their own).
Its joints must land where the sent pose puts them, rebuilt here from the received messages.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from instrument.motion.bvh import read_bvh
from oscrecv import free_port
from vmcpose import sent_pose

GODOT = shutil.which("godot3-server")
ROOT = Path(__file__).resolve().parents[1]
PROJECT = ROOT / "examples" / "godot"
CHECK = ROOT / "tests" / "godot" / "vmc_check.gd"
UNITY_TO_GODOT = np.array([-1.0, 1.0, 1.0])  # both Y up, the character facing +Z; Unity is left-handed
pytestmark = pytest.mark.skipif(GODOT is None, reason="godot3-server is not installed (apt-get install godot3-server)")


def mixamo_name(bone: str) -> str:
    """Mixamo's name as Godot imports it (a bone name cannot hold a colon in Godot)."""
    for ours, theirs in (("UpperArm", "Arm"), ("LowerArm", "ForeArm"), ("UpperLeg", "UpLeg"), ("LowerLeg", "Leg"),
                         ("Toes", "ToeBase"), ("Chest", "Spine1")):
        if bone.endswith(ours):
            return "mixamorig_" + bone[: -len(ours)] + theirs
    return "mixamorig_" + bone


def another_rig(rest_path: Path, scale: float) -> tuple[dict, list[str]]:
    """The rest skeleton as someone else's Godot Skeleton: names, size, A-pose, feet, bone frames."""
    skeleton = read_bvh(rest_path).skeleton
    names = skeleton.names
    positions = np.zeros((len(names), 3))
    for j, joint in enumerate(skeleton.joints):  # the rest file's axes are Godot's (Y up, facing +Z, left +X)
        positions[j] = (positions[joint.parent] if joint.parent >= 0 else 0.0) + np.array(joint.offset) * 0.01 * scale
    for side, angle in (("Left", -40.0), ("Right", 40.0)):
        pivot = positions[names.index(f"{side}UpperArm")]
        turn = Rotation.from_euler("z", angle, degrees=True).as_matrix()
        for bone in ("LowerArm", "Hand"):
            k = names.index(f"{side}{bone}")
            positions[k] = pivot + turn @ (positions[k] - pivot)
    for side, angle in (("Left", 15.0), ("Right", -15.0)):  # the feet turned out at rest
        pivot = positions[names.index(f"{side}Foot")]
        turn = Rotation.from_euler("y", angle, degrees=True).as_matrix()
        k = names.index(f"{side}Toes")
        positions[k] = pivot + turn @ (positions[k] - pivot)
    frames = Rotation.random(len(names), random_state=3).as_matrix()  # each bone's rest frame, anyhow turned
    humanoid = [n for n in names if n != "joint_Root"]
    bones = []
    for j, joint in enumerate(skeleton.joints):
        parent = joint.parent
        parent_frame = frames[parent] if parent >= 0 else np.eye(3)
        parent_position = positions[parent] if parent >= 0 else np.zeros(3)
        basis = parent_frame.T @ frames[j]
        origin = parent_frame.T @ (positions[j] - parent_position)
        name = mixamo_name(joint.name) if joint.name in humanoid else joint.name
        bones.append({"name": name, "parent": parent, "rest": list(basis.T.reshape(-1)) + list(origin)})
    return {"bones": bones, "names": {h: mixamo_name(h) for h in humanoid}}, humanoid


def test_godot_poses_another_characters_skeleton(tmp_path):
    rest, rig_path, report = tmp_path / "rest.bvh", tmp_path / "rig.json", tmp_path / "report.json"
    instrument = [sys.executable, "-m", "instrument"]
    assert subprocess.run(instrument + ["skeleton", "--out", str(rest)], capture_output=True).returncode == 0
    scale, frames, port = 1.3, 45, free_port()
    rig, humanoid = another_rig(rest, scale)
    rig_path.write_text(json.dumps(rig))
    environment = dict(os.environ, VMC_RIG=str(rig_path), VMC_PORT=str(port), VMC_FRAMES=str(frames),
                       VMC_REPORT=str(report), VMC_SCALE=str(scale))
    godot = subprocess.Popen([GODOT, "--path", str(PROJECT), "-s", str(CHECK)], env=environment,
                             stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in godot.stdout:  # wait until it listens
        if "listening on" in line or "cannot listen" in line:
            break
    run = subprocess.run(instrument + ["run", "--seconds", "3", "--osc", f"127.0.0.1:{port}/vmc", "--quiet"],
                         capture_output=True, text=True, timeout=120)
    output = godot.communicate(timeout=180)[0]
    assert run.returncode == 0, run.stderr
    assert godot.returncode == 0, output[-3000:]
    result = json.loads(report.read_text())
    assert result["count"] >= frames  # one _process call applies every datagram that has come in
    expected, _ = sent_pose(rest, result["messages"])
    for bone in humanoid:
        theirs = np.array(result["positions"][mixamo_name(bone)]) / scale
        ours = expected[bone] * UNITY_TO_GODOT
        assert np.linalg.norm(theirs - ours) < 0.01, (bone, theirs, ours)
