"""Blender, headless, drives rigs that are not ours from the VMC stream with the shipped add-on.

One Blender run drives four rigs made from the rest skeleton `instrument skeleton` writes (see
tests/blender/vmc_addon_check.py): one per bone-name preset of the add-on (Mixamo, Rigify, VRM),
each changed the way someone else's rig differs (another size, an A-pose, feet turned out, other
bone rolls), and the rest as imported with a pose applied as its rest pose. Every rig's joints
must land where the sent pose puts them (that pose rebuilt here from the received messages on
the rest skeleton, independently of the add-on), and each recording must hold one key per frame.
"""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from oscrecv import free_port
from vmcpose import sent_pose

BLENDER = shutil.which("blender")
ROOT = Path(__file__).resolve().parents[1]
ADDON = ROOT / "examples" / "blender" / "instrument_vmc.py"
CHECK = ROOT / "tests" / "blender" / "vmc_addon_check.py"
UNITY_TO_BLENDER = np.array([[-1.0, 0, 0], [0, 0, -1.0], [0, 1.0, 0]])
FRAMES, SCALE = 45, 1.3
RIGS = ("MIXAMO", "RIGIFY", "VRM", "APPLIED")
pytestmark = pytest.mark.skipif(BLENDER is None, reason="blender is not installed (apt-get install blender)")


@pytest.fixture(scope="module")
def driven(tmp_path_factory) -> tuple[Path, dict]:
    """(the rest file, the check's report) after one Blender run driving every rig from `instrument run`."""
    folder = tmp_path_factory.mktemp("blender_vmc")
    rest, report = folder / "rest.bvh", folder / "report.json"
    instrument = [sys.executable, "-m", "instrument"]
    assert subprocess.run(instrument + ["skeleton", "--out", str(rest)], capture_output=True).returncode == 0
    port = free_port()
    blender = subprocess.Popen(
        [BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(CHECK), "--",
         str(ADDON), str(rest), str(port), str(FRAMES), str(SCALE), str(report)],
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    for line in blender.stdout:  # wait until it listens
        if "listening on" in line:
            break
    run = subprocess.run(instrument + ["run", "--seconds", "3", "--osc", f"127.0.0.1:{port}/vmc", "--vmc-root", "path",
                                       "--quiet"],
                         capture_output=True, text=True, timeout=120)
    output = blender.communicate(timeout=180)[0]
    assert run.returncode == 0, run.stderr
    assert blender.returncode == 0, output[-3000:]
    return rest, json.loads(report.read_text())


def test_the_scene_takes_the_rest_files_rate(driven):
    assert driven[1]["fps"] == 30.0


@pytest.mark.parametrize("rig", RIGS)
def test_addon_drives_the_rig_within_a_centimetre(driven, rig):
    rest, report = driven
    result = report["rigs"][rig]
    assert result["count"] == FRAMES
    assert result["operators"]  # Start and Stop from the panel work with this rig and its preset
    expected, ends = sent_pose(rest, report["messages"])
    heads, tails = result["heads"], result["tails"]
    assert len(heads) == 21 and set(tails) == {"Head", "LeftHand", "RightHand", "LeftToes", "RightToes"}
    for bone, head in heads.items():
        ours = UNITY_TO_BLENDER @ expected[bone]
        assert np.linalg.norm(np.array(head) / result["scale"] - ours) < 0.01, (rig, bone, head, ours)
    for bone, tail in tails.items():  # the end bones point the sent way too
        ours = UNITY_TO_BLENDER @ ends[bone]
        assert np.linalg.norm(np.array(tail) / result["scale"] - ours) < 0.01, (rig, bone, tail, ours)


@pytest.mark.parametrize("rig", RIGS)
def test_addon_records_one_key_per_frame(driven, rig):
    result = driven[1]["rigs"][rig]
    assert result["action"] and set(result["keys"]) == set(result["names"].values())
    assert len(result["keys"]) == 21
    for bone, keys in result["keys"].items():
        assert len(keys) == FRAMES and np.all(np.diff(keys) == 1.0), (rig, bone, keys[:5])


def test_rigs_are_rested_as_the_check_says(driven):
    """The rigs differ from the sent rest as described: arms 40 deg down, the applied spine 10 deg
    forward, bones named by the presets (so a rig found its bones by its preset, not by luck)."""
    rigs = driven[1]["rigs"]
    for rig in RIGS:
        assert abs(rigs[rig]["rest_arm_drop"] - 40.0) < 0.5, (rig, rigs[rig]["rest_arm_drop"])
    assert abs(rigs["APPLIED"]["rest_spine_lean"] - 10.0) < 0.5, rigs["APPLIED"]["rest_spine_lean"]
    assert abs(rigs["MIXAMO"]["rest_spine_lean"]) < 0.5
    assert rigs["MIXAMO"]["names"]["LeftUpperArm"] == "mixamorig:LeftArm"
    assert rigs["RIGIFY"]["names"]["LeftUpperArm"] == "upper_arm.L"
    assert rigs["VRM"]["names"]["LeftUpperArm"] == "J_Bip_L_UpperArm"
