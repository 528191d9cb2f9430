"""`instrument evaluate --units`: runs, turns and stands against their real takes, stops and starts.

Small cases on the shipped model and on real takes; the full benchmark of issue 25's targets is
examples/units_figures.py (docs/evaluate.md)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest
from conftest import SHARED_WALKS

from instrument.evaluation.assessment import model_limbs
from instrument.evaluation.sequence import velocity_jumps
from instrument.evaluation.transitions import settled, transition_figures
from instrument.evaluation.units import _Measure, _model_ground, assess_units
from instrument.motion.bvh import Motion, read_bvh
from instrument.motion.kinematics import world_positions

MOTIONS = SHARED_WALKS.parent / "bandai-motions"
needs_motions = pytest.mark.skipif(not (MOTIONS.is_dir() and SHARED_WALKS.is_dir()),
                                   reason=f"real takes not found in {SHARED_WALKS} and {MOTIONS}")


def cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "instrument", *args], capture_output=True, text=True, timeout=900)


@pytest.fixture(scope="module")
def measure(model):
    limbs, cm, template = model_limbs(model)
    return _Measure(model, limbs, cm, _model_ground(model, limbs, template))


def test_a_stand_stays_put_and_a_run_outpaces_the_walk_of_its_style(model):
    """The stand's hips under 6 cm/s and feet under 2 (issue 25), the run faster than the walk
    with shorter steps, the turn turning the way it is steered."""
    from instrument.evaluation.assessment import assess

    units = assess_units(model, styles=["normal"], seconds=3.0, sections=("run", "stand", "turn"))
    walk = assess(model, 3.0, styles=["normal"], kinds=("one",)).synth["normal"]
    stand, run = units.synth["stand"]["normal"], units.synth["run"]["normal"]
    assert stand["hips_cm_s"] < 6.0 and stand["feet_cm_s"] < 2.0
    assert run["speed_cm_s"] > 1.2 * walk["speed_cm_s"] and run["step_s"] < walk["step_s"]
    left, right = units.synth["turn"]["normal left"], units.synth["turn"]["normal right"]
    assert left["turn_signed_deg_s"] > 5.0 and right["turn_signed_deg_s"] < -5.0
    assert set(units.synth["run"]) == {"normal", "normal x2", "normal -1"}  # x2 and -1 are measured too


def test_a_walk_stops_within_two_steps_and_sets_off_again(model, measure):
    """walk -> stand -> walk through the engine: still within two steps of the command, back at
    90% of the walking speed within two steps, no foot skating as the worst extrapolated walks
    may (12 cm/s, docs/evaluate.md; the 1.2x-real target is the benchmark's), none in the air."""
    figures = transition_figures(model, "walk", {"normal": 1.0}, measure)
    stop, start = figures["walk->stand"], figures["stand->walk"]
    assert 1 <= stop["stop_steps"] <= 2 and 0.0 < stop["stop_s"] < 2.0
    assert 1 <= start["speed_steps"] <= 2 and 0.0 < start["speed_s"] < 2.0
    assert stop["steady_cm_s"] > 80.0  # it was walking before
    assert stop["slide_cm_s"] < 12.0 and start["slide_cm_s"] < 12.0
    assert stop["air_frames"] == 0 and start["air_frames"] == 0


def test_settled_is_where_stillness_lasts_to_the_end():
    assert settled(np.array([False, True, False, True, True])) == 3
    assert settled(np.array([True, True])) == 0
    assert settled(np.array([True, True, False])) is None  # moving at the end: never stopped


@needs_motions
def test_the_jump_measure_finds_a_pop_injected_into_a_real_take(model):
    """A knee snapped 25 degrees for one frame of a real walk (a pop) is a jump far above the take's own largest."""
    take = read_bvh(sorted(SHARED_WALKS.glob("*_normal_*.bvh"))[0])
    clean = velocity_jumps(world_positions(take))
    knee = model_limbs(model)[0].legs[0].knee  # the shipped model's skeleton is the takes'
    channels = take.channels.copy()
    first = int(take.skeleton.channel_start()[knee]) + take.skeleton.joints[knee].channels.index("Xrotation")
    channels[60, first] += 25.0
    popped = velocity_jumps(world_positions(Motion(take.skeleton, channels, take.fps)))
    assert clean.max() < 8.0
    assert popped.max() > 1.5 * clean.max() and int(np.argmax(popped)) in (60, 61, 62)


@needs_motions
def test_evaluate_units_prints_each_unit_beside_its_real_takes(tmp_path):
    for pattern in ("walk_elderly", "run_elderly", "walk-turn-left_elderly", "raise-up-both-hands_elderly",
                    "walk_active", "run_active", "walk-turn-left_active", "raise-up-both-hands_active"):
        folder = SHARED_WALKS if pattern.startswith("walk_") else MOTIONS
        for take in sorted(folder.glob(f"*_{pattern}_*.bvh"))[:2]:
            (tmp_path / take.name).symlink_to(take)
    result = cli("evaluate", "--styles", "elderly", "--variants", "one", "--seconds", "2", "--units",
                 "--real", str(SHARED_WALKS / "nonexistent-subfolder-not-used"), "--real", str(tmp_path))
    assert result.returncode == 1 and "nonexistent-subfolder-not-used: no such folder" in result.stderr
    assert len(result.stderr.strip().splitlines()) == 1  # refused in one line, before any work
    result = cli("evaluate", "--styles", "elderly", "--variants", "one", "--seconds", "2", "--units", "--real", str(tmp_path))
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    for heading in ("| run |", "| turn |", "| stand |", "| transition |", "| target |"):
        assert any(line.startswith(heading) for line in lines), heading
    for row in ("| elderly (real) |", "| elderly x2 |", "| elderly left (real) |", "| walk->stand elderly -1 |",
                "| stand->run elderly x2 |"):
        assert any(line.startswith(row) for line in lines), row
    targets = [line for line in lines if line.startswith("| run speed cm/s | elderly |")]
    assert len(targets) == 1 and ("PASS" in targets[0] or "FAIL" in targets[0])


def test_a_transition_past_the_styles_is_held_to_its_gait_at_those_weights():
    """The jump target: at weight 1 the style's real takes bound a transition, whatever its gait
    does; at x2 the larger of all styles' takes and the gait's own jump in the same sequence, so a
    swing wider than any take's passes and a pop beyond the gait's own swing fails."""
    from instrument.evaluation.targets import check
    from instrument.evaluation.units import UnitAssessment

    def jump_row(name: str, weight: float, jump: float, gait_jump: float):
        result = UnitAssessment(weights={name.split(" ", 1)[1]: {"active": weight}},
                                real_jumps={"walk": {"all": 10.0, "active": 8.0}})
        result.transitions[name] = {"stop_steps": 1.0, "jump_cm_f2": jump, "jump_joint": "Hand_R",
                                    "gait_jump_cm_f2": gait_jump, "slide_cm_s": 1.0, "air_frames": 0.0, "window_frames": 30.0}
        return next(row for row in check(result) if row.target == "transition jump cm/frame^2")

    assert jump_row("walk->stand active", 1.0, 9.0, 12.0).passed is False  # weight 1: the style's takes (8)
    assert jump_row("walk->stand active x2", 2.0, 11.0, 9.0).passed is False  # neither the takes (10) nor its gait (9)
    swing = jump_row("walk->stand active x2", 2.0, 13.0, 13.5)
    assert swing.passed and "walk's own" in swing.bound  # the x2 walk swings 13.5 itself
    assert jump_row("walk->stand active x2", 2.0, 14.0, 13.5).passed is False  # a pop beyond it


def test_the_target_rows_are_plain_values_a_json_report_writes():
    """A turn's rate is a numpy float, so its row's comparison was numpy's bool: `evaluate --units
    --json` on a model with turns stopped at json.dumps with a TypeError traceback."""
    import json

    from instrument.evaluation.targets import check
    from instrument.evaluation.units import UnitAssessment

    turn = {"turn_deg_s": np.float64(20.9), "skate_cm_s": np.float64(1.0)}
    result = UnitAssessment(weights={"feminine left": {"feminine": 1.0}}, synth={"turn": {"feminine left": turn}},
                            real={"turn": {"feminine left": {"turn_deg_s": np.float64(21.2), "skate_cm_s": np.float64(1.1)}}})
    rows = check(result)
    assert [r.passed for r in rows] == [True, True]
    assert json.loads(json.dumps([vars(r) for r in rows]))[0]["passed"] is True
