"""The stop-and-start figures (`instrument evaluate --units`, examples/units_figures.py) measure
what a user gets: the sequence the evaluation renders through the engine is, frame for frame, the
BVH that `instrument run --fast --bvh` records from a score playing the same cues, read back by an
independent reader (tests/bvh_independent.py: the `bvh` package and scipy's rotations). And what
the file shows of a stop: the feet closed up as a stand from rest has them, so the next start sets
off without a jolt (docs/evaluate.md, "A stop that closes its feet")."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from bvh_independent import world_positions
from conftest import REPO
from instrument.evaluation.sequence import velocity_jumps
from instrument.evaluation.transitions import step_frames, transition_sequence
from instrument.models.modelfile import load_model
from instrument.motion.kinematics import world_positions as own_world_positions
from instrument.motion.limbs import find_limbs
from instrument.synthesis.engine import default_controls, render
from instrument.synthesis.parameters import GAITS


def _feet_apart(positions: np.ndarray, hips: list[int], pivots: list[int], frame: int) -> np.ndarray:
    """Where one foot's front-most joint (`pivots`) stands from the other's at `frame`,
    horizontally, in the body's frame: (forward, sideways), sideways along the line between the
    hip joints (`hips`)."""
    side = positions[frame, hips[0]] - positions[frame, hips[1]]
    side = side[[0, 2]] / np.linalg.norm(side[[0, 2]])
    forward = np.array([side[1], -side[0]])
    apart = (positions[frame, pivots[0]] - positions[frame, pivots[1]])[[0, 2]]
    return np.array([apart @ forward, apart @ side])


def _recorded(tmp_path, cues: str, *options: str) -> tuple[str, list[str], np.ndarray, float]:
    """A score (`cues`, its TOML) played by `instrument run --score --fast --no-osc --bvh` with
    `options`, and the file read back by the independent reader: (what the command said, the
    joints' names, their world positions, the file's rate)."""
    (tmp_path / "score.toml").write_text(cues)
    done = subprocess.run([sys.executable, "-m", "instrument", "run", "--score", "score.toml", "--fast", "--no-osc",
                           *options, "--bvh", "take.bvh"], capture_output=True, text=True, cwd=tmp_path, timeout=900)
    assert done.returncode == 0, done.stderr
    return (done.stdout + done.stderr, *world_positions(tmp_path / "take.bvh"))


def _hips_speed(names: list[str], recorded: np.ndarray, fps: float) -> np.ndarray:
    """(frames - 1,) the shipped model's root joint's horizontal speed in a recording (cm/s)."""
    layout = load_model(REPO / "models" / "default.npz").layout
    hips = recorded[:, names.index(layout.skeleton.names[layout.root])][:, [0, 2]]
    return np.linalg.norm(np.diff(hips, axis=0), axis=1) * fps


def test_the_evaluations_stop_and_start_is_the_bvh_a_score_records(tmp_path):
    model = load_model(REPO / "models" / "default.npz")
    sequence = transition_sequence(model, "walk", {"feminine": 1.0})
    stop_at, start_at = sequence.changes
    fps = model.fps
    frames = len(sequence.labels)
    # the same cues as a score: the style and the walk from the start, a stand, the walk again
    _, names, recorded, recorded_fps = _recorded(
        tmp_path, f'[[cue]]\nat = 0\nramp = {{ "style/feminine" = 1.0, gait = "walk" }}\n\n'
                  f'[[cue]]\nat = {stop_at / fps!r}\nramp = {{ gait = "stand" }}\n\n'
                  f'[[cue]]\nat = {start_at / fps!r}\nramp = {{ gait = "walk" }}\n',
        "--quiet", "--fps", repr(fps), "--seconds", repr(frames / fps))
    assert abs(recorded_fps - fps) < 1e-3 and len(recorded) == frames  # Frame Time is written to 6 places
    own = own_world_positions(sequence.motion)
    order = [sequence.motion.skeleton.names.index(n) for n in names]
    assert np.abs(recorded - own[:, order]).max() < 1e-3  # model units (cm): the BVH's written precision
    # so every figure of the evaluation holds for the file: the velocity jumps it judges transitions by
    assert np.allclose(velocity_jumps(recorded), velocity_jumps(own[:, order]), atol=1e-2)
    # and what the file shows: it walks, stands still, walks again
    hips = recorded[:, names.index(sequence.motion.skeleton.names[model.layout.root])][:, [0, 2]]
    speed = np.linalg.norm(np.diff(hips, axis=0), axis=1) * fps
    walking, standing = speed[stop_at - 60:stop_at].mean(), speed[stop_at + 60:start_at].mean()
    assert walking > 60.0 and standing < 2.0
    assert speed[-60:].mean() > 0.8 * walking
    # the stop closes the feet up: in the stand's last frame they stand as a stand from rest has them
    # (the stop left them where its last steps landed, 15 cm from that), within a twentieth of a stride
    legs = find_limbs(model.layout.skeleton, model.layout.root, np.asarray(model.layout.template)).legs
    hip_joints, pivots = [leg.hip for leg in legs], [leg.pivot for leg in legs]
    joint_names = sequence.motion.skeleton.names
    in_file = {j: names.index(joint_names[j]) for j in hip_joints + pivots}  # the BVH's joint order
    rest = own_world_positions(render(model, default_controls(model, {"feminine": 1.0}, gait=GAITS.index("stand")), 60))
    stride = walking * 2.0 * step_frames(model, "walk") / fps
    closed = (_feet_apart(recorded, [in_file[j] for j in hip_joints], [in_file[j] for j in pivots], start_at - 1)
              - _feet_apart(rest, hip_joints, pivots, 59))
    assert np.linalg.norm(closed) < stride / 20.0, (closed, stride)
    # so the start after it jolts little more than the walk itself does (set off from the feet as the
    # stop left them, its first step's knee jumped 2.6 times as far in a frame as the walk's largest)
    jumps = velocity_jumps(recorded)
    assert jumps[start_at:start_at + 2 * int(fps)].max() < 1.5 * jumps[stop_at - 90:stop_at].max()


def test_a_recorded_run_from_a_stand_lifts_its_rear_foot_and_speeds_up_over_two_pushes(tmp_path):
    """What a user gets of a run's first step: a score that runs (normal x2, whose start swept
    worst), stands and runs again, recorded by `instrument run --fast --bvh` and read back by the
    independent reader. A running foot's toes never go back along the way the body travels by
    much more than they do in the steady run: the start eases the stance leg's swing and the
    travel in up to its toe-off, so the sweep has stopped as the foot lifts. Eased over the whole
    step, the rear toes were swept back 7.8 cm in a frame as they rose (the steady run's most is
    1.1), and the swing brought them forward again (units.py, "A run's first step pushes off").
    And the body speeds up only while a foot is down, over two pushes: the hips' speed (over 5
    frames) gains no more than 0.85 of the run's within any one step's frames (the model's mean
    run step). Set at full speed by the first toe-off, it gained 0.95 (0.94 to 1.06 over the
    styles at 1 and x2; with two pushes 0.53 to 0.75: each push about half, a step's window
    spanning the end of one and the start of the next)."""
    fps = 30.0
    run_cue = 7.0
    frames = int(round((run_cue + 1.5) * fps))
    _, names, recorded, _ = _recorded(
        tmp_path, '[[cue]]\nat = 0\nramp = { "style/normal" = 2.0, gait = "run" }\n\n'
                  '[[cue]]\nat = 4.0\nramp = { gait = "stand" }\n\n'
                  f'[[cue]]\nat = {run_cue!r}\nramp = {{ gait = "run" }}\n',
        "--quiet", "--fps", repr(fps), "--seconds", repr(frames / fps))
    model = load_model(REPO / "models" / "default.npz")
    layout = model.layout
    legs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template)).legs
    hips = recorded[:, names.index(layout.skeleton.names[layout.root])][:, [0, 2]]
    travel = np.diff(hips, axis=0)
    way = travel / np.maximum(np.linalg.norm(travel, axis=1, keepdims=True), 1e-9)  # the body's way, frame by frame
    toes = [recorded[:, names.index(layout.skeleton.names[leg.pivot])][:, [0, 2]] for leg in legs]
    back = np.max([-(np.diff(toe, axis=0) * way).sum(axis=1) for toe in toes], axis=0)  # cm a frame, the worse foot
    cue = int(round(run_cue * fps))
    speed = np.linalg.norm(travel, axis=1) * fps
    assert speed[cue - 30:cue].mean() < 2.0 and speed[-10:].mean() > 300.0  # stood, then ran
    steady = back[30:120].max()
    assert back[cue:].max() <= 2.5 * max(steady, 0.5), (back[cue:].max(), steady)
    paced = np.linalg.norm(hips[5:] - hips[:-5], axis=1) / 5 * fps  # cm/s over 5 frames
    step = int(round(step_frames(model, "run")))
    running = paced[30:115].mean()  # the run before the stand
    gained = (paced[cue + step:] - paced[cue:-step]).max()
    assert gained <= 0.85 * running, (gained / running, step)


@pytest.mark.parametrize("walk_frames", [60, 64, 68])  # the stop told early, half way and late in a step
def test_a_recorded_walk_stops_without_flinging_a_foot_forward_and_back(tmp_path, walk_frames):
    """What a user gets of a stop: a score that walks (feminine at weight 1, whose stop popped
    hardest) and then stands, recorded by `instrument run --fast --bvh` and read back by the
    independent reader. From the stop cue to a second into the stand no joint's velocity (its
    frame-to-frame displacement, from the file's positions) changes more in a frame than 1.25
    times it does in the steady walk before it: the braking body shortens its steps as its travel
    eases out, and a stop told too late in a step to brake within it takes one more step. Braked
    with the steps' full swing, the swinging foot landed a stride ahead of the stopped body and
    was pulled back under the hips, stopped dead as the stand began: 12.3-12.4 cm/frame^2
    against the walk's 4.9 (docs/evaluate.md, "A braking body shortens its steps")."""
    fps = 30.0
    frames = walk_frames + 90
    _, names, recorded, recorded_fps = _recorded(
        tmp_path, f'[[cue]]\nat = 0\nramp = {{ "style/feminine" = 1.0, gait = "walk" }}\n\n'
                  f'[[cue]]\nat = {walk_frames / fps!r}\nramp = {{ gait = "stand" }}\n',
        "--quiet", "--fps", repr(fps), "--seconds", repr(frames / fps))
    assert abs(recorded_fps - fps) < 1e-3 and len(recorded) == frames
    jumps = np.zeros(frames)  # each frame's largest joint velocity change, from the file alone
    jumps[2:] = np.linalg.norm(np.diff(recorded, 2, axis=0), axis=-1).max(axis=1)
    speed = _hips_speed(names, recorded, fps)
    assert speed[walk_frames - 30:walk_frames].mean() > 60.0 and speed[-30:].mean() < 2.0  # walked, then stood still
    assert jumps[walk_frames:walk_frames + 60].max() <= 1.25 * jumps[15:walk_frames].max()


