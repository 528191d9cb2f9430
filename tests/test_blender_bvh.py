"""Blender's own BVH importer is an independent reader of the files the project writes, in every
Blender the add-on supports: Debian's 3.4 through the add-on's `import_bvh` (its importer cannot
open files on Python 3.11 by itself), and PyPI's bpy 4.5 LTS and 5.0 both ways: File > Import as
it is, and the add-on's."""

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest
from blender_hosts import blender_command, blender_env
from samples import cmu_style_walk

from instrument.motion.bvh import parse_bvh, read_bvh, write_bvh
from instrument.motion.features import choose_layout, extract, restore
from instrument.motion.kinematics import world_positions

CHECK = Path(__file__).parent / "blender" / "import_bvh_check.py"
ADDON = Path(__file__).resolve().parents[1] / "examples" / "blender" / "instrument_vmc.py"
WAYS = [("3.4", "addon"), ("4.5", "plain"), ("4.5", "addon"), ("5.0", "plain"), ("5.0", "addon")]


@pytest.fixture(params=WAYS, ids=["-".join(way) for way in WAYS])
def blender_positions(request, tmp_path):
    """Imports a file in one Blender, one way, and returns what it holds at the given frames."""
    host, how = request.param

    def positions(path: Path, frames: list[int]) -> dict:
        command = blender_command(host, CHECK, "plain" if how == "plain" else str(ADDON), str(path), *map(str, frames))
        result = subprocess.run(command, capture_output=True, text=True, timeout=300, env=blender_env(tmp_path))
        assert result.returncode == 0, (result.stdout + result.stderr)[-2000:]
        return json.loads(next(line for line in result.stdout.splitlines() if line.startswith("{")))

    return positions


def assert_same_pose(motion, imported, frames):
    ours = world_positions(motion)
    names = motion.skeleton.names
    assert imported["bones"] == names
    assert imported["frames"] == [1.0, float(motion.frames)]
    for frame in frames:
        theirs = np.array([imported["positions"][str(frame)][n] for n in names])
        # Blender turns Y-up into Z-up: (x, y, z) -> (x, -z, y)
        np.testing.assert_allclose(theirs, ours[frame][:, [0, 2, 1]] * [1, -1, 1], atol=2e-3)


def test_blender_imports_a_restored_shared_walk(real_walks, tmp_path, blender_positions):
    motion = read_bvh(real_walks[0])
    layout = choose_layout([motion])
    features, start, heading = extract(motion, layout)
    restored = restore(features, layout, motion.fps, start, heading)
    path = tmp_path / "restored.bvh"
    write_bvh(path, restored)
    frames = [0, motion.frames // 2, motion.frames - 1]
    assert_same_pose(read_bvh(path), blender_positions(path, frames), frames)


def test_blender_imports_a_written_cmu_style_file(tmp_path, blender_positions):
    text, _ = cmu_style_walk(fps=30, order="XYZ")
    motion = parse_bvh(text)
    path = tmp_path / "cmu.bvh"
    write_bvh(path, motion)
    frames = [0, 40]
    assert_same_pose(motion, blender_positions(path, frames), frames)
