"""Training from real walks, model files, `instrument train` and `instrument info`."""

import hashlib
import json
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from conftest import REPO
from instrument.errors import UserError
from instrument.models.modelfile import default_model_path, load_model, save_model
from samples import cmu_style_walk, reorder_bvh


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "instrument", *args], capture_output=True, text=True, timeout=600)


@pytest.fixture(scope="module")
def small_model(real_walks, tmp_path_factory):
    chosen = [p for p in real_walks if "_normal_" in p.name][:3] + [p for p in real_walks if "_elderly_" in p.name][:3]
    out = tmp_path_factory.mktemp("model") / "small.npz"
    result = cli("train", *map(str, chosen), "--out", str(out), "--licence", "test licence")
    assert result.returncode == 0, result.stderr
    return out, chosen, result


def test_train_prints_likelihood_per_iteration_and_a_summary(small_model):
    _, chosen, result = small_model
    lines = [l for l in result.stderr.splitlines() if l.startswith("EM iteration")]
    values = [float(l.rsplit(" ", 1)[1]) for l in lines]
    assert len(values) >= 3
    assert all(b >= a - 1e-6 for a, b in zip(values, values[1:]))
    assert "done in" in result.stderr and "6 takes" in result.stderr


def test_model_file_holds_plain_arrays_and_metadata(small_model):
    path, chosen, _ = small_model
    with np.load(path, allow_pickle=False) as data:
        assert all(data[k].dtype != object for k in data.files)
        meta = json.loads(str(data["metadata"]))
    assert meta["format_version"] == 1
    assert meta["styles"] == ["elderly", "normal"]
    assert meta["labels"] == ["right", "left"] and meta["states"] == 5 and meta["fps"] == 30.0
    assert meta["windows"] == [[0.0, 1.0, 0.0], [-0.5, 0.0, 0.5], [1.0, -2.0, 1.0]]
    assert meta["licence"] == "test licence"
    assert "train" in meta["training"]["command"] and meta["training"]["states"] == 5
    assert meta["features"]["root"] == "Hips" and "joint_Root" in meta["features"]["left_out"]
    by_name = {d["file"]: d for d in meta["data"]}
    for p in chosen:
        assert by_name[p.name]["sha256"] == hashlib.sha256(p.read_bytes()).hexdigest()
    model = load_model(path)
    assert model.styles.means.shape == (2, 2, 5, 3 * model.layout.dimension)
    assert (model.styles.variances > 0).all()


def test_info_json(small_model):
    path, _, _ = small_model
    result = cli("info", str(path), "--json")
    assert result.returncode == 0, result.stderr
    info = json.loads(result.stdout)
    assert info["styles"] == ["elderly", "normal"] and info["fps"] == 30.0 and info["states"] == 5
    assert info["licence"] == "test licence"
    # the model's expected step length (sum of state duration means) matches the data's
    for style in info["styles"]:
        assert info["model_step_frames"][style] == pytest.approx(info["mean_step_frames"][style], rel=0.05)
    # no style state collapses: the floor is 2 frames where the steps are long enough (these are)
    assert min(info["shortest_state_frames"].values()) >= 2.0 - 1e-9
    # what the adaptation chose, per unit (a walks-only model: the walk's, on alternate takes), as info prints it
    printed = cli("info", str(path)).stdout
    for style, chosen in info["training"]["adaptation"].items():
        assert chosen["units"] == {"walk": {"depth": chosen["depth"], "tau": chosen["tau"], "folds": "takes",
                                            "heldout_loglik_per_frame": chosen["heldout_loglik_per_frame"]}}
        depth = "none" if chosen["depth"] is None else chosen["depth"]
        assert f"{style:<12} walk {depth}/{chosen['tau']:g}\n" in printed


