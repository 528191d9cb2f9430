import json
import subprocess
import sys

import numpy as np
import pytest

from instrument.models.modelfile import default_model_path, load_model
from instrument.motion.bvh import read_bvh
from instrument.motion.kinematics import world_positions
from instrument.motion.steps import segment_steps


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "instrument", *args], capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize("style,method", [("masculine", "stream"), ("active", "full")])
def test_synth_writes_a_travelling_walk_in_the_style_s_tempo(tmp_path, style, method):
    out = tmp_path / "walk.bvh"
    result = cli("synth", "--style", f"{style}=1", "--seconds", "10", "--out", str(out), "--method", method)
    assert result.returncode == 0, result.stderr
    motion = read_bvh(out)
    assert motion.frames == 300 and motion.fps == 30.0
    hips = world_positions(motion)[:, motion.skeleton.index("Hips")]
    travelled = np.linalg.norm(hips[-1, [0, 2]] - hips[0, [0, 2]])
    assert travelled > 500  # centimetres in 10 s: the character walks
    steps = segment_steps(motion).steps
    labels = [s.label for s in steps]
    assert len(steps) >= 12 and all(a != b for a, b in zip(labels, labels[1:]))
    expected = load_model(default_model_path()).metadata["mean_step_frames"][style]
    assert np.mean([s.frames for s in steps]) == pytest.approx(expected, rel=0.1)


def test_slower_speed_gives_longer_steps(tmp_path):
    for speed in ("1", "0.5"):
        assert cli("synth", "--speed", speed, "--seconds", "12", "--out", str(tmp_path / f"{speed}.bvh")).returncode == 0
    normal = np.mean([s.frames for s in segment_steps(read_bvh(tmp_path / "1.bvh")).steps])
    slow = np.mean([s.frames for s in segment_steps(read_bvh(tmp_path / "0.5.bvh")).steps])
    assert slow == pytest.approx(2 * normal, rel=0.1)


@pytest.mark.parametrize(
    "args,message",
    [
        (["--style", "sleepy=1"], "the model has no style 'sleepy'"),
        (["--style", "elderly=lots"], "--style elderly: expected a number from -10 to 10, not 'lots'"),
        (["--style", "elderly"], "expected NAME=WEIGHT"),
        (["--speed", "0"], "--speed: expected a number from 0.25 to 4, not '0'"),
        (["--speed", "-2"], "--speed: expected a number from 0.25 to 4"),
        (["--seconds", "ten"], "--seconds: expected a number above 0"),
        (["--lookahead", "0"], "--lookahead: expected a whole number from 1 to 1000"),
        (["--model", "missing.npz"], "missing.npz: no such model file"),
    ],
)
def test_synth_errors_are_one_line(tmp_path, args, message):
    result = cli("synth", *args, "--out", str(tmp_path / "x.bvh"))
    assert result.returncode == 1
    assert message in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "x.bvh").exists()


def test_bench_json_has_the_promised_figures():
    result = cli("bench", "--json", "--repeat", "1")
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout)
    for key in ("mlpg_frames_per_s", "nnmnkwii_frames_per_s", "stream_us_per_frame", "stream_us_per_frame_batch", "characters_at_30fps"):
        assert key in figures
    assert figures["mlpg_frames_per_s"] > 0 and figures["stream_us_per_frame"] > 0
    assert figures["characters_at_30fps"] == int(1e6 / 30 / figures["stream_us_per_frame_batch"])
    # the stream, the pose path (the feet planted) and the range stage, each also against the window
    # solve timed turn about with it (the ratios are medians of per-turn ratios: test_mlpg.py)
    for figure, ratio in (("stream_us_per_frame", "stream_to_window_solve"),
                          ("stream_us_per_frame_batch", "stream_batch_to_window_solve"),
                          ("pose_us_per_frame", "pose_to_window_solve"),
                          ("pose_us_per_character_batch", "pose_batch_to_window_solve"),
                          ("widen_us_per_frame", "widen_to_window_solve")):
        assert figures[figure] > 0 and figures[ratio] > 0
    assert figures["contact_us_per_frame"] > 0  # the lock timed on its own
