"""Blender, headless, drives a rig that is not ours from the VMC stream with the shipped add-on.

The rig is the rest skeleton `instrument skeleton` writes, changed the way someone else's rig
differs: Mixamo names, another size, an A-pose instead of a T-pose, other bone rolls. Its joints
must land where the sent pose puts them (that pose rebuilt here from the received messages on
the rest skeleton, independently of the add-on), and the recording must hold one key per frame.
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
pytestmark = pytest.mark.skipif(BLENDER is None, reason="blender is not installed (apt-get install blender)")


def test_addon_drives_someone_elses_rig_and_records_it(tmp_path):
    rest, report = tmp_path / "rest.bvh", tmp_path / "report.json"
    instrument = [sys.executable, "-m", "instrument"]
    assert subprocess.run(instrument + ["skeleton", "--out", str(rest)], capture_output=True).returncode == 0
    port, frames, scale = free_port(), 45, 1.3
    blender = subprocess.Popen(
        [BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(CHECK), "--",
         str(ADDON), str(rest), str(port), str(frames), str(scale), str(report)],
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
    result = json.loads(report.read_text())
    assert result["count"] == frames
    assert result["fps"] == 30.0  # the scene took the rest file's rate
    assert result["operators"]  # Start and Stop from the panel work

    expected, ends = sent_pose(rest, result["messages"])
    heads, tails = result["heads"], result["tails"]
    assert len(heads) == 21 and set(tails) == {"Head", "LeftHand", "RightHand", "LeftToes", "RightToes"}
    for bone, head in heads.items():
        ours = UNITY_TO_BLENDER @ expected[bone]
        assert np.linalg.norm(np.array(head) / scale - ours) < 0.01, (bone, head, ours)
    for bone, tail in tails.items():  # the end bones point the sent way too
        ours = UNITY_TO_BLENDER @ ends[bone]
        assert np.linalg.norm(np.array(tail) / scale - ours) < 0.01, (bone, tail, ours)

    # one key per received frame, on consecutive frames, for every driven bone
    assert result["action"] and len(result["keys"]) == 21
    for bone, keys in result["keys"].items():
        assert len(keys) == frames and np.all(np.diff(keys) == 1.0), (bone, keys[:5])
