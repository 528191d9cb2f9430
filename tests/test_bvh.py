import subprocess
import sys

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from instrument.errors import UserError
from instrument.motion.bvh import bvh_text, parse_bvh, read_bvh, write_bvh
from samples import cmu_style_walk, reorder_bvh

SIMPLE = """HIERARCHY
ROOT Hips
{
\tOFFSET 0 0 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Leg
\t{
\t\tOFFSET 0 -10 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 -10 0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 90 0 0 0 0 10 20 30
1 90 2 0 0 0 15 25 35
"""


def test_reads_every_shared_walk_with_its_skeleton(real_walks):
    for path in real_walks:
        motion = read_bvh(path)
        assert len(motion.skeleton.joints) == 22, path
        assert motion.skeleton.names[:2] == ["joint_Root", "Hips"]
        assert motion.channels.shape == (motion.frames, 132)
        assert motion.fps == 30.0
        assert 180 <= motion.frames <= 466
    assert len(real_walks) == 175


def test_simple_file_values_and_end_site():
    motion = parse_bvh(SIMPLE)
    assert motion.skeleton.names == ["Hips", "Leg"]
    assert motion.skeleton.joints[1].end_site == (0.0, -10.0, 0.0)
    assert motion.skeleton.joints[1].rotation_order == "ZXY"
    np.testing.assert_array_equal(motion.channels[1], [1, 90, 2, 0, 0, 0, 15, 25, 35])


def test_crlf_tabs_and_spaces_read_alike():
    crlf = SIMPLE.replace("\t", "    ").replace("\n", "\r\n")
    a, b = parse_bvh(SIMPLE), parse_bvh(crlf)
    np.testing.assert_array_equal(a.channels, b.channels)
    assert a.skeleton == b.skeleton


def test_cmu_style_file_loads():
    text, _ = cmu_style_walk(newline="\r\n")
    motion = parse_bvh(text, "cmu.bvh")
    assert len(motion.skeleton.joints) == 31
    assert motion.fps == pytest.approx(120.0)
    assert [len(j.channels) for j in motion.skeleton.joints[:3]] == [6, 3, 3]
    assert motion.skeleton.joints[2].rotation_order == "ZYX"


def test_write_reads_back_to_written_precision(real_walks, tmp_path):
    motion = read_bvh(real_walks[0])
    out = tmp_path / "copy.bvh"
    write_bvh(out, motion)
    again = read_bvh(out)
    assert again.skeleton.same_layout(motion.skeleton)
    np.testing.assert_allclose(again.skeleton.offsets, motion.skeleton.offsets, atol=5e-7)
    np.testing.assert_allclose(again.channels, motion.channels, atol=5e-7)
    assert again.fps == motion.fps
    assert not list(tmp_path.glob("*.part"))


def test_the_longest_shared_walk_reads_whole(real_walks):
    # its speed is a figure of `instrument bench`, not of a test
    longest = max(real_walks, key=lambda p: p.stat().st_size)
    assert read_bvh(longest).frames == 466


