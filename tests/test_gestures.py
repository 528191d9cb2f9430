"""Gestures over the walk (issue 26): a wave or a raise of both hands, learnt from the standing
takes' phases, played by a second label stream over the gait's upper body, from every way a
value reaches the instrument.

The phases are found in the real takes; the shipped model holds both gestures; a wave started
while walking raises the hands above the head and lowers them, leaving the legs and the root
exactly as the walk without it; a hold repeats until released; `synth --gesture` writes one
(read back with an independent BVH reader); a surface's OSC press reaches the engine through a
real UDP socket, and the recorded log replays it; so does a score's tap.
"""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace

import numpy as np
import pytest

from bvh_independent import world_positions
from conftest import REPO
from oscrecv import Receiver, frame_count, free_port
from waiting import wait_until
from walks import finer

from instrument.control.state import ControlState
from instrument.errors import UserError
from instrument.models.gestures import gesture_labels
from instrument.models.hsmm import HSMM
from instrument.models.modelfile import load_model, save_model
from instrument.motion.bvh import read_bvh
from instrument.motion.features import choose_layout, resample
from instrument.motion.gestures import PHASES, gesture_phases, hand_tracks, turning_points
from instrument.synthesis.engine import Engine, default_controls
from instrument.synthesis.gestures import GestureLayer
from instrument.synthesis.interpolation import body_groups
from instrument.synthesis.parameters import GROUPS
from instrument.synthesis.stream import UNIT

MOTIONS = REPO.parent / "shared" / "data" / "bandai-motions"
needs_motions = pytest.mark.skipif(not MOTIONS.is_dir(), reason=f"gesture takes not found in {MOTIONS}")
RUN = [sys.executable, "-m", "instrument", "run"]


# ---- the phases of a take ------------------------------------------------------------------------

def test_turning_points_alternate_highs_and_lows_and_ignore_wobbles():
    t = np.arange(120)
    signal = np.sin(2 * np.pi * t / 24) + 0.05 * np.sin(2 * np.pi * t / 3)  # a sway with a small wobble on it
    points = turning_points(signal, 0.5)
    assert len(points) == 10  # a high at 6, then a turn every 12 frames: 6, 18, ..., 114
    assert np.abs(np.array(points) - (6 + 12 * np.arange(10))).max() <= 1
    assert all(np.sign(signal[a]) != np.sign(signal[b]) for a, b in zip(points, points[1:]))


@needs_motions
@pytest.mark.parametrize("name", ["dataset-2_wave-both-hands_youthful_001", "dataset-2_raise-up-both-hands_normal_002",
                                  # its hands reach the high band in 4 frames, then settle for 6 more: the
                                  # raise goes on while they rise (it was too short to keep, the settling a half)
                                  "dataset-2_raise-up-both-hands_active_001"])
def test_a_takes_phases_raise_repeat_and_lower_in_order(model, name):
    motion = resample(read_bvh(MOTIONS / f"{name}.bvh"), model.fps)
    phases = gesture_phases(motion, model.layout, model.states)
    labels = [s.label for s in phases]
    assert labels[0] == "raise" and labels[-1] == "lower"
    repeats = labels[1:-1]
    assert len(repeats) >= 2 and all(label.startswith("repeat") for label in repeats)  # an a and a b at least
    assert all(a != b for a, b in zip(repeats, repeats[1:]))  # a and b in turn, as the planner plays them
    assert all(a.end <= b.start for a, b in zip(phases, phases[1:]))
    heights = hand_tracks(motion, model.layout)[0]
    raise_, lower = phases[0], phases[-1]
    assert heights[raise_.end - 1] - heights[raise_.start] > 0.3  # leg lengths: the hands go up ...
    assert heights[lower.start] - heights[lower.end - 1] > 0.3  # ... and come down


def test_a_tap_plays_as_many_repeat_halves_as_the_takes_hold(model):
    """The half under way counts: a raise whose takes hold two halves plays a and b, then lowers."""
    for name, labels in gesture_labels(model.metadata).items():
        engine = Engine(model)
        controls = default_controls(model, {"normal": 1.0})
        played = []
        for k in range(int(20 * model.fps)):
            engine.next_features(replace(controls, gestures=(name,) if k == 30 else ()))
            played.append(engine.gestures.label[0] if engine.gestures.playing else -1)
        runs = [label for k, label in enumerate(played) if label in labels[2:] and (k == 0 or played[k - 1] != label)]
        repeats = model.metadata["gestures"][name]["repeats"]
        assert len(runs) == repeats + repeats % 2, (name, runs)  # a whole cycle: only a b goes on to the lower
        assert engine.gestures.started == 1 and played[-1] == -1  # over by itself


