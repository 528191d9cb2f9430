"""`instrument skeleton` writes a rest a user can rig: the normalised T-pose, standing at the
origin on the floor, facing +Z (Blender's -Y after its importer), humanoid names, end bones
with a length; `--template` still writes the model's own skeleton in its template pose."""

import subprocess
import sys
from pathlib import Path

import numpy as np
from bvh import Bvh

from instrument.models.modelfile import load_model
from instrument.motion.bvh import read_bvh
from instrument.motion.kinematics import world_positions
from instrument.shipped import default_model_path

SKELETON = [sys.executable, "-m", "instrument", "skeleton"]


def unit(v):
    return np.asarray(v) / np.linalg.norm(v)


def test_rest_is_a_t_pose_at_the_origin_facing_plus_z(tmp_path):
    path = tmp_path / "rest.bvh"
    result = subprocess.run(SKELETON + ["--out", str(path)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    motion = read_bvh(path)
    skeleton = motion.skeleton
    assert motion.fps == 30.0 and motion.frames == 1
    assert np.all(motion.channels == 0.0)  # the rest is the pose: every rotation zero
    names = skeleton.names
    for bone in ("Hips", "Spine", "Chest", "Neck", "Head", "LeftUpperArm", "RightLowerLeg", "LeftToes"):
        assert bone in names
    position = dict(zip(names, world_positions(motion)[0]))
    hips = position["Hips"]
    assert abs(hips[0]) < 1e-6 and abs(hips[2]) < 1e-6 and 80 < hips[1] < 100  # centimetres, over the origin
    assert min(p[1] for p in position.values()) > -1e-6  # nothing below the floor
    assert min(position["LeftToes"][1], position["RightToes"][1]) < 1e-6  # standing on it
    # arms straight out, left along +X (facing +Z); legs straight down; spine up; feet ahead
    for side, x in (("Left", 1.0), ("Right", -1.0)):
        for a, b in (("UpperArm", "LowerArm"), ("LowerArm", "Hand")):
            assert np.allclose(unit(position[side + b] - position[side + a]), [x, 0, 0], atol=1e-4)
        for a, b in (("UpperLeg", "LowerLeg"), ("LowerLeg", "Foot")):
            assert np.allclose(unit(position[side + b] - position[side + a]), [0, -1, 0], atol=1e-4)
        foot = position[side + "Toes"] - position[side + "Foot"]
        assert foot[2] > 0 and abs(foot[0]) < 1e-4  # ahead, not turned out
    assert np.allclose(unit(position["Neck"] - position["Hips"]), [0, 1, 0], atol=1e-4)
    # the end bones have a length, pointing their T-pose way
    ends = {j.name: j.end_site for j in skeleton.joints if j.end_site is not None}
    assert unit(ends["LeftHand"])[0] > 0.99 and unit(ends["RightHand"])[0] < -0.99 and unit(ends["Head"])[1] > 0.99
    assert unit(ends["LeftToes"])[2] > 0.99


def test_template_option_writes_the_models_own_skeleton(tmp_path):
    path = tmp_path / "template.bvh"
    assert subprocess.run(SKELETON + ["--template", "--out", str(path)], capture_output=True).returncode == 0
    model = load_model(default_model_path())
    motion = read_bvh(path)
    assert motion.skeleton.same_layout(model.layout.skeleton)
    assert np.allclose(motion.channels[0], model.layout.template, atol=1e-5)


def test_rest_of_a_cmu_model_has_one_name_per_joint_and_finite_offsets(tmp_path):
    """A model trained on the public CMU takes (ASF names: lowerneck, guessed as the Neck, above
    a joint named Neck; collars at the chest's top): its rest, read back by the `bvh` package,
    has 31 joints with 31 names and no NaN. Before, the two collars' line of no length made
    every offset above the hips NaN, and two joints were named Neck (and two LeftShoulder)."""
    model, rest = tmp_path / "cmu.npz", tmp_path / "rest.bvh"
    data = Path(__file__).parent / "data" / "cmu-131"
    trained = subprocess.run([sys.executable, "-m", "instrument", "train", str(data), "--out", str(model), "--quiet"],
                             capture_output=True, text=True, timeout=600)
    assert trained.returncode == 0, trained.stderr
    result = subprocess.run(SKELETON + ["--model", str(model), "--out", str(rest)], capture_output=True, text=True)
    assert result.returncode == 0 and "Warning" not in result.stderr, result.stderr
    read = Bvh(rest.read_text())
    names = read.get_joints_names()
    assert len(names) == 31 and len(set(names)) == 31
    assert {"Hips", "LeftUpperLeg", "LeftUpperArm", "LeftShoulder", "Neck", "Neck_2"} <= set(names)
    offsets = np.array([read.joint_offset(name) for name in names])
    assert np.all(np.isfinite(offsets)) and np.abs(offsets).sum() > 0
