"""Style adaptation against styles sampled from known models: re-aligned EM, shared transforms,
the duration floor, and settings chosen by held-out likelihood."""


from dataclasses import replace

import numpy as np
import pytest

from conftest import REPO, needs_walks, walk_files
from instrument.training.adaptation import (DEFAULT, ONE_PASS_MAP, REFERENCE_FPS, TAUS, Settings, adapt, adapt_styles,
                                          alignment, combined, duration_floor, floored_keeping_length, heldout_score,
                                          unit_folds)
from instrument.models.hsmm import HSMM, Floors
from instrument.training.average import train_average, variance_floors
from instrument.training.corpus import load_corpus, segments_by_label, styled_takes
from test_hsmm import STATES, TRUE_DURATION_MEANS, sample

FLOORS = Floors(np.full(2, 1e-3))
SHIFT = np.array([2.0, -1.0])


@pytest.fixture(scope="module")
def average():
    rng = np.random.default_rng(11)
    return train_average([sample(0, 200, rng), sample(1, 200, rng)], STATES, FLOORS, iterations=40, tolerance=1e-6)


def shifted(count: int, seed: int, stretch: int = 0) -> list[list[np.ndarray]]:
    """A style: every output shifted by SHIFT, and (with `stretch`) state 2 of each step held
    `stretch` frames longer, so lambda 0's alignment of it is wrong."""
    rng = np.random.default_rng(seed)
    out = []
    for label in range(2):
        steps = []
        for s in sample(label, count, rng):
            if stretch:
                s = np.vstack([s[:1]] * stretch + [s])
            steps.append(s + SHIFT)
        out.append(steps)
    return out


def test_no_data_gives_the_average(average):
    adapted = adapt(average, [[], []], FLOORS)
    for name in ("means", "variances", "duration_means", "duration_variances"):
        np.testing.assert_array_equal(getattr(adapted, name), getattr(average, name))


def test_re_aligned_em_explains_the_style_better_than_one_pass(average):
    data, held = shifted(100, 1, stretch=4), shifted(50, 2, stretch=4)
    trace: list[float] = []
    realigned = adapt(average, data, FLOORS, Settings(depth=None, tau=10.0), trace)
    one_pass = adapt(average, data, FLOORS, ONE_PASS_MAP)
    assert len(trace) >= 2 and trace[-1] > trace[0]
    assert all(b >= a - 1e-6 for a, b in zip(trace, trace[1:]))
    ll_realigned, frames = heldout_score(realigned, held)
    ll_one_pass, _ = heldout_score(one_pass, held)
    assert ll_realigned / frames > ll_one_pass / frames
    np.testing.assert_allclose(realigned.means - average.means, np.broadcast_to(SHIFT, average.means.shape), atol=0.3)


def test_a_shared_transform_moves_every_state_from_a_few_steps(average):
    few = shifted(3, 3)
    transformed = adapt(average, few, FLOORS, Settings(depth=0, tau=16.0))
    map_only = adapt(average, few, FLOORS, ONE_PASS_MAP)
    error = lambda m: np.abs(m.means - average.means - SHIFT).mean()  # noqa: E731
    assert error(transformed) < 0.5 * error(map_only)
    assert error(transformed) < 0.3


def test_durations_never_fall_below_the_floor(average):
    rng = np.random.default_rng(4)
    # steps whose first state lasts a single frame: plain EM would shrink that state to ~1 frame
    data = [[np.vstack([s[:1], s[int(TRUE_DURATION_MEANS[k, 0]) :]]) for s in sample(k, 60, rng)] for k in range(2)]
    floor = duration_floor(average, data, DEFAULT.floor_share)
    assert (floor >= 1.0).all()
    free = adapt(average, data, FLOORS, Settings(depth=None, tau=1.0, floor_share=0.0))
    floored = adapt(average, data, FLOORS, Settings(depth=None, tau=1.0))
    assert free.duration_means.min() < floor.min()
    assert (floored.duration_means >= floor - 1e-12).all()
    # the floor takes its frames from the other states: the step lasts as the data's steps do
    lengths = np.array([np.mean([len(s) for s in label]) for label in data])
    np.testing.assert_allclose(floored.duration_means.sum(axis=1), lengths, rtol=0.02)
    assert np.abs(np.maximum(free.duration_means, floor).sum(axis=1) - lengths).max() > 0.2  # raising alone: longer