@needs_motions
def test_a_wave_sways_in_half_cycles_a_raise_holds(model):
    wave = gesture_phases(resample(read_bvh(MOTIONS / "dataset-2_wave-both-hands_feminine_001.bvh"), model.fps),
                          model.layout, model.states)
    halves = [s.frames for s in wave if s.label.startswith("repeat")]
    assert len(halves) >= 8 and 8 <= np.median(halves) <= 20  # a sway each 0.3 to 0.7 s


@needs_motions
@pytest.mark.parametrize("name", [
    # a hold of 2.4 s: six pieces of 0.4 s at 30 fps; counted in frames, five at 120
    "dataset-2_raise-up-both-hands_elderly_002",
    # a wave: a 0.12 s wobble after the raise was a half cycle at 120 fps (5 frames were 0.04 s there)
    "dataset-2_wave-both-hands_youthful_001",
])
def test_a_takes_phases_are_the_same_motion_at_100_and_120_fps(name):
    """The take at its own 30 fps and resampled (as `train --fps` reads it): the same phases, each
    cut between two frames within a 30 fps frame's time of the 30 fps cut. A frame k at `fps`
    stands for the time from (k - 0.5) / fps to (k + 0.5) / fps, so a cut before frame k is at
    (k - 0.5) / fps, at either rate. The layout is the take's own (any layout of its skeleton)."""
    take = read_bvh(MOTIONS / f"{name}.bvh")
    layout = choose_layout([take])
    reference = gesture_phases(take, layout)
    assert take.fps == 30 and len(reference) >= 4
    for fps in (100.0, 120.0):
        phases = gesture_phases(resample(take, fps), layout)
        assert [s.label for s in phases] == [s.label for s in reference], fps
        for ours, theirs in zip(phases, reference):
            for k, k30 in ((ours.start, theirs.start), (ours.end, theirs.end)):
                assert abs((k - 0.5) / fps - (k30 - 0.5) / take.fps) <= 1 / take.fps + 1e-9, (fps, ours, theirs)


# ---- the shipped model ------------------------------------------------------------------------

def test_the_shipped_model_holds_both_gestures_after_the_units(model):
    labels = gesture_labels(model.metadata)
    assert list(labels) == ["wave", "raise"]
    assert labels["wave"][0] == 2 * len(model.units)
    assert model.labels[labels["raise"][0]:] == [f"gesture/raise/{p}" for p in PHASES]
    assert all(g["repeats"] >= 2 for g in model.metadata["gestures"].values())


def test_a_model_without_gestures_loads_and_walks_as_before(model, tmp_path):
    """The shipped model with its gestures' labels and entry taken away: a model as issue 25 made them."""
    first = gesture_labels(model.metadata)["wave"][0]
    metadata = {k: v for k, v in model.metadata.items() if k != "gestures"} | {"labels": model.labels[:first]}
    def cut(h: HSMM) -> HSMM:  # the labels' axis: the third from the end of the means, the second of the durations
        return HSMM(h.means[..., :first, :, :], h.variances[..., :first, :, :], h.duration_means[..., :first, :],
                    h.duration_variances[..., :first, :])

    extras = {k: v[..., :first, :, :] if k.startswith("contact") else v for k, v in model.extras.items()}
    old = type(model)(metadata, cut(model.average), cut(model.styles), model.static_std, model.static_step_max, extras)
    save_model(tmp_path / "old.npz", old)
    loaded = load_model(tmp_path / "old.npz")
    engine = Engine(loaded)
    controls = default_controls(loaded, {"normal": 1.0}, gestures=("wave",))
    frames = [engine.next_features(controls) for _ in range(40)]
    assert engine.gestures.names == [] and np.isfinite(frames).all()


def test_a_model_whose_gestures_entry_does_not_fit_its_labels_is_one_line(model, tmp_path):
    broken = replace(model, metadata=model.metadata | {"gestures": {"wave": {"first": 3, "repeats": 2}}})
    save_model(tmp_path / "broken.npz", broken)
    with pytest.raises(UserError, match=r"broken\.npz: metadata 'gestures'"):
        load_model(tmp_path / "broken.npz")