@pytest.mark.parametrize("called_off", [0.5, 0.8])  # s after the walk cue: in the start's first step and its second
def test_a_recorded_start_called_off_brakes_without_a_jolt(tmp_path, called_off):
    """What a user gets of a start called off: a score that walks (feminine, whose stop popped
    hardest), stands, sets off and is told to stand again while it sets off, recorded by
    `instrument run --fast --bvh` and read back by the independent reader. The body brakes from
    the travel and stride it had reached (units.smoothstep_of): from the walk cue to the end no
    joint's velocity changes more in a frame than 1.25 times it does in the steady walk at the
    score's start, and it ends standing still. (Told to stand before its first step begins, at
    the stand's next step boundary, 0.3 s after the cue here, it never sets off.)"""
    fps = 30.0
    walk_cue = 6.0
    frames = int(round((walk_cue + 2.5) * fps))
    _, names, recorded, recorded_fps = _recorded(
        tmp_path, f'[[cue]]\nat = 0\nramp = {{ "style/feminine" = 1.0, gait = "walk" }}\n\n'
                  f'[[cue]]\nat = 3.0\nramp = {{ gait = "stand" }}\n\n'
                  f'[[cue]]\nat = {walk_cue!r}\nramp = {{ gait = "walk" }}\n\n'
                  f'[[cue]]\nat = {walk_cue + called_off!r}\nramp = {{ gait = "stand" }}\n',
        "--quiet", "--fps", repr(fps), "--seconds", repr(frames / fps))
    assert abs(recorded_fps - fps) < 1e-3 and len(recorded) == frames
    jumps = velocity_jumps(recorded)
    speed = _hips_speed(names, recorded, fps)
    cue = int(round(walk_cue * fps))
    assert speed[30:90].mean() > 60.0 and speed[cue - 30:cue].mean() < 2.0  # walked, then stood still before the cue
    assert speed[cue:].max() > 5.0  # it did set off
    assert speed[-15:].mean() < 2.0  # and ends standing still
    assert jumps[cue:].max() <= 1.25 * jumps[15:90].max()