BROKEN = {
    "missing MOTION": (SIMPLE.split("MOTION")[0], "MOTION section is missing"),
    "truncated frames": (SIMPLE.replace("Frames: 2", "Frames: 3"), "truncated: header says 3 frames, file has 2"),
    "channel count": (SIMPLE.replace("1 90 2 0 0 0 15 25 35", "1 90 2 0 0 0 15 25"), "frame has 8 values, the hierarchy has 9 channels"),
    "not a number": (SIMPLE.replace("15 25 35", "15 abc 35"), "not a number: 'abc'"),
    "CHANNELS count": (SIMPLE.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation"), "CHANNELS says 4 channels but lists 3"),
    "unknown channel": (SIMPLE.replace("Xrotation Yrotation\n\t\tEnd", "Xrotation Wrotation\n\t\tEnd"), "unknown channel 'Wrotation'"),
    "bad offset": (SIMPLE.replace("OFFSET 0 -10 0\n\t\tCHANNELS", "OFFSET 0 x 0\n\t\tCHANNELS"), "OFFSET has a value that is not a number"),
    "empty file": ("", "bad.bvh: the file is empty"),  # not "bad.bvh:0: unexpected end of file"
    "blank file": ("\n  \n\t\n", "bad.bvh: the file is empty"),
    # the body is 20 long: its hips 9 km up for a frame is no motion (read, it trained a floating style)
    "leap": (SIMPLE.replace("1 90 2 0", "1 900000 2 0"), "Hips Yposition leaps 899910 in one frame (the body is about 20 long)"),
}
LINES = {"missing MOTION": 15, "truncated frames": 20, "channel count": 20, "not a number": 20, "CHANNELS count": 9, "unknown channel": 9,
         "bad offset": 8, "leap": 20}


@pytest.mark.parametrize("case", sorted(BROKEN))
def test_broken_files_name_file_and_line(case):
    text, message = BROKEN[case]
    with pytest.raises(UserError) as error:
        parse_bvh(text, "bad.bvh")
    text_of_error = str(error.value)
    assert message in text_of_error
    assert "\n" not in text_of_error
    if case in LINES:
        assert text_of_error.startswith(f"bad.bvh:{LINES[case]}: "), text_of_error


def test_broken_file_on_the_command_line_is_one_line_and_exit_1(tmp_path):
    bad = tmp_path / "bad.bvh"
    bad.write_text(SIMPLE.replace("15 25 35", "15 abc 35"))
    result = subprocess.run([sys.executable, "-m", "instrument", "inspect", str(bad)], capture_output=True, text=True)
    assert result.returncode == 1
    assert result.stderr.strip().count("\n") == 0
    assert f"{bad}:20: not a number" in result.stderr
    assert "Traceback" not in result.stderr


def test_a_glitch_frame_in_a_real_take_is_refused_by_train_at_its_line(real_walks, tmp_path):
    """One frame of a shared walk with its hips 10 km up (finite, so read before): train trained
    on it without a word, and the style's walk floated 39 m above the floor, standing still."""
    lines = real_walks[0].read_text().splitlines()
    first = lines.index("MOTION") + 4  # 1-based line of the first frame
    values = lines[first - 1 + 100].split()
    values[7] = "1000000"  # Hips Yposition (joint_Root's six channels come first)
    lines[first - 1 + 100] = " ".join(values)
    take = tmp_path / real_walks[0].name
    take.write_text("\n".join(lines) + "\n")
    assert read_bvh(real_walks[0]).frames > 101  # (the untouched take reads)
    result = subprocess.run([sys.executable, "-m", "instrument", "train", str(take), "--out", str(tmp_path / "m.npz")],
                            capture_output=True, text=True, timeout=600)
    assert result.returncode == 1, result.stderr
    assert result.stderr.strip().splitlines()[-1].startswith(f"instrument train: error: {take}:{first + 100}: Hips Yposition leaps ")
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "m.npz").exists()


@pytest.mark.parametrize("order", ["XYZ", "ZYX", "YXZ"])
def test_other_euler_orders_and_three_channel_joints_give_the_same_pose(order):
    text, _ = cmu_style_walk(fps=30)
    original = parse_bvh(text)
    from instrument.motion.kinematics import world_positions

    reordered = parse_bvh(reorder_bvh(text, order))
    assert reordered.skeleton.joints[3].rotation_order == order
    np.testing.assert_allclose(world_positions(reordered), world_positions(original), atol=1e-4)


def test_text_of_written_file_has_hierarchy_and_frame_count(real_walks):
    motion = read_bvh(real_walks[0])
    text = bvh_text(motion)
    assert text.startswith("HIERARCHY\nROOT joint_Root\n")
    assert f"Frames: {motion.frames}\n" in text
    assert text.count("End Site") == 5


@pytest.mark.parametrize(
    "encode",
    [
        pytest.param(lambda text: text.encode("latin-1"), id="latin-1"),
        pytest.param(lambda text: b"\xef\xbb\xbf" + text.encode("utf-8"), id="utf-8 with a byte-order mark"),
    ],
)
def test_a_file_in_an_exporters_code_page_reads_with_its_joint_names(tmp_path, encode):
    """Exporters on Windows write joint names in the machine's 8-bit code page, or UTF-8 with a
    byte-order mark: both read, the names as written, the numbers as in plain UTF-8."""
    path = tmp_path / "hüfte.bvh"
    path.write_bytes(encode(SIMPLE.replace("JOINT Leg", "JOINT Hüfte_links")))
    motion = read_bvh(path)
    assert motion.skeleton.names == ["Hips", "Hüfte_links"]
    np.testing.assert_array_equal(motion.channels, parse_bvh(SIMPLE, "simple").channels)