# ---- the layer ------------------------------------------------------------------------------

def walk(model, weights, seconds, presses, gait: int = 1):
    """Static features of character 0, frame by frame, with each gesture held over its (from, to) seconds."""
    engine = Engine(model)
    controls = default_controls(model, weights, gait=gait)
    frames, shares = [], []
    for k in range(int(seconds * model.fps)):
        held = tuple(name for name, (a, b) in presses.items() if a <= k / model.fps < b)
        frames.append(engine.next_features(replace(controls, gestures=held))[0])
        shares.append(engine.gestures.weights[0] if engine.gestures.playing else 0.0)
    return np.array(frames), np.array(shares), engine


def hands_over_head(model, static):
    """The hands' height above the head's top joint (model units), frame by frame, through the
    model's own posing (the same pose an output sends)."""
    from instrument.evaluation.gestures import Body
    from instrument.synthesis.posing import CrowdPoses

    body = Body(model)
    poses = CrowdPoses(model.layout, model.fps, 1, None)
    heights = []
    for frame in static:
        positions = poses.next(frame[None], None, None).world_positions[0]
        heights.append(positions[body.hands, 1].max() - positions[body.head, 1])
    return np.array(heights)


@pytest.mark.parametrize("spread", [0.0, 0.6])  # the shared tables as they are, and each character's own put together
def test_a_stream_of_some_dimensions_makes_them_as_the_whole_stream_does(model, spread):
    """The gesture's stream solves only the upper body's range of dimensions, from the full tables."""
    from instrument.synthesis.stream import Crowd

    engine = Engine(model, 3)
    engine.retune(default_controls(model, {"elderly": 1.0, "youthful": 0.5}, liveliness=0.5), spread)
    columns = engine.gestures.solved
    assert 0 < columns.start and columns.stop < model.layout.dimension  # a range inside: an offset to get right
    whole, part = (Crowd(engine.space, 3, seeds=[4, 5, 6], columns=c) for c in (None, columns))
    for crowd in (whole, part):
        crowd.tables = engine.stream.tables
        crowd.tune(engine.features[0].duration_means, engine.features[0].duration_variances, 1.0, None, 0.5)
    for _ in range(60):
        a, b = whole.step(), part.step()
        assert b.shape == (3, columns.stop - columns.start)
        np.testing.assert_allclose(b, a[:, columns], rtol=0, atol=1e-12)


@pytest.mark.parametrize("spread", [0.0, 0.6])
def test_the_gaits_solve_makes_the_gestures_frame_as_the_gestures_own_stream_does(model, spread):
    """While a gesture has every character's whole upper body the gait's solve makes its frame
    (one solve a frame): the same frames as the gesture's own stream, to rounding."""
    engines = [Engine(model, 3) for _ in range(2)]
    engines[1].gestures.whole_range = False  # never hosted: its own stream all along
    controls = default_controls(model, {"youthful": 1.0, "elderly": 0.5}, liveliness=0.5)
    hosted, frames = 0, [[], []]
    for k in range(200):
        held = ("wave",) if 30 <= k < 120 else ()
        for engine, made in zip(engines, frames):
            made.append(engine.next_features(replace(controls, gestures=held), spread))
        hosted += engines[0].gestures.host is not None
        assert engines[1].gestures.host is None
        if hosted and engines[0].gestures.weights.min() < 1.0:
            break  # from the ease out on, the gait's arms differ (they went on from the gesture's frames)
    assert hosted > 50
    np.testing.assert_allclose(np.array(frames[0][:-1]), np.array(frames[1][:-1]), rtol=0, atol=1e-12)


def test_the_hosted_rows_cache_makes_the_frames_the_rows_put_together_each_frame_make(model, monkeypatch):
    """The gait's stream keeps a plain character's hosted (gait state, gesture state) rows while
    its tables stay (stream.py `_gather_pairs`): the frames are those of the rows put together
    every frame, to the bit, through a style change while the gesture plays (its rows are the
    new tables') and with a cache so small it is emptied and filled again all along."""
    import instrument.synthesis.stream as stream

    controls = default_controls(model, {"youthful": 1.0})
    changed = default_controls(model, {"elderly": 1.0, "feminine": 0.5})
    made = []
    for slots in (0, 100, stream.PAIR_SLOTS):  # none (every row put together each frame), a small one, the shipped one
        monkeypatch.setattr(stream, "PAIR_SLOTS", slots)
        engine, frames, hosted = Engine(model), [], 0
        for k in range(260):
            mix = controls if k < 150 else changed
            frames.append(engine.next_features(replace(mix, gestures=("wave",) if 20 <= k < 220 else ())))
            hosted += engine.gestures.host is not None
        assert hosted > 150 and len(engine.stream._pairs[0]) == slots + 3
        made.append(np.array(frames))
    assert np.array_equal(made[0], made[1]) and np.array_equal(made[0], made[2])


