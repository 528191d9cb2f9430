"""Blender's own BVH importer is an independent reader of the files the project writes."""

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from instrument.motion.bvh import parse_bvh, read_bvh, write_bvh
from instrument.motion.features import choose_layout, extract, restore
from instrument.motion.kinematics import world_positions
from samples import cmu_style_walk

BLENDER = shutil.which("blender")
CHECK = Path(__file__).parent / "blender" / "import_bvh_check.py"
pytestmark = pytest.mark.skipif(BLENDER is None, reason="blender is not installed (apt-get install blender)")


def blender_positions(path: Path, frames: list[int]) -> dict:
    result = subprocess.run(
        [BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(CHECK), "--", str(path), *map(str, frames)],
        capture_output=True, text=True, timeout=300,
    )
    assert result.returncode == 0, result.stderr[-2000:]
    line = next(l for l in result.stdout.splitlines() if l.startswith("{"))
    return json.loads(line)


def assert_same_pose(motion, imported, frames):
    ours = world_positions(motion)
    names = motion.skeleton.names
    assert imported["bones"] == names
    assert imported["frames"] == [1.0, float(motion.frames)]
    for frame in frames:
        theirs = np.array([imported["positions"][str(frame)][n] for n in names])
        # Blender turns Y-up into Z-up: (x, y, z) -> (x, -z, y)
        np.testing.assert_allclose(theirs, ours[frame][:, [0, 2, 1]] * [1, -1, 1], atol=2e-3)


def test_blender_imports_a_restored_shared_walk(real_walks, tmp_path):
    motion = read_bvh(real_walks[0])
    layout = choose_layout([motion])
    features, start, heading = extract(motion, layout)
    restored = restore(features, layout, motion.fps, start, heading)
    path = tmp_path / "restored.bvh"
    write_bvh(path, restored)
    frames = [0, motion.frames // 2, motion.frames - 1]
    assert_same_pose(read_bvh(path), blender_positions(path, frames), frames)


def test_blender_imports_a_written_cmu_style_file(tmp_path):
    text, _ = cmu_style_walk(fps=30, order="XYZ")
    motion = parse_bvh(text)
    path = tmp_path / "cmu.bvh"
    write_bvh(path, motion)
    frames = [0, 40]
    assert_same_pose(motion, blender_positions(path, frames), frames)
