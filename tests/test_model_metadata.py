"""A model file broken by hand or by another program is one line naming the file and what is
wrong with it, for every command that reads a model (`info`, `skeleton`, `synth`, `run`); never a
traceback, never a walk made of overflowing numbers."""

from __future__ import annotations

import copy
import json
import subprocess
import sys

import numpy as np
import pytest

from instrument.cli.main import main
from instrument.models.modelfile import default_model_path

SHIPPED = np.load(default_model_path(), allow_pickle=False)
ARRAYS = {name: SHIPPED[name] for name in SHIPPED.files}
METADATA = json.loads(str(ARRAYS["metadata"]))


def set_entry(*keys_and_value):
    *keys, value = keys_and_value

    def change(metadata: dict) -> None:
        for key in keys[:-1]:
            metadata = metadata[key]
        metadata[keys[-1]] = value
    return change


def drop_entry(key):
    return lambda metadata: metadata.pop(key)


BROKEN = {  # what is broken: (the change, what the one line says)
    "fps a word": (set_entry("fps", "fast"), "metadata 'fps'"),
    "fps zero": (set_entry("fps", 0), "metadata 'fps'"),
    "fps a list": (set_entry("fps", [30]), "metadata 'fps'"),
    "states a fraction": (set_entry("states", 5.5), "metadata 'states'"),
    "labels numbers": (set_entry("labels", [1, 2]), "metadata 'labels'"),
    "styles repeated": (set_entry("styles", ["a"] * 7), "metadata 'styles'"),
    # a style the live controls cannot address: `run` crashed on style/old/man (KeyError 'old')
    "style with a slash": (set_entry("styles", ["active", "old/man", "exhausted", "feminine", "masculine", "normal", "youthful"]),
                           "metadata 'styles': expected names without '/'"),
    "skeleton empty": (set_entry("skeleton", {}), "metadata 'skeleton' or 'features'"),
    "skeleton missing": (drop_entry("skeleton"), "metadata lacks 'skeleton'"),
    "joint parent past the end": (lambda m: m["skeleton"]["joints"][3].__setitem__("parent", 99), "joint 3"),
    "feature root unknown": (set_entry("features", "root", "Nope"), "metadata 'skeleton' or 'features'"),
    "template too short": (set_entry("features", "template", [0.0]), "the template pose"),
    "takes without frames": (set_entry("data", [{"file": "x.bvh"}]), "metadata 'data'"),
    "step frames a list": (set_entry("mean_step_frames", [1]), "metadata 'mean_step_frames'"),
    "training a word": (set_entry("training", "x"), "metadata 'training'"),
    "clearance ragged": (set_entry("contact", "clearance", [[1, 2], [3]]), "metadata 'contact'"),
    # a toe-less foot's tip (footlock): a word or a list was a traceback in run and synth, NaN
    # turned the tip's floor test off without a word, true read as 1
    "tip clearance a word": (set_entry("contact", "tip_clearance", "x"), "tip_clearance a number"),
    "tip clearance a list": (set_entry("contact", "tip_clearance", [1, 2]), "tip_clearance a number"),
    "tip clearance not a number": (set_entry("contact", "tip_clearance", float("nan")), "tip_clearance a number"),
    "tip clearance true": (set_entry("contact", "tip_clearance", True), "tip_clearance a number"),
}


def model_with(tmp_path, name: str, change=None, arrays: dict | None = None):
    metadata = copy.deepcopy(METADATA)
    if change is not None:
        change(metadata)
    path = tmp_path / f"{name.replace(' ', '-')}.npz"
    np.savez(path, **(arrays or ARRAYS) | {"metadata": np.array(json.dumps(metadata))})
    return path


def one_line_error(capsys, *argv) -> str:
    capsys.readouterr()
    try:
        status = main([str(a) for a in argv])  # an exception other than SystemExit fails the test with its traceback
    except SystemExit as done:
        status = done.code
    err = capsys.readouterr().err
    assert status == 1 and len(err.strip().splitlines()) == 1 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize("broken", BROKEN)
def test_broken_metadata_is_one_line_for_info_and_skeleton(tmp_path, capsys, broken):
    change, said = BROKEN[broken]
    model = model_with(tmp_path, broken, change)
    for argv in (["info", model], ["skeleton", "--model", model, "--out", tmp_path / "rest.bvh"],
                 ["skeleton", "--template", "--model", model, "--out", tmp_path / "rest.bvh"]):
        err = one_line_error(capsys, *argv)
        assert str(model) in err and said in err
    assert not (tmp_path / "rest.bvh").exists()


def test_broken_metadata_is_one_line_for_synth_and_run(tmp_path):
    model = model_with(tmp_path, "skeleton", BROKEN["skeleton empty"][0])
    for argv in (["synth", "--model", str(model), "--out", str(tmp_path / "walk.bvh"), "--seconds", "1"],
                 ["run", "--model", str(model), "--no-osc", "--seconds", "1"]):
        result = subprocess.run([sys.executable, "-m", "instrument", *argv], capture_output=True, text=True, timeout=300)
        assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
        assert "metadata 'skeleton' or 'features'" in result.stderr


@pytest.mark.parametrize("factor", [1e300, 1e20])
def test_a_model_with_extreme_means_is_refused_before_it_overflows(tmp_path, factor):
    arrays = dict(ARRAYS) | {name: ARRAYS[name] * factor for name in ("average_means", "style_means")}
    model = model_with(tmp_path, "extreme", arrays=arrays)
    result = subprocess.run([sys.executable, "-m", "instrument", "synth", "--model", str(model), "--out", str(tmp_path / "walk.bvh"),
                             "--seconds", "1"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 1 and len(result.stderr.strip().splitlines()) == 1, result.stderr
    assert "'average_means' holds values beyond" in result.stderr and not (tmp_path / "walk.bvh").exists()


def test_a_model_that_cannot_be_read_says_so_not_that_it_is_no_model(tmp_path, capsys):
    err = one_line_error(capsys, "info", "/proc/self/mem")  # a file whose every read fails (EIO)
    assert "cannot read" in err and "not a model file" not in err
    err = one_line_error(capsys, "info", tmp_path)
    assert "is a folder" in err


def test_the_template_takes_no_humanoid_map(tmp_path, capsys):
    err = one_line_error(capsys, "skeleton", "--template", "--humanoid", tmp_path / "missing.toml", "--out", tmp_path / "rest.bvh")
    assert "--humanoid" in err and not (tmp_path / "rest.bvh").exists()