class PlainGestures(GestureLayer):
    """The gesture stage restated plainly, the reference of the compiled one: the gesture's own
    stream stepped every frame, the units, the half cycles and the ease in Python, the blend in
    numpy. While the compiled stage has the gait's solve make the gesture's frame (every weight
    1, none lowering: `hosted` here), the gait's last frames of the upper body are the gesture's,
    so its upper body goes on from them when handed back: here they are put there after its step."""

    hosted = False

    def begin(self, held, gait):
        held = set(held)
        if self.playing in self.held - held:  # let go: during the raise it was a tap
            self.tapped = self.label == self.first + 1
        pressed, self.held = sorted((held - self.held) & set(self.labels)), held
        if pressed and self.playing is None:
            self._start(pressed[0])
        self.blending, self.gait = self.playing is not None, gait
        if not self.blending:
            return
        crowd, first = self.crowd, self.first
        for n in range(crowd.count):  # the unit the plan goes on in: the repeat's while it repeats
            going_on = self.playing in held or (self.tapped[n] and self.done[n] + 1 < self._repeats)
            phase = min(max(self.label[n] - first, -1), 4) + 1
            crowd.counters[n, UNIT] = self._next_units[0 if going_on else 1, phase]
        could_host = self.whole and gait is not None and crowd.sent >= 2 and gait.sent >= 2
        self.gesture = crowd.step()
        playing, whole = False, True
        for n in range(crowd.count):
            here = crowd.history_ids[n, 1] // crowd.space.states
            if here != self.label[n] and here in (first + 2, first + 3) and self.label[n] != first + 1:
                self.done[n] += 1  # a repeat half finished
            self.label[n] = here
            inside = first <= here <= first + 3
            self.ease[n] = min(max(self.ease[n] + (self.rise if inside else -self.fall), 0.0), 1.0)
            self.weights[n] = self.ease[n] * self.ease[n] * (3.0 - 2.0 * self.ease[n])
            playing = playing or inside or self.ease[n] > 0.0
            whole = whole and self.weights[n] == 1.0 and here != first
        self.whole, self.hosted = whole, could_host and whole
        if not playing:
            self.playing = None

    def after(self, frames, ids):
        if self.blending:
            if self.hosted:
                self.gait.history[:, 1, self.solved] = self.gesture
            mine = frames[:, self.columns]
            frames[:, self.columns] = mine + self.weights[:, None] * (self.gesture[:, self.columns - self.solved.start] - mine)
        self.shown[:, 0], self.shown_ids[:, 0] = self.shown[:, 1], self.shown_ids[:, 1]
        self.shown[:, 1], self.shown_ids[:, 1] = frames[:, self.solved], ids
        self.seen = min(self.seen + 1, 2)
        return frames


@pytest.mark.parametrize("characters, spread, liveliness", [(1, 0.0, 0.0), (4, 0.6, 0.4)])
def test_a_wave_poses_as_the_plain_restatement_of_the_gesture_stage_makes_them(model, characters, spread, liveliness):
    """The engine's poses over whole gestures (a wave held, let go, lowered and eased out; a raise
    tapped), one character and a crowd in its own style mixes, are those the gesture stage
    restated plainly makes (`PlainGestures`), to rounding: the compiled stage, and the gait's solve
    making the gesture's frame, change nothing the characters do."""
    controls = default_controls(model, {"youthful": 1.0, "elderly": 0.5}, liveliness=liveliness)
    runs = []
    for plain in (False, True):
        engine = Engine(model, characters)
        if plain:
            engine.gestures = engine.gesture_tables.layer = PlainGestures(model, engine.space, characters,
                                                                         engine.stream.lookahead, engine.cast.seeds)
        poses, hosted, playing = [], 0, 0
        for k in range(330):
            held = ("wave",) if 20 <= k < 110 else ("raise",) if k == 200 else ()
            pose = engine.frame(k / model.fps, replace(controls, gestures=held), spread)
            poses.append(np.concatenate([pose.world_positions.ravel(), pose.rotations.ravel()]))
            hosted += engine.gestures.host is not None
            playing += engine.gestures.playing is not None
        assert engine.gestures.started == 2 and engine.gestures.playing is None  # both over by themselves
        runs.append((np.array(poses), hosted, playing))
    (made, hosted, playing), (restated, _, played) = runs
    assert hosted > 60 and playing == played > 200  # the gait's solve made many of the gestures' frames
    np.testing.assert_allclose(made, restated, rtol=0, atol=1e-12)