@given(st.lists(st.tuples(st.integers(0, SIMPLE.count("\n")), st.sampled_from(["", "  ", "\t", " \t "])), max_size=6))
@settings(max_examples=60, deadline=None)
def test_blank_lines_anywhere_read_the_same_motion(blanks):
    """Exporters and hand edits leave blank lines between frames too (Blender's reader skips them):
    a file with blank lines anywhere reads as the file without them."""
    lines = SIMPLE.split("\n")
    for at, blank in sorted(blanks, reverse=True):
        lines.insert(at, blank)
    motion = parse_bvh("\n".join(lines), "blank.bvh")
    plain = parse_bvh(SIMPLE)
    assert motion.skeleton == plain.skeleton
    np.testing.assert_array_equal(motion.channels, plain.channels)


def test_a_bad_frame_after_blank_lines_is_named_by_its_own_line():
    lines = SIMPLE.replace("15 25 35", "15 abc 35").split("\n")
    lines[18:18] = ["", ""]  # two blank lines after the first frame: the bad frame moves from line 20 to 22
    with pytest.raises(UserError, match=r"^bad\.bvh:22: not a number: 'abc'$"):
        parse_bvh("\n".join(lines), "bad.bvh")


def test_a_capture_in_another_format_is_named_by_every_command_that_reads_bvh(tmp_path):
    """A user who gives a glTF, FBX... export learns what the file is and what to give, in one line
    naming it, from every command (they all read through read_bvh), not "starts with HIERARCHY"."""
    take = tmp_path / "take.bvh"
    take.write_text(SIMPLE)
    glb = tmp_path / "take.glb"
    made = subprocess.run([sys.executable, "-m", "instrument", "convert", str(take), "--out", str(glb)],
                          capture_output=True, text=True)
    assert made.returncode == 0, made.stderr  # a real .glb, as `convert` writes it
    takes = tmp_path / "takes"
    takes.mkdir()
    (takes / "walk_happy_001.glb").write_bytes(glb.read_bytes())
    expected = {
        ("inspect", str(glb)): f"{glb}: a binary glTF (.glb) file, not a BVH (give a .bvh capture",
        ("convert", str(glb), "--out", str(tmp_path / "again.glb")): f"{glb}: a binary glTF (.glb) file, not a BVH",
        ("render", "--bvh", str(glb), "--out", str(tmp_path / "walk.png")): f"{glb}: a binary glTF (.glb) file, not a BVH",
        ("train", str(takes), "--out", str(tmp_path / "model.npz")):
            f"{takes}: no .bvh files in this folder (it holds .glb files: export the takes as .bvh)",
        ("evaluate", "--real", str(takes)):  # the shipped model's takes, looked for by name among BVH files
            "takes the model was trained on is there (it holds .glb files: export the takes as .bvh)",
    }
    for args, message in expected.items():
        result = subprocess.run([sys.executable, "-m", "instrument", *args], capture_output=True, text=True)
        assert result.returncode == 1 and "Traceback" not in result.stderr, result.stderr
        assert result.stderr.strip().count("\n") == 0 and message in result.stderr, (args, result.stderr)
    # what the file holds decides, not its name: a .glb renamed .bvh, an FBX, a glTF's JSON
    renamed = tmp_path / "walk_happy_002.bvh"
    renamed.write_bytes(glb.read_bytes())
    with pytest.raises(UserError, match=f"^{renamed}: a binary glTF \\(.glb\\) file, not a BVH"):
        read_bvh(renamed)
    with pytest.raises(UserError, match="^walk.bvh: an FBX file, not a BVH"):
        parse_bvh("; FBX 7.4.0 project file\n; Created by Blender FBX exporter\n", "walk.bvh")
    with pytest.raises(UserError, match="^walk.gltf: a glTF file, not a BVH"):
        parse_bvh('{\n  "asset": {"version": "2.0"}\n}\n', "walk.gltf")
    with pytest.raises(UserError, match="^bad.bvh:1: a BVH file starts with HIERARCHY$"):  # text of no known format
        parse_bvh("Frames: 2\n", "bad.bvh")