@pytest.mark.parametrize("fps", [25, 60])
def test_a_stop_recorded_at_25_or_60_fps_closes_its_feet_and_stays_finite(tmp_path, fps):
    """A stand's closing step advances 1 / (0.4 s x fps) a frame; at 25 and 60 fps those sum to a
    hair under 1, and the frame after divided 0 by 0: the foot's held heading became NaN, and every
    frame after it (`run --fps 60 --bvh` wrote 567 of 751 frames, then failed 184; the OSC stream
    carried NaN; `evaluate --units` on a model trained at 60 fps died with a traceback)."""
    said, names, positions, recorded_fps = _recorded(
        tmp_path, '[[cue]]\nat = 0\nramp = { "style/normal" = 1.0, gait = "walk" }\n\n'
                  '[[cue]]\nat = 4.5\nramp = { gait = "stand" }\n\n[[cue]]\nat = 8.5\nramp = { gait = "walk" }\n\n'
                  '[[cue]]\nhold = 3\n', "--fps", str(fps))
    # (a pose not finite is held, not written: runtime/finite.py says so)
    assert "output errors" not in said and "poses held" not in said and "stopped after" in said, said
    assert len(positions) == int(round(11.5 * fps)) + 1 and np.isfinite(positions).all()
    hips = positions[:, names.index("Hips")]
    standing = slice(int(7.0 * fps), int(8.5 * fps))  # stood still, the closing step taken
    assert np.abs(np.diff(hips[standing][:, [0, 2]], axis=0)).max() * fps < 6.0  # cm/s: still
    moving = np.linalg.norm(hips[-1, [0, 2]] - hips[int(8.5 * fps), [0, 2]]) / 3.0
    assert moving > 50.0  # cm/s: and it walks on, not NaN, not stuck