def test_a_wave_while_walking_raises_the_hands_over_the_head_and_leaves_the_legs_alone(model):
    with_wave, shares, engine = walk(model, {"youthful": 1.0}, 12, {"wave": (2.0, 2.1)})
    plain, _, _ = walk(model, {"youthful": 1.0}, 12, {})
    upper = body_groups(model.layout)[GROUPS.index("upper")]
    assert np.array_equal(with_wave[:, ~upper], plain[:, ~upper])  # legs and root: the walk's, to the bit
    playing = np.flatnonzero(shares > 0)
    assert playing[0] == 60 and shares[playing[-1]] < 1.0  # from the press, and eased out at the end
    assert shares[60] < 0.2 and np.diff(shares[60:66]).min() > 0  # eased in, not switched
    assert not np.allclose(with_wave[60:200][:, upper], plain[60:200][:, upper], atol=1e-3)
    # after the ease out the arms go on from where they were seen (the gait's upper body, left to the
    # gesture's stream while it had all of it, restarts at the lower from the gesture's frames): no
    # jump, and back in the walk's swing within 2 s
    end = playing[-1] + 1
    assert end + 60 < len(shares)
    steps = np.abs(np.diff(with_wave[end - 13:, upper], axis=0)).max(axis=0)
    assert (steps <= 1.25 * np.abs(np.diff(plain[:, upper], axis=0)).max(axis=0)).all()
    assert np.abs(with_wave[end + 60:, upper] - plain[end + 60:, upper]).max() < 0.02
    assert engine.gestures.started == 1 and engine.gestures.playing is None  # over by itself
    over = hands_over_head(model, with_wave)
    assert over[:60].max() < 0  # walking: the hands below the head
    assert over[60:180].max() > 0  # both hands above the head within 4 s of the press
    assert over[playing[-1]:].max() < 0  # and lowered after


def test_holding_a_gesture_repeats_it_until_released(model):
    tap = walk(model, {"normal": 1.0}, 20, {"raise": (1.0, 1.05)})[1]
    held = walk(model, {"normal": 1.0}, 20, {"raise": (1.0, 12.0)})[1]
    tap_frames, held_frames = np.flatnonzero(tap > 0), np.flatnonzero(held > 0)
    assert held_frames[-1] > 12.0 * model.fps  # lowered only after the release ...
    assert held_frames[-1] < 16.0 * model.fps  # ... and soon after it
    assert tap_frames[-1] < held_frames[-1] - 3 * model.fps
    tap = walk(model, {"normal": 1.0}, 14, {"wave": (1.0, 1.05)})[1]
    short = walk(model, {"normal": 1.0}, 14, {"wave": (1.0, 2.5)})[1]  # let go once the hands are up: it lowers
    assert np.flatnonzero(short > 0)[-1] < 4.5 * model.fps < np.flatnonzero(tap > 0)[-1]


def test_a_gesture_eases_in_and_out_over_the_same_seconds_at_any_rate(model):
    """The shipped model and its twin at 120 fps (every state four times as many frames: the same
    walk in seconds) hand the upper body to a wave and back over the same times: the ease is a
    time. Counted in frames (6 and 12) it took a quarter as long at 120 fps."""
    fine = finer(model, 4)
    eases = []
    for m in (model, fine):
        shares = walk(m, {"normal": 1.0}, 9, {"wave": (1.0, 1.05)})[1]  # the wave lowered by 8 s
        whole = np.flatnonzero(shares == 1.0)
        rising = np.count_nonzero((shares[: whole[0]] > 0) & (shares[: whole[0]] < 1))
        falling = np.count_nonzero((shares[whole[-1]:] > 0) & (shares[whole[-1]:] < 1))
        eases.append(np.array([rising + 1, falling + 1]) / m.fps)  # frames to go from 0 to 1 and back, in seconds
    np.testing.assert_allclose(eases[1], eases[0], rtol=1e-9)
    assert eases[0][1] > eases[0][0] > 0  # it hands the arms back more slowly than it takes them