def test_a_floor_keeps_the_steps_length_where_it_can():
    means = np.array([[1.0, 6.0, 3.0, 2.0], [4.0, 4.0, 4.0, 4.0], [0.5, 0.5, 0.5, 0.5], [0.5, 2.0, 2.0, 0.1]])
    floor = np.array([[2.0, 1.0, 2.9, 1.0], [1.0, 1.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0], [2.7, 1.9, 0.1, 0.1]])
    out = floored_keeping_length(means, floor)
    assert (out >= floor - 1e-12).all()
    np.testing.assert_allclose(out[:2].sum(axis=1), means[:2].sum(axis=1))  # the length kept
    np.testing.assert_allclose(out[1], means[1])  # nothing under its floor: unchanged
    np.testing.assert_allclose(out[0, 2], 2.9)  # pushed under its floor by the others' share: held there
    np.testing.assert_allclose(out[0, [1, 3]] / out[0, [1, 3]].sum(), [0.75, 0.25])  # the rest in proportion
    np.testing.assert_allclose(out[2], floor[2])  # no room at all: every state at its floor
    np.testing.assert_allclose(out[3], floor[3])  # room used up on the way: the rest at their floors too


def test_styles_choose_their_settings_and_tiny_styles_warn(average):
    many = [shifted(20, 5 + k) for k in range(4)]  # four takes
    tiny = [shifted(2, 9)]  # one take, two steps a label
    report: list[str] = []
    styles, chosen = adapt_styles(average, {"many": [("walk", t) for t in many], "tiny": [("walk", t) for t in tiny]},
                                  FLOORS, report)
    assert any("'tiny'" in w for w in report)  # said once, by whoever reads the report
    assert not any("'many'" in w for w in report)
    assert chosen["many"].heldout_loglik_per_frame is not None and chosen["tiny"].heldout_loglik_per_frame is None
    assert chosen["tiny"].settings == DEFAULT
    assert styles.means.shape == (2,) + average.means.shape
    for k in range(2):  # both styles move toward the shift, the one with data closer
        assert np.abs(styles.means[k] - average.means - SHIFT).mean() < np.abs(SHIFT).mean()
    assert np.isfinite(styles.variances).all() and (styles.variances > 0).all()


def test_a_style_adapts_alike_at_any_frame_rate(average):
    """The same steps sampled four times as often (each frame held four frames, as a 120 fps take
    of a 30 fps one) with lambda 0 at that rate: the style comes out the same, its durations in
    seconds. The prior's weight is data in seconds, and the duration floor a time: counted in
    frames, a 120 fps style's data outweighed its prior four times sooner and its floor was a
    quarter as long."""
    rate = 4
    fine = HSMM(average.means, average.variances, average.duration_means * rate, average.duration_variances * rate**2)
    few = shifted(3, 3)  # little data: where the prior's weight shows
    held = [[np.repeat(s, rate, axis=0) for s in label] for label in few]
    fps = REFERENCE_FPS * rate
    np.testing.assert_allclose(duration_floor(fine, held, DEFAULT.floor_share, fps) / rate,
                               duration_floor(average, few, DEFAULT.floor_share), rtol=1e-12)
    in_frames = duration_floor(fine, held, DEFAULT.floor_share)  # the floor as frames of the fine rate
    assert (in_frames / rate < duration_floor(average, few, DEFAULT.floor_share) - 0.5).any()
    for depth in (None, 0):  # MAP alone, and a shared transform under it
        settings = Settings(depth=depth, tau=16.0)
        reference = adapt(average, few, FLOORS, settings)
        at_rate = adapt(fine, held, FLOORS, settings, fps=fps)
        np.testing.assert_allclose(at_rate.means, reference.means, atol=1e-9)
        np.testing.assert_allclose(at_rate.duration_means / rate, reference.duration_means, atol=1e-9)
        in_frames = adapt(fine, held, FLOORS, settings)  # the weight as frames of the fine rate
        assert np.abs(in_frames.means - reference.means).max() > 0.3


