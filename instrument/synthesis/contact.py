"""Feet that stay planted: contact learnt per state from the data, enforced frame by frame.

Training (`instrument/training/contact.py`) labels each foot of each frame as in contact when
its lowest joint is within CONTACT_CM of its ground clearance and moves slower than
CONTACT_SPEED_CM_S horizontally, and stores per (label, state) the share of frames in contact,
for the average model and each style (aligned by each model's own state posteriors). Live, the
probabilities move with the style weights like every other parameter (offsets from the average,
so they blend and extrapolate) and a foot counts as planted in a state whose share is at least
PLANTED, or at least POSSIBLE when the generated foot is on the floor and nearly still (as the
data was labelled).

The foot lock (`footlock.py`, compiled and batched over characters) enforces it causally, one
frame at a time, on the pose the features give:
- when a foot lands, the point it lands on (the foot's front-most joint,
  limbs.Leg.pivot, horizontally)
  is locked, and the foot turned back about the vertical to the heading it landed with (a foot
  that yaws in the generated walk swung its heel and toe tip about the lock);
- while the other foot swings, a planted foot stands flat: one whose toes are up (an
  extrapolated style can stand on its heels through the whole stance) is pitched down about
  its ankle, blended in with its own lock once the other foot is released (while both are
  planted, not at all), so a heel strike keeps a rolling landing over BLEND_FRAMES' time and
  the swinging foot never passes below the planted one's toes (blended in only as the other
  foot's lock blended out, the landing toes stayed up while the trailing ones left the floor);
- each leg is solved by analytic two-bone IK (law of cosines for the knee, bent about its own
  hinge; then the hip swings the leg), the foot keeping its generated world orientation, towards: the lock
  horizontally, its lowest joint on the floor vertically; the lock blends in and out over
  BLEND_FRAMES frames at 30 fps (REFERENCE_FPS; the same time at any rate), so nothing pops, but
  for a foot landing from flight (the other foot neither planted nor held: a run's), which the
  body comes down on alone and which stops as real feet so landed do, within two frames
  (footlock.LANDING_PACE);
- where that would stretch a planted leg past its generated length (hip to ankle), the heel
  rises instead: the foot pitches up about its front-most joint, up to MAX_HEEL_RISE from
  standing flat (a cap that wins) and otherwise changing no faster than HEEL_RISE_SPEED,
  that joint keeping its generated world rotation, as a real foot rolls onto its toes at the
  end of stance. Stretching the leg
  straightened the knee (25 to 8 degrees for a 1.7 cm reach) and swung the thigh back, which
  left the hip's range up to 19% wider than the takes';
- no foot joint goes below its clearance, planted or not, and a swinging foot keeps up to
  SWING_CM above it (all of it on a bent knee, none on a straight one reaching to land), which
  goes as the foot is planted over HOLD_FRAMES (a frame at 30 fps, eased over that time at a
  higher rate: footlock's docstring);
- a released foot rises as generated (only the horizontal pull blends out; in a run's flight,
  its leg no longer than made: the lock, letting go as the generated foot went on, stretched the
  leg straight for a frame at toe-off, the knee from 31 degrees of bend to 2 and back), but for a
  hand-over: while the other foot is planted with its lowest point not yet down (a heel
  landing, its toes up), the released foot's lowest joint leaves the floor only as its lock
  blends out, so one foot or the other is always on it;
- a walk always has a foot on the floor: when no state plants either, the likelier one is; a run
  has flight: a state where lambda 0 plants neither foot, in a unit whose data is more often in
  the air than on both feet (`flight_states`), plants a foot only where its share
  reaches PLANTED, so the lock never pulls a foot down in mid-flight (doing so made the knees
  jump twice as far in a frame as in the real runs);
- where a planted leg cannot reach even so (an exaggerated style can lift the hips), it stretches
  up to STRETCH of its length, and the body comes down by the rest, eased over BLEND_FRAMES' time;
- in a stand (the engine says which frames are), once its pose is still with both feet locked
  in, a foot locked away from where the pose puts it (a stop lands its last steps staggered)
  steps there, lifted, one foot at a time (footlock.settle_feet); set off, it lets go of its
  lock over BLEND_FRAMES as any foot does.
Before the lock, outside the data, the body takes a share of a planted foot's generated slide
(`follow.py`), so the IK does not have to stretch the leg after a body that slides on.
Nothing looks ahead beyond what the frame's state already says, so live and `synth` agree.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..motion.features import REFERENCE_FPS
from ..motion.limbs import find_limbs
from .interpolation import part_weights_per_group
from .parameters import GROUPS

CONTACT_CM = 2.0
CONTACT_SPEED_CM_S = 30.0
# the lock's times are counted in frames at REFERENCE_FPS (the shipped model's rate) and taken as
# the same time at any other: `per_frame` (docs/evaluate.md, "The lock the same in seconds at any rate")
BLEND_FRAMES = 4  # frames at REFERENCE_FPS a foot's lock takes to blend in or out (133 ms)
SWING_CM = 2.0  # a foot in the air keeps its lowest joint this far above its clearance
# frames at REFERENCE_FPS the swing lift takes to go as a foot is planted and the hold on its lowest
# joint to go as it is released (or stops handing over): one, the frame it happens at 30 fps, but
# eased over that time at a higher rate, where in one frame the same 2-3 cm made a pop whose third
# difference grows with the rate's square (at 120 fps the made walk's jitter was 3.9x its takes')
HOLD_FRAMES = 1
PLANTED = 0.5  # a state this sure of a foot's contact plants it
POSSIBLE = 0.2  # a state this sure plants a foot that is on the floor and still
NEARLY_STRAIGHT = np.radians(10.0)  # a knee bent less than this may be bent the wrong way (see footlock.leg_swings)
SWING_BENT = np.radians(30.0)  # a swinging foot gets its full SWING_CM once its knee is bent this far


@dataclass(frozen=True)
class ContactSpace:
    """Contact probabilities as lambda 0 plus style offsets, flattened over (label, state)."""

    base: np.ndarray  # (labels * states, 2)
    offsets: np.ndarray  # (styles, labels * states, 2)
    clearance: np.ndarray  # (2, foot joints)
    legs: int  # index of the legs' body group in per-part weights
    flight: np.ndarray  # (labels * states,) bool: a run's flight there (`flight_states`)
    tip_clearance: float | None = None  # a toe-less foot's End Site's clearance (limbs.tip_clearance); None: no tip

    def shares(self, weights: np.ndarray, part_weights: np.ndarray | None = None) -> np.ndarray:
        """(N, labels * states, 2): how surely each foot is planted in each state for N
        characters at weights (N, styles) and part weights (N, styles, groups) (the legs' own
        weights when given per body part), 0 to 1."""
        legs = np.ascontiguousarray(np.atleast_2d(self.leg_weights(weights, part_weights)))
        states = np.ascontiguousarray(np.broadcast_to(np.arange(len(self.base)), (len(legs), len(self.base))))
        return self.shares_in(legs, states)

    def shares_in(self, legs: np.ndarray, states: np.ndarray) -> np.ndarray:
        """(N, M, 2) `shares` of the states `states` (N, M) only (the engine's: each character's
        frame's state, so a retune makes no table), for leg weights `legs` (N, styles)."""
        out = np.empty(states.shape + (2,))
        _shares(legs, self.base, self.offsets, self.flight, states, out)
        return out

    def leg_weights(self, weights: np.ndarray, part_weights: np.ndarray | None = None) -> np.ndarray:
        """The style weights the legs walk with, (..., styles): their own where given per body part."""
        weights = np.asarray(weights, dtype=np.float64)
        if part_weights is None:
            return weights
        return part_weights_per_group(weights, part_weights)[..., self.legs]


@njit(cache=True)
def per_frame(frames: float, fps: float) -> float:
    """The share of a change that takes `frames` frames at REFERENCE_FPS made in one frame at
    `fps`: the same time at any rate (exactly 1 / frames at 30 fps)."""
    return REFERENCE_FPS / (frames * fps)


@njit(cache=True)
def eased_per_frame(share: float, fps: float) -> float:
    """The share of the way an exponential ease that moves `share` of the way in a frame at
    REFERENCE_FPS moves in one frame at `fps`: as far in a second at any rate (exactly `share`
    at 30 fps). The lock's body drop and the range stage ease so."""
    return 1.0 - (1.0 - share) ** (REFERENCE_FPS / fps)


def contact_space(model) -> ContactSpace | None:
    """None for a model trained without contact statistics (it then runs as before)."""

    extras = getattr(model, "extras", {}) or {}
    base, styles = extras.get("contact_average"), extras.get("contact_styles")
    stored = model.metadata.get("contact", {}).get("clearance")
    layout = model.layout
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    labels, states = len(model.labels), model.states
    if base is None or styles is None or stored is None or limbs is None:
        return None
    if base.shape != (labels, states, 2) or styles.shape != (len(model.style_names), labels, states, 2):
        return None
    flat = base.reshape(-1, 2)
    tip = model.metadata.get("contact", {}).get("tip_clearance")
    return ContactSpace(flat, styles.reshape(len(model.style_names), -1, 2) - flat, np.asarray(stored), GROUPS.index("legs"),
                        flight_states(flat, model.metadata.get("contact", {}).get("air"), states, len(model.units)),
                        None if tip is None else float(tip))


def flight_states(shares: np.ndarray, air=None, states: int = 1, units: int = 0) -> np.ndarray:
    """(labels * states,) bool: the states of a run's flight, where lambda 0's shares `shares`
    (labels * states, 2) plant neither foot, in a unit that has flight. Where training stored
    `air` ((labels, states): the share of each state's frames with both feet in the air,
    training/contact.air_labels), a unit (its two labels, the first 2 * `units`) has flight when
    its steps are more often in the air than on both feet: some state's air share exceeds every
    state's share of both feet planted (the lesser of the two feet's shares, a bound on it); the
    other labels (gestures) each on its own. That is what tells a run from a walk (a walk has
    double support and no flight, a run flight and no double support) and it asks no threshold of
    a capture: the shared runs' most airborne states are in the air in 0.54-0.60 of their frames
    with both feet planted in at most 0.03 of any state's, but another actor's jog, its flight
    shorter, can stay under half, and a walk's air can be a floor misread: the public CMU walk
    (tests/data/cmu-131), whose feet slide and pivot on the floor so that half of its states
    plant neither foot surely, is in the air in up to 0.33 of a state's frames and on both feet
    in up to 0.44. (Taken for flight before `air` was stored, the lock let both feet go there
    and the walk skated 4.4 times as much as its takes; the rule before this one asked for a
    state in the air in half its frames.) A model trained before `air` was stored reads flight
    from the shares alone."""
    flight = shares.max(axis=1) < PLANTED
    try:
        air = np.asarray(air if air is not None else [], dtype=np.float64)
    except (TypeError, ValueError):  # not a table of numbers (a model file edited by hand): as before `air`
        return flight
    if air.size != len(flight) or len(flight) % states or not np.isfinite(air).all():
        return flight
    airborne = air.reshape(-1, states).max(axis=1)  # per label
    both = shares.min(axis=1).reshape(-1, states).max(axis=1)
    for unit in range(min(units, len(airborne) // 2)):
        steps = slice(2 * unit, 2 * unit + 2)
        airborne[steps], both[steps] = airborne[steps].max(), both[steps].max()
    return flight & np.repeat(airborne > both, states)


@njit(cache=True, nogil=True)
def _shares(legs, base, offsets, flight, states, out):  # pragma: no cover - compiled
    """out[n, m] = lambda 0's contact shares of state states[n, m] plus leg weights legs[n] times
    the style offsets, clipped to 0..1, and in flight (`ContactSpace.flight`) a share below
    PLANTED made none (the lock leaves both feet in the air), for each character n."""
    for n in range(states.shape[0]):
        for m in range(states.shape[1]):
            state = states[n, m]
            for foot in range(2):
                change = 0.0
                for style in range(legs.shape[1]):
                    change += legs[n, style] * offsets[style, state, foot]
                share = min(max(base[state, foot] + change, 0.0), 1.0)
                out[n, m, foot] = 0.0 if flight[state] and share < PLANTED else share