def test_a_gesture_while_standing_and_running_keeps_the_feet_to_the_gait(model):
    for gait in (0, 2):
        with_wave, shares, _ = walk(model, {"masculine": 1.0}, 6, {"wave": (1.0, 1.1)}, gait=gait)
        plain = walk(model, {"masculine": 1.0}, 6, {}, gait=gait)[0]
        upper = body_groups(model.layout)[GROUPS.index("upper")]
        assert shares.max() == 1.0 and np.array_equal(with_wave[:, ~upper], plain[:, ~upper])


def test_a_crowd_gestures_at_once_each_character_in_its_own_style_mix(model):
    upper = body_groups(model.layout)[GROUPS.index("upper")]
    controls = default_controls(model, {"elderly": 1.0})
    runs = []
    for presses in ((), (30,)):
        engine, frames, shares = Engine(model, characters=4), [], []
        for k in range(240):
            frames.append(engine.next_features(replace(controls, gestures=("raise",) if k in presses else ()), 1.0))
            shares.append(engine.gestures.weights.copy() if engine.gestures.playing else np.zeros(4))
        runs.append((np.array(frames), np.array(shares)))
    (plain, _), (raised, shares) = runs
    assert (shares.max(axis=0) == 1.0).all()  # every character raised its hands ...
    assert len(set((shares > 0).sum(axis=0))) > 1  # ... for as long as its own style's durations say
    assert np.array_equal(raised[..., ~upper], plain[..., ~upper])


