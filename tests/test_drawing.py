"""Looking without a renderer: contact sheets, animations and the live view, drawn headless."""

import subprocess
import sys

import numpy as np
import pytest

from oscrecv import free_port

pytest.importorskip("matplotlib", reason="matplotlib (the view extra) is not installed")
from PIL import Image  # noqa: E402  (comes with matplotlib)

CLI = [sys.executable, "-m", "instrument"]


def picture(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("L"), dtype=float) / 255.0


@pytest.fixture(scope="module")
def walks(tmp_path_factory):
    folder = tmp_path_factory.mktemp("walks")
    for style in ("elderly", "youthful"):
        result = subprocess.run(CLI + ["synth", "--style", f"{style}=1.5", "--seconds", "4", "--out", str(folder / f"{style}.bvh")],
                                capture_output=True, text=True)
        assert result.returncode == 0, result.stderr
    return folder


def rendered_sheet(walks, name: str, out_name: str) -> np.ndarray:
    """`instrument render` of walks/NAME.bvh, read back as a picture."""
    out = walks / out_name
    result = subprocess.run(CLI + ["render", "--bvh", str(walks / f"{name}.bvh"), "--out", str(out)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    return picture(out)


def test_contact_sheets_show_figures_and_differ_between_styles(walks):
    sheets = [rendered_sheet(walks, style, f"{style}.png") for style in ("elderly", "youthful")]
    for sheet in sheets:
        ink = (sheet < 0.5).mean()
        assert 0.003 < ink < 0.3  # figures are drawn, the page is not filled
    assert sheets[0].shape == sheets[1].shape
    assert np.abs(sheets[0] - sheets[1]).mean() > 0.005


def test_a_z_up_capture_is_drawn_standing(walks):
    """A capture exported Z up is drawn as its Y-up take is (it lay flat: the figures a smear
    along the floor), turned as training reads it."""
    from instrument.motion.bvh import read_bvh, write_bvh
    from samples import z_up

    write_bvh(walks / "z-up.bvh", z_up(read_bvh(walks / "youthful.bvh")))
    sheets = [rendered_sheet(walks, name, f"{name}-sheet.png") for name in ("youthful", "z-up")]
    assert np.abs(sheets[0] - sheets[1]).mean() < 0.002


def test_animation_has_frames(walks):
    out = walks / "walk.gif"
    result = subprocess.run(CLI + ["render", "--bvh", str(walks / "youthful.bvh"), "--out", str(out)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    gif = Image.open(out)
    assert gif.n_frames >= 50
    gif.seek(0)
    first = np.asarray(gif.convert("L"), dtype=float)
    gif.seek(gif.n_frames // 2)
    middle = np.asarray(gif.convert("L"), dtype=float)
    assert np.abs(first - middle).mean() > 0.1


def test_render_refuses_other_formats(walks):
    result = subprocess.run(CLI + ["render", "--bvh", str(walks / "youthful.bvh"), "--out", str(walks / "walk.jpg")], capture_output=True, text=True)
    assert result.returncode == 1 and "give a .png" in result.stderr


def test_live_view_draws_the_received_walk(tmp_path):
    port, out = free_port(), tmp_path / "view.png"
    viewer = subprocess.Popen(CLI + ["view", "--port", str(port), "--frames", "30", "--save", str(out)],
                              stderr=subprocess.PIPE, text=True)
    for line in viewer.stderr:
        if "listening" in line:
            break
    run = subprocess.run(CLI + ["run", "--seconds", "2", "--osc", f"127.0.0.1:{port}/flat", "--quiet"], capture_output=True, text=True)
    assert run.returncode == 0
    assert viewer.wait(30) == 0
    ink = (picture(out) < 0.5).mean()
    assert 0.002 < ink < 0.3


def near(sheet: np.ndarray, colour: str) -> int:
    """Pixels of an RGB picture within a small distance of a #rrggbb colour."""
    rgb = np.array([int(colour[k : k + 2], 16) for k in (1, 3, 5)], dtype=float)
    return int((np.linalg.norm(sheet - rgb, axis=-1) < 40).sum())


def test_a_contact_sheet_draws_left_limbs_blue_and_right_limbs_red(walks, model):
    from instrument.output.drawing import bone_colours

    names = model.layout.skeleton.names
    colours = dict(zip(names, bone_colours(names)))
    assert {n for n, c in colours.items() if c == "tab:blue"} == {n for n in names if n.endswith("_L")}
    assert {n for n, c in colours.items() if c == "tab:red"} == {n for n in names if n.endswith("_R")}
    out = walks / "sides.png"
    result = subprocess.run(CLI + ["render", "--bvh", str(walks / "youthful.bvh"), "--out", str(out)], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    sheet = np.asarray(Image.open(out).convert("RGB"), dtype=float)
    blue, red = near(sheet, "#1f77b4"), near(sheet, "#d62728")  # matplotlib's tab:blue and tab:red
    assert blue > 500 and red > 500  # both sides drawn, each in its colour
    assert 0.5 < blue / red < 2.0  # an arm and a leg on each side: about as much of each


@pytest.mark.parametrize("fps", [24.0, 30.0, 60.0, 120.0])
def test_a_contact_sheet_shows_twelve_figures_a_tenth_of_a_second_apart(fps):
    from instrument.cli.render_cmd import sheet_frames

    frames = sheet_frames(int(4 * fps), fps)
    times = np.array(frames) / fps
    assert len(frames) == 12 and times[0] == 0.0
    assert np.allclose(np.diff(times), 0.1, atol=0.5 / fps)  # 0.1 s, to the nearest frame
    assert sheet_frames(int(4 * fps), fps, every=5) == list(range(0, int(4 * fps), 5))  # --every: all of them
