"""Blender, headless, receives the live walk over OSC and poses an armature with it (Debian's
Blender 3.4, PyPI's bpy 4.5 LTS and 5.0)."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from blender_hosts import HOSTS, blender_command, blender_env
from oscrecv import free_port

from instrument.motion.bvh import read_bvh
from instrument.motion.kinematics import local_transforms, world_positions
from instrument.motion.rotations import matrix_to_quat

RECEIVER = Path(__file__).resolve().parents[1] / "examples" / "blender" / "walk_receiver.py"


@pytest.mark.parametrize("host", HOSTS)
def test_blender_applies_what_the_instrument_sends(tmp_path, host):
    rest, report, recording = tmp_path / "rest.bvh", tmp_path / "applied.json", tmp_path / "sent.bvh"
    instrument = [sys.executable, "-m", "instrument"]
    assert subprocess.run(instrument + ["skeleton", "--template", "--out", str(rest)], capture_output=True).returncode == 0
    port = free_port()
    blender = subprocess.Popen(
        blender_command(host, RECEIVER, "--rest", str(rest), "--port", str(port), "--frames", "40", "--timeout", "120",
                        "--report", str(report)),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=blender_env(tmp_path))
    for line in blender.stdout:  # wait until it listens
        if "listening on" in line:
            break
    run = subprocess.run(instrument + ["run", "--seconds", "3", "--osc", f"127.0.0.1:{port}/flat", "--bvh", str(recording), "--quiet"],
                         capture_output=True, text=True, timeout=120)
    output = blender.communicate(timeout=120)[0]
    assert run.returncode == 0, run.stderr
    assert blender.returncode == 0, output[-3000:]
    applied = json.loads(report.read_text())
    frame = applied["frame"]
    assert frame >= 39
    sent = read_bvh(recording)
    names = sent.skeleton.names
    # the rotations Blender holds, turned back into BVH space, are the recorded ones
    quats = matrix_to_quat(local_transforms(sent)[0][frame])
    for k, name in enumerate(names):
        theirs = np.array(applied["applied"][name])
        assert min(np.abs(theirs - quats[k]).max(), np.abs(theirs + quats[k]).max()) < 1e-4, name
    # and the armature's pose matches the instrument's own kinematics (Blender is Z-up)
    ours = world_positions(sent)[frame][:, [0, 2, 1]] * [1, -1, 1]
    heads = np.array([applied["heads"][n] for n in names])
    np.testing.assert_allclose(heads, ours, atol=0.05)  # centimetres, through float32 OSC