def test_a_crowd_cut_into_parts_on_the_cores_gestures_as_one_part_does(model, monkeypatch):
    """A crowd's stream cut into one part per core (cores.py; each part's solve on a thread of its
    own) makes a held wave, the gait's solve making the gesture's frames, as the crowd in one part
    does: the same frames to the bit (the gesture's plan is the whole crowd's, made before the parts)."""
    from instrument.synthesis import stream

    controls = default_controls(model, {"active": 1.0, "feminine": 0.5}, liveliness=0.3)
    runs = []
    for cut in (lambda count, least=None: [(0, count // 2), (count // 2, count)], lambda count, least=None: [(0, count)]):
        monkeypatch.setattr(stream, "parts", cut)
        engine, frames, hosted = Engine(model, 6), [], 0
        for k in range(150):
            frames.append(engine.next_features(replace(controls, gestures=("wave",) if 20 <= k < 100 else ()), 0.7))
            hosted += engine.gestures.host is not None
        assert hosted > 40 and engine.gestures.started == 1
        runs.append(np.array(frames))
    assert np.array_equal(*runs)


def test_a_gesture_the_model_lacks_or_a_second_press_while_one_plays_changes_nothing(model):
    engine = Engine(model)
    controls = default_controls(model, {"normal": 1.0})
    for k in range(90):
        held = ("wave",) if 10 <= k < 12 else ("raise", "wave") if 30 <= k < 32 else ()
        engine.next_features(replace(controls, gestures=held))
    assert engine.gestures.started == 1


# ---- control --------------------------------------------------------------------------------

def test_the_control_state_holds_a_gesture_while_pressed(model):
    state = ControlState(model.style_names, model.states)
    assert state.set("gesture/wave", 1.0) and state.snapshot().gestures == ("wave",)
    assert state.set("gesture/wave", 0.0) and state.snapshot().gestures == ()
    assert not state.set("gesture/dance", 1.0) and state.problem("gesture/dance", 1.0) == "unknown target"
    assert state.problem("gesture/wave", 2.0) is not None


def test_the_shipped_mappings_press_gestures():
    from instrument.control.mapping import load_mapping

    found = {}
    for path in sorted((REPO / "mappings").glob("*.toml")):
        mapping = load_mapping(path)
        found[path.stem] = {c.target for c in mapping.controls if c.target.startswith("gesture/")}
        assert all(c.mode == "momentary" for c in mapping.controls if c.target.startswith("gesture/"))
    pads = [name for name, targets in found.items() if targets == {"gesture/wave", "gesture/raise"}]
    assert {"akai-midimix", "korg-nanokontrol2", "sony-dualshock4", "xbox-wireless-bluetooth", "generic-gamepad"} <= set(pads)


def test_bench_times_a_frame_while_a_gesture_plays(model):
    """`instrument bench`'s gesture figures: each work timed against the yardstick, the gesture held
    all along (measure_gesture checks it never lowered)."""
    from instrument.cli.benchmarks import measure_gesture
    from instrument.synthesis.stream import Controls

    solved = []
    figures = measure_gesture(model, Controls(np.full(len(model.style_names), 0.2)), 2, lambda: solved.append(1))
    assert figures["gesture_name"] == "wave" and len(solved) == 2 + 1  # two turns and the warm-up
    for work in ("gesture_stream", "gesture_stage", "gesture_engine", "engine"):
        assert figures[f"{work}_us_per_frame"] > 0 and figures[f"{work}_to_window_solve"] > 0


@pytest.mark.parametrize("name,channel,notes", [
    # what the surfaces send for the buttons the files name, from the makers' MIDI tables: the X-Touch
    # Mini's layer A top row (notes 8-15 on its global channel, 11), the Launch Control XL's track focus
    # buttons 1-2 (notes 41, 42 on factory template 1's channel, 9)
    ("behringer-x-touch-mini", 11, (8, 9)),
    ("novation-launch-control-xl", 9, (41, 42)),
])
def test_a_surfaces_own_pad_message_presses_its_gesture(model, name, channel, notes):
    from conftest import play_mapped
    from instrument.control.events import ControlEvent
    from instrument.control.mapping import Mapper, load_mapping

    state = ControlState(model.style_names, model.states)
    mapper = Mapper(load_mapping(REPO / "mappings" / f"{name}.toml", state))
    for gesture, note in zip(("wave", "raise"), notes):
        assert play_mapped(mapper, state, ControlEvent(0.0, f"midi:{name}", f"note/{channel}/{note}", 127))
        assert state.snapshot().gestures == (gesture,)
        assert play_mapped(mapper, state, ControlEvent(0.1, f"midi:{name}", f"note/{channel}/{note}", 0))
        assert state.snapshot().gestures == ()


def test_synth_writes_a_wave_and_refuses_an_unknown_gesture_in_one_line(model, tmp_path):
    out = tmp_path / "wave.bvh"
    result = subprocess.run([sys.executable, "-m", "instrument", "synth", "--style", "active=1", "--gesture", "wave@1",
                             "--seconds", "6", "--out", str(out)], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    names, positions, _ = world_positions(out)
    hands = [names.index(n) for n in ("Hand_R", "Hand_L")]
    head = names.index("Head")
    over = positions[:, hands, 1].max(axis=1) - positions[:, head, 1]
    assert over[:30].max() < 0 < over[30:150].max()  # below the head before the press, above it after
    bad = subprocess.run([sys.executable, "-m", "instrument", "synth", "--gesture", "dance@1", "--out",
                          str(tmp_path / "x.bvh")], capture_output=True, text=True, timeout=120)
    assert bad.returncode != 0 and len(bad.stderr.strip().splitlines()) == 1 and "dance" in bad.stderr
    assert not (tmp_path / "x.bvh").exists()


def test_an_osc_press_reaches_the_engine_and_the_recorded_log_replays_it(tmp_path):
    """Real UDP both ways: a surface holds /walk/gesture/wave; the flat stream's hands (in the
    frames sent) go up, and the recorded take replays byte for byte."""
    from pythonosc.udp_client import SimpleUDPClient

    log, live, replayed = tmp_path / "take.jsonl", tmp_path / "live.bvh", tmp_path / "replayed.bvh"
    control_port, receiver = free_port(), Receiver()
    process = subprocess.Popen(RUN + ["--osc-in", str(control_port), "--osc", f"127.0.0.1:{receiver.port}/flat",
                                      "--seconds", "10", "--quiet", "--record", str(log), "--bvh", str(live)],
                               stderr=subprocess.PIPE, text=True)
    surface = SimpleUDPClient("127.0.0.1", control_port)
    try:
        wait_until(lambda: frame_count(receiver) >= 15, "15 frames")
        surface.send_message("/walk/gesture/wave", 1.0)
        wait_until(lambda: any(a == "/walk/frame" for a, _ in receiver.messages()[-3:]) and _pressed(log), "the press recorded",
                   timeout=60)
        surface.send_message("/walk/gesture/wave", 0.0)
        stderr = process.communicate(timeout=120)[1]
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
        receiver.close()
    assert process.returncode == 0, stderr
    events = [json.loads(line) for line in log.read_text().splitlines()[1:-1]]  # the last line: where the run stopped
    assert [(e["control"], e["value"]) for e in events if e["control"].startswith("gesture")] == [("gesture/wave", 1.0),
                                                                                             ("gesture/wave", 0.0)]
    names, positions, _ = world_positions(live)
    over = positions[:, [names.index("Hand_R"), names.index("Hand_L")], 1].max(axis=1) - positions[:, names.index("Head"), 1]
    pressed_at = int(round(events[[e["control"] for e in events].index("gesture/wave")]["t"] * 30))
    assert over[:pressed_at].max() < 0 < over[pressed_at:].max()
    replay = subprocess.run(RUN + ["--replay", str(log), "--fast", "--no-osc", "--quiet", "--seconds", "10", "--bvh",
                                   str(replayed)], capture_output=True, text=True, timeout=120)
    assert replay.returncode == 0, replay.stderr
    assert live.read_bytes() == replayed.read_bytes()


def test_a_scores_cue_taps_a_gesture_and_the_recorded_log_replays_it(tmp_path):
    """A score's cues press the wave at 1 s and let go 0.1 s later (docs/scores.md): the BVH `run
    --score --fast` writes (read back independently) has the hands over the head only after the
    press, the recording holds the press and the release at the cues' times, and replays the same
    frames byte for byte."""
    score, log = tmp_path / "wave.toml", tmp_path / "take.jsonl"
    score.write_text('[[cue]]\nat = 1\nramp = { "gesture/wave" = 1 }\n\n[[cue]]\nafter = 0.1\nramp = { "gesture/wave" = 0 }\n')
    walks = {name: tmp_path / f"{name}.bvh" for name in ("scored", "replayed")}
    for name, source in (("scored", ["--score", str(score), "--record", str(log)]), ("replayed", ["--replay", str(log)])):
        result = subprocess.run(RUN + source + ["--fast", "--no-osc", "--quiet", "--seconds", "6", "--bvh", str(walks[name])],
                                capture_output=True, text=True, timeout=120)
        assert result.returncode == 0, result.stderr
    events = [json.loads(line) for line in log.read_text().splitlines()[1:-1]]  # the last line: where the run stopped
    assert [(e["control"], e["value"]) for e in events] == [("gesture/wave", 1.0), ("gesture/wave", 0.0)]
    assert [e["t"] for e in events] == pytest.approx([1.0, 1.1])
    names, positions, _ = world_positions(walks["scored"])
    over = positions[:, [names.index("Hand_R"), names.index("Hand_L")], 1].max(axis=1) - positions[:, names.index("Head"), 1]
    assert over[:30].max() < 0 < over[30:].max()
    assert walks["scored"].read_bytes() == walks["replayed"].read_bytes()


def _pressed(log) -> bool:
    try:
        return any(json.loads(line).get("control") == "gesture/wave" for line in log.read_text().splitlines()[1:])
    except (OSError, ValueError):
        return False


def test_evaluate_reports_each_gesture_and_the_walk_it_rides_on(tmp_path):
    result = subprocess.run([sys.executable, "-m", "instrument", "evaluate", "--styles", "youthful", "elderly", "--variants",
                             "one", "--seconds", "10", "--gestures", "--json"], capture_output=True, text=True, timeout=600)
    assert result.returncode == 0, result.stderr
    figures = json.loads(result.stdout)["gestures"]["synth"]
    assert set(figures) == {f"{g} {s}" for g in ("wave", "raise") for s in ("elderly", "youthful")}
    assert figures["wave youthful"]["over_head_cm"] > 10 > -10 > figures["wave elderly"]["over_head_cm"]
    assert all(f["speed_ratio"] == 1.0 and f["skate_ratio"] == 1.0 for f in figures.values())  # the gait's legs, untouched
    for style in ("elderly", "youthful"):  # as in the takes, a raise is over sooner than a wave
        assert 1.0 < figures[f"raise {style}"]["duration_s"] < figures[f"wave {style}"]["duration_s"]
