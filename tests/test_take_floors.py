"""Each take on its own floor (issue 30): a capture's floor is not always level from take to take
(the public CMU takes' feet stand 3.5 cm higher in take 02 than in take 01), so `instrument
evaluate` and training's contact labels measure every take against its own floor
(motion/quality.py `take_floors`), and a made walk against their mean."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from instrument.models.hsmm import HSMM
from instrument.motion.bvh import Motion, read_bvh
from instrument.motion.features import choose_layout
from instrument.motion.kinematics import world_positions
from instrument.motion.limbs import centimetres_per_unit, clearance, find_limbs, sole_clearance
from instrument.motion.quality import take_floors, walk_figures
from instrument.synthesis.contact import PLANTED, flight_states
from instrument.training.average import train_average, variance_floors
from instrument.training.contact import air_labels, contact_labels, train_contact
from instrument.training.corpus import load_corpus, segments_by_label, styled_takes

CMU = Path(__file__).parent / "data" / "cmu-131"
FLOOR_FIGURES = ("air_frac", "float_frac", "under_frac", "contact_skate_cm_s")


@pytest.fixture(scope="module")
def take():
    motion = read_bvh(CMU / "cmu131_jackson_01.bvh")
    layout = choose_layout([motion])
    limbs = find_limbs(motion.skeleton, layout.root, np.asarray(layout.template))
    positions = world_positions(motion)
    return motion, layout, limbs, positions, centimetres_per_unit(layout, positions[0])


def lifted(motion: Motion, by: float) -> Motion:
    """The take with its root (and so the whole body and the floor it walks on) `by` units higher."""
    root = motion.skeleton.joints[0]
    column = motion.skeleton.channel_start()[0] + root.channels.index("Yposition")
    channels = motion.channels.copy()
    channels[:, column] += by
    return replace(motion, channels=channels)


def test_a_take_on_a_higher_floor_measures_as_itself(take):
    motion, layout, limbs, positions, cm = take
    high = lifted(motion, 3.5 / cm)  # take 02's floor against take 01's
    floors = take_floors([positions, world_positions(high)], limbs)
    assert floors.sole[1] - floors.sole[0] == pytest.approx(3.5 / cm)
    low_figures = walk_figures(motion, layout, limbs, floors.ground[0], cm, floors.sole[0])
    high_figures = walk_figures(high, layout, limbs, floors.ground[1], cm, floors.sole[1])
    for key in FLOOR_FIGURES:
        assert high_figures[key] == pytest.approx(low_figures[key], abs=1e-9), key
    # one floor for both (the lower take's, as before): the higher take's feet were off the floor
    pooled = clearance([positions, world_positions(high)], limbs)
    one_floor = walk_figures(high, layout, limbs, pooled, cm, sole_clearance([positions, world_positions(high)], limbs))
    assert one_floor["float_frac"] > high_figures["float_frac"] + 0.1
    assert one_floor["air_frac"] > high_figures["air_frac"] + 0.1
    # the mean floor lies between the two, weighted by frames
    assert floors.mean_sole == pytest.approx((floors.sole[0] + floors.sole[1]) / 2)


def test_contact_is_found_on_each_takes_own_floor(take):
    motion, layout, limbs, positions, cm = take
    high = world_positions(lifted(motion, 3.5 / cm))
    floors = take_floors([positions, high], limbs)
    own = contact_labels(high, limbs, floors.ground[1], cm, motion.fps)
    np.testing.assert_array_equal(own, contact_labels(positions, limbs, floors.ground[0], cm, motion.fps))
    assert own.mean() > 0.2
    shared = contact_labels(high, limbs, clearance([positions, high], limbs), cm, motion.fps)
    assert shared.mean() == 0.0  # 3.5 cm above the shared floor: never within 2 cm of it


@pytest.fixture(scope="module")
def cmu_contact():
    """The public CMU takes' average step model and contact statistics, trained as `instrument
    train` trains them (30 fps, 5 states), and each take's contact and air labels."""
    pairs = styled_takes([CMU])
    layout, takes, _, _ = load_corpus(pairs, 30.0)
    segments = segments_by_label(takes, 5)
    average = train_average(segments, 5, variance_floors(segments))
    one_style = HSMM(*(getattr(average, p)[None] for p in ("means", "variances", "duration_means", "duration_variances")))
    arrays, metadata = train_contact(layout, takes, average, one_style, ["jackson"], 30.0, 5)
    return arrays, metadata


def test_a_stylised_walk_whose_feet_slide_has_no_flight(cmu_contact):
    """The public CMU walk plants neither foot surely (share below PLANTED) in some of its states,
    its feet sliding and pivoting on the floor (not still, so not planted); those states were
    taken for a run's flight and the lock let both feet go there: the walk skated 93 cm/s
    against its takes' 21 (4.4x). Both feet are in the air in at most a third of any state's
    frames, so the walk has no flight: the lock plants the likelier foot (skate 7.7 cm/s, 0.36x)."""
    arrays, metadata = cmu_contact
    shares = arrays["contact_average"].reshape(-1, 2)
    air = np.asarray(metadata["air"])
    assert air.shape == arrays["contact_average"].shape[:2] and air.max() < PLANTED
    assert flight_states(shares).any()  # by the shares alone (models trained before `air`): flight
    assert not flight_states(shares, metadata["air"], 5, 1).any()


def test_a_unit_with_flight_keeps_its_flight_states():
    """A run (more often in the air than on both feet) keeps every state that plants neither
    foot as flight, its landing state too, whatever that state's own air share (the shared
    runs' flight states are in the air in 0.29-0.60 of their frames, their landing states in
    0.02-0.06); a jog whose flight is shorter (its most airborne state in the air in 0.45 of its
    frames, under the half the rule before asked for) has flight too; a walk beside them with
    uncertain states and as much air, but double support, has none; a model without `air`, or
    with one of another shape, reads flight from the shares alone."""
    states = 5
    stance = [[0.9, 0.0], [0.95, 0.0], [0.9, 0.0], [0.0, 0.9], [0.0, 0.95], [0.0, 0.9]]
    shares = np.full((6 * states, 2), 0.9)  # walk/right, walk/left (double support), run/right, run/left, jog/right, jog/left
    shares[2 * states :] = np.repeat(stance, states, axis=0)[: 4 * states]
    uncertain = [1, 6, 10, 13, 14, 15, 18, 19, 23, 24, 28, 29]
    shares[uncertain] = [[0.4, 0.1], [0.2, 0.35], [0.41, 0.01], [0.24, 0.0], [0.12, 0.0], [0.01, 0.3], [0.0, 0.23],
                         [0.0, 0.11], [0.3, 0.0], [0.1, 0.0], [0.0, 0.3], [0.0, 0.1]]
    air = np.zeros(6 * states)
    air[uncertain] = [0.3, 0.45, 0.02, 0.29, 0.6, 0.06, 0.34, 0.45, 0.3, 0.45, 0.3, 0.45]
    flight = flight_states(shares, air.reshape(6, states).tolist(), states, 3)
    assert list(np.flatnonzero(flight)) == uncertain[2:]
    assert list(np.flatnonzero(flight_states(shares))) == uncertain
    assert list(np.flatnonzero(flight_states(shares, air[:-1].tolist(), states, 3))) == uncertain


def test_air_is_both_feet_above_the_floor_however_they_move(take):
    """Training's air labels: both feet's lowest joints more than AIR_CM above their take's
    floor, as `instrument evaluate` counts its air (the same frames), where contact also asks for
    a still foot: the CMU take has neither foot planted in many more frames than both in the air."""
    motion, layout, limbs, positions, cm = take
    floors = take_floors([positions], limbs)
    air = air_labels(positions, limbs, floors.ground[0], cm)[:, 0]
    figures = walk_figures(motion, layout, limbs, floors.ground[0], cm, floors.sole[0])
    assert air.mean() == pytest.approx(figures["air_frac"])
    planted = contact_labels(positions, limbs, floors.ground[0], cm, motion.fps)
    assert 0.0 < air.mean() < 0.5 * (planted.max(axis=1) == 0).mean()
