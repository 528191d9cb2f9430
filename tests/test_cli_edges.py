"""Every command, every edge: bad values, bad files and outputs give one line (exit 1, or 2 for
a usage error) naming the option or the file, line and key; never a traceback.

The bad option values are made from the option table itself (instrument.control.options.OPTIONS),
so an option added to the table is tested here without a new line in this file.
"""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from conftest import REPO
from instrument.control.options import OPTIONS
from instrument.cli.main import main
from instrument.control.events import ControlEvent, read_log
from instrument.control.hub import ControlHub
from instrument.control.loghead import logged_mappings
from instrument.control.mapping import load_mapping
from instrument.control.state import ControlState
from instrument.errors import UserError
from instrument.motion.bvh import read_bvh
from instrument.tomlfile import tomllib, toml_string
from samples import cmu_style_walk

NANO = REPO / "mappings" / "korg-nanokontrol2.toml"
STYLES = ["active", "elderly", "exhausted", "feminine", "masculine", "musical", "youthful"]


def cli(capsys, *argv: str) -> tuple[int, str]:
    """Run the command line in this process: (exit status, stderr). An exception other than
    SystemExit fails the test with its traceback: that is what these tests guard against."""
    capsys.readouterr()
    try:
        status = main([str(a) for a in argv])
    except SystemExit as done:
        status = done.code
    return status, capsys.readouterr().err