def merged(takes: list[list[list[np.ndarray]]]) -> list[list[np.ndarray]]:
    """Takes' steps (take, label, step) as one list of steps per label."""
    return [[s for take in takes for s in take[k]] for k in range(len(takes[0]))]


def test_a_walks_only_corpus_trains_as_one_walk_setting_per_style(average):
    """Walks alone, one unit: each style is the adaptation of all its steps with its walk's settings,
    from lambda 0's alignment as the style was adapted before units were chosen apart (summed over
    the alternate takes' or the one take's halves when chosen; all steps at once when too few to
    choose), to the bit. A too-short walk was aligned in halves and summed, and came out 3.5e-12
    away in its means with other durations and likelihoods."""
    corpus = {"many": [shifted(6, 20 + k) for k in range(3)], "one": [shifted(8, 30)], "tiny": [shifted(2, 31)]}
    warnings: list[str] = []
    styles, report = adapt_styles(average, {s: [("walk", t) for t in takes] for s, takes in corpus.items()}, FLOORS,
                                  warnings)
    assert [report[s].units["walk"].folds for s in corpus] == ["takes", "halves", "default"]
    assert len(warnings) == 1 and "'tiny'" in warnings[0] and "its walk" in warnings[0]
    for i, (style, takes) in enumerate(corpus.items()):
        if len(takes) >= 2:  # alternate takes
            folds = [merged(takes[0::2]), merged(takes[1::2])]
        else:  # the one take's halves
            folds = [[label[: len(label) // 2] for label in takes[0]], [label[len(label) // 2 :] for label in takes[0]]]
        first = None if style == "tiny" else combined(*(alignment(average, fold) for fold in folds))
        trace: list[float] = []
        alone = adapt(average, merged(takes), FLOORS, report[style].settings, trace, first)
        for name in ("means", "variances", "duration_means", "duration_variances"):
            np.testing.assert_array_equal(getattr(styles, name)[i], getattr(alone, name), err_msg=f"{style} {name}")
        assert report[style].loglik_per_frame == trace


def test_each_unit_is_split_in_folds_on_its_own():
    """Three walks and one run: the walks alternate between the folds, the run's one take is cut in
    its halves (split with the walks, it lay in one fold and was scored only where no run had been
    adapted)."""
    folds, how = unit_folds([take("walk", 2, 0.0), take("run", 4, 10.0), take("walk", 2, 20.0), take("walk", 2, 30.0)],
                            UNITS)
    assert how == {"walk": "takes", "run": "halves"}
    marks = fold_marks(folds)
    assert marks[0][0] == [0.0, 1.0, 30.0, 31.0] and marks[1][0] == [20.0, 21.0]  # walks 1 and 3, walk 2
    assert marks[0][2] == [10.0, 11.0] and marks[1][2] == [12.0, 13.0]  # the run's first and second half


def test_takes_that_leave_a_fold_without_a_foot_are_split_in_halves():
    """A unit is split by takes only where each fold then holds a step of each foot: a run of one
    long take and one of a single right step is split in the halves of its steps (by takes, the
    second fold had no left step to score), and walks whose alternate takes both hold both feet
    still alternate."""
    one_foot = ("run", [[], [], [np.full((3, 2), 20.0)], []])
    folds, how = unit_folds([take("walk", 2, 0.0), take("run", 4, 10.0), take("walk", 1, 30.0), one_foot], UNITS)
    assert how == {"walk": "takes", "run": "halves"}
    marks = fold_marks(folds)
    assert marks[0][0] == [0.0, 1.0] and marks[1][0] == [30.0]  # walk 1, walk 2
    assert marks[0][2] == [10.0, 11.0] and marks[1][2] == [12.0, 13.0, 20.0]  # the run's right steps in halves
    assert marks[0][3] == [10.0, 11.0] and marks[1][3] == [12.0, 13.0]  # and its left: a step of each in each fold


UNITS = ("walk", "run")


def take(unit: str, steps: int, mark: float) -> tuple[str, list[list[np.ndarray]]]:
    """A take of `steps` steps a foot of `unit` (UNITS), each step's frames all `mark` plus its index."""
    label = [np.full((3, 2), mark + i) for i in range(steps)]
    return unit, ([label, label, [], []] if unit == "walk" else [[], [], label, label])


def fold_marks(folds: list[list[list[np.ndarray]]]) -> list[list[list[float]]]:
    """Which steps each fold's labels hold, by their marks (see take)."""
    return [[[float(s[0, 0]) for s in label] for label in fold] for fold in folds]


MOTIONS = REPO.parent / "shared" / "data" / "bandai-motions"


@needs_walks
@pytest.mark.skipif(not MOTIONS.is_dir(), reason=f"runs not found in {MOTIONS}")
def test_a_one_take_run_is_adapted_with_its_own_prior_not_the_walks():
    """Walks and one run take a style (harden8's corpus, smaller: feminine's 27 walks, three of
    each other style's, every style's first run). Chosen on all the style's steps, feminine's
    walk's tau 64 held its run too, and its 3-4 steps a foot kept a third of the take (its flight
    halved in the made run). Each unit now has its own: the walk what its own held-out takes
    choose, the run, too short to split (`few`), the walk's depth with the smallest prior whatever
    tau the walk chose. Scored on feminine's 11 other run takes (never trained on), the made run
    explains them better per frame than the run adapted at the walk's depth with tau 64 (491.8
    against 468.7 when written), the prior a walk's choice of 64 held it to."""
    runs = sorted(MOTIONS.glob("dataset-2_run_*_001.bvh"))
    held = sorted(set(MOTIONS.glob("dataset-2_run_feminine_*.bvh")) - set(runs))
    walks = [f for f in walk_files() if "_feminine_" in f.name]
    for style in {f.stem.split("_")[2] for f in runs} - {"feminine"}:
        walks += [f for f in walk_files() if f"_{style}_" in f.name][:3]
    _, takes, _, _ = load_corpus(styled_takes(walks + runs + held), 30.0)
    units = ["walk", "run"]
    train = [t for t in takes if t.path not in held]
    segments = segments_by_label(train, 5, units)
    floors = variance_floors(segments)
    average = train_average(segments, 5, floors)
    feminine = [t for t in train if t.style == "feminine"]
    styles, report = adapt_styles(average, {"feminine": [(t.unit, segments_by_label([t], 5, units)) for t in feminine]},
                                  floors, [], units=units)
    chosen = report["feminine"]
    walk, run = chosen.units["walk"], chosen.units["run"]
    assert walk.folds == "takes" and walk.settings == chosen.settings
    assert run.folds == "few" and run.heldout_loglik_per_frame is None
    assert run.settings == replace(walk.settings, tau=TAUS[0])
    runs_only = segments_by_label([t for t in takes if t.path in held], 5, units)
    others = [label if k >= 2 else [] for k, label in enumerate(runs_only)]  # the run's labels only
    own, frames = heldout_score(HSMM(*(getattr(styles, f)[0] for f in HSMM.__dataclass_fields__)), others)
    held_to = adapt(average, segments_by_label(feminine, 5, units), floors, replace(run.settings, tau=64.0))
    at_64, _ = heldout_score(held_to, others)
    assert frames > 500 and own / frames > at_64 / frames + 10.0, (own / frames, at_64 / frames)
