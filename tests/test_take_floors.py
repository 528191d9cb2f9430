"""Each take on its own floor (issue 30): a capture's floor is not always level from take to take
(the public CMU takes' feet stand 3.5 cm higher in take 02 than in take 01), so `instrument
evaluate` and training's contact labels measure every take against its own floor
(motion/quality.py `take_floors`), and a made walk against their mean."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from instrument.motion.bvh import Motion, read_bvh
from instrument.motion.features import choose_layout
from instrument.motion.kinematics import world_positions
from instrument.motion.limbs import centimetres_per_unit, clearance, find_limbs, sole_clearance
from instrument.motion.quality import take_floors, walk_figures
from instrument.training.contact import contact_labels

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
