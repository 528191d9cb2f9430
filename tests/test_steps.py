import subprocess
import sys

import numpy as np
import pytest

from instrument.motion.bvh import Motion, parse_bvh, read_bvh, write_bvh
from instrument.motion.features import resample
from instrument.motion.steps import contiguous_runs, segment_steps
from samples import STRIDE_SECONDS, cmu_style_walk


def test_every_shared_walk_alternates_with_plausible_steps(real_walks):
    per_style: dict[str, list[int]] = {}
    for path in real_walks:
        motion = read_bvh(path)
        segmentation = segment_steps(motion)
        steps = segmentation.steps
        assert len(steps) >= 6, path
        assert len(contiguous_runs(steps)) == 1, path
        labels = [s.label for s in steps]
        assert all(a != b for a, b in zip(labels, labels[1:])), path
        assert steps[0].start > 0 and steps[-1].end < motion.frames  # partial steps dropped
        assert segmentation.feet == ("Toes_L", "Toes_R")
        seconds = np.array([s.frames for s in steps]) / motion.fps
        assert seconds.min() >= 0.25 and seconds.max() <= 1.0, path
        per_style.setdefault(path.name.split("_")[2], []).extend(s.frames for s in steps)
    assert len(per_style) == 7
    for style, frames in per_style.items():
        assert 0.35 <= np.mean(frames) / 30 <= 0.7, style


@pytest.mark.parametrize("fps", [120.0, 30.0])
def test_cmu_style_walk_steps_start_where_the_left_foot_leads(fps):
    text, left_ahead = cmu_style_walk(fps=fps)
    motion = parse_bvh(text)
    segmentation = segment_steps(motion)
    assert segmentation.feet == ("LeftToeBase", "RightToeBase")
    rights = [s.start for s in segmentation.steps if s.label == "right"]
    assert len(rights) >= 3
    for start in rights:
        assert np.min(np.abs(left_ahead - start)) <= 0.02 * fps
    mean = np.mean([s.frames for s in segmentation.steps])
    assert mean == pytest.approx(STRIDE_SECONDS / 2 * fps, rel=0.03)


def test_standing_still_has_no_steps():
    text, _ = cmu_style_walk(fps=30)
    walk = parse_bvh(text)
    still = Motion(walk.skeleton, np.repeat(walk.channels[:1], 120, axis=0), 30.0)
    segmentation = segment_steps(still)
    assert segmentation.steps == []
    assert segmentation.warnings


def test_walking_on_the_spot_says_the_body_does_not_travel():
    """A treadmill take (the legs walk, the root stays) has no steps, and says why rather than
    leaving "no complete steps found" (then `train`'s "no steps found in any file") a mystery."""
    text, _ = cmu_style_walk(fps=30)
    walk = parse_bvh(text)
    channels = walk.channels.copy()
    channels[:, [0, 2]] = channels[:1, [0, 2]]  # the root's X and Z position held: no travel
    segmentation = segment_steps(Motion(walk.skeleton, channels, 30.0))
    assert segmentation.steps == [] and segment_steps(walk).steps
    assert any("does not travel" in w and "treadmill" in w for w in segmentation.warnings), segmentation.warnings


def test_train_on_takes_without_steps_says_why_in_its_one_line(tmp_path):
    """`train` on treadmill takes alone: its one line names a file and the reason (its warnings
    are not printed when nothing is left to train on)."""
    text, _ = cmu_style_walk(fps=30)
    walk = parse_bvh(text)
    channels = walk.channels.copy()
    channels[:, [0, 2]] = channels[:1, [0, 2]]
    write_bvh(tmp_path / "me_walk_calm_001.bvh", Motion(walk.skeleton, channels, 30.0))
    result = subprocess.run([sys.executable, "-m", "instrument", "train", str(tmp_path), "--out", str(tmp_path / "m.npz"),
                             "--quiet"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 1 and "Traceback" not in result.stderr
    line = result.stderr.strip().splitlines()[-1]
    assert "no steps found in any file" in line and "me_walk_calm_001.bvh" in line and "does not travel" in line, line


def test_a_pause_splits_the_walk_and_each_run_alternates():
    text, _ = cmu_style_walk(fps=30, seconds=4.4)
    walk = resample(parse_bvh(text), 30.0)
    pause = np.repeat(walk.channels[-1:], 60, axis=0)
    second = walk.channels.copy()
    second[:, 2] += walk.channels[-1, 2] - walk.channels[0, 2]  # carry on from where it stopped
    motion = Motion(walk.skeleton, np.vstack([walk.channels, pause, second]), 30.0)
    steps = segment_steps(motion).steps
    runs = contiguous_runs(steps)
    assert len(runs) == 2
    for run in runs:
        labels = [s.label for s in run]
        assert all(a != b for a, b in zip(labels, labels[1:]))
    assert not any(s.start < walk.frames + 60 <= s.end - 5 and s.start > walk.frames - 5 for s in steps)