def test_info_prints_how_each_units_settings_were_chosen(small_model, tmp_path):
    """A unit too short to split shows `(few)`, halves `(halves)`, no transform `none`; alternate
    takes nothing (the small model's metadata given a run as a one-take run's training writes it)."""
    units: dict = {}

    def given_a_run_and_a_stand(arrays: dict) -> None:
        metadata = json.loads(str(arrays["metadata"]))
        units.update(metadata["training"]["adaptation"]["normal"]["units"])
        units["run"] = {"depth": 2, "tau": 16.0, "heldout_loglik_per_frame": None, "folds": "few"}
        units["stand"] = {"depth": None, "tau": 64.0, "heldout_loglik_per_frame": 401.5, "folds": "halves"}
        metadata["training"]["adaptation"]["normal"]["units"] = units
        arrays["metadata"] = np.array(json.dumps(metadata))

    edited = tmp_path / "edited.npz"
    _rewrite(small_model[0], edited, given_a_run_and_a_stand)
    result = cli("info", str(edited))
    assert result.returncode == 0, result.stderr
    walk = units["walk"]
    walk_depth = "none" if walk["depth"] is None else walk["depth"]
    assert f"normal       walk {walk_depth}/{walk['tau']:g}, run 2/16 (few), stand none/64 (halves)\n" in result.stdout


def test_save_and_load_round_trip(small_model, tmp_path):
    model = load_model(small_model[0])
    copy = tmp_path / "copy.npz"
    save_model(copy, model)
    again = load_model(copy)
    np.testing.assert_array_equal(again.styles.means, model.styles.means)
    assert again.metadata == model.metadata | {"format": "instrument-style-model", "format_version": 1}


def _rewrite(source: Path, target: Path, change) -> None:
    with np.load(source, allow_pickle=False) as data:
        arrays = {k: data[k] for k in data.files}
    change(arrays)
    np.savez(target, **arrays)