def one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Small real inputs: a walk, a controller log, a show file."""
    folder = tmp_path_factory.mktemp("inputs")
    walk, _ = cmu_style_walk(fps=30)
    (folder / "walk.bvh").write_text(walk)
    (folder / "mid.jsonl").write_text(ControlEvent(0.5, "midi:x", "cc/1/1", 64).to_json() + "\n")
    (folder / "show.toml").write_text('fps = 30\nno-osc = true\n')
    (folder / "score.toml").write_text('[[cue]]\nramp = { gait = "run" }\n[[cue]]\nhold = 0.2\n')
    return folder


def bad_values(key: str) -> list[str]:
    """Values the table says are wrong for `key`: not a number, nan, just outside the range."""
    accepts = OPTIONS[key]
    values = ["x", "nan", "inf"]
    if accepts.low is not None:
        values.append(f"{accepts.low:g}" if accepts.above_low else f"{accepts.low - 1:g}")
    if accepts.high is not None:
        values.append(f"{accepts.high * 10 + 1:g}")
    if accepts.kind is int:
        values.append("1.5")
    return values


def required(command: str, files, tmp_path) -> list[str]:
    """Whatever else the command needs to get as far as reading the option."""
    out = tmp_path / "out"
    return {
        "run": ["--no-osc", "--seconds", "1"] if command != "run --seconds" else ["--no-osc"],
        "view": ["--save", tmp_path / "v.png"],
        "learn": ["--out", out, "--midi-virtual", "x"],
        "log": ["import", files / "x.mid", "--out", out],
        "train": [files / "walk.bvh", "--out", tmp_path / "m.npz"],
        "synth": ["--out", tmp_path / "s.bvh"],
        "bench": [],
        "render": ["--bvh", files / "walk.bvh", "--out", tmp_path / "r.png"],
        "evaluate": ["--styles", "elderly"],
        "service": ["--config", files / "show.toml", "--out", tmp_path / "show.service"],
    }[command.split()[0]]


@pytest.mark.parametrize("key", sorted(OPTIONS))
def test_every_bad_option_value_is_one_line(capsys, files, tmp_path, key):
    command, option = key.split()
    for bad in bad_values(key):
        argv = [command, *required(key, files, tmp_path)]
        if key == "synth --style":
            argv += ["--style", f"elderly={bad}"]
        else:
            argv += [option, bad]
        status, err = cli(capsys, *argv)
        line = one_line(err)
        assert status in (1, 2), (argv, err)
        assert option in line and repr(bad) in line, (argv, line)
    assert not list(tmp_path.iterdir())  # nothing written


def test_usage_errors_exit_2_in_one_line(capsys):
    for argv in (["synth"], ["run", "--no-such-option"], ["nosuch"], ["log", "sideways", "x", "--out", "y"]):
        status, err = cli(capsys, *argv)
        assert status == 2
        assert "--help" in one_line(err)


@pytest.mark.parametrize("argv,message", [
    (["run", "--console-token", "s3cret", "--no-osc", "--seconds", "1"], "--console-token means nothing without --console"),
    (["bench", "--console", "0"], "--console means nothing without --pacing"),
    (["bench", "--pacing", "1", "--console-pages", "2"], "--console-pages means nothing without --console"),
])
def test_an_option_without_the_one_it_belongs_to_is_refused(capsys, argv, message):
    status, err = cli(capsys, *argv)
    assert status == 1
    assert message in one_line(err)


@pytest.mark.parametrize("kind", ["garbage", "utf16"])
def test_text_files_that_are_not_utf8_are_one_line(capsys, tmp_path, kind):
    data = b"\x80\x81 not text\n" if kind == "garbage" else '{"t": 0}\n'.encode("utf-16")
    cases = {
        "log.jsonl": ["run", "--replay", "{f}", "--no-osc", "--seconds", "1"],
        "map.toml": ["run", "--mapping", "{f}", "--no-osc", "--seconds", "1"],
        "show.toml": ["run", "--config", "{f}"],
        "presets.toml": ["run", "--presets", "{f}", "--no-osc", "--seconds", "1"],
        "manifest.csv": ["train", "--manifest", "{f}", "--out", str(tmp_path / "m.npz")],
        "export.jsonl": ["log", "export", "{f}", "--out", str(tmp_path / "x.mid")],
    }
    for name, argv in cases.items():
        path = tmp_path / name
        path.write_bytes(data)
        status, err = cli(capsys, *[a.replace("{f}", str(path)) for a in argv])
        line = one_line(err)
        assert status == 1 and f"{path}:1: not UTF-8 text" in line, line
        assert ("UTF-16" in line) == (kind == "utf16")
    assert not (tmp_path / "m.npz").exists() and not (tmp_path / "x.mid").exists()


def test_a_bvh_with_a_byte_order_mark_reads(capsys, tmp_path):
    text, _ = cmu_style_walk(fps=30)
    path = tmp_path / "bom.bvh"
    path.write_bytes(b"\xef\xbb\xbf" + text.encode("utf-8"))
    assert read_bvh(path).frames == 132
    status, err = cli(capsys, "inspect", path)
    assert status == 0, err


@pytest.mark.parametrize("frame_time", ["1000000000", "0.000001", "33.3", "nan"])
def test_a_frame_time_out_of_range_is_one_line(capsys, tmp_path, frame_time):
    text, _ = cmu_style_walk(fps=30)
    path = tmp_path / "walk_odd_001.bvh"
    path.write_text(text.replace("Frame Time: 0.03333333", f"Frame Time: {frame_time}"))
    assert f"Frame Time: {frame_time}" in path.read_text()
    for argv in (["render", "--bvh", path, "--out", tmp_path / "r.png"], ["train", path, "--out", tmp_path / "m.npz", "--quiet"],
                 ["inspect", path]):
        status, err = cli(capsys, *argv)
        assert status == 1 and f"{path}:" in one_line(err) and "Frame Time" in err, err
    assert not (tmp_path / "r.png").exists() and not (tmp_path / "m.npz").exists()


def test_a_one_frame_bvh_is_inspected_with_the_others(capsys, tmp_path):
    assert cli(capsys, "skeleton", "--out", tmp_path / "rest.bvh")[0] == 0
    text, _ = cmu_style_walk(fps=30)
    (tmp_path / "walk.bvh").write_text(text)
    capsys.readouterr()
    status = main(["inspect", "--json", str(tmp_path / "rest.bvh"), str(tmp_path / "walk.bvh")])
    document = json.loads(capsys.readouterr().out)
    assert status == 0
    assert [len(d["steps"]) > 0 for d in document] == [False, True]
    assert "too short to hold a step" in document[0]["warnings"][0]
    assert document[0]["feet"] == [] and len(document[1]["feet"]) == 2  # none found: not ["", ""]
    assert main(["inspect", str(tmp_path / "rest.bvh")]) == 0
    assert "feet not found" in capsys.readouterr().out  # not "feet  / "


@pytest.mark.parametrize("argv,message", [
    (["render", "--bvh", "{walk}", "--out", "/nonexistent/x.gif"], "/nonexistent/x.gif: the folder /nonexistent does not exist"),
    (["render", "--bvh", "{walk}", "--out", "{walk}.png", "--every", "3"], None),
    (["log", "export", "{log}", "--out", "/proc/x.mid"], "/proc/x.mid: cannot write"),
    (["log", "import", "{walk}", "--out", "/nonexistent/x.jsonl"], "/nonexistent/x.jsonl: the folder"),
    (["view", "--save", "/proc/v.png"], "/proc/v.png: cannot write"),
    (["view", "--save", "{tmp}/v.txt"], "--save {tmp}/v.txt: give a .png file"),
    (["train", "{walk}", "--out", "/nonexistent/x.npz"], "/nonexistent/x.npz: the folder /nonexistent does not exist"),
    (["train", "{walk}", "--out", "{tmp}"], "{tmp}: is a folder"),
    (["synth", "--out", "{walk}"], "{walk}: already exists; give --force"),
    (["skeleton", "--out", "{walk}"], "{walk}: already exists; give --force"),
    (["log", "import", "{walk}", "--out", "{walk}", "--force"], "{walk}: is also the input"),
    # a recording over a file the show reads, --force or not (it replaced the score with the log)
    (["run", "--score", "{score}", "--fast", "--no-osc", "--record", "{score}", "--force"], "{score}: is also the input"),
    (["run", "--config", "{show}", "--seconds", "0.1", "--bvh", "{tmp}/x.bvh", "--record", "{show}", "--force"],
     "{show}: is also the input"),
    (["info", "{walk}"], "{walk}: not a model file"),
    (["synth", "--out", "{tmp}/s.bvh", "--style", "elderly.arms=1"], "no body part 'arms'"),
    (["synth", "--out", "{tmp}/s.bvh", "--gait", "jog"], "--gait: expected stand, walk, run or a number from 0 to 2, not 'jog'"),
    (["synth", "--out", "{tmp}/s.bvh", "--seconds", "2", "--gesture", "wave@2"], "--gesture wave@2: starts after the walk ends"),
    (["train", "{walk}", "--out", "{tmp}/m.bvh"], "--out {tmp}/m.bvh: give a .npz file"),
    (["learn", "--out", "{tmp}/m.json", "--midi-virtual", "x"], "--out {tmp}/m.json: give a .toml file"),
])
def test_outputs_and_inputs_are_one_line(capsys, files, tmp_path, argv, message):
    fill = {"{walk}": str(files / "walk.bvh"), "{log}": str(files / "mid.jsonl"), "{tmp}": str(tmp_path),
            "{score}": str(files / "score.toml"), "{show}": str(files / "show.toml")}

    def filled(text: str) -> str:
        for key, value in fill.items():
            text = text.replace(key, value)
        return text

    before = {p.name: p.stat().st_mtime_ns for p in files.iterdir()}
    status, err = cli(capsys, *map(filled, argv))
    if message is None:  # the control case: this one works
        assert status == 0, err
        (files / "walk.bvh.png").unlink()
        return
    assert status == 1 and filled(message) in one_line(err), err
    assert {p.name: p.stat().st_mtime_ns for p in files.iterdir()} == before  # inputs untouched
    assert not list(tmp_path.iterdir())


def test_a_take_named_twice_is_one_line_and_a_manifest_gives_its_folders_styles(capsys, files, tmp_path):
    """The same take twice (a folder and a file in it, or a manifest giving it two styles) would
    weigh double or teach two styles the same steps: refused, naming it. A folder given with a
    manifest naming its takes reads their styles from the manifest (before, from their names,
    which here hold none)."""
    takes = tmp_path / "takes"
    takes.mkdir()
    (takes / "a.bvh").write_text((files / "walk.bvh").read_text())
    twice = tmp_path / "twice.csv"
    twice.write_text("file,style\ntakes/a.bvh,proud\ntakes/a.bvh,calm\n")
    status, err = cli(capsys, "train", "--manifest", twice, "--out", tmp_path / "m.npz")
    assert status == 1 and one_line(err).endswith(f"{twice}:3: 'a.bvh': named twice (line 2 too); give each take once")
    twice = tmp_path / "twice.toml"
    twice.write_text('[[take]]\nfile = "takes/a.bvh"\nstyle = "proud"\n\n[[take]]\nfile = "takes/a.bvh"\nstyle = "calm"\n')
    status, err = cli(capsys, "train", "--manifest", twice, "--out", tmp_path / "m.npz")
    assert status == 1 and one_line(err).endswith(f"{twice}:5: 'a.bvh': named twice (line 1 too); give each take once")
    status, err = cli(capsys, "train", takes, takes / "a.bvh", "--style-from", "(a)", "--out", tmp_path / "m.npz")
    assert status == 1 and "a.bvh: named twice" in one_line(err)
    manifest = tmp_path / "styles.csv"
    manifest.write_text("file,style\ntakes/a.bvh,proud\n")
    status, err = cli(capsys, "train", takes, "--manifest", manifest, "--out", tmp_path / "m.npz", "--quiet")
    assert status == 0, err
    assert json.loads(main_output(capsys, "info", tmp_path / "m.npz", "--json"))["styles"] == ["proud"]


@pytest.mark.parametrize("kind", ["csv", "toml"])
def test_a_manifest_naming_a_take_not_there_names_its_line(capsys, files, tmp_path, kind):
    """A typo in a manifest's file column is refused where it was written (the manifest's line or
    take), before any take is read; a folder named as a take is said to be one, and a name too
    long for the file system is one line too (it was a traceback)."""
    (tmp_path / "a.bvh").write_text((files / "walk.bvh").read_text())
    (tmp_path / "sub").mkdir()
    for missing, said in (("a.bhv", "'a.bhv': no such file"), ("sub", "'sub': a folder, not a BVH file"),
                          ("x" * 300 + ".bvh", "...: cannot read (File name too long)")):  # the name cut short
        manifest = tmp_path / f"takes.{kind}"
        manifest.write_text("file,style\na.bvh,proud\n" + f"{missing},calm\n" if kind == "csv" else
                            f'[[take]]\nfile = "a.bvh"\nstyle = "proud"\n\n[[take]]\nfile = "{missing}"\nstyle = "calm"\n')
        status, err = cli(capsys, "train", "--manifest", manifest, "--out", tmp_path / "m.npz")
        where = f"{manifest}:3" if kind == "csv" else f"{manifest}:5: take 2"
        line = one_line(err)
        assert status == 1 and f"{where}: '" in line and line.endswith(said) and len(line) < 300
    assert not (tmp_path / "m.npz").exists()


def main_output(capsys, *argv) -> str:
    capsys.readouterr()
    assert main([str(a) for a in argv]) == 0
    return capsys.readouterr().out


def test_force_overwrites_through_a_part_file(capsys, tmp_path):
    out = tmp_path / "rest.bvh"
    out.write_text("precious")
    status, err = cli(capsys, "skeleton", "--out", out)
    assert status == 1 and out.read_text() == "precious"
    status, err = cli(capsys, "skeleton", "--out", out, "--force")
    assert status == 0, err
    assert read_bvh(out).frames == 1 and sorted(p.name for p in tmp_path.iterdir()) == ["rest.bvh"]


def test_view_with_no_display_says_so(tmp_path):
    env = {k: v for k, v in __import__("os").environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    result = subprocess.run([sys.executable, "-m", "instrument", "view"], capture_output=True, text=True, timeout=120, env=env)
    assert result.returncode == 1
    assert "no display" in one_line(result.stderr) and "--save" in result.stderr


def test_a_failed_start_creates_no_recording(capsys, tmp_path):
    log, bvh = tmp_path / "new.jsonl", tmp_path / "take.bvh"
    status, err = cli(capsys, "run", "--record", log, "--bvh", "/proc/x.bvh", "--no-osc", "--seconds", "1")
    assert status == 1 and "/proc/x.bvh" in one_line(err)
    status, err = cli(capsys, "run", "--record", log, "--humanoid", tmp_path / "none.toml", "--bvh", bvh, "--seconds", "1",
                      "--osc", "127.0.0.1:9/vmc")
    assert status == 1 and "none.toml" in one_line(err)
    assert not list(tmp_path.iterdir())  # the corrected command can run
    status, err = cli(capsys, "run", "--record", log, "--bvh", log, "--no-osc", "--seconds", "1")
    assert status == 1 and "both name" in one_line(err)
    status, err = cli(capsys, "run", "--bvh", tmp_path / "take.glb", "--no-osc", "--seconds", "1")  # it held BVH text
    assert status == 1 and f"{tmp_path / 'take.glb'}: a recording is BVH: give a .bvh name" in one_line(err)
    assert not list(tmp_path.iterdir())


def test_recover_leaves_a_healthy_recording_alone(capsys, tmp_path):
    path = tmp_path / "rest.bvh"
    assert cli(capsys, "skeleton", "--out", path)[0] == 0
    before = path.read_bytes()
    status, err = cli(capsys, "recover", path)
    assert status == 0, err
    assert path.read_bytes() == before


@pytest.mark.parametrize("newline", ["\n", ""])
def test_recover_says_it_cut_a_partial_last_line(capsys, tmp_path, newline):
    """A run killed while writing a frame leaves part of its line (with or without its newline):
    recover cuts it, and says so (it said "as the header says; left as it is" of a file it had
    just changed)."""
    path = tmp_path / "take.bvh"
    status, err = cli(capsys, "run", "--no-osc", "--quiet", "--fast", "--seconds", "0.5", "--bvh", path)
    assert status == 0, err
    healthy = path.read_bytes()
    last = healthy.rstrip(b"\n").rsplit(b"\n", 1)[1]
    path.write_bytes(healthy + last[: len(last) // 2] + newline.encode())
    result = subprocess.run([sys.executable, "-m", "instrument", "recover", str(path)], capture_output=True, text=True, timeout=120)
    status, said = result.returncode, result.stdout
    assert status == 0 and "cut 1 line that was not a whole frame" in said and "left as it is" not in said, said
    assert path.read_bytes() == healthy


def test_recover_names_a_damaged_line_it_cut_from_among_the_frames(capsys, tmp_path):
    """A killed run cuts a take's end, never its middle: recover drops a line short of a value with
    frames after it too, but said only "cut 1 line that was not a whole frame", as of a cut end,
    while every later frame now came a frame early. It names the line and says so."""
    path = tmp_path / "take.bvh"
    assert cli(capsys, "run", "--no-osc", "--quiet", "--fast", "--seconds", "0.5", "--bvh", path)[0] == 0
    lines = path.read_text().split("\n")
    at = lines.index("MOTION") + 3 + 5  # the sixth frame's line (0-based)
    lines[at] = lines[at].rsplit(" ", 1)[0]
    path.write_text("\n".join(lines))
    result = subprocess.run([sys.executable, "-m", "instrument", "recover", str(path)], capture_output=True, text=True, timeout=120)
    said = result.stdout
    assert result.returncode == 0, result.stderr
    assert f"{path}: 14 frames (the header said 15); cut 1 line that was not a whole frame (line {at + 1} among the frames: " \
           "the frames after it come a frame earlier; a killed run cuts only the end)" in said, said


def test_a_recorded_log_carries_its_mappings(tmp_path):
    state = ControlState(STYLES, 5)
    mapping = load_mapping(NANO, state)
    log = tmp_path / "take.jsonl"
    hub = ControlHub([mapping], record=log)
    hub.apply(state, ControlEvent(0.25, "midi:nano", "cc/1/0", 127.0))
    hub.close()
    assert [e.control for e in read_log(log)] == ["cc/1/0"]  # the header is not an event
    (carried,) = logged_mappings(log, state)
    assert repr(carried.controls) == repr(mapping.controls) and carried.midi == mapping.midi and carried.text == NANO.read_text()
    header = json.loads(log.read_text().splitlines()[0])
    header["mappings"][0]["toml"] = header["mappings"][0]["toml"].replace("cc", "note", 1)  # edited by hand
    log.write_text(json.dumps(header) + "\n")
    with pytest.raises(UserError, match="does not match its sha256"):
        logged_mappings(log, state)


def test_a_log_of_midi_events_without_a_mapping_is_an_error(capsys, files):
    status, err = cli(capsys, "run", "--replay", files / "mid.jsonl", "--no-osc", "--fast")
    assert status == 1 and "has MIDI events but no mapping to read them" in one_line(err)


def test_learned_names_are_escaped_for_toml():
    for name in ['Port\\1 "A"', "caf\u00e9:0\t"]:
        assert tomllib.loads(f"midi = {toml_string(name)}")["midi"] == name


def test_synth_sets_one_body_part(capsys, tmp_path):
    paths = {k: tmp_path / f"{k}.bvh" for k in ("none", "legs", "whole")}
    for kind, style in (("none", []), ("legs", ["--style", "elderly.legs=2"]), ("whole", ["--style", "elderly=2"])):
        status, err = cli(capsys, "synth", "--seconds", "2", "--out", paths[kind], *style)
        assert status == 0, err
    none, legs, whole = (read_bvh(paths[k]).channels for k in ("none", "legs", "whole"))
    assert abs(legs - none).max() > 1.0 and abs(legs - whole).max() > 1.0


def test_the_docs_say_what_every_option_accepts():
    text = (REPO / "docs" / "cli.md").read_text()
    for key, accepts in OPTIONS.items():
        row = next((line for line in text.splitlines() if line.startswith(f"| `{key}")), None)
        assert row is not None, key
        bounds = [b for b in (accepts.low, accepts.high) if b is not None]
        assert all((f"{b:g}" if accepts.kind is float else f"{int(b)}") in row for b in bounds), (key, row)


def test_no_osc_with_osc_is_refused_not_dropped(tmp_path):
    """`run --no-osc --osc HOST:PORT` used to drop the target silently; a show file likewise."""
    import subprocess
    import sys

    result = subprocess.run([sys.executable, "-m", "instrument", "run", "--no-osc", "--osc", "127.0.0.1:9000/flat",
                             "--fast", "--seconds", "1"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 1 and "contradict" in result.stderr and len(result.stderr.strip().splitlines()) == 1
    show = tmp_path / "show.toml"
    show.write_text('no-osc = true\nosc = ["127.0.0.1:9000/flat"]\nfast = true\nseconds = 1\n')
    result = subprocess.run([sys.executable, "-m", "instrument", "run", "--config", str(show)], capture_output=True,
                            text=True, timeout=300)
    assert result.returncode == 1 and "contradict" in result.stderr and len(result.stderr.strip().splitlines()) == 1
