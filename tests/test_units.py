"""Motion units: stand, walk, run and turns as labels the planner chooses (issue 25).

Training reads which unit a take holds from its name or a manifest; the shipped model holds all
five units; the gait and the steering choose them live, at the next step boundary, through the
one engine (so `run`, `synth` and crowds get them alike); `synth --gait` writes them, read back
with an independent BVH reader.
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from bvh_independent import world_positions
from conftest import REPO, needs_walks, walk_only

from instrument.errors import UserError
from instrument.motion.bvh import read_bvh
from instrument.motion.standing import standing_steps, still_frames
from instrument.synthesis.engine import Engine, default_controls
from instrument.synthesis.stream import LABEL, STATE, UNIT, Controls
from instrument.synthesis.units import STOP_SECONDS
from instrument.training.corpus import TakeFile, load_corpus, read_manifest, styled_takes
from instrument.training.units import unit_from_name

MOTIONS = REPO.parent / "shared" / "data" / "bandai-motions"
needs_motions = pytest.mark.skipif(not MOTIONS.is_dir(), reason=f"runs, turns and standing takes not found in {MOTIONS}")


# ---- which unit a take holds -------------------------------------------------------------------

@pytest.mark.parametrize("name, unit", [
    ("dataset-2_walk_elderly_003", "walk"),
    ("dataset-2_run_active_012", "run"),
    ("dataset-2_walk-turn-left_normal_001", "turn-left"),
    ("dataset-2_walk-turn-right_youthful_008", "turn-right"),
    ("dataset-2_wave-both-hands_feminine_002", "stand"),
    ("dataset-2_raise-up-both-hands_masculine_004", "stand"),
    ("walk_not-confident_001", "walk"),
    ("style2_take3", "walk"),  # a name that says nothing is a walk, as every corpus before units
    ("01_01", "walk"),
    ("me_WalkTurnLeft_proud_1", "turn-left"),  # a word starts at a capital
    ("me_Running_proud_1", "run"),
    ("me_forest-walk_proud_1", "walk"),  # "rest" inside a word is none: it was a stand
    ("me_walk-brunch_proud_1", "walk"),  # "run" inside a word: it was a run
    ("me_praise-walk_proud_1", "walk"),  # "raise" inside a word: it was a stand
    ("me_WALKTURNLEFT_proud_1", "turn-left"),  # one case throughout shows no word's start: a joined
    ("me_walkturnright_proud_1", "turn-right"),  # turn's words are found anywhere (they read as walks)
])
def test_the_unit_is_read_from_the_file_name(name, unit):
    assert unit_from_name(Path(name + ".bvh")) == unit


def test_a_name_whose_letters_lower_to_two_is_read_where_its_words_are():
    """`İ` lower-cases to two characters: positions found in the lowered name were read back in
    the name a character off, and a name of several (through `train --unit-from`) raised IndexError."""
    from instrument.models.units import named_by_words
    from instrument.training.units import UNIT_WORDS

    assert named_by_words("İİİİ_walk", UNIT_WORDS) == "walk"
    assert named_by_words("İİİİxwalk", UNIT_WORDS) is None
    assert named_by_words("İstanbul-Run", UNIT_WORDS) == "run"


def test_unit_from_a_pattern_that_finds_no_unit_names_the_file():
    with pytest.raises(UserError, match=r"take_7\.bvh: --unit-from found 'take', not a unit"):
        unit_from_name(Path("take_7.bvh"), r"^([a-z]+)_")


def test_unit_from_reads_a_standing_takes_gesture_where_it_reads_its_unit(tmp_path):
    """A studio's own names (`actorB_Active_IdleWave01.bvh`, trained with `--unit-from
    '_([A-Za-z]+?)[0-9]+$'`): the stand was read from --unit-from's group but its gesture from the
    default part before the style (`actorB`), so the model trained no gesture, and said nothing."""
    for name in ("actorB_Active_IdleWave01", "actorB_Active_IdleRaise01", "actorB_Active_Idle01", "actorB_Active_Jog01"):
        (tmp_path / f"{name}.bvh").touch()
    takes = styled_takes([tmp_path], r"actorB_([A-Za-z]+)_", r"_([A-Za-z]+?)[0-9]+$")
    assert sorted((t.path.stem, t.unit, t.gesture) for t in takes) == [
        ("actorB_Active_Idle01", "stand", ""), ("actorB_Active_IdleRaise01", "stand", "raise"),
        ("actorB_Active_IdleWave01", "stand", "wave"), ("actorB_Active_Jog01", "run", "")]
    # without --unit-from, the part before the style says both, as before
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "dataset-2_wave-both-hands_active_001.bvh").touch()
    assert [(t.unit, t.gesture) for t in styled_takes([tmp_path / "x"])] == [("stand", "wave")]


@pytest.mark.parametrize("name, said", [
    ("actorB_Active_Jog01", "'Jog01' says run"),  # a studio's scheme: the unit after the style
    ("actorB_Active_IdleWave01", "'IdleWave01' says stand"),
    ("actorB_Active_WalkTurnLeft01", "'WalkTurnLeft01' says turn-left"),
    ("actorB_Active_Walk01", None), ("dataset-2_walk_elderly_003", None), ("style2_take3", None),
    ("me_forest-walk_proud_1", None),  # a word inside a word is none, as for the unit itself
])
def test_a_unit_the_default_reading_does_not_look_for_is_found(name, said):
    """By default the unit is the part before the style: `actorB_Active_Jog01` trained as a walk,
    and train said only `units: walk` (train and inspect now warn, naming the part)."""
    from instrument.training.units import unit_said_elsewhere

    assert unit_from_name(Path(name + ".bvh")) == "walk"
    assert unit_said_elsewhere(Path(name + ".bvh")) == said


def test_a_manifest_says_each_takes_unit_and_a_bad_one_names_its_line(tmp_path):
    for take in ("a.bvh", "b.bvh", "c.bvh"):  # the takes named are there (a missing one is refused at its line)
        (tmp_path / take).touch()
    (tmp_path / "m.csv").write_text("file,style,unit\na.bvh,calm,run\nb.bvh,calm,\nc.bvh,calm,stand\n")
    takes = read_manifest(tmp_path / "m.csv")
    assert [t.unit for t in takes] == ["run", "walk", "stand"]
    (tmp_path / "bad.csv").write_text("file,style,unit\na.bvh,calm,run\nb.bvh,calm,hop\n")
    with pytest.raises(UserError, match=r"bad\.csv:3: unit 'hop' is not one of walk, run"):
        read_manifest(tmp_path / "bad.csv")
    (tmp_path / "m.toml").write_text('[[take]]\nfile = "a.bvh"\nstyle = "calm"\nunit = "turn-left"\n'
                                     '[[take]]\nfile = "b.bvh"\nstyle = "calm"\n')
    assert [t.unit for t in read_manifest(tmp_path / "m.toml")] == ["turn-left", "walk"]


def test_a_manifest_unit_left_empty_is_a_walk_in_csv_and_toml_alike(tmp_path):
    """A CSV's blank unit field was a walk, a TOML take's `unit = ""` refused (docs/training.md said
    both were walks): left empty, it is a walk in both, and a gesture given it says so."""
    for take in ("a.bvh", "b.bvh"):
        (tmp_path / take).touch()
    (tmp_path / "m.csv").write_text("file,style,unit\na.bvh,calm,\nb.bvh,calm, \n")
    (tmp_path / "m.toml").write_text('[[take]]\nfile = "a.bvh"\nstyle = "calm"\nunit = ""\n'
                                     '[[take]]\nfile = "b.bvh"\nstyle = "calm"\nunit = " "\n')
    for name in ("m.csv", "m.toml"):
        assert [t.unit for t in read_manifest(tmp_path / name)] == ["walk", "walk"], name
    (tmp_path / "m.toml").write_text('[[take]]\nfile = "a.bvh"\nstyle = "calm"\nunit = ""\ngesture = "wave"\n')
    with pytest.raises(UserError) as refused:
        read_manifest(tmp_path / "m.toml")
    assert str(refused.value).startswith(f"{tmp_path / 'm.toml'}:5: take 1: gesture 'wave' given to a walk take "
                                         "(no unit given: a walk)"), refused.value


def test_a_manifest_says_a_standing_takes_gesture_and_a_bad_one_names_its_line(tmp_path):
    """A take whose name says nothing (`take007.bvh`) trained its stand but no gesture: the
    manifest's fourth column (a [[take]]'s `gesture`) says it; left empty, the name says it."""
    for take in ("a.bvh", "b.bvh", "c.bvh"):
        (tmp_path / take).touch()
    (tmp_path / "m.csv").write_text("file,style,unit,gesture\na.bvh,calm,stand,wave\nb.bvh,calm,stand,\nc.bvh,calm,run,\n")
    assert [(t.unit, t.gesture) for t in read_manifest(tmp_path / "m.csv")] == [("stand", "wave"), ("stand", ""), ("run", "")]
    (tmp_path / "m.toml").write_text('[[take]]\nfile = "a.bvh"\nstyle = "calm"\nunit = "stand"\ngesture = "Raise"\n')
    assert read_manifest(tmp_path / "m.toml")[0].gesture == "raise"
    for text, said in (("a.bvh,calm,stand,hop\n", ":2: gesture 'hop' is not one of wave, raise"),
                       ("a.bvh,calm,stand,waves\n", ":2: gesture 'waves' is not one of wave, raise"),  # read by words: a wave
                       ("a.bvh,calm,stand,hands-up\n", ":2: gesture 'hands-up' is not one of wave, raise"),
                       ("b.bvh,calm,stand,wave\na.bvh,calm,run,wave\n", ":3: gesture 'wave' given to a run take:"),
                       ("a.bvh,calm,,wave\n", ":2: gesture 'wave' given to a walk take (no unit given: a walk):")):
        (tmp_path / "bad.csv").write_text("file,style,unit,gesture\n" + text)
        with pytest.raises(UserError) as refused:
            read_manifest(tmp_path / "bad.csv")
        assert str(refused.value).startswith(f"{tmp_path / 'bad.csv'}{said}"), refused.value


@pytest.mark.parametrize("unit", ["runn", "jog", "Running", "walk-turn-left", "turnleft", "rest"])
def test_a_manifest_unit_is_one_of_the_units_not_a_word_for_one(tmp_path, unit):
    """A manifest's `unit` was read by its words as a file name is (`runn` a run, `rest` a stand):
    a name is guessed from, but a manifest is the user's word, so a unit not in the table of units
    is refused at its line (a TOML take's `unit` key's line), naming the units it may be."""
    for take in ("a.bvh", "b.bvh"):
        (tmp_path / take).touch()
    units = "walk, run, turn-left, turn-right, stand"
    (tmp_path / "m.csv").write_text(f"file,style,unit\na.bvh,calm,walk\nb.bvh,calm,{unit}\n")
    with pytest.raises(UserError) as refused:
        read_manifest(tmp_path / "m.csv")
    assert str(refused.value) == f"{tmp_path / 'm.csv'}:3: unit {unit!r} is not one of {units}"
    (tmp_path / "m.toml").write_text(f'[[take]]\nfile = "a.bvh"\nstyle = "calm"\n\n[[take]]\nfile = "b.bvh"\n'
                                     f'style = "calm"\n# the second take\nunit = "{unit}"\n')
    with pytest.raises(UserError) as refused:
        read_manifest(tmp_path / "m.toml")
    assert str(refused.value) == f"{tmp_path / 'm.toml'}:9: take 2: unit {unit!r} is not one of {units}"
    (tmp_path / "case.csv").write_text("file,style,unit\na.bvh,calm,Walk\nb.bvh,calm,TURN-LEFT\n")  # a unit in any case
    assert [t.unit for t in read_manifest(tmp_path / "case.csv")] == ["walk", "turn-left"]


@pytest.mark.parametrize("name, text, where", [
    ("units.csv", "file,style,units\na.bvh,calm,walk\nb.bvh,calm,run\n", ":1: a CSV manifest starts with the header"),
    ("two.csv", "file,style\na.bvh,calm\nb.bvh,calm,run\n", ":3: 3 fields, but the header 'file,style' names 2"),
    ("four.csv", "file,style,unit\na.bvh,calm,walk\nb.bvh,calm,run,fast\n", ":3: 4 fields"),
    ("units.toml", '[[take]]\nfile = "a.bvh"\nstyle = "calm"\n[[take]]\nfile = "b.bvh"\nstyle = "calm"\nunits = "run"\n',
     ":7: take 2: unknown key 'units'"),
    ("misspelt.toml", '[[take]]\nfile = "a.bvh"\nstyle = "calm"\n[[take]]\nfile = "b.bvh"\nstyl = "calm"\n',
     ":6: take 2: unknown key 'styl'"),  # said before the style it lacks: the key is the mistake
    ("unit.toml", '[[take]]\nfile = "a.bvh"\nstyle = "calm"\nunit = 2\n', ":4: take 1: 'unit' is a string"),
    # a table misspelt: its take was dropped unread, and a model trained on the others
    ("takes.toml", '[[take]]\nfile = "a.bvh"\nstyle = "calm"\n[[takes]]\nfile = "b.bvh"\nstyle = "brisk"\n',
     ":4: unknown table or key 'takes' (a manifest holds [[take]] tables)"),
    ("empty.csv", "file,style\n", ":1: a header and no takes"),
])
def test_a_manifest_column_or_key_it_does_not_read_is_refused_at_its_line(tmp_path, name, text, where):
    """A unit column misspelt (`units`), a row with a unit under a header without one, or a
    [[take]] key misspelt was dropped unread: the run trained as a walk, silently."""
    for take in ("a.bvh", "b.bvh"):
        (tmp_path / take).touch()
    (tmp_path / name).write_text(text)
    with pytest.raises(UserError) as refused:
        read_manifest(tmp_path / name)
    assert str(refused.value).startswith(f"{tmp_path / name}{where}"), refused.value
    (tmp_path / "spreadsheet.csv").write_text("file,style,unit,\na.bvh,calm,run,\nb.bvh,calm,,\n")  # empty trailing columns
    assert [t.unit for t in read_manifest(tmp_path / "spreadsheet.csv")] == ["run", "walk"]


@pytest.mark.parametrize("style", ["old/man", "Old Man", "old.man", "a=b", "calm#1"])
def test_a_style_the_controls_cannot_name_is_refused_at_its_line(tmp_path, style):
    """A style is a control target's part (`style/<name>`, `part/<name>/legs`), an OSC address's
    and synth's `--style NAME.PART=W`: a manifest's `old/man` trained a model `run` crashed on
    (KeyError 'old' as the state read style/old/man), `Old Man` one no OSC surface could set."""
    (tmp_path / "a.bvh").touch()
    (tmp_path / "m.csv").write_text(f"file,style\na.bvh,{style}\n")
    with pytest.raises(UserError, match=rf"^{re.escape(str(tmp_path / 'm.csv'))}:2: style .* is not a name of letters"):
        read_manifest(tmp_path / "m.csv")
    (tmp_path / "m.toml").write_text(f'[[take]]\nfile = "a.bvh"\nstyle = "{style}"\n')
    with pytest.raises(UserError, match=r"m\.toml:1: take 1: style .* is not a name of letters"):
        read_manifest(tmp_path / "m.toml")
    (tmp_path / "old man.5_1.bvh").touch()  # --style-from's group finds 'old man.5'
    with pytest.raises(UserError, match=r"old man\.5_1\.bvh: --style-from: style 'old man\.5' is not a name"):
        styled_takes([tmp_path / "old man.5_1.bvh"], r"^(.*)_\d+$")
    for fine in ("not-confident", "old_man", "Proud2", "älter"):
        (tmp_path / "m.csv").write_text(f"file,style\na.bvh,{fine}\n")
        assert read_manifest(tmp_path / "m.csv")[0].style == fine


@needs_motions
def test_styled_takes_of_the_motions_folder_hold_every_unit():
    units = {t.unit for t in styled_takes([MOTIONS])}
    assert units == {"run", "turn-left", "turn-right", "stand"}


@needs_motions
@needs_walks
def test_a_style_without_a_unit_the_others_have_is_said(real_walks):
    """A capture with no runs for one style (a session that ran out of time) trained its run as
    the average's without a word: each style lacking a unit the corpus has is named."""
    walks = {p.name.split("_")[2]: p for p in real_walks}
    pairs = [TakeFile(walks["active"], "active"), TakeFile(walks["elderly"], "elderly"),
             TakeFile(MOTIONS / "dataset-2_run_active_001.bvh", "active", "run")]
    _, takes, warnings, _ = load_corpus(pairs, 30.0)
    assert {(t.style, t.unit) for t in takes} == {("active", "walk"), ("elderly", "walk"), ("active", "run")}
    assert [w for w in warnings if "no run take" in w] == [
        "style 'elderly': no run take, so its run is the average's, moved only as its other units are"]


@needs_motions
@needs_walks
def test_a_turning_take_is_trained_as_the_way_it_turns(tmp_path, real_walks):
    """One of the Bandai set's masculine takes named turn-left turns right (checked with the
    independent reader: its hips' heading); a straight walk named as a turn is left out."""
    mislabelled = MOTIONS / "dataset-2_walk-turn-left_masculine_006.bvh"
    names, positions, _ = world_positions(mislabelled)
    hips = positions[:, names.index("Hips")]
    travel = np.diff(hips[:: 10][:, [0, 2]], axis=0)
    heading = np.unwrap(np.arctan2(travel[:, 0], travel[:, 1]))
    assert np.degrees(heading[-1] - heading[0]) < -45  # to the right, seen from above (+x to the left of +z)
    straight = tmp_path / "dataset-2_walk-turn-left_normal_009.bvh"
    straight.write_bytes(real_walks[0].read_bytes())
    pairs = [TakeFile(mislabelled, "masculine", "turn-left"), TakeFile(straight, "normal", "turn-left"),
             TakeFile(MOTIONS / "dataset-2_walk-turn-left_masculine_001.bvh", "masculine", "turn-left")]
    _, takes, warnings, _ = load_corpus(pairs, 30.0)
    assert [(t.path.name, t.unit) for t in takes] == [(mislabelled.name, "turn-right"),
                                                      ("dataset-2_walk-turn-left_masculine_001.bvh", "turn-left")]
    assert any(w.startswith(f"{mislabelled}: named turn-left but turns") and "used as turn-right" in w for w in warnings)
    assert any(w.startswith(f"{straight}: named turn-left but turns") and "left out" in w for w in warnings)


@needs_motions
def test_a_left_turn_whose_left_toes_point_inwards_keeps_one_foot_a_side(model):
    """The feet are found by their leg's side, not each joint's: this take's left toes point
    inwards through its turn, and were taken for the right foot (no steps: left out)."""
    from instrument.motion.features import resample
    from instrument.motion.steps import segment_steps

    take = resample(read_bvh(MOTIONS / "dataset-2_walk-turn-left_feminine_001.bvh"), model.fps)
    segmentation = segment_steps(take, model.layout)
    assert len(segmentation.steps) >= 5
    left, right = segmentation.feet
    assert left.endswith("_L") and right.endswith("_R")


# ---- still standing ----------------------------------------------------------------------------

@needs_motions
@needs_walks
def test_still_standing_is_found_in_the_standing_takes_and_never_in_walks_or_runs(model, real_walks):
    layout = model.layout
    take = read_bvh(MOTIONS / "dataset-2_raise-up-both-hands_elderly_003.bvh")
    pieces = standing_steps(take, layout).steps
    assert pieces, "the standing take's rest before and after the gesture"
    assert [p.label for p in pieces[:2]] == ["right", "left"][: len(pieces[:2])]
    names, positions, _ = world_positions(MOTIONS / "dataset-2_raise-up-both-hands_elderly_003.bvh")
    hips = positions[:, names.index("Hips")]
    for p in pieces:  # the hips barely move in every piece (an independent reader's positions, cm)
        speed = np.linalg.norm(np.diff(hips[p.start:p.end][:, [0, 2]], axis=0), axis=1) * take.fps
        assert speed.max() < 10.0
    assert not still_frames(read_bvh(real_walks[0]), layout).any()
    assert not still_frames(read_bvh(MOTIONS / "dataset-2_run_normal_001.bvh"), layout).any()


@needs_motions
@needs_walks
def test_a_styles_standing_takes_of_one_piece_each_give_both_labels(real_walks):
    """Active's wave and raise hold one still piece each (as 23 of the 56 Bandai standing takes
    do): every take's began "right", so the style had no left piece, and a corpus of one standing
    take per style lost its stand unit. A style's pieces go on alternating from take to take, and
    every other style starts at left (one single-piece take a style still gives both labels)."""
    stands = [TakeFile(MOTIONS / f"dataset-2_{what}_active_001.bvh", "active", "stand")
              for what in ("wave-both-hands", "raise-up-both-hands")]
    stands.append(TakeFile(MOTIONS / "dataset-2_wave-both-hands_elderly_001.bvh", "elderly", "stand"))
    _, takes, _, _ = load_corpus([TakeFile(real_walks[0], "normal"), *stands], 30.0)
    labels = {(t.path.name, t.style): [s.label for s in t.steps] for t in takes if t.unit == "stand"}
    assert list(labels.values()) == [["right"], ["left"], ["left"]], labels


@needs_motions
@needs_walks
def test_a_stand_too_short_for_both_labels_is_said_in_a_stands_words(real_walks, tmp_path):
    """One style's one standing take holding one still piece: the stand is left out, and the
    warning says what a stand lacks (it said "no left step long enough for 5 states")."""
    (tmp_path / "takes.csv").write_text(f"file,style,unit\n{real_walks[0]},calm,walk\n"
                                        f"{MOTIONS / 'dataset-2_wave-both-hands_active_001.bvh'},calm,stand\n")
    result = subprocess.run([sys.executable, "-m", "instrument", "train", "--manifest", str(tmp_path / "takes.csv"),
                             "--out", str(tmp_path / "m.npz")], capture_output=True, text=True, timeout=900)
    assert result.returncode == 0, result.stderr
    assert ("warning: unit 'stand': its takes hold too little still standing with the arms down for a right and a left "
            "piece of 5 frames or more (one still stretch of 0.8 s gives both, before or after the gesture): left out "
            "(its gait plays the walk)") in result.stderr, result.stderr


@needs_motions
@pytest.mark.parametrize("name", ["dataset-2_raise-up-both-hands_normal_001", "dataset-2_raise-up-both-hands_youthful_004"])
def test_a_pause_is_no_stand_at_any_rate(model, name):
    """A standing take read at 120 fps stands in as many pieces as at 30, none shorter than the
    shortest stretch kept at 30 fps: a still stretch must last a time. Counted in frames (5), the
    120 fps take's pauses of 42-167 ms were stand pieces too (3 pieces against 1, 2 against 0)."""
    from instrument.motion.features import resample

    take = read_bvh(MOTIONS / f"{name}.bvh")
    found = {fps: standing_steps(resample(take, fps), model.layout).steps for fps in (30.0, 120.0)}
    assert len(found[120.0]) == len(found[30.0])
    shortest = min([(p.end - p.start) / 30.0 for p in found[30.0]], default=0.0)
    assert all((p.end - p.start) / 120.0 >= min(shortest, 5 / 30) - 1e-9 for p in found[120.0])


# ---- the shipped model ---------------------------------------------------------------------------

def test_the_shipped_model_holds_every_unit(model):
    assert model.units == ["walk", "run", "turn-left", "turn-right", "stand"]
    assert model.labels[:2] == ["walk/right", "walk/left"] and model.labels[9] == "stand/left"
    assert all(label.startswith("gesture/") for label in model.labels[10:])  # the gestures' after the units' (issue 26)
    walk_steps = [d for d in model.metadata["data"] if d["unit"] == "walk"]
    assert len(walk_steps) == 175  # the walks it always had, and the new takes beside them


def _engine_frames(model, plan: list[tuple[int, int]], characters: int = 1, turn: float = 0.0, weights=None):
    """Frames of an engine playing (gait, frames) in turn; per frame and character the unit and
    label of the frame made, the plan's coming unit, the plan's state and the root's horizontal
    speed (model units/s)."""
    engine = Engine(model, characters)
    base = default_controls(model, weights or {"normal": 1.0})
    units, coming, labels, states, speeds = [], [], [], [], []
    made = 0
    for gait, frames in plan:
        controls = Controls(base.weights, gait=gait, turn=turn)
        for _ in range(frames):
            engine.frame(made / engine.fps, controls)
            made += 1
            units.append(engine.frame_ids // (2 * model.states))
            coming.append(engine.stream.counters[:, UNIT].copy())
            labels.append(engine.frame_ids // model.states)  # the label of the frame made
            states.append(engine.stream.counters[:, STATE].copy())
            speeds.append(np.hypot(engine.knots.frames[-1][:, 1], engine.knots.frames[-1][:, 2]))
    return engine, np.array(units), np.array(coming), np.array(labels), np.array(states), np.array(speeds)


STAND, WALK, RUN = 0, 1, 2


def test_a_gait_change_is_in_the_next_frames_plan_and_takes_the_body_at_the_next_step(model):
    stand = model.units.index("stand")
    engine, units, coming, labels, states, _ = _engine_frames(model, [(WALK, 40), (STAND, 60)])
    assert (units[:40] == 0).all()
    assert coming[40, 0] == stand  # the frame after the change already plans the stand
    first_stand = 40 + int(np.argmax(units[40:, 0] == stand))
    # the step under way was finished, and one more only where it ended too soon to brake in
    # (units.STOP_SECONDS): the walk's label changed at most once, and then that soon
    assert first_stand > 40
    walking_label = labels[40, 0]
    changes = np.flatnonzero(np.diff(labels[40:first_stand, 0]))
    assert len(changes) <= 1
    if len(changes):
        assert changes[0] + 1 < STOP_SECONDS * model.fps
    assert first_stand - 40 <= 2 * engine.stream.base[0, walking_label].sum() + 1  # within the step after
    assert (units[first_stand:, 0] == stand).all()


@pytest.mark.parametrize("walk_frames", [60, 68])  # told early and late in a step
def test_a_braking_walk_draws_its_pose_in_no_faster_than_it_slows(model, walk_frames):
    """From the stop command until the stand, the engine draws the pose towards the stand's no
    faster than the body's travel eases out (`UnitChooser.stride` never below `travel`), and the
    stand begins within two seconds: the steps shorten as the body brakes. What the user gets of
    it, a stop that does not fling a foot forward and back, is measured on the recorded BVH
    (tests/test_transition_bvh.py)."""
    engine = Engine(model)
    base = default_controls(model, {"feminine": 1.0})
    walk, stand = Controls(base.weights, gait=WALK), Controls(base.weights, gait=STAND)
    units, shortened = [], False
    for k in range(walk_frames + 60):
        engine.next_features(walk if k < walk_frames else stand)
        units.append(int(engine.frame_ids[0]) // (2 * model.states))
        if k >= walk_frames and units[-1] != model.units.index("stand"):
            assert engine.units.stride[0] <= engine.units.travel[0] + 1e-12
            shortened |= engine.units.stride[0] < 1.0
    first_stand = int(np.argmax(np.array(units) == model.units.index("stand")))
    assert walk_frames < first_stand < walk_frames + 60 and shortened


def test_a_stop_told_too_late_in_a_step_waits_a_step_and_does_not_jolt(model):
    """A run told to stand a frame before its step ends: the plan shows the stand at once, a step
    further on (NEXT), the run takes one more step, and no joint's velocity jumps more than in the
    run itself (told that late and taken at once, a toe jumped 2.5 times the run's largest)."""
    from instrument.evaluation.sequence import velocity_jumps
    from instrument.motion.kinematics import ChannelStream, world_positions
    from instrument.motion.bvh import Motion
    from instrument.synthesis.stream import NEXT

    engine = Engine(model)
    base = default_controls(model, {"normal": 1.0})
    run, stand = Controls(base.weights, gait=RUN), Controls(base.weights, gait=STAND)
    channels = ChannelStream(model.layout.skeleton)
    rows, labels, told = [], [], None
    for k in range(150):
        late = engine.units._frames_left(engine.stream)[0] < 2
        if told is None and k > 60 and late:
            told = k
        pose = engine.frame(k / engine.fps, run if told is None else stand)
        rows.append(channels.next(pose.rotations[0], pose.translations[0]))
        labels.append(int(engine.frame_ids[0]) // model.states)
        if k == told:
            run_unit = model.units.index("run")
            assert engine.stream.counters[0, NEXT] == run_unit + 1 and engine.stream.counters[0, UNIT] == model.units.index("stand")
    assert told is not None
    units = np.array(labels) // 2
    first_stand = told + int(np.argmax(units[told:] == model.units.index("stand")))
    run_steps = len(set(np.flatnonzero(np.diff(labels[told:first_stand]))))  # label changes on the way
    assert run_steps == 1, "one more run step, then the stand"
    jumps = velocity_jumps(world_positions(Motion(model.layout.skeleton, np.array(rows), model.fps)))
    assert jumps[told:told + 45].max() < 1.2 * jumps[15:told].max()


@pytest.mark.parametrize("gait, weights, moving_frames, stand_frames", [
    (WALK, {"masculine": 2.0}, 60, 60), (WALK, {"masculine": 2.0}, 75, 90),
    (RUN, {"normal": 2.0}, 135, 60)])  # the run's start set off on the foot whose toe-off popped
def test_a_body_set_off_after_a_stop_takes_a_half_step_without_a_jolt(model, gait, weights, moving_frames, stand_frames):
    """From the command to move after a stop to 1.5 s on, no joint's velocity jumps more than in
    the steady gait before the stop (masculine x2's walk and normal x2's run, whose starts popped
    hardest): the first step is a half step in the legs as in the root, so its stance foot stays
    where the stand left it and the lock, letting go of it, has nothing to undo. With the step's
    full swing while the travel eased in, the lock held the stance foot behind the one made, its
    heel rose, and the rise collapsed as it let go: the walk 2.5-2.6 times its steady jump (now
    0.8-1.0). The run's first stance foot, let go at half a step's pace through its toe-off and
    drawn back at the end of the step by a stride eased by a smoothstep, rose straight up and
    swung forward at once as the next step began: 1.35 times the steady run's (now 1.02)."""
    from instrument.evaluation.sequence import velocity_jumps
    from instrument.motion.bvh import Motion
    from instrument.motion.kinematics import ChannelStream
    from instrument.motion.kinematics import world_positions as positions_of

    engine = Engine(model)
    base = default_controls(model, weights)
    moving, stand = Controls(base.weights, gait=gait), Controls(base.weights, gait=STAND)
    channels = ChannelStream(model.layout.skeleton)
    told = moving_frames + stand_frames
    rows, units = [], []
    for k in range(told + 45):
        pose = engine.frame(k / engine.fps, stand if moving_frames <= k < told else moving)
        rows.append(channels.next(pose.rotations[0], pose.translations[0]))
        units.append(int(engine.frame_ids[0]) // (2 * model.states))
    going = np.array(units) != model.units.index("stand")
    assert not going[told - 10:told].any() and going[-10:].all()  # stood, then set off
    jumps = velocity_jumps(positions_of(Motion(model.layout.skeleton, np.array(rows), model.fps)))
    assert jumps[told:].max() <= 1.25 * jumps[15:moving_frames].max()


@pytest.mark.parametrize("stand_frames", [60, 66])  # the walk sets off on one foot and on the other
def test_a_body_setting_off_from_a_stand_accelerates(model, stand_frames):
    """The root's speed (posed, world) rises from the stand to the walk's with no change from one
    frame to the next larger than the steady walk's own (set off at full speed, it went from 0
    to 77 cm/s in a frame), and the first step covers less ground than a steady one."""
    engine, speed, units = _root_speeds(model, {"active": 1.0}, [(STAND, stand_frames), (WALK, 150)])
    walking = units != model.units.index("stand")
    first = int(np.argmax(walking))  # the first frame of the walk
    change = np.abs(np.diff(speed))
    steady = change[first + 60:].max()
    assert speed[first - 5:first].max() < 2.0  # stood still until then
    assert change[first - 1:first + 30].max() <= 1.1 * steady
    step = int(round(engine.stream.base[0, 0].sum()))  # frames of a step
    assert speed[first:first + step].sum() < 0.8 * speed[first + 60:first + 60 + step].sum()


@pytest.mark.parametrize("run_frames", [60, 66])  # the stop told early and late in a step
def test_a_running_body_brakes_into_a_stand(model, run_frames):
    """The root's speed (posed, world) falls from the run's to none as the stand begins with no
    change from one frame to the next larger than the steady run's own: its travel is eased out
    over the steps it still takes. Cut at the stand's first frame, the hips went from 3.3 m/s to
    none in a frame (every joint's velocity jumped 11 cm/frame^2)."""
    _, speed, units = _root_speeds(model, {"active": 2.0}, [(RUN, run_frames), (STAND, 60)])
    standing = units == model.units.index("stand")
    first = int(np.argmax(standing))  # the stand's first frame
    change = np.abs(np.diff(speed))
    steady = change[20:run_frames - 2].max()
    assert speed[run_frames - 10:run_frames].mean() > 200.0  # cm/s: running when told
    assert change[first - 3:first + 6].max() <= 1.1 * steady


def test_an_inverted_run_set_off_from_a_stand_reaches_its_speed_within_two_steps(model):
    """The hips' speed over a step's window reaches 90% of the steady inverted run's within the
    first two run steps (issue 25's start target). With its root speed variances extrapolated
    freely (to 2-4 m/s against delta variances of a few cm/s a frame), the window MLPG barely
    pulled the speed towards the run's: it took 5 steps."""
    engine, speed, units = _root_speeds(model, {"normal": -1.0}, [(STAND, 30), (RUN, 180)])
    run = model.units.index("run")
    first = int(np.argmax(units == run))
    step = int(round(engine.stream.base[0, 2 * run].sum()))  # frames of a run step
    paced = np.convolve(speed, np.ones(step) / step, mode="same")
    steady = paced[first + 90:-step].mean()
    reached = first + int(np.argmax(paced[first:] >= 0.9 * steady))
    assert paced[first:].max() >= 0.9 * steady and steady > 50.0  # cm/s: it does run
    assert reached - first <= 2 * step


def test_stand_is_still_run_is_faster_than_walk_and_walking_again_reaches_its_speed(model):
    _, units, _, _, _, speed = _engine_frames(model, [(WALK, 90), (STAND, 90), (RUN, 90), (WALK, 90)])
    cm = _cm(model)
    walk, stand, run, again = (speed[k * 90 + 45:(k + 1) * 90, 0] * cm for k in range(4))
    assert stand.mean() < 2.0  # cm/s: the stand unit holds the root's travel at zero
    assert run.mean() > 1.3 * walk.mean()
    assert abs(again.mean() - walk.mean()) < 0.1 * walk.mean()


def _root_speeds(model, weights: dict[str, float], gaits: list[tuple[int, int]]):
    """The engine after `gaits` ((gait, frames) one after another), the root's speed (posed, world,
    cm/s) from each frame to the next, and the unit each of those next frames was made of."""
    engine = Engine(model)
    base = default_controls(model, weights)
    roots, units = [], []
    for gait, frames in gaits:
        for _ in range(frames):
            pose = engine.frame(len(roots) / engine.fps, Controls(base.weights, gait=gait))
            roots.append(pose.world_positions[0, model.layout.root, [0, 2]])
            units.append(int(engine.frame_ids[0]) // (2 * model.states))
    speed = np.linalg.norm(np.diff(np.array(roots), axis=0), axis=1) * engine.fps * _cm(model)
    return engine, speed, np.array(units[1:])


def _cm(model) -> float:
    from instrument.synthesis.engine import metres_to_units
    return 100.0 / metres_to_units(model.layout)


def _own_turn_rate(model, weights: dict[str, float], side: int) -> float:
    """rad/s (+ left) the turning steps of `side` (+1 left) turn at in the lambda* of these
    weights, made apart from the engine: the duration-weighted mean yaw rate of the unit's labels."""
    from instrument.synthesis.interpolation import interpolate, style_space

    lam = interpolate(style_space(model), default_controls(model, weights).weights)
    k = model.units.index("turn-left" if side > 0 else "turn-right")
    yaw = lam.means.reshape(len(model.labels), model.states, -1)[2 * k:2 * k + 2, :, 3]  # root.yaw_rate
    durations = lam.duration_means[2 * k:2 * k + 2]
    return float((yaw * durations).sum() / durations.sum())


def _stride_turn_rate(path: Path, start: float = 0.0, stop: float = np.inf) -> float:
    """deg/s (+ left) a written walk's hips turn over whole strides: the heading of the line
    between the upper legs, from the first left footfall (the left foot furthest ahead) to the
    last between `start` and `stop` seconds, the hips' sway within a stride left out (read back
    with the independent reader)."""
    from scipy.signal import find_peaks

    names, positions, fps = world_positions(path)
    across = positions[:, names.index("UpperLeg_L")] - positions[:, names.index("UpperLeg_R")]
    heading = np.unwrap(np.arctan2(-across[:, 2], across[:, 0]))  # about +y: + turns left
    forward = np.cross(across / np.linalg.norm(across, axis=1, keepdims=True), [0.0, 1.0, 0.0])
    ahead = np.einsum("tk,tk->t", positions[:, names.index("Foot_L")] - positions[:, names.index("Foot_R")], forward)
    footfalls, _ = find_peaks(ahead, distance=int(0.3 * fps), prominence=0.25 * np.ptp(ahead))
    footfalls = footfalls[(footfalls >= start * fps) & (footfalls <= stop * fps)]
    first, last = footfalls[0], footfalls[-1]
    assert len(footfalls) >= 6 and last - first > min(10.0, 0.6 * (min(stop, len(ahead) / fps) - start)) * fps
    return float(np.degrees(heading[last] - heading[first]) / ((last - first) / fps))


@pytest.mark.parametrize("speed, fraction", [(1.0, 0.5), (2.0, 0.75), (0.5, 0.25)])
@pytest.mark.parametrize("style, side", [("exhausted", -1), ("youthful", 1)])
def test_a_style_steered_at_part_of_its_own_turn_turns_at_the_rate_asked(tmp_path, model, style, side, speed, fraction):
    """Turning steps are shared out by the character's own turns, not the average model's:
    exhausted x2's right turns turn 35 deg/s, youthful x2's left 15, the average's 22. Shared out
    by the average's rate and one step in so many (a turning step's foot fell on the same foot
    each time: a turn-left unit's right step turns 2 degrees past the walk's, its left 13, for
    youthful x2), `synth` steered at half their own rates turned exhausted x2 1.61 times what it
    asked (28.0 deg/s for 17.4) and youthful x2 0.75 times (5.7 for 7.6). At another pace the
    drive scales the steps' yaw by the cadence (0.5 at speed 0.5, 1.7-1.8 at speed 2), and the
    window MLPG joins steps taken faster further from their means: shared by the rate alone and
    a gain per step predicted from the means, normal at speed 2 turned 0.17-0.69 times what it
    asked, and these exhausted x2 0.72 and youthful x2 1.36 at speed 2, youthful x2 1.14 at 0.5;
    the heading the steps owe is now measured from the frames made (the fractions here keep some
    steps straight at each pace)."""
    weights = {style: 2.0}
    turn = fraction * _own_turn_rate(model, weights, side)
    assert np.sign(turn) == side
    seconds = 20 / min(speed, 1.0)  # ten strides
    done = _synth(tmp_path, "--style", f"{style}=2", "--turn", f"{turn:.6f}", "--speed", f"{speed:g}",
                  "--seconds", f"{seconds:g}", "--out", "turn.bvh")
    assert done.returncode == 0, done.stderr
    made = _stride_turn_rate(tmp_path / "turn.bvh")
    assert made == pytest.approx(np.degrees(turn), rel=0.10)


def _score_turn_rate(tmp_path, score: str, start: float, stop: float) -> float:
    """deg/s the hips turn over whole strides between `start` and `stop` s of `score` rendered
    by `run --score --fast --bvh`."""
    (tmp_path / "piece.toml").write_text(score)
    done = subprocess.run([sys.executable, "-m", "instrument", "run", "--score", "piece.toml", "--fast", "--no-osc",
                           "--quiet", "--seconds", f"{stop:g}", "--bvh", "piece.bvh"], capture_output=True, text=True,
                          cwd=tmp_path, timeout=900)
    assert done.returncode == 0, done.stderr
    return _stride_turn_rate(tmp_path / "piece.bvh", start, stop)


def test_a_style_that_turns_the_other_way_leaves_no_debt_for_the_next(tmp_path, model):
    """A style whose right turns turn left (active at -3: no step can turn right, the drive
    steers it) steered right for 20 s, then normal: the heading owed ran up to -303 degrees in
    30 s and normal turned -21.9 deg/s for the 30 s after, asked -10. Owed only where a step can
    turn that way, and held within a turning step's gain and a stride's turn, it turns at what is
    asked 3 s on (before: -22.3)."""
    turn = -np.radians(10.0)
    score = (f'[[cue]]\nat = 0\nramp = {{ "style/active" = -3.0, turn = {turn:.6f} }}\n\n'
             '[[cue]]\nat = 20\nramp = { "style/active" = 0.0, "style/normal" = 1.0 }\n')
    assert _score_turn_rate(tmp_path, score, 23.0, 38.0) == pytest.approx(-10.0, rel=0.15)


def test_a_turn_lowered_after_a_long_slow_steer_turns_at_the_rate_asked(tmp_path, model):
    """At speed 0.5 the drive halves the steps' yaw: shared by the rate alone, 0.8 of normal's
    rate asked more than every step turning gives, and the heading owed ran to +220 degrees in
    30 s; lowered to 7.3 deg/s, the walk turned 12.3 for the next 20 s paying it back (here 12.8)."""
    rate = _own_turn_rate(model, {"normal": 1.0}, 1)
    score = (f'[[cue]]\nat = 0\nramp = {{ "style/normal" = 1.0, speed = 0.5, turn = {0.8 * rate:.6f} }}\n\n'
             f'[[cue]]\nat = 20\nramp = {{ turn = {np.radians(7.3):.6f} }}\n')
    assert _score_turn_rate(tmp_path, score, 23.0, 40.0) == pytest.approx(7.3, rel=0.15)


def test_turning_steps_are_taken_in_proportion_to_the_turn(model):
    left, right = model.units.index("turn-left"), model.units.index("turn-right")
    rate = _own_turn_rate(model, {"normal": 1.0}, 1)
    shares = []
    for fraction in (0.0, 0.5, 1.0):
        _, units, _, _, _, _ = _engine_frames(model, [(WALK, 300)], turn=fraction * rate)
        shares.append(np.mean(units[60:, 0] == left))
        assert not (units[:, 0] == right).any()
    assert shares[0] == 0.0
    assert 0.3 < shares[1] < 0.7
    assert shares[2] > 0.9
    _, units, _, _, _, _ = _engine_frames(model, [(WALK, 200)], turn=_own_turn_rate(model, {"normal": 1.0}, -1))
    assert np.mean(units[60:, 0] == right) > 0.9


def test_every_character_of_a_crowd_changes_gait_at_its_own_step(model):
    stand = model.units.index("stand")
    _, units, coming, _, _, _ = _engine_frames(model, [(WALK, 30), (STAND, 60)], characters=6)
    assert (coming[30] == stand).all()
    arrivals = [30 + int(np.argmax(units[30:, n] == stand)) for n in range(6)]
    assert all((units[a:, n] == stand).all() for n, a in enumerate(arrivals))
    assert len(set(arrivals)) > 1  # they started in different phases of the step: they arrive apart


def test_the_turning_unit_a_steered_walk_lacks_is_read_from_the_chooser_the_walk_uses(model):
    """`UnitChooser.unsteered` answers from the tables the chooser steers by: a walk-only model
    plays every gait as its walk, so a steered run or stand lacks its turning steps as the walk does
    (the function it replaced asked the gait's name and said nothing of a run played as a walk);
    the shipped model has both sides, and its run and stand take no turning steps by design."""
    from instrument.synthesis.units import UnitChooser

    walks = UnitChooser(walk_only(model), 1)
    assert [walks.unsteered(gait, 1.0) for gait in range(3)] == ["turn-left"] * 3
    assert [walks.unsteered(gait, -0.2) for gait in range(3)] == ["turn-right"] * 3
    assert walks.unsteered(1, 0.0) is None
    shipped = UnitChooser(model, 1)
    assert [shipped.unsteered(gait, turn) for gait in range(3) for turn in (-1.0, 1.0)] == [None] * 6


def test_a_walk_only_model_plays_every_gait_as_its_walk(model):
    walks = walk_only(model)
    engine = Engine(walks)
    assert engine.units.missing == ["stand", "run"]
    _, units, _, _, _, speed = _engine_frames(walks, [(STAND, 60), (RUN, 60)])
    assert (units == 0).all() and speed[30:].min() > 0


# ---- synth --gait, read back independently ----------------------------------------------------------

def _synth(tmp_path, *args) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "instrument", "synth", *args], capture_output=True, text=True,
                          cwd=tmp_path, timeout=900)


def test_synth_gait_writes_a_stand_and_a_run(tmp_path):
    done = _synth(tmp_path, "--gait", "stand", "--seconds", "4", "--out", "stand.bvh")
    assert done.returncode == 0, done.stderr
    done = _synth(tmp_path, "--gait", "2", "--seconds", "4", "--out", "run.bvh")
    assert done.returncode == 0, done.stderr
    done = _synth(tmp_path, "--seconds", "4", "--out", "walk.bvh")
    assert done.returncode == 0, done.stderr
    fps = 30.0

    def hips_speed(name: str) -> np.ndarray:
        names, positions, _ = world_positions(tmp_path / name)
        hips = positions[30:, names.index("Hips")]
        return np.linalg.norm(np.diff(hips[:, [0, 2]], axis=0), axis=1) * fps

    assert hips_speed("stand.bvh").mean() < 6.0  # cm/s: the standing takes' quiet stretches measure 0.6 to 6
    assert hips_speed("run.bvh").mean() > 1.3 * hips_speed("walk.bvh").mean()


@pytest.mark.parametrize("gait", ["hop", "Run"])  # names as written, as style names are
def test_synth_refuses_an_unknown_gait_in_one_line(tmp_path, gait):
    done = _synth(tmp_path, "--gait", gait, "--out", "x.bvh")
    assert done.returncode != 0
    assert done.stderr.strip().count("\n") == 0 and "--gait" in done.stderr and repr(gait) in done.stderr
    assert "stand, walk, run" in done.stderr
    assert not (tmp_path / "x.bvh").exists()


def test_a_score_that_stops_stands_and_runs_renders_with_run_fast_bvh(tmp_path):
    """The offline way to a sequence: a score's cues set the gait, `run --fast --bvh` records it."""
    (tmp_path / "piece.toml").write_text(
        "[[cue]]\nat = 3\nramp = { gait = 0 }\n\n[[cue]]\nat = 7\nramp = { gait = 2 }\n")
    done = subprocess.run([sys.executable, "-m", "instrument", "run", "--score", "piece.toml", "--fast", "--no-osc",
                           "--quiet", "--seconds", "11", "--bvh", "piece.bvh"], capture_output=True, text=True,
                          cwd=tmp_path, timeout=900)
    assert done.returncode == 0, done.stderr
    names, positions, fps = world_positions(tmp_path / "piece.bvh")
    hips = positions[:, names.index("Hips")][:, [0, 2]]

    def speed(start: float, stop: float) -> float:  # cm/s over the floor between two times
        a, b = int(start * fps), int(stop * fps)
        return float(np.linalg.norm(np.diff(hips[a:b], axis=0), axis=1).mean() * fps)

    walking, standing, running = speed(1, 3), speed(4.5, 7), speed(9, 11)
    assert walking > 60.0
    assert standing < 6.0  # stopped within a second and a half of the cue, and still
    assert running > 1.3 * walking


def test_synth_says_when_a_model_has_no_unit_for_the_gait_and_writes_its_walk(model, tmp_path):
    from instrument.models.modelfile import save_model

    save_model(tmp_path / "walks.npz", walk_only(model))
    done = _synth(tmp_path, "--model", "walks.npz", "--gait", "run", "--seconds", "2", "--out", "run.bvh")
    assert done.returncode == 0, done.stderr
    assert "--gait run: this model has no run unit (it has walk); it walks" in done.stderr
    assert len(world_positions(tmp_path / "run.bvh")[1]) == 2 * model.fps  # the walk, written whole
    done = _synth(tmp_path, "--model", "walks.npz", "--gait", "walk", "--seconds", "2", "--out", "walk.bvh")
    assert "unit" not in done.stderr, done.stderr
    # steered, a walk of a model without turning steps turns by yaw rate alone: said, as the gait is
    done = _synth(tmp_path, "--model", "walks.npz", "--turn", "1", "--seconds", "2", "--out", "turn.bvh")
    assert done.returncode == 0, done.stderr
    assert "--turn 1: this model has no turn-left unit (it has walk); its walk is steered without turning steps" \
        in done.stderr
    # a score's gait the model has no unit for: `run --check` says so at the cue's line, before the show
    (tmp_path / "run.toml").write_text('[[cue]]\nat = 0\nramp = { gait = "walk" }\n\n[[cue]]\nat = 2\n'
                                       'ramp = { gait = "run" }\n\n[[cue]]\nat = 4\nramp = { gait = "run" }\n')
    done = subprocess.run([sys.executable, "-m", "instrument", "run", "--model", "walks.npz", "--score", "run.toml",
                           "--check"], capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stderr.count("run.toml:5: gait run: this model has no run unit (it has walk); it walks") == 1, done.stderr
    names, positions, _ = world_positions(tmp_path / "turn.bvh")
    heading = np.diff(positions[[30, -1]][:, names.index("Hips"), [0, 2]], axis=0)[0]
    assert abs(np.degrees(np.arctan2(heading[1], heading[0])) - np.degrees(np.arctan2(1.0, 0.0))) > 10  # it turned
    done = _synth(tmp_path, "--turn", "1", "--seconds", "2", "--out", "shipped.bvh")  # the shipped model has them
    assert "turn" not in done.stderr, done.stderr
    # and live, once, on the console, the show going on: a score steering the walk right
    (tmp_path / "steer.toml").write_text("[[cue]]\nat = 0.5\nramp = { turn = -1 }\n[[cue]]\nhold = 1\n")
    done = subprocess.run([sys.executable, "-m", "instrument", "run", "--model", "walks.npz", "--score", "steer.toml",
                           "--fast", "--no-osc"], capture_output=True, text=True, cwd=tmp_path, timeout=900)
    assert done.returncode == 0, done.stderr
    said = [line for line in (done.stdout + done.stderr).splitlines() if "turn-right" in line]
    assert said == ["warning: turn: this model has no turn-right unit (it has walk); its walk is steered without "
                    "turning steps"], done.stdout + done.stderr


@pytest.mark.parametrize("going_frames", [25, 35])  # its first step begins 19 frames on: stopped at levels 0.29 and 0.78
def test_a_body_stopped_while_it_sets_off_brakes_without_a_jolt(model, going_frames):
    """Walk, stand, set off, and stand again before the first step is done: the body brakes from
    the travel and stride it had (its start eased by a smootherstep, its braking by a smoothstep).
    Moved at once to its level's smoothstep, the stride fell from 0.93 to 0.85 in a frame and a
    joint jumped 1.22 times the steady walk's (masculine x2)."""
    from instrument.evaluation.sequence import velocity_jumps
    from instrument.motion.bvh import Motion
    from instrument.motion.kinematics import ChannelStream
    from instrument.motion.kinematics import world_positions as positions_of

    engine = Engine(model)
    base = default_controls(model, {"masculine": 2.0})
    moving, stand = Controls(base.weights, gait=WALK), Controls(base.weights, gait=STAND)
    plan = [(moving, 135), (stand, 60), (moving, going_frames), (stand, 75)]
    channels = ChannelStream(model.layout.skeleton)
    rows, levels = [], []
    for controls, frames in plan:
        for _ in range(frames):
            pose = engine.frame(len(rows) / engine.fps, controls)
            rows.append(channels.next(pose.rotations[0], pose.translations[0]))
            levels.append(float(engine.units.level[0]))
    halted = 135 + 60 + going_frames
    assert 0.0 < levels[halted - 1] < 1.0  # told to stand while it still set off
    jumps = velocity_jumps(positions_of(Motion(model.layout.skeleton, np.array(rows), model.fps)))
    assert jumps[halted - 1:].max() <= 1.1 * jumps[15:135].max()


def _play(engine: Engine, plan: list[tuple[Controls, int]], read=lambda engine: None) -> list:
    """The engine's frames through a plan of (controls, frames), and what `read` reads of the
    engine after each."""
    seen = []
    for controls, frames in plan:
        for _ in range(frames):
            engine.frame(len(seen) / engine.fps, controls)
            seen.append(read(engine))
    return seen


@pytest.mark.parametrize("going_frames", [15, 16, 20, 24, 28])  # in a run's first step (before, at and after its
def test_a_run_stopped_while_it_sets_off_brakes_its_legs_with_its_travel(model, going_frames):  # toe-off) and second
    """A run's start eases each leg apart from the rest of the pose (with the travel while it is the
    stance leg, over its step while it swings, over two pushes); told to stand during it, each
    leg's share of its swing is drawn down from where it was, not snapped to the rest's (0.80 ->
    0.25 in a frame, masculine x2: a joint jumped 2.3 times the steady run's): across the stop it
    changes in a frame no more than it did in the start itself."""
    def leg_shares(engine: Engine) -> list[float]:
        units = engine.units
        strides = units.strides()[0] if units.shortening else np.ones(model.layout.dimension)
        return [float(strides[leg].mean()) for leg in units.legs]

    base = default_controls(model, {"masculine": 2.0})
    moving, stand = Controls(base.weights, gait=RUN), Controls(base.weights, gait=STAND)
    shares = np.array(_play(Engine(model), [(moving, 135), (stand, 60), (moving, going_frames), (stand, 60)], leg_shares))
    cue, halted = 135 + 60, 135 + 60 + going_frames
    change = np.abs(np.diff(shares, axis=0)).max(axis=1)
    assert change[cue:halted - 1].max() > 0.05  # it did set off: the legs eased in
    assert shares[cue:halted].min() < 1.0 and (shares[-1] == 1.0).all()  # and stood still again at the end
    assert change[halted - 2:].max() <= change[cue:halted - 1].max() + 1e-9


@pytest.mark.parametrize("slowed_at", [14, 16, 18])  # frames after the run cue: in the first step
def test_a_run_start_slowed_in_its_first_step_still_reaches_its_speed(model, slowed_at):
    """A two-push start's pose eases over both steps at the plan's pace when it began; slowed in
    its first step (speed 0.5), that level reached 1 before the second push began, the start
    ended with the travel at the first push's share, and the body ran on at half its travel (its
    feet at full stride, skating) for good (a reviewer's find). It ends only once the travel and
    both legs are there too."""
    engine = Engine(model)
    base = default_controls(model, {"normal": 2.0})
    _play(engine, [(Controls(base.weights, gait=RUN), 100), (Controls(base.weights, gait=STAND), 60),
                   (Controls(base.weights, gait=RUN), slowed_at), (Controls(base.weights, gait=RUN, speed=0.5), 200)])
    units = engine.units
    assert units.travel[0] == 1.0 and not units.starting[0] and not units.shortening


def _travel_and_units(engine: Engine, weights: dict[str, float], plan: list[tuple[int, int]]) -> tuple[list[float], list[int]]:
    """One character's travel share and the unit of its step under way, frame by frame, through a
    plan of (gait, frames) at `weights`."""
    base = default_controls(engine.model, weights)
    read = _play(engine, [(Controls(base.weights, gait=gait), frames) for gait, frames in plan],
                 lambda engine: (float(engine.units.travel[0]), int(engine.stream.counters[0, LABEL]) // 2))
    return [travel for travel, _ in read], [unit for _, unit in read]


@pytest.mark.parametrize("then", [RUN, WALK])
def test_a_second_start_stands_still_until_its_first_step(model, then):
    """A body that set off over two pushes kept its second push's flag: told to move again, it
    took the first push's share of its travel (0.5) while it still stood, its hips drifting and a
    walk's start no longer the walk's (a reviewer's find). Its travel is 0 until its first step."""
    engine = Engine(model)
    travel, units = _travel_and_units(engine, {"normal": 1.0}, [(RUN, 100), (STAND, 90), (RUN, 60), (STAND, 90), (then, 40)])
    standing = [unit == engine.units.stand for unit in units]
    cue = 100 + 90 + 60 + 90
    first_step = cue + standing[cue:].index(False)
    assert standing[cue - 1] and first_step > cue  # it stood still when told, and stood on a while
    assert max(travel[cue:first_step]) == 0.0
    assert max(travel[first_step:]) > 0.5  # and then it set off


@pytest.mark.parametrize("gait, style, going, stopped", [(RUN, "active", 30, 8), (WALK, "feminine", 30, 8)])
def test_a_stop_called_off_late_goes_on_without_standing_a_step(model, gait, style, going, stopped):
    """A stop called off within a step's notice of its stand made the change wait a step: the
    stand came anyway, for one step, and the body's travel fell from where its braking had got to
    (0.55 of its gait's, active's run) to 0 in one frame (a reviewer's find). Called off, it goes
    on: its travel changes in a frame no more than a braking smoothstep over STOP_SECONDS does."""
    engine = Engine(model)
    travel, units = _travel_and_units(engine, {style: 1.0}, [(gait, 135), (STAND, 60), (gait, going), (STAND, stopped), (gait, 60)])
    called_off = 135 + 60 + going + stopped
    assert engine.units.stand not in units[called_off:]  # it never stood again
    assert np.abs(np.diff(travel[called_off - stopped:])).max() <= 1.5 / (STOP_SECONDS * model.fps) + 1e-9


@pytest.mark.parametrize("gait, stopped", [(WALK, 17), (RUN, 11)])
def test_a_stop_called_off_takes_its_stride_back_with_its_travel(model, gait, stopped):
    """Braking, a body's stride (the share of its steps' swing) follows its level down, so the
    stance foot comes under the body no faster than it slows; called off before the stand, the
    stride came back up over STOP_SECONDS on its own, ahead of the travel (0.33 against 0.31 the
    first frame, youthful's walk), sweeping the stance foot back faster than the body sped up:
    the lock held it 30 cm ahead of the pose's and it snapped back as it let go (a toe jumping
    2.1 times the steady walk's). It comes back up no faster than the level."""
    engine = Engine(model)
    base = default_controls(model, {"youthful": 1.0})
    read = _play(engine, [(Controls(base.weights, gait=gait), 135), (Controls(base.weights, gait=STAND), stopped),
                          (Controls(base.weights, gait=gait), 45)],
                 lambda engine: (float(engine.units.travel[0]), float(engine.units.stride[0])))
    travel, stride = np.array(read).T
    called_off = 135 + stopped
    assert stride[called_off - 1] < 0.9  # it had braked
    assert (stride[called_off:] <= travel[called_off:] + 1e-9).all()
    assert stride[-1] == travel[-1] == 1.0  # and it is back at its gait


def test_a_stop_called_off_lets_its_planted_foot_go_where_the_lock_holds_it(model):
    """Called off, a braking body's pose took its stride back with its travel, the planted leg's
    too: its share rose through the end of its stance, where the foot is furthest behind the
    hips, sweeping the foot as made 27 cm behind where the lock held it, and as the lock let go
    the foot snapped back and then swung forward (youthful's walk called off 17 frames after the
    stop: Toes_R jumped 10.7 cm/frame^2, 1.9 times the steady walk's largest). The planted leg
    now goes to the share that puts its foot at the lock as it lets go, then to the rest's over
    its swing: no joint jumps more than the steady walk's largest within 30% (1.10 times measured)."""
    from instrument.evaluation.sequence import render_sequence, velocity_jumps
    from instrument.motion.kinematics import world_positions as positions_of

    base = default_controls(model, {"youthful": 1.0})
    moving, stand = Controls(base.weights, gait=WALK), Controls(base.weights, gait=STAND)
    sequence = render_sequence(model, [(moving, 135), (stand, 17), (moving, 45)])
    jumps = velocity_jumps(positions_of(sequence.motion))
    steady = jumps[15:135].max()  # the walk before the stop, settled
    assert set(sequence.labels[135:] // 2) == {model.units.index("walk")}  # it never stood
    assert jumps[135 + 17:].max() <= 1.3 * steady


def test_a_stop_called_off_twice_rejoins_from_where_its_legs_are(model):
    """Stopped again while it rejoined (its legs braking from their own shares) and called off a
    second time, a body went on by closing its legs' gaps as a halted start does: the planted
    leg's share rose with the rest through the end of its stance, the sweep the first call-off
    no longer makes (feminine's walk, stops of 12 and 8 frames 6 apart: a joint jumped 1.56
    times the steady walk's largest). It rejoins from where its legs are: 1.34 measured."""
    from instrument.evaluation.sequence import render_sequence, velocity_jumps
    from instrument.motion.kinematics import world_positions as positions_of

    base = default_controls(model, {"feminine": 1.0})
    moving, stand = Controls(base.weights, gait=WALK), Controls(base.weights, gait=STAND)
    sequence = render_sequence(model, [(moving, 135), (stand, 12), (moving, 6), (stand, 8), (moving, 60)])
    jumps = velocity_jumps(positions_of(sequence.motion))
    steady = jumps[15:135].max()  # the walk before the stop, settled
    assert set(sequence.labels[135:] // 2) == {model.units.index("walk")}  # it never stood
    assert jumps[135 + 12 + 6 + 8:].max() <= 1.45 * steady


@pytest.mark.parametrize("gait, style, gap", [(WALK, "normal", 5), (RUN, "active", 2)])
def test_a_start_called_off_before_its_first_step_stands_on(model, gait, style, gap):
    """Told to move in the last frames of a stand's step, the change waits a step (NOTICE_SECONDS)
    and the body holds the pose it stood in; told to stand again `gap` frames later, it stands on
    at once (had the stop waited too, the body took its gait's first step in place: a hand jumped
    3.6 times the steady walk's). Its stand goes on as it was: the stream's last frames put back
    as they were when it was told to move (bent towards the coming step meanwhile, they came back
    over 20 frames) and the pose eased back in from the one it held, not drawn to the stand's means
    from it (a joint jumped 3-8 times the stand's own largest). Now no joint jumps more than the
    stand's own largest before the start, within half again (the ease back adds its curve to the
    sway's: 1.05-1.2 times measured)."""
    from instrument.evaluation.sequence import render_sequence, velocity_jumps
    from instrument.motion.kinematics import world_positions as positions_of

    base = default_controls(model, {style: 1.0})
    moving, stand = Controls(base.weights, gait=gait), Controls(base.weights, gait=STAND)
    sequence = render_sequence(model, [(moving, 135), (stand, 120), (moving, gap), (stand, 45)])
    told = 135 + 120
    units = sequence.labels // 2
    stand_unit = model.units.index("stand")
    assert set(units[told - 15:]) == {stand_unit}  # it stood when told to move, and stood on
    jumps = velocity_jumps(positions_of(sequence.motion))
    own = jumps[told - 55:told].max()  # the stand's own, settled
    assert jumps[told:].max() <= 1.5 * own


@pytest.mark.parametrize("style, gap", [("normal", 5), ("active", 2)])
def test_a_start_called_off_while_a_wave_plays_leaves_the_arm_where_the_wave_has_it(model, style, gap):
    """A start called off puts the stream's frames back as they were when the body was told to
    move, but not while a gesture plays: the gait's frames then hold the gesture's upper body,
    which moved on meanwhile (put back, the arm jumped back along its wave: 6.7-21 cm/frame^2
    against 1.3-4.5). Every joint moves as in the same wave with no start told."""
    from instrument.evaluation.sequence import render_sequence, velocity_jumps
    from instrument.motion.kinematics import world_positions as positions_of

    weights = default_controls(model, {style: 1.0}).weights
    stand, waving = Controls(weights, gait=STAND), Controls(weights, gait=STAND, gestures=("wave",))
    walking = Controls(weights, gait=WALK, gestures=("wave",))
    told = render_sequence(model, [(stand, 150), (waving, 105), (walking, gap), (waving, 45)])
    untold = render_sequence(model, [(stand, 150), (waving, 105 + gap + 45)])
    jumps, own = (velocity_jumps(positions_of(s.motion))[255:].max() for s in (told, untold))
    assert jumps <= 1.05 * own


@pytest.mark.parametrize("frames", [1, 2])
def test_a_start_told_at_the_first_frame_and_called_off_stands_as_a_stand(model, frames):
    """Told to move at the stream's second frame and to stand again right after, there are no
    two frames of its own to put back (the stream's first frame's zeros were taken for a known
    frame: a leg jumped 13 times the stand's own). The body stands within four times a plain
    stand's largest jump over the same frames: told for 1 and 2 frames, its hands jump 0.08 and
    0.17 cm/frame^2 as the held pose eases over the start and back (the lock does not move them),
    against the plain stand's 0.057 at a knee; 0.097 (its toes at the second frame) before a
    walk's release went in joint space and a landing's hold came in eased out, when the bound
    was twice it (1.7x)."""
    from instrument.evaluation.sequence import render_sequence, velocity_jumps
    from instrument.motion.kinematics import world_positions as positions_of

    weights = default_controls(model, {"normal": 1.0}).weights
    stand, walking = Controls(weights, gait=STAND), Controls(weights, gait=WALK)
    told = render_sequence(model, [(stand, 1), (walking, frames), (stand, 58)])
    plain = render_sequence(model, [(stand, 60)])
    jumps, own = (velocity_jumps(positions_of(s.motion)).max() for s in (told, plain))
    assert jumps <= 4.0 * own


def _step_state_frames(labels: np.ndarray, states: np.ndarray) -> list[tuple[int, tuple[int, ...]]]:
    """Each whole step of a character's frames: (label, frames of each of its states)."""
    steps, first = [], 0
    for end in np.flatnonzero(np.diff(labels) != 0) + 1:
        if first > 0:  # the first run of frames may be a step begun before the window
            part = states[first:end]
            steps.append((int(labels[first]), tuple(np.bincount(part, minlength=int(part.max()) + 1).tolist())))
        first = end
    return steps


@pytest.mark.parametrize("gait, weights, moving_frames", [
    (RUN, {"active": 2.0}, 138), (WALK, {"active": 1.0}, 100), (WALK, {"masculine": 1.0}, 100)])
def test_a_gait_set_off_again_pairs_its_right_and_left_steps_as_from_rest(model, gait, weights, moving_frames):
    """After a stop and a restart, each leading step and the following step after it take the
    same frames state by state, as from rest (stream._plan: the pair's mirror models then cancel
    each other's turn). Each label kept its own fraction of a frame across the stand, so a gait
    left after an odd number of steps came back with its two feet's fractions apart for good:
    active x2's run went on 14 and 15 frames a step, the walk curved 4 degrees a minute."""
    _, _, _, labels, states, _ = _engine_frames(model, [(gait, moving_frames), (STAND, 90), (gait, 240)],
                                                weights=weights)
    stand = 2 * model.units.index("stand")
    steps = [step for step in _step_state_frames(labels[moving_frames:, 0], states[moving_frames:, 0])]
    again = [k for k, (label, _) in enumerate(steps) if label >= stand][-1] + 1  # the first step set off again
    pairs = list(zip(steps[again:-1:2], steps[again + 1::2]))  # (leading step, the step after it)
    assert len(pairs) >= 4 and all(a[0] // 2 == b[0] // 2 != stand // 2 and a[0] != b[0] for a, b in pairs)
    assert all(a[1] == b[1] for a, b in pairs), pairs
