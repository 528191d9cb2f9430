"""glTF 2.0 export: `synth --out walk.glb` and `convert REC.bvh --out rec.glb`.

Checked three independent ways: the Khronos glTF-Validator (npm, through node) finds no error;
the file, decoded here with numpy alone (its own reader and forward kinematics), poses the
skeleton where the instrument's own kinematics put it, frame for frame, in metres; and Blender's
glTF importer (PyPI's bpy 4.5 LTS and 5.0) makes an armature with one key per frame, its joints
in the same places.
"""

import json
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from blender_hosts import blender_command, blender_env
from gltf_validator import validate
from scipy.spatial.transform import Rotation

from instrument.motion.bvh import read_bvh
from instrument.motion.kinematics import world_positions
from instrument.output.gltf import _glb, glb_bytes

INSTRUMENT = [sys.executable, "-m", "instrument"]
IMPORT = Path(__file__).parent / "blender" / "import_gltf_check.py"
CM = 0.01  # the shipped model's unit (centimetres) in metres
SECONDS = 2


def instrument(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(INSTRUMENT + list(args), capture_output=True, text=True, timeout=300)


def read_glb(path: Path) -> tuple[dict, bytes]:
    """The JSON document and binary chunk of a .glb, read by the container's layout."""
    data = path.read_bytes()
    magic, version, length = struct.unpack_from("<4sII", data)
    assert (magic, version, length) == (b"glTF", 2, len(data))
    json_length, json_type = struct.unpack_from("<I4s", data, 12)
    assert json_type == b"JSON"
    document = json.loads(data[20 : 20 + json_length])
    bin_length, bin_type = struct.unpack_from("<I4s", data, 20 + json_length)
    assert bin_type == b"BIN\0"
    return document, data[28 + json_length : 28 + json_length + bin_length]


def accessor(document: dict, binary: bytes, index: int) -> np.ndarray:
    spec = document["accessors"][index]
    view = document["bufferViews"][spec["bufferView"]]
    width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[spec["type"]]
    assert spec["componentType"] == 5126
    values = np.frombuffer(binary, "<f4", spec["count"] * width, view["byteOffset"] + spec.get("byteOffset", 0))
    return values.reshape(spec["count"], width).astype(np.float64)


def glb_world_positions(path: Path) -> tuple[dict, np.ndarray, np.ndarray]:
    """(document, key times, world positions (frames, nodes, 3)) by forward kinematics of the file's
    animated node transforms."""
    document, binary = read_glb(path)
    nodes = document["nodes"]
    parent = {child: n for n, node in enumerate(nodes) for child in node.get("children", [])}
    (animation,) = document["animations"]
    tracks = {}
    for channel in animation["channels"]:
        sampler = animation["samplers"][channel["sampler"]]
        tracks[channel["target"]["node"], channel["target"]["path"]] = accessor(document, binary, sampler["output"])
    times = accessor(document, binary, animation["samplers"][0]["input"])[:, 0]
    frames = len(times)
    world_rot = np.zeros((frames, len(nodes), 3, 3))
    world_pos = np.zeros((frames, len(nodes), 3))
    for n in range(len(nodes)):  # parents are listed before their children here, as in a BVH
        local_rot = Rotation.from_quat(tracks[n, "rotation"]).as_matrix()
        local_pos = tracks[n, "translation"]
        if n in parent:
            p = parent[n]
            world_rot[:, n] = world_rot[:, p] @ local_rot
            world_pos[:, n] = world_pos[:, p] + np.einsum("fij,fj->fi", world_rot[:, p], local_pos)
        else:
            world_rot[:, n], world_pos[:, n] = local_rot, local_pos
    return document, times, world_pos


def assert_same_motion(glb: Path, motion) -> dict:
    """The file carries `motion`: its skeleton as nodes and a skin, and its poses in metres."""
    document, times, positions = glb_world_positions(glb)
    names = motion.skeleton.names
    assert [node["name"] for node in document["nodes"]] == names
    for j, joint in enumerate(motion.skeleton.joints):
        assert document["nodes"][j].get("children", []) == motion.skeleton.children(j)
        np.testing.assert_allclose(document["nodes"][j]["translation"], np.array(joint.offset) * CM, atol=1e-6)
    assert document["skins"][0]["joints"] == list(range(len(names)))
    channels = [(c["target"]["node"], c["target"]["path"]) for c in document["animations"][0]["channels"]]
    assert sorted(channels) == sorted((j, p) for j in range(len(names)) for p in ("rotation", "translation"))
    np.testing.assert_allclose(times, np.arange(motion.frames) / motion.fps, atol=1e-5)
    np.testing.assert_allclose(positions, world_positions(motion) * CM, atol=1e-4)  # 0.1 mm, through float32
    return document


@pytest.fixture(scope="module")
def exported(tmp_path_factory) -> dict:
    """A synthesized walk (as BVH, as .glb straight from synth, and converted) and a recording of
    `instrument run` converted."""
    folder = tmp_path_factory.mktemp("gltf")
    paths = {name: folder / name for name in ("walk.bvh", "walk.glb", "converted.glb", "rec.bvh", "rec.glb", "rest.bvh",
                                              "rest.glb")}
    for out in ("walk.bvh", "walk.glb"):
        result = instrument("synth", "--seconds", str(SECONDS), "--out", str(paths[out]))
        assert result.returncode == 0, result.stderr
    result = instrument("run", "--seconds", str(SECONDS), "--no-osc", "--quiet", "--bvh", str(paths["rec.bvh"]))
    assert result.returncode == 0, result.stderr
    for out in ("rest.bvh", "rest.glb"):
        result = instrument("skeleton", "--out", str(paths[out]))
        assert result.returncode == 0, result.stderr
    for source, out in (("walk.bvh", "converted.glb"), ("rec.bvh", "rec.glb")):
        result = instrument("convert", str(paths[source]), "--out", str(paths[out]))
        assert result.returncode == 0, result.stderr
    return paths


@pytest.mark.parametrize("name", ["walk.glb", "converted.glb", "rec.glb", "rest.glb"])
def test_the_khronos_validator_finds_no_error(exported, name):
    issues = validate(exported[name])
    assert issues["numErrors"] == 0, issues["messages"]
    assert issues["numWarnings"] == 0, issues["messages"]


def test_the_validator_sees_a_broken_file(exported, tmp_path):
    """The oracle can fail: a channel aimed at a node that does not exist is an error."""
    document, binary = read_glb(exported["walk.glb"])
    document["animations"][0]["channels"][0]["target"]["node"] = len(document["nodes"]) + 5
    broken = tmp_path / "broken.glb"
    broken.write_bytes(_glb(json.dumps(document).encode(), binary))
    assert validate(broken)["numErrors"] > 0


@pytest.mark.parametrize("glb, bvh", [("converted.glb", "walk.bvh"), ("rec.glb", "rec.bvh")])
def test_a_converted_file_carries_the_motion(exported, glb, bvh):
    motion = read_bvh(exported[bvh])
    assert motion.frames >= SECONDS * 30 - 1
    assert_same_motion(exported[glb], motion)


def test_skeleton_writes_the_same_rest_as_glb(exported):
    """skeleton --out rest.glb: the rest of skeleton --out rest.bvh (before, any name was written
    as BVH text, rest.glb included)."""
    rest = read_bvh(exported["rest.bvh"])
    assert rest.frames == 1 and "LeftUpperArm" in rest.skeleton.names
    assert_same_motion(exported["rest.glb"], rest)


def test_synth_writes_the_same_walk_as_glb(exported):
    """synth --out walk.glb and synth --out walk.bvh (the same seed) are the same walk."""
    assert_same_motion(exported["walk.glb"], read_bvh(exported["walk.bvh"]))


def test_unknown_extensions_are_refused_in_one_line(exported, tmp_path):
    for command in (["synth", "--seconds", "1", "--out", str(tmp_path / "walk.fbx")],
                    ["convert", str(exported["rec.bvh"]), "--out", str(tmp_path / "rec.gltf")],
                    ["skeleton", "--out", str(tmp_path / "rest.txt")]):
        result = instrument(*command)
        assert result.returncode == 1
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and "unknown extension" in lines[0] and ".glb" in lines[0], result.stderr
    assert not list(tmp_path.iterdir())


def test_convert_will_not_overwrite_without_force(exported):
    before = exported["rec.glb"].read_bytes()
    result = instrument("convert", str(exported["walk.bvh"]), "--out", str(exported["rec.glb"]))
    assert result.returncode == 1 and "--force" in result.stderr
    assert exported["rec.glb"].read_bytes() == before


def test_a_value_past_float32_is_one_line_not_a_broken_file(exported, tmp_path):
    """A BVH may hold a position float64 takes and float32 cannot (1e300): the .glb held
    Infinity, which the validator refuses, and numpy warned on stderr; now one line, no file.
    (In every frame: one frame's would leap, which the BVH reader refuses at its line first.)"""
    lines = exported["walk.bvh"].read_text().splitlines()
    first = lines.index(next(line for line in lines if line.startswith("Frame Time"))) + 1
    for number in range(first, len(lines)):
        values = lines[number].split()
        values[0] = "1e300"
        lines[number] = " ".join(values)
    (tmp_path / "huge.bvh").write_text("\n".join(lines) + "\n")
    result = instrument("convert", str(tmp_path / "huge.bvh"), "--out", str(tmp_path / "huge.glb"))
    assert result.returncode == 1
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "huge.glb: a value is too large for glTF's 32-bit floats" in lines[0], result.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["huge.bvh"]


def test_a_motion_without_frames_is_refused():
    from instrument.errors import UserError
    from instrument.motion.bvh import Motion

    motion = read_bvh(Path(__file__).resolve().parents[1] / "examples" / "data" / "dataset-2_walk_normal_001.bvh")
    with pytest.raises(UserError, match="no frames"):
        glb_bytes(Motion(motion.skeleton, motion.channels[:0], motion.fps))


@pytest.mark.parametrize("host", ["4.5", "5.0"])
@pytest.mark.parametrize("glb, bvh", [("walk.glb", "walk.bvh"), ("rec.glb", "rec.bvh")])
def test_blender_imports_one_key_per_frame(exported, tmp_path, host, glb, bvh):
    motion = read_bvh(exported[bvh])
    frames = [0, motion.frames // 2, motion.frames - 1]
    report = tmp_path / "imported.json"
    result = subprocess.run(blender_command(host, IMPORT, str(round(motion.fps)), str(exported[glb]), str(report),
                                            *map(str, frames)),
                            capture_output=True, text=True, timeout=300, env=blender_env(tmp_path))
    assert result.returncode == 0, (result.stdout + result.stderr)[-3000:]
    imported = json.loads(report.read_text())
    names = motion.skeleton.names
    assert sorted(imported["bones"]) == sorted(names)
    for bone, keys in imported["keys"].items():
        assert len(keys) == motion.frames and np.allclose(np.diff(keys), 1.0), (bone, keys[:5])
    assert set(imported["keys"]) == set(names)
    ours = world_positions(motion) * CM
    for frame in frames:  # Blender is Z up: (x, y, z) -> (x, -z, y)
        theirs = np.array([imported["heads"][str(frame)][n] for n in names])
        np.testing.assert_allclose(theirs, ours[frame][:, [0, 2, 1]] * [1, -1, 1], atol=1e-3)


def test_a_z_up_capture_is_converted_standing_y_up(exported, tmp_path):
    """glTF is Y up: a capture exported Z up (Blender's, 3ds Max's scene) was written lying on its
    back, and its unit guessed from the wrong axis; it is turned Y up as training reads it, and
    its joints land where the Y-up take's do, in metres."""
    from instrument.motion.bvh import write_bvh
    from samples import z_up

    walk = read_bvh(exported["walk.bvh"])
    lying = z_up(walk)
    write_bvh(tmp_path / "z-up.bvh", lying)
    result = instrument("convert", str(tmp_path / "z-up.bvh"), "--out", str(tmp_path / "z-up.glb"))
    assert result.returncode == 0 and "+Z is up" in result.stderr, result.stderr
    _, _, positions = glb_world_positions(tmp_path / "z-up.glb")
    np.testing.assert_allclose(positions, world_positions(walk) * CM, atol=1e-4)