@pytest.mark.parametrize("case", ["corrupt", "truncated", "version", "shape", "negative variance", "not json", "empty"])
def test_bad_model_files_are_one_line_errors(small_model, tmp_path, case):
    source, bad = small_model[0], tmp_path / "bad.npz"
    raw = source.read_bytes()
    if case == "corrupt":
        bad.write_bytes(b"PK\x03\x04" + bytes(range(256)) * 10)
    elif case == "truncated":
        bad.write_bytes(raw[: len(raw) // 2])
    elif case == "empty":
        bad.write_bytes(b"")
    elif case == "version":
        _rewrite(source, bad, lambda a: a.__setitem__("metadata", np.array(str(a["metadata"]).replace('"format_version": 1', '"format_version": 99'))))
    elif case == "shape":
        _rewrite(source, bad, lambda a: a.__setitem__("style_means", a["style_means"][:1]))
    elif case == "negative variance":
        _rewrite(source, bad, lambda a: a.__setitem__("average_variances", -a["average_variances"]))
    elif case == "not json":
        _rewrite(source, bad, lambda a: a.__setitem__("metadata", np.array("{not json")))
    with pytest.raises(UserError) as error:
        load_model(bad)
    assert str(bad) in str(error.value) and "\n" not in str(error.value)
    result = cli("info", str(bad))
    assert result.returncode == 1 and "Traceback" not in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1


def test_train_errors_are_one_line(real_walks, tmp_path):
    cmu, _ = cmu_style_walk(fps=30)
    (tmp_path / "other_skeleton_cmu_001.bvh").write_text(cmu)
    cases = {
        "skeleton": ([str(real_walks[0]), str(tmp_path / "other_skeleton_cmu_001.bvh")], "other_skeleton_cmu_001.bvh"),
        "regex groups": ([str(real_walks[0]), "--style-from", "walk"], "exactly one group"),
        "regex syntax": ([str(real_walks[0]), "--style-from", "(walk"], "not a regular expression"),
        "no style": ([str(real_walks[0]), "--style-from", r"_(zzz)_"], "cannot read a style"),
        "no data": ([], "no training data"),
        "states": ([str(real_walks[0]), "--states", "0"], "--states"),
    }
    for name, (args, message) in cases.items():
        result = cli("train", *args, "--out", str(tmp_path / "x.npz"), "--quiet")
        assert result.returncode == (2 if name == "states" else 1), name  # a bad option value is a usage error
        assert message in result.stderr, (name, result.stderr)
        assert len(result.stderr.strip().splitlines()) == 1, (name, result.stderr)
    assert not (tmp_path / "x.npz").exists()


def first_frames(path: Path, frames: int, out: Path) -> Path:
    """The first `frames` frames of a BVH file, written to `out` (a take cut short)."""
    head, motion = path.read_text().split("Frame Time:", 1)
    lines = motion.split("\n")
    head = head[: head.rindex("Frames:")] + f"Frames: {frames}\n"
    out.write_text(head + "Frame Time:" + lines[0] + "\n" + "\n".join(lines[1 : 1 + frames]) + "\n")
    return out


@pytest.mark.parametrize("quiet", [False, True], ids=["progress", "quiet"])
def test_train_says_a_small_style_warning_once_also_when_quiet(real_walks, tmp_path, quiet):
    """A style with too few steps is trained anyway, with one warning line (not a second, raw
    Python warning); --quiet leaves out the progress, not the warning."""
    normal = next(p for p in real_walks if "_normal_" in p.name)
    tiny = first_frames(normal, 100, tmp_path / "cut_walk_tiny_001.bvh")  # about three steps
    result = cli("train", str(normal), str(tiny), "--out", str(tmp_path / "m.npz"), *(["--quiet"] if quiet else []))
    assert result.returncode == 0, result.stderr
    lines = result.stderr.splitlines()
    said = [line for line in lines if "'tiny'" in line]
    assert len(said) == 1 and said[0].startswith("warning: style 'tiny' has only "), result.stderr
    assert "Warning" not in result.stderr  # no Python warning beside it
    assert all(line.startswith("warning: ") for line in lines) if quiet else any("done in" in line for line in lines)


@pytest.mark.parametrize("kind", ["csv", "toml"])
def test_manifest_names_styles_and_other_conventions_train(tmp_path, kind):
    # a CMU-style skeleton in XYZ order with 3-channel joints: nothing is tied to the shared skeleton
    for k, speed in enumerate(["slow", "slow", "quick", "quick"]):
        text, _ = cmu_style_walk(fps=120 if k % 2 else 30, seconds=4.4 + k * 0.3)
        (tmp_path / f"take{k}.bvh").write_text(reorder_bvh(text, "XYZ"))
    rows = [("take0.bvh", "slow"), ("take1.bvh", "slow"), ("take2.bvh", "quick"), ("take3.bvh", "quick")]
    if kind == "csv":
        manifest = tmp_path / "takes.csv"
        manifest.write_text("file,style\n" + "".join(f"{f},{s}\n" for f, s in rows))
    else:
        manifest = tmp_path / "takes.toml"
        manifest.write_text("".join(f'[[take]]\nfile = "{f}"\nstyle = "{s}"\n' for f, s in rows))
    out = tmp_path / "m.npz"
    result = cli("train", "--manifest", str(manifest), "--out", str(out), "--states", "3")
    assert result.returncode == 0, result.stderr
    model = load_model(out)
    assert model.style_names == ["quick", "slow"] and model.states == 3
    assert model.metadata["skeleton"]["joints"][2]["channels"] == ["Xrotation", "Yrotation", "Zrotation"]
    adaptation = model.metadata["training"]["adaptation"]  # what was chosen for each style, and its shortest state
    assert set(adaptation) == {"quick", "slow"}
    for style, chosen in adaptation.items():
        assert chosen["min_duration"] == pytest.approx(model.style(style).duration_means.min())


def test_a_unit_with_one_foots_steps_and_a_style_without_walks_train_a_model_that_plays(tmp_path):
    """Two takes a user's corpus may well hold: a run with one step long enough (a right, no
    left) died in a traceback (IndexError: the average of a label no take had a segment of), and
    a style with runs but no walk wrote a model no command loaded (its walk's mean step NaN)."""
    for k in range(2):
        text, _ = cmu_style_walk(fps=30, seconds=4.4 + k * 0.3)
        (tmp_path / f"walk{k}.bvh").write_text(text)
    (tmp_path / "short.bvh").write_text(cmu_style_walk(fps=30, seconds=1.2)[0])  # one right step
    (tmp_path / "runs.bvh").write_text(cmu_style_walk(fps=30, seconds=4.0)[0])
    (tmp_path / "short.csv").write_text("file,style,unit\nwalk0.bvh,calm,walk\nwalk1.bvh,calm,walk\nshort.bvh,calm,run\n")
    result = cli("train", "--manifest", str(tmp_path / "short.csv"), "--out", str(tmp_path / "s.npz"), "--states", "3")
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    assert "unit 'run': no left step long enough for 3 states in any take: left out" in result.stderr
    assert load_model(tmp_path / "s.npz").units == ["walk"]  # its runs play the walk, and say so
    (tmp_path / "takes.csv").write_text("file,style,unit\nwalk0.bvh,calm,walk\nwalk1.bvh,calm,walk\nruns.bvh,brisk,run\n")
    out = tmp_path / "m.npz"
    result = cli("train", "--manifest", str(tmp_path / "takes.csv"), "--out", str(out), "--states", "3", "--quiet")
    assert result.returncode == 0 and "Traceback" not in result.stderr, result.stderr
    model = load_model(out)  # it loads
    assert model.units == ["walk", "run"] and model.style_names == ["brisk", "calm"]
    assert set(model.metadata["mean_step_frames"]) == {"calm"}  # brisk has no walking step to measure
    for style in model.style_names:
        done = cli("synth", "--model", str(out), "--style", f"{style}=1", "--gait", "run", "--turn", "0.5",
                   "--seconds", "2", "--out", str(tmp_path / f"{style}.bvh"))
        assert done.returncode == 0, done.stderr
        assert np.isfinite(np.loadtxt(tmp_path / f"{style}.bvh", skiprows=(tmp_path / f"{style}.bvh").read_text()
                                      .splitlines().index("MOTION") + 3)).all()
    (tmp_path / "one.csv").write_text("file,style\nshort.bvh,calm\n")  # a walk of one foot: one line, not a traceback
    result = cli("train", "--manifest", str(tmp_path / "one.csv"), "--out", str(tmp_path / "n.npz"), "--states", "3",
                 "--quiet")
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "the walking takes hold no left step long enough for 3 states" in result.stderr


def test_bad_manifest_names_file_and_line(tmp_path):
    manifest = tmp_path / "takes.csv"
    manifest.write_text("file,style\na.bvh,slow\nb.bvh\n")
    (tmp_path / "a.bvh").touch()  # line 2 names a file that is there: line 3 lacks its style
    result = cli("train", "--manifest", str(manifest), "--out", str(tmp_path / "m.npz"))
    assert result.returncode == 1 and f"{manifest}:3: 'b.bvh': no style: each take is a line file,style" in result.stderr
    for row, said in (("b.bvh,,walk", "'b.bvh': no style"), (",slow,walk", "no file")):  # a field left empty
        manifest.write_text(f"file,style,unit\na.bvh,slow,walk\n{row}\n")
        result = cli("train", "--manifest", str(manifest), "--out", str(tmp_path / "m.npz"))
        assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert f"{manifest}:3: {said}: each take is a line file,style (neither empty)" in result.stderr


def test_shipped_default_model(real_walks):
    path = default_model_path()
    assert path == REPO / "models" / "default.npz"
    model = load_model(path)
    assert model.style_names == ["active", "elderly", "exhausted", "feminine", "masculine", "normal", "youthful"]
    assert "CC BY-NC 4.0" in model.metadata["licence"]
    assert "Bandai Namco Research" in model.metadata["attribution"]
    shipped = {d["file"]: d["sha256"] for d in model.metadata["data"]}
    assert sum(d["unit"] == "walk" for d in model.metadata["data"]) == 175  # and the runs, turns and stands beside them
    for p in real_walks[::20]:
        assert shipped[p.name] == hashlib.sha256(p.read_bytes()).hexdigest()
    card = (REPO / "models" / "README.md").read_text()
    assert "instrument train" in card and "CC BY-NC 4.0" in card


def test_wheel_ships_the_default_model(tmp_path):
    result = subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(tmp_path), str(REPO)],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    wheel = next(tmp_path.glob("instrument-*.whl"))
    assert "instrument/shipped_models/default.npz" in zipfile.ZipFile(wheel).namelist()
