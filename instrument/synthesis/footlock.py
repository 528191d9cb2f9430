"""The foot lock, compiled and batched: one call plants the feet of every character of a frame.

What the lock does is described in `instrument.synthesis.contact` (which also trains the
contact statistics). Here it runs as numba kernels over arrays, each with the job of one method
of the plain-Python lock it replaced (kept as the test oracle, tests/reference_lock.py):

- `planted_feet`: which feet are planted this frame (the state's share, or a foot on the floor
  and still where the state allows it; always one foot); a foot landing from flight takes its
  lock in at LANDING_PACE times the usual pace (`lock_frame`);
- `hold_heading`: a planted foot turned back about the vertical to the heading it landed with
  (`foot_heading`: read from the foot's axis across it, `across_axes`, which its pitching leaves
  where it is; the toe line's heading turns half round as a run's toe-off pitches the foot past vertical);
- `lay_flat`: a planted foot alone on the floor, toes up, pitched down about its ankle to flat
  (about its axis across it, as `heel_rise` pitches it);
- `lock_target`: where an ankle should go (the lock blended in, the floor, the swing lift as
  `swing_share` allows); the horizontal hold by `pull_step`'s curve: in fastest at touch-down
  (ease-out), out on a smoothstep;
- `release_joints`: a walk's foot let go from its full lock (the other planted) given back in
  joint space: its lock's last solution, kept each locked frame as rotation offsets at hip, knee
  and ankle and the toes' world turn, eased out over RELEASE_FRAMES on top of the generated leg
  (letting go of the IK's target instead jumped the knee as the heel-rise cap fell at toe-off:
  docs/evaluate.md, "The release in joint space");
- `heel_rise`: the foot pitched up about its front-most joint (the toes) where the lock would stretch a
  planted leg past its generated length (the toes beyond it keep their generated world rotation,
  as a real foot bends there, instead of dipping into the floor), at most MAX_HEEL_RISE from
  flat and within HEEL_RISE_SPEED of the frame before's rise;
- `within_reach`: a foot released in a run's flight brought back within its leg's generated length;
- `settle_feet`: in a still stand, a foot locked away from where the stand's pose puts it (a stop
  leaves them staggered) steps there, lifted, one at a time (a closing step); a foot set off
  from a stand lets go of its lock at a step's pace, as every foot does. Let go at half that pace
  (while a step's first state had the swinging foot behind, which the first step's pose, drawn
  from the stood one, no longer has), a run's first stance foot, whose other foot does not land
  before its toe-off, was held through it and dragged back towards the foot as made as it rose,
  then swung forward at once (docs/evaluate.md, "A run's first toe-off let go at a step's pace");
- `body_drop`: how far the body must come down for a planted leg to reach its target;
- `leg_swings`: two-bone IK, the thigh's and the shin's turns that take an ankle to a target;
- `solve_leg`: those turns applied in place to the local rotations;
- `lock_frame`: one character's frame, in the order above (`_targets` gathers `lock_target` and
  `heel_rise` for both legs); `lock_crowd`: every character's.

A foot that is its ankle alone (no toe joint) but ends in an End Site (`limbs.foot_tip`: many
CMU conversions and some suits put one at the toes) takes that tip as its pivot point
(`FootLock.tips`, `_pivot_at`): locked where it lands, the heel rolling up about it, counted
among the foot's lowest points and laid flat about, as a toe joint is. About the ankle alone no
heel could rise: a planted leg that could not reach stretched and swung the thigh back, and a
toe-less walk's hips swung 25-37% wider than its takes' (docs/evaluate.md, "No toes").

Times, not frames: the lock's paces are counted in frames at `motion.features.REFERENCE_FPS` (30, the
shipped model's rate) and taken as that time at any rate (`contact.per_frame`): its blend in and
out (BLEND_FRAMES; LANDING_PACE is a multiple of it), the body's drop (eased
1 / BLEND_FRAMES of the way in a 30 fps frame's time), as HEEL_RISE_SPEED and SETTLE_SECONDS were
already. The swing lift a foot keeps in the air goes as it is planted, and the hold of its
lowest joint on the floor goes as it is released (not handing over), over HOLD_FRAMES: one frame
at 30 fps, as before, but eased over that 33 ms at a higher rate (`LockState.landed` and `held`).
Dropped in one frame, those 2-3 cm were a pop whose third difference grows with the square of
the rate: active's walk made at 120 fps had 4.3 times the jitter of the same walk unlocked, now
2.0 times, and at 30 fps the walks are the same to the digit. Only the vertical lift and hold
fade so; the horizontal pull stays the lock's weight, so toes held down are held where they were
planted as much as before, not slid along the floor (blending the hold out with the lock's
weight instead kept the toes down while the lock let go: skate 1.5 to 6.2 cm/s at 120 fps, and
at 30 fps the hips swung 2-3 degrees wider). docs/evaluate.md, "The lock the same in seconds at
any rate".

Nothing is allocated a character: vectors are tuples (`_sub`, `_cross`), and matrices and
per-frame arrays are written into the caller's arrays (`lock_work`, made once a call), since
some seventy small heap arrays a character and frame were about half the lock's time.

`FootLock` holds what does not change (the legs' joints, the floor, the units); each
character's state (how far each foot's lock is blended in, the locked points and headings, the
body's drop, the feet's previous positions, the heels' rises) lives in `LockState` arrays, one
row per character.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np
from numba import njit

from ..motion.features import FeatureLayout
from ..motion.kinematics import _compose, compose_joint, forward_kinematics
from ..motion.limbs import centimetres_per_unit, find_limbs, foot_tip
from .contact import (BLEND_FRAMES, CONTACT_CM, CONTACT_SPEED_CM_S, HOLD_FRAMES, NEARLY_STRAIGHT, PLANTED, POSSIBLE, SWING_BENT,
                      SWING_CM, eased_per_frame, per_frame)
from .follow import ease

MAX_HEEL_RISE = np.radians(50.0)  # the most a planted foot pitches up about its toes, from standing flat
# how fast a heel rise may change (real ankles turn at up to 300-400 deg/s at push-off): near a
# leg's full reach the rise that just reaches can swing by 35 deg from one frame to the next
HEEL_RISE_SPEED = np.radians(400.0)  # radians per second
STRETCH = 0.98  # of a leg's full length: how far the lock stretches a leg before the body comes down
# a standing body's planted foot further than this from where the stand's pose puts it steps there
# (a closing step): a stop leaves its feet where its last, braked steps landed them (on the shipped
# model at weight 1, 7-17 cm staggered front to back)
SETTLE_CM = 4.0
SETTLE_SECONDS = 0.4  # how long a closing step takes, lift-off to touch-down
SETTLE_LIFT_CM = 4.0  # how high a closing step lifts the foot, at its middle
# ... and begins only while both generated feet move slower than this (a stand's move under 3 cm/s;
# in its last frames before a start the pose already steps off, towards the walk's first state)
SETTLE_STILL_CM_S = 5.0
CLOSED = 2.0  # LockState.settling of a foot that has taken its closing step, or needed none
# a foot landing from flight (the other foot neither planted nor held by its lock: a run's) takes its
# lock in this many times the usual pace: the body comes down on it alone, and real feet so landed stop
# within two frames of touching down (the shipped runs' active takes: 131, 32, 3 cm/s); taken in over
# BLEND_FRAMES, as a walk's heel strike rolls in with the other foot down, a run's landing foot slid on
# for a third of a stance of six frames (active's run skated 1.08x its takes')
LANDING_PACE = 2.0
# a walk's foot released (the other planted) gives back the lock's correction in joint space: the
# last fully locked frame's local rotation offsets at hip, knee, ankle and toes, eased out (smoothstep)
# over this many frames at REFERENCE_FPS, on top of the generated rotations (`release_joints`)
RELEASE_FRAMES = 8


@dataclass
class LockState:
    """Every character's lock, carried from frame to frame (row n: character n)."""

    weights: np.ndarray  # (N, 2) how far each foot's lock is blended in, 0..1
    points: np.ndarray  # (N, 2, 3) world point each foot is locked to (NaN before its first landing)
    headings: np.ndarray  # (N, 2) each locked foot's heading (foot_heading: about the vertical) at landing
    drop: np.ndarray  # (N,) how far the body is lowered for a planted leg to reach its target
    previous: np.ndarray  # (N, 2, 3) each pivot's position in the frame before, the body's follow offset
    # included (NaN at first): what the lock's 'nearly still' test measures; not RootFollow.previous
    rises: np.ndarray  # (N, 2) each foot's heel rise in the frame before (radians)
    settling: np.ndarray  # (N, 2) each foot's closing step: 0 may take one, (0, 1) how far through, CLOSED (`settle_feet`)
    landed: np.ndarray  # (N, 2) how far each foot's swing lift has gone as it was planted, 0..1 (over HOLD_FRAMES)
    held: np.ndarray  # (N, 2) how far each foot's lowest joint is held on the floor, 0..1 (over HOLD_FRAMES)
    # (N, 2, 4, 3, 3) each planted foot's lock as local rotation offsets (generated^T @ locked) at its
    # hip, knee and ankle, and its pivot's world turn (locked @ generated^T), as of its last fully locked frame
    offsets: np.ndarray
    released: np.ndarray  # (N, 2, 4, 3, 3) the offsets a released walk's foot is giving back (its `offsets` at release)
    releasing: np.ndarray  # (N, 2) how much of them it still carries, 1..0 (0: none)
    # (N, 2) how far the lock's IK holds each foot, 0..1: `weights` but while a released foot is given
    # back in joint space (none), and from none again, at the landing's pace, once such a foot lands
    locking: np.ndarray
    pulls: np.ndarray  # (N, 2) how far the lock holds each foot horizontally, 0..1 (`pull_step`)

    def part(self, start: int, stop: int) -> LockState:
        """Characters start to stop: views of the same arrays, for a part of the crowd on a core."""
        return LockState(*(getattr(self, f.name)[start:stop] for f in fields(self)))

    def release(self, n: int) -> None:
        """Character n's feet unlocked, as before its first frame (it was put somewhere else)."""
        self.weights[n], self.points[n], self.headings[n], self.drop[n], self.previous[n] = 0.0, np.nan, 0.0, 0.0, np.nan
        self.rises[n] = 0.0
        self.settling[n] = 0.0
        self.landed[n], self.held[n] = 0.0, 0.0
        self.offsets[n], self.released[n], self.releasing[n], self.pulls[n] = np.eye(3), np.eye(3), 0.0, 0.0
        self.locking[n] = 0.0


class FootLock:
    """A skeleton's feet as the lock sees them: legs, floor, units (the same for every character)."""

    def __init__(self, layout: FeatureLayout, ground: np.ndarray, fps: float, tip_clearance: float | None = None):
        """`ground` (2, foot joints): each foot joint's clearance; `tip_clearance`: that of the End
        Site of a foot without toe joints (learnt in training: limbs.tip_clearance; None: such
        a foot has no pivot but its ankle, as in models trained before it was kept)."""
        self.layout, self.fps = layout, float(fps)
        self.limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
        self.ground = np.ascontiguousarray(ground, dtype=np.float64)  # (2, foot joints) clearance
        self.parents = np.asarray(layout.skeleton.parents, dtype=np.int64)
        self.parent_rot = np.ascontiguousarray(layout.template_pose[2])  # the root's parent's world rotation
        legs = self.limbs.legs
        self.joints = np.array([[leg.hip, leg.knee, leg.ankle] for leg in legs], dtype=np.int64)  # (2, 3)
        # (2, foot joints), each foot's pivot (its front-most joint, limbs.Leg.pivot) moved last, as
        # the kernels read it; the clearance's columns in the same order
        order = [[k for k, j in enumerate(leg.foot) if j != leg.pivot] + [leg.foot.index(leg.pivot)] for leg in legs]
        self.feet = np.array([np.asarray(leg.foot)[o] for leg, o in zip(legs, order)], dtype=np.int64)
        self.ground = np.ascontiguousarray([self.ground[f, o] for f, o in enumerate(order)])
        self.reach = np.array([leg.thigh + leg.shin for leg in legs])  # hip to ankle, stretched
        # (2, 3) a toe-less foot's tip in its ankle's frame (limbs.foot_tip), which its heel rolls up
        # about; zeros for a foot with a toe joint, or none known. `pivot_ground` (2,): the clearance
        # of the point a heel rises about (the tip's, or the pivot joint's)
        tips = [None if tip_clearance is None else foot_tip(layout, leg) for leg in legs]
        self.tips = np.array([np.zeros(3) if t is None else t for t in tips])
        self.pivot_ground = np.array([self.ground[f, -1] if t is None else tip_clearance for f, t in enumerate(tips)])
        template_rot, template_pos = (a[0] for a in forward_kinematics(layout.skeleton, layout.template_pose[0][None],
                                                                        layout.template_pose[1][None]))
        self.cm = centimetres_per_unit(layout, template_pos)
        self.swing_lift = SWING_CM / self.cm  # in the skeleton's units
        self.across = across_axes(template_rot, template_pos, legs, self.tips)

    def start(self, count: int) -> LockState:
        """The state of `count` characters before their first frame: nothing locked yet."""
        return LockState(np.zeros((count, 2)), np.full((count, 2, 3), np.nan), np.zeros((count, 2)), np.zeros(count),
                         np.full((count, 2, 3), np.nan), np.zeros((count, 2)), np.zeros((count, 2)), np.zeros((count, 2)),
                         np.zeros((count, 2)), np.tile(np.eye(3), (count, 2, 4, 1, 1)), np.tile(np.eye(3), (count, 2, 4, 1, 1)),
                         np.zeros((count, 2)), np.zeros((count, 2)), np.zeros((count, 2)))

    def apply(self, state: LockState, rotations: np.ndarray, translations: np.ndarray, shares: np.ndarray,
              world_rot: np.ndarray, world_pos: np.ndarray, standing: np.ndarray | None = None) -> None:
        """Plants the feet of N characters in place: local rotations (N, J, 3, 3) and translations
        (N, J, 3) are adjusted and their world transforms (same shapes) written; `world_rot` and
        `world_pos` hold the unadjusted pose's on entry. `shares` (N, 2): how surely each foot is
        planted in each character's state; `standing` (N,) bool: the character's frame is of a
        stand, where a foot held away from the stand's pose steps there (`settle_feet`; None: none is)."""
        standing = np.zeros(len(shares), dtype=np.bool_) if standing is None else np.ascontiguousarray(standing, dtype=np.bool_)
        lock_crowd(rotations, translations, np.ascontiguousarray(shares, dtype=np.float64), world_rot, world_pos,
                   state.weights, state.points, state.headings, state.drop, state.previous, state.rises,
                   state.settling, state.landed, state.held, state.offsets, state.released, state.releasing, state.pulls, state.locking, standing, self.parents, self.joints, self.feet, self.across,
                   self.tips, self.pivot_ground, self.ground, self.reach, self.parent_rot, self.layout.root, self.fps, self.cm,
                   self.swing_lift)


    def pivots(self, world_rot: np.ndarray, world_pos: np.ndarray) -> np.ndarray:
        """(N, 2, 3) each foot's pivot point in N poses' world transforms (N, J, 3, 3), (N, J, 3):
        the pivot joint, or a toe-less foot's tip (`tips`), the points the lock holds."""
        legs = self.limbs.legs
        return np.stack([world_pos[:, leg.pivot] if leg.pivot != leg.ankle
                         else world_pos[:, leg.ankle] + world_rot[:, leg.ankle] @ self.tips[f] for f, leg in enumerate(legs)],
                        axis=1)

def across_axes(world_rot: np.ndarray, world_pos: np.ndarray, legs, tips: np.ndarray) -> np.ndarray:
    """(2, 3) each foot's axis across it (level, to the side of its toe line in the template
    pose, whose world rotations and positions are given), in its ankle's frame: what
    `foot_heading` reads a foot's heading from. The toe line's
    own heading turns half round as a foot pitches past vertical (a run's toe-off has the toes
    behind the ankle), and a lock holding the heading it landed with spun the foot about the
    vertical as it let go; pitching leaves the axis across the foot where it was. A foot without
    joints below its ankle takes its toe line to its tip (`tips` (2, 3), in the ankle's frame:
    FootLock.tips); without a tip either it has none (zeros: no heading, none held)."""
    axes = np.zeros((2, 3))
    for f, leg in enumerate(legs):
        toes = world_pos[leg.pivot] - world_pos[leg.ankle] if leg.pivot != leg.ankle else world_rot[leg.ankle] @ tips[f]
        level = np.hypot(toes[0], toes[2])
        if level > 1e-9:
            across = np.array([toes[2], 0.0, -toes[0]]) / level  # up x toes: the heading's +90 deg, level
            axes[f] = world_rot[leg.ankle].T @ across
    return axes


# ---- kernels (compiled; the names and jobs of the plain-Python lock's methods) --------------

@njit(cache=True, error_model="numpy")
def _tip_height(world_rot, world_pos, foot, tip):  # pragma: no cover - compiled
    """The height of a toe-less foot's `tip` (FootLock.tips: zeros for a foot with toe joints,
    which have none: inf), the foot's only joint being its ankle."""
    if tip[0] == 0.0 and tip[1] == 0.0 and tip[2] == 0.0:
        return np.inf
    return world_pos[foot[-1], 1] + _dot(world_rot[foot[-1], 1], tip)


@njit(cache=True, error_model="numpy")
def _lowest_lift(world_rot, world_pos, foot, tip, ground_f, tip_ground):  # pragma: no cover - compiled
    """Height of the foot's lowest joint (or toe-less tip, above `tip_ground`) above its clearance."""
    lift = _tip_height(world_rot, world_pos, foot, tip) - tip_ground
    for k in range(foot.shape[0]):
        lift = min(lift, world_pos[foot[k], 1] - ground_f[k])
    return lift


@njit(cache=True, error_model="numpy")
def planted_feet(shares, world_rot, world_pos, previous, joints, feet, tips, pivot_ground, ground, fps, cm,
                 planted):  # pragma: no cover - compiled
    """A foot is planted where its state says so, or where the state allows it and the generated
    foot is on the floor and nearly still (as the data's contact was labelled): written into
    `planted` (2,) bool; `previous` (2, 3) becomes this frame's pivots. Returns each generated
    pivot's horizontal speed since the frame before (cm/s; NaN at first), which the closing
    step's 'still' test reads too. Pivots: `_pivot_at`."""
    pivots = (_pivot_at(world_rot, world_pos, joints[0, 2], feet[0, -1], tips[0]),
              _pivot_at(world_rot, world_pos, joints[1, 2], feet[1, -1], tips[1]))
    speeds = (np.hypot(pivots[0][0] - previous[0, 0], pivots[0][2] - previous[0, 2]) * fps * cm,
              np.hypot(pivots[1][0] - previous[1, 0], pivots[1][2] - previous[1, 2]) * fps * cm)
    for f in range(2):
        pivot = pivots[f]
        speed = speeds[f]
        for i in range(3):
            previous[f, i] = pivot[i]
        planted[f] = shares[f] >= PLANTED
        if not planted[f] and shares[f] >= POSSIBLE:
            lift = _lowest_lift(world_rot, world_pos, feet[f], tips[f], ground[f], pivot_ground[f]) * cm
            planted[f] = lift < CONTACT_CM and speed < CONTACT_SPEED_CM_S  # NaN speed (first frame): False
    if not planted[0] and not planted[1] and max(shares[0], shares[1]) > 0.0:  # a walk has a foot on the floor
        planted[0 if shares[0] >= shares[1] else 1] = True
    return speeds


@njit(cache=True, error_model="numpy")
def _sole_lift(world_rot, world_pos, foot, tip, ground_f, tip_ground):  # pragma: no cover - compiled
    """Height of the foot's lowest point above the lowest clearance of its joints (where its
    sole stands): a heel down with the toes up is off the floor by this, not by `_lowest_lift`.
    A toe-less foot's tip counts as a joint (`_tip_height`)."""
    low = _tip_height(world_rot, world_pos, foot, tip)
    floor = tip_ground if low < np.inf else np.inf
    for k in range(foot.shape[0]):
        low = min(low, world_pos[foot[k], 1])
        floor = min(floor, ground_f[k])
    return low - floor


@njit(cache=True, error_model="numpy")
def swing_share(world_pos, leg):  # pragma: no cover - compiled
    """How much of the swing lift a swinging foot keeps: all of it on a knee bent SWING_BENT or
    more (mid-swing, where an exaggerated style would drag it along the floor), none on a
    straight one (reaching for the floor to land: lifting it there bends the knee the data
    straightens and flexes the hip)."""
    hip, knee, ankle = world_pos[leg[0]], world_pos[leg[1]], world_pos[leg[2]]
    thigh, shin = _sub(knee, hip), _sub(ankle, knee)
    cos = _dot(thigh, shin) / (np.sqrt(_dot(thigh, thigh)) * np.sqrt(_dot(shin, shin)) + 1e-12)
    return min(1.0, np.arccos(min(max(cos, -1.0), 1.0)) / SWING_BENT)


@njit(cache=True, error_model="numpy")
def lock_target(world_rot, world_pos, leg, foot, tip, ground_f, tip_ground, weight, point, landed, held, swing_lift,
                target, pull):  # pragma: no cover - compiled
    """Where the ankle (leg: hip, knee, ankle) should be, written into `target` (3,): the lock
    blended in horizontally, the lowest foot joint on the floor while planted, never below it,
    and a little above it while swinging on a bent knee. A released foot rises as generated (held down, the knee would
    straighten at toe-off), but for a hand-over: while the other foot is planted with its
    lowest point not yet down (a heel landing, its toes up), the released foot's lowest joint
    comes off the floor only as its lock blends out, so one foot or the other is always on the
    floor. Rising as generated there, the trailing foot's toes left the floor before the
    landing foot's were down: both feet off the floor in up to 7% of the frames
    (docs/evaluate.md, "Floating the stricter way"). `landed` (0..1, eased): how far the swing
    lift has gone as the foot was planted (1 planted, 0 swinging); `held`: how far its lowest
    joint is held down (1 planted or handing over, 0 released): both change over HOLD_FRAMES'
    time, not in a frame, and only vertically. `weight` is the lock's IK weight (`LockState.locking`),
    `pull` (0..1) how far the pivot is pulled horizontally to `point` (`LockState.pulls`: in faster
    than the weight as a foot lands, and kept on a walk's released foot while its weight is none).
    The pivot is `_pivot_at`'s (a toe-less foot's `tip`)."""
    lift = _lowest_lift(world_rot, world_pos, foot, tip, ground_f, tip_ground)
    for i in range(3):
        target[i] = world_pos[leg[2], i]
    w = ease(weight)
    down = held * w * lift if held > 0.0 else 0.0
    if pull > 0:
        pivot = _pivot_at(world_rot, world_pos, leg[2], foot[-1], tip)
        target[0] += pull * (point[0] - pivot[0])
        target[2] += pull * (point[2] - pivot[2])
    target[1] -= down
    lowest_after = lift - down
    floor = (1.0 - landed) * (1.0 - w) * swing_lift * swing_share(world_pos, leg) if landed < 1.0 else 0.0
    if lowest_after < floor:
        target[1] += floor - lowest_after


@njit(cache=True, error_model="numpy")
def _toe_line(world_rot, world_pos, ankle, pivot, tip):  # pragma: no cover - compiled
    """The ankle to the point its heel rises about: the pivot joint, or for a foot that is its
    ankle alone, its `tip` (in the ankle's frame; zeros where it has none)."""
    if pivot != ankle:
        return _sub(world_pos[pivot], world_pos[ankle])
    r = world_rot[ankle]
    return (_dot(r[0], tip), _dot(r[1], tip), _dot(r[2], tip))


@njit(cache=True, error_model="numpy")
def _pivot_at(world_rot, world_pos, ankle, pivot, tip):  # pragma: no cover - compiled
    """Where the foot's pivot point is (a tuple): its pivot joint, or for a foot that is its
    ankle alone, its `tip` (`_toe_line`): the point the lock holds where the foot lands."""
    if pivot != ankle:
        return (world_pos[pivot, 0], world_pos[pivot, 1], world_pos[pivot, 2])
    toes = _toe_line(world_rot, world_pos, ankle, pivot, tip)
    return (world_pos[ankle, 0] + toes[0], world_pos[ankle, 1] + toes[1], world_pos[ankle, 2] + toes[2])


@njit(cache=True, error_model="numpy")
def heel_rise(world_rot, world_pos, leg, pivot, tip, across, clearance, on_floor, target, allowed, low, high,
              turn):  # pragma: no cover - compiled
    """The foot's turn (3x3, world: written into `turn`) and its angle (returned) about its pivot
    (its front-most joint, the toes) when the lock asks the leg (hip, knee, ankle) to reach
    further than `allowed` (hip to ankle): the heel rises, as
    a real foot rolls onto its toes, so the knee keeps its bend instead of straightening and the
    hip is not pulled into extension. Moves `target` (the ankle's) with it. The rise asked for:
    the smallest that reaches, the one that comes nearest when none does, none when the leg
    reaches already; a foot whose toes are `on_floor` or more higher above their clearance than
    the heel is above its own (a heel just landing) asks for none, and in between a share:
    rolling on toes in the air would lift the whole foot off the floor. That angle is then held
    in [`low`, `high`] (the lock keeps each rise within HEEL_RISE_SPEED of the frame before's,
    so a rise no longer asked for comes down at that pace), and the foot to at most
    MAX_HEEL_RISE from flat, which wins over `low`. `clearance` (2,): the ankle's and the
    pivot's heights standing on the floor. A foot without a toe joint rises about its `tip`
    (`_toe_line`), the toe joint's place."""
    toes = _toe_line(world_rot, world_pos, leg[2], pivot, tip)
    toe = (target[0] + toes[0], target[1] + toes[1], target[2] + toes[2])  # where the pivot goes with the ankle
    # the foot's pitch axis, lifting the heel: its axis across it (up x the toe line, for a flat
    # foot), which the turn leaves where it is, and so the heading held; the toe line's own, near
    # vertical at toe-off, turned the foot sideways
    k = _across_world(world_rot, leg[2], across)
    level = np.hypot(k[0], k[2])
    if level < 1e-12:
        _set_identity(turn)
        return 0.0
    # from flat, not from the pose made: a foot made already rising at push-off was turned past
    # the vertical, its heel in front of its toes, and back the next frame (a 35 deg flicker)
    risen = _rise_angle(toes, k, level, clearance[0], clearance[1])
    high = min(high, max(MAX_HEEL_RISE - risen, 0.0))
    theta = min(max(_needed_rise(world_pos[leg[0]], toes, toe, k, clearance, on_floor, target, allowed), min(low, high)),
                high)
    if theta <= 0.0:
        _set_identity(turn)
        return 0.0
    _axis_rotation(k, np.sin(theta), 1.0 - np.cos(theta), turn)
    v = _sub(target, toe)
    for i in range(3):
        target[i] = toe[i] + _dot(turn[i], v)
    return theta


@njit(cache=True, error_model="numpy")
def _needed_rise(hip, toes, toe, k, clearance, on_floor, target, allowed):  # pragma: no cover - compiled
    """heel_rise's angle before its bounds: the smallest rise that brings the reach down to
    `allowed`, else the one in [0, MAX_HEEL_RISE] that comes nearest; 0 where none is asked."""
    toes_up = toes[1] - (clearance[1] - clearance[0])  # toes' lift above the heel's, each above its clearance
    share = min(max(1.0 - toes_up / on_floor, 0.0), 1.0)
    gap = _sub(target, hip)
    reach = np.sqrt(_dot(gap, gap))
    if share <= 0.0 or reach <= allowed:
        return 0.0
    allowed = reach - share * (reach - allowed)
    v = _sub(target, toe)
    u = _sub(toe, hip)
    # the squared reach after a turn t is |u|^2 + |v|^2 + 2 (a cos t + b sin t + c), with
    # a cos t + b sin t = r cos(t - phi)
    kv, uk = _dot(k, v), _dot(u, k)
    a = _dot(u, v) - uk * kv
    b = _dot(u, _cross(k, v))
    c = uk * kv
    r = np.sqrt(a * a + b * b)
    if r < 1e-12:
        return 0.0
    phi = np.arctan2(b, a)
    q = ((allowed * allowed - _dot(u, u) - _dot(v, v)) / 2.0 - c) / r
    theta = -1.0
    if q > -1.0:  # the smallest rise that brings the reach down to `allowed`
        spread = np.arccos(min(q, 1.0))
        for candidate in (phi - spread, phi + spread):
            candidate = (candidate + np.pi) % (2.0 * np.pi) - np.pi
            if 0.0 < candidate <= MAX_HEEL_RISE and (theta < 0.0 or candidate < theta):
                theta = candidate
    if theta < 0.0:  # out of reach: the rise in [0, MAX_HEEL_RISE] that comes nearest
        theta, best = 0.0, np.cos(phi)
        nearest = (phi + 2.0 * np.pi) % (2.0 * np.pi) - np.pi  # phi + pi, where r cos(t - phi) is least
        for candidate in (MAX_HEEL_RISE, nearest):
            if 0.0 < candidate <= MAX_HEEL_RISE and np.cos(candidate - phi) < best:
                theta, best = candidate, np.cos(candidate - phi)
    return theta


@njit(cache=True, error_model="numpy")
def body_drop(world_pos, joints, reach, targets, planted, extension):  # pragma: no cover - compiled
    """How far the body must come down for every planted leg to reach its target (an
    exaggerated style can lift the hips further than a heel rise makes up), before easing; 0
    when it reaches. A leg may stretch past its generated `extension` (hip to ankle) up to
    STRETCH of its full length before the body comes down."""
    need = 0.0
    for f in range(2):
        if planted[f]:
            gap = _sub(targets[f], world_pos[joints[f, 0]])
            need = max(need, np.sqrt(_dot(gap, gap)) - max(extension[f], STRETCH * reach[f]))
    return max(need, 0.0)


@njit(cache=True, error_model="numpy")
def _product(a, b, out):  # pragma: no cover - compiled
    """out = a @ b for 3x3 matrices, without a BLAS call or an allocation."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@njit(cache=True, error_model="numpy")
def _product_t(a, b, out):  # pragma: no cover - compiled
    """out = a.T @ b for 3x3 matrices."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[0, i] * b[0, j] + a[1, i] * b[1, j] + a[2, i] * b[2, j]


@njit(cache=True, error_model="numpy")
def _identity(m) -> bool:  # pragma: no cover - compiled
    for i in range(3):
        for j in range(3):
            if m[i, j] != (1.0 if i == j else 0.0):
                return False
    return True


@njit(cache=True, error_model="numpy")
def _dot(a, b) -> float:  # pragma: no cover - compiled
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


@njit(cache=True, error_model="numpy")
def _sub(a, b):  # pragma: no cover - compiled
    """a - b for 3-vectors (arrays or tuples), as a tuple: the lock's vectors live in registers,
    not in arrays allocated on the heap a character and frame."""
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


@njit(cache=True, error_model="numpy")
def _scaled(a, s):  # pragma: no cover - compiled
    """a / s for a 3-vector, as a tuple."""
    return (a[0] / s, a[1] / s, a[2] / s)


@njit(cache=True, error_model="numpy")
def _cross(a, b):  # pragma: no cover - compiled
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@njit(cache=True, error_model="numpy")
def _set_identity(out):  # pragma: no cover - compiled
    for i in range(3):
        for j in range(3):
            out[i, j] = 1.0 if i == j else 0.0


@njit(cache=True, error_model="numpy")
def _copy_matrix(a, out):  # pragma: no cover - compiled
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, j]


@njit(cache=True, error_model="numpy")
def _axis_rotation(axis, sine: float, versine: float, out):  # pragma: no cover - compiled
    """out = I + sin K + (1 - cos) K K (Rodrigues), K the cross-product matrix of the unit `axis`."""
    K = ((0.0, -axis[2], axis[1]), (axis[2], 0.0, -axis[0]), (-axis[1], axis[0], 0.0))
    for i in range(3):
        for j in range(3):
            KK = K[i][0] * K[0][j] + K[i][1] * K[1][j] + K[i][2] * K[2][j]
            out[i, j] = (1.0 if i == j else 0.0) + (sine * K[i][j] + versine * KK)


@njit(cache=True, error_model="numpy")
def _rotation_between(a, b, out):  # pragma: no cover - compiled
    """out = the smallest rotation taking direction a to direction b."""
    a = _scaled(a, np.sqrt(_dot(a, a)))
    b = _scaled(b, np.sqrt(_dot(b, b)))
    axis = _cross(a, b)
    s = np.sqrt(_dot(axis, axis))
    if s < 1e-12:
        _set_identity(out)
    else:
        _axis_rotation(_scaled(axis, s), s, 1.0 - _dot(a, b), out)


@njit(cache=True, error_model="numpy")
def leg_swings(hip, knee, ankle, target, toes, swing, shin, work):  # pragma: no cover - compiled
    """Two-bone IK, as world rotations of the thigh (about the hip: written into `swing`) and the
    shin (about the knee, applied after the thigh's: into `shin`; `work` (2, 3, 3) is scratch)
    that take the ankle to `target`, or as near as the leg
    allows: the knee bends about its own hinge (the axis across its generated bend; for a
    straight leg, across the line to the toes) to the angle the law of cosines gives, then the
    hip swings the leg onto the target. A generated leg bent a little backwards (less than
    NEARLY_STRAIGHT, the toes' side telling which way is forward) is bent forward through
    straight, not further back, so a leg shortened from nearly straight never folds the wrong
    way and flips back a frame later; a clearer bend is the knee's own (a swinging foot's toes
    may point anywhere)."""
    thigh_vector, shin_vector = _sub(knee, hip), _sub(ankle, knee)
    upper = np.sqrt(_dot(thigh_vector, thigh_vector))
    lower = np.sqrt(_dot(shin_vector, shin_vector))
    reach = _sub(target, hip)
    distance = min(max(np.sqrt(_dot(reach, reach)), abs(upper - lower) + 1e-6), (upper + lower) * 0.9999)
    forward = _cross(toes, thigh_vector)  # the axis a knee bends forward about (the shin back, the knee towards the toes)
    hinge = _cross(thigh_vector, shin_vector)
    now = np.arccos(min(max(_dot(thigh_vector, shin_vector) / (upper * lower), -1.0), 1.0))  # 0: straight
    if np.sqrt(_dot(hinge, hinge)) < 1e-3 * upper * lower:  # straight: the knee bends forward
        hinge, now = forward, 0.0
    elif now < NEARLY_STRAIGHT and _dot(hinge, forward) < 0.0:  # bent a little backwards: bent forward through straight
        hinge, now = (-hinge[0], -hinge[1], -hinge[2]), -now
    length = np.sqrt(_dot(hinge, hinge))
    if length < 1e-12:
        _set_identity(swing)
        _set_identity(shin)
        return
    cos_new = min(max((upper**2 + lower**2 - distance**2) / (2.0 * upper * lower), -1.0), 1.0)
    angle = np.pi - np.arccos(cos_new) - now
    bend, turned = work[0], work[1]
    _axis_rotation(_scaled(hinge, length), np.sin(angle), 1.0 - np.cos(angle), bend)
    bent_shin = (thigh_vector[0] + _dot(bend[0], shin_vector), thigh_vector[1] + _dot(bend[1], shin_vector),
                 thigh_vector[2] + _dot(bend[2], shin_vector))  # thigh + bend @ shin
    _rotation_between(bent_shin, reach, swing)
    _product(swing, bend, turned)
    for i in range(3):
        for j in range(3):
            shin[i, j] = _dot(turned[i], swing[j])  # swing @ bend @ swing.T


@njit(cache=True, error_model="numpy")
def solve_leg(rotations, world_rot, world_pos, parents, hip, knee, ankle, toe, tip, target, work):  # pragma: no cover - compiled
    """Leg IK in place on the local rotations: hip and knee swung, the ankle keeping its world
    rotation. The hip is the knee's parent and the knee the ankle's (limbs.py): below the hip
    everything turns with the thigh, below the knee also with the shin. `work` (7, 3, 3): scratch.
    The toe line (to the `toe` joint, or a toe-less foot's `tip`) tells a straight knee which way is forward."""
    toes = _toe_line(world_rot, world_pos, ankle, toe, tip)
    thigh, shin, hip_world, knee_world, turn = work[0], work[1], work[2], work[3], work[4]
    leg_swings(world_pos[hip], world_pos[knee], world_pos[ankle], target, toes, thigh, shin, work[5:])
    _product(thigh, world_rot[hip], hip_world)  # thigh @ world_rot[hip]
    _product(shin, thigh, turn)
    _product(turn, world_rot[knee], knee_world)  # shin @ thigh @ world_rot[knee]
    parent = parents[hip]
    if parent >= 0:
        _product_t(world_rot[parent], hip_world, rotations[hip])
    else:
        _copy_matrix(hip_world, rotations[hip])
    _product_t(hip_world, knee_world, rotations[knee])
    _product_t(knee_world, world_rot[ankle], rotations[ankle])


@njit(cache=True, error_model="numpy")
def lock_work():  # pragma: no cover - compiled
    """What a character's `lock_frame` writes as it goes, made once for a whole crowd's call so the
    lock allocates nothing a character: planted (2,) bool, extension (2,), targets (2, 3), turns
    (2, 3, 3), angles (2,), scratch matrices (8, 3, 3), closing steps' lifts (2,) and holds (2,), the
    legs' generated local rotations (2, 4, 3, 3: `release_joints`' joints) and which feet land (2,) bool."""
    return (np.empty(2, dtype=np.bool_), np.empty(2), np.empty((2, 3)), np.empty((2, 3, 3)), np.empty(2),
            np.empty((8, 3, 3)), np.empty(2), np.empty(2), np.empty((2, 4, 3, 3)), np.empty(2, dtype=np.bool_))


@njit(cache=True, error_model="numpy")
def lock_frame(rotations, translations, shares, world_rot, world_pos, weights, points, headings, drop, previous, rises,
               settling, landed, held, offsets, released, releasing, pulls, locking, standing, parents, joints, feet, across, tips, pivot_ground, ground, reach, parent_rot,
               root, fps, cm,
               swing_lift, work):  # pragma: no cover - compiled
    """One character's frame (arrays of that character; `drop` a 1-element view, `standing` a
    bool). Returns nothing: rotations, translations, the world transforms and the state are
    updated in place."""
    planted, extension, targets, turns, angles, matrices, lifts, holding, generated, fresh = work
    speeds = planted_feet(shares, world_rot, world_pos, previous, joints, feet, tips, pivot_ground, ground, fps, cm, planted)
    for f in range(2):  # a planted leg's local rotations as made, which its lock's offsets are measured from
        if planted[f]:
            leg = (joints[f, 0], joints[f, 1], joints[f, 2], feet[f, -1])
            for k in range(3):
                _copy_matrix(rotations[leg[k]], generated[f, k])
            _copy_matrix(world_rot[leg[3]], generated[f, 3])  # the toes': their world rotation
    # both generated feet nearly still (no closing step while the pose steps off; NaN at first: not still)
    still = standing and speeds[0] < SETTLE_STILL_CM_S and speeds[1] < SETTLE_STILL_CM_S
    step = per_frame(BLEND_FRAMES, fps)
    hold_step = per_frame(HOLD_FRAMES, fps)
    for f in range(2):
        fresh[f] = planted[f] and weights[f] == 0.0  # landing: locked where it is (below, once any release is applied)
    # each foot's pace in: faster landing from flight, the other foot neither planted nor held
    pace = (LANDING_PACE * step if weights[1] == 0.0 and not planted[1] else step,
            LANDING_PACE * step if weights[0] == 0.0 and not planted[0] else step)
    for f in range(2):
        if not planted[f] and weights[f] == 1.0 and planted[1 - f]:  # a walk's foot let go from its full lock: given back in joint space
            releasing[f], rises[f], held[f], locking[f] = 1.0, 0.0, 0.0, 0.0
            for k in range(4):
                _copy_matrix(offsets[f, k], released[f, k])
    for f in range(2):
        weights[f] = min(1.0, weights[f] + pace[f]) if planted[f] else max(0.0, weights[f] - step)
        pulls[f] = pull_step(pulls[f], planted[f], pace[f], step)
        landed[f] = min(1.0, landed[f] + hold_step) if planted[f] else max(0.0, landed[f] - hold_step)
        if releasing[f] > 0.0:  # runs out even if the foot lands again first (a quick step: it lands where it is shown)
            releasing[f] = max(0.0, releasing[f] - per_frame(RELEASE_FRAMES, fps))
            # the swing lift comes in as the offsets go (at once, a bent knee's foot was lifted 2 cm in a frame)
            landed[f] = max(landed[f], releasing[f])
            release_joints(rotations, translations, world_rot, world_pos, parents, joints[f], feet[f], tips[f], across[f],
                           ground[f, 0], pivot_ground[f], released[f], ease(releasing[f]), matrices[:3])
        # the weight the lock's IK holds the foot with: `weights`' pace, but none from a walk's release
        # on (given back in joint space; `weights` still blends out as before, for the body's follow
        # and the footfalls), so a foot planted again before its release ran out takes the lock in
        # from none (at `weights`, not yet 0, the heading, the flat foot and the hold came back in a frame)
        locking[f] = min(1.0, locking[f] + pace[f]) if planted[f] else max(0.0, locking[f] - step)
    for f in range(2):
        if fresh[f]:
            pivot = _pivot_at(world_rot, world_pos, joints[f, 2], feet[f, -1], tips[f])
            for i in range(3):
                points[f, i] = pivot[i]
            headings[f] = foot_heading(world_rot, joints[f, 2], across[f])
            # landed: a stand may close it up again; and the body has stepped, so the other foot, if
            # a stand closed it up, may be closed up again too (a stop after one step leaves it behind)
            settling[f] = 0.0
            if settling[1 - f] == CLOSED:
                settling[1 - f] = 0.0
    settle_feet(still, planted, weights, points, headings, settling, world_rot, world_pos, joints, feet, tips, across,
                SETTLE_CM / cm,
                1.0 / (SETTLE_SECONDS * fps), SETTLE_LIFT_CM / cm, lifts)
    for f in range(2):
        if locking[f] > 0.0:
            hold_heading(rotations, world_rot, world_pos, joints[f, 1], joints[f, 2], feet[f], across[f], headings[f],
                         ease(locking[f]))
    for f in range(2):  # alone on the floor, a planted foot stands flat; a released other foot whose lock is
        # still blending out does not keep it from doing so (it would hold the landing foot's toes up
        # while the trailing foot's come off the floor: docs/evaluate.md, "Floating the stricter way")
        share = ease(locking[f]) * (1.0 - (ease(locking[1 - f]) if planted[1 - f] else 0.0))
        if share > 0.0:
            lay_flat(rotations, world_rot, world_pos, joints[f, 1], joints[f, 2], feet[f], tips[f], across[f], ground[f, 0],
                     pivot_ground[f], share)
    for f in range(2):  # each leg's generated hip-to-ankle distance, which the lock keeps where it can
        gap = _sub(world_pos[joints[f, 2]], world_pos[joints[f, 0]])
        extension[f] = np.sqrt(_dot(gap, gap))
    on_floor = CONTACT_CM / cm
    rise_step = HEEL_RISE_SPEED / fps
    _targets(world_rot, world_pos, joints, feet, across, tips, pivot_ground, ground, locking, pulls, points, planted, landed, held,
             hold_step, swing_lift, on_floor, extension, rises, rise_step, targets, turns, angles, holding)
    # eased towards what it needs by 1 / BLEND_FRAMES of the way a frame at REFERENCE_FPS: the same time at any rate
    drop[0] += (body_drop(world_pos, joints, reach, targets, planted, extension) - drop[0]) * eased_per_frame(
        1.0 / BLEND_FRAMES, fps)
    if drop[0] > 1e-9:
        for a in range(3):  # [0, drop, 0] @ parent_rot, element by element (no temporary array)
            translations[root, a] -= drop[0] * parent_rot[1, a]
        world_pos[:, 1] -= drop[0]
        _targets(world_rot, world_pos, joints, feet, across, tips, pivot_ground, ground, locking, pulls, points, planted, landed,
                 held, hold_step, swing_lift, on_floor, extension, rises, rise_step, targets, turns, angles, holding)
    rises[0], rises[1] = angles[0], angles[1]
    held[0], held[1] = holding[0], holding[1]
    for f in range(2):  # a closing step's foot off the floor
        targets[f, 1] += lifts[f]
    turned = matrices[0]
    for f in range(2):
        ankle, pivot = joints[f, 2], feet[f, -1]
        if pivot != ankle and not _identity(turns[f]):
            # the toes keep their generated world rotation, bending as the heel rises
            # (everything below the ankle turns with it: the pivot's parent's new world rotation)
            _product(turns[f], world_rot[parents[pivot]], turned)
            _product_t(turned, world_rot[pivot], rotations[pivot])
        _product(turns[f], world_rot[ankle], turned)
        _copy_matrix(turned, world_rot[ankle])  # the foot keeps its generated world rotation, but for the heel's rise
        gap = _sub(targets[f], world_pos[ankle])
        if np.sqrt(_dot(gap, gap)) > 1e-9:
            solve_leg(rotations, world_rot, world_pos, parents, joints[f, 0], joints[f, 1], ankle, feet[f, -1], tips[f],
                      targets[f], matrices[1:])
        elif not _identity(turns[f]):  # the ankle where it was made, the foot turned all the same
            _product_t(world_rot[joints[f, 1]], world_rot[ankle], rotations[ankle])
    for f in range(2):  # a fully held foot's lock (with what it still gives back of an earlier one) as offsets from
        # the rotations made: what a release the next frame gives back (only a foot at full weight is released so)
        if planted[f] and weights[f] == 1.0:
            leg = (joints[f, 0], joints[f, 1], joints[f, 2], feet[f, -1])
            for k in range(3):
                _product_t(generated[f, k], rotations[leg[k]], offsets[f, k])
            # the toes' world turn (locked @ made^T): the toes keep their world rotation as the heel rises
            for i in range(3):
                for j in range(3):
                    offsets[f, 3, i, j] = _dot(world_rot[leg[3]][i], generated[f, 3][j])


@njit(cache=True, error_model="numpy")
def pull_step(pull, planted, pace, step):  # pragma: no cover - compiled
    """A foot's horizontal hold a frame on (0..1): a planted foot's comes in on an ease-out curve
    (fastest at touch-down, `pace` of the curve a frame), a lifted foot's goes on a smoothstep
    (`step` a frame). Each frame finds where on its curve the hold is and moves along it, so a foot
    that lands or lifts again partway through keeps its hold, and its position, continuous. On
    smoothstep, a landing foot slid on at the made foot's speed for the first frames of its blend
    (the made heel strike's: 50-85 cm/s at 120 fps) while the hold started at zero speed; eased out,
    the hold's own speed at touch-down is still zero (the lock's point is where the foot is), and
    the planted slide at 30 / 120 fps went from 4.65 / 7.05 to 3.79 / 3.90 cm/s on active at weight
    2 (docs/evaluate.md, "A landing foot's hold, eased out"). A foot is let go as before: smoothstep
    ends at zero speed, where an ease-out would jump by the whole gap to the made foot."""
    if planted:
        along = min(1.0, 1.0 - np.sqrt(max(0.0, 1.0 - pull)) + pace)
        return 1.0 - (1.0 - along) * (1.0 - along)
    along = max(0.0, 0.5 - np.sin(np.arcsin(min(1.0, max(-1.0, 1.0 - 2.0 * pull))) / 3.0) - step)
    return ease(along)


@njit(cache=True, error_model="numpy")
def release_joints(rotations, translations, world_rot, world_pos, parents, leg, foot, tip, across, ankle_clearance,
                   pivot_clearance, offsets, share, turn):  # pragma: no cover - compiled
    """A walk's released foot given back in joint space: `share` (1..0) of each of its lock's
    offsets (4, 3, 3: generated^T @ locked local rotations at the hip, knee, ankle and pivot, as
    of its last fully locked frame; the angle scaled about the offset's own axis) applied on top of
    the generated local rotations, and the leg's world transforms (hip, knee and `foot`) by FK.
    Letting go of the ankle's IK target instead (the lock's weight, hold and heel rise) jumped the
    ankle as the rise's cap fell at toe-off; rotations eased out cannot snap. The foot is then
    pitched back about its ankle to no more than MAX_HEEL_RISE from flat (or as made, if more):
    the offsets' pitch on a made foot pitching up at toe-off took it up to 20 deg past the vertical
    (elderly -1). The toes keep their world rotation as made but for a share of the lock's world
    turn of them (offsets[3]: about the vertical, the held heading), as a rising heel leaves them.
    `turn` (3, 3, 3): scratch."""
    made = _risen(world_rot, world_pos, leg[2], foot[-1], tip, across, ankle_clearance, pivot_clearance)
    pivot = foot[-1]
    _copy_matrix(world_rot[pivot], turn[2])  # the toes' world rotation as made
    chain = (leg[0], leg[1], leg[2])
    for k in range(3):
        _scaled_rotation(offsets[k], share, turn[0])
        _product(rotations[chain[k]], turn[0], turn[1])  # the generated rotation, then the share of the offset
        _copy_matrix(turn[1], rotations[chain[k]])
    _leg_forward(rotations, translations, world_rot, world_pos, parents, leg, foot)
    excess = _risen(world_rot, world_pos, leg[2], pivot, tip, across, ankle_clearance, pivot_clearance) - max(
        MAX_HEEL_RISE, made)
    k = _across_world(world_rot, leg[2], across)
    if excess > 0.0 and np.hypot(k[0], k[2]) > 1e-12:  # about the foot's axis across it (heel_rise's): negative lowers the heel
        turn_foot(rotations, world_rot, world_pos, leg[1], leg[2], foot, k[0], k[1], k[2], np.cos(excess), -np.sin(excess))
    if pivot != leg[2]:  # the toes: their world rotation as made, turned by the share of the lock's world turn of them
        _scaled_rotation(offsets[3], share, turn[0])
        _product(turn[0], turn[2], turn[1])
        _product_t(world_rot[parents[pivot]], turn[1], rotations[pivot])
        _leg_forward(rotations, translations, world_rot, world_pos, parents, leg, foot)


@njit(cache=True, error_model="numpy")
def _leg_forward(rotations, translations, world_rot, world_pos, parents, leg, foot):  # pragma: no cover - compiled
    """The world transforms of a leg's hip, knee and `foot` joints from their local ones (FK; a BVH
    lists parents before children)."""
    for j in range(parents.shape[0]):
        member = j == leg[0] or j == leg[1]
        for i in range(foot.shape[0]):
            member = member or foot[i] == j
        if member:
            compose_joint(parents, rotations, translations, world_rot, world_pos, j)


@njit(cache=True, error_model="numpy")
def _risen(world_rot, world_pos, ankle, pivot, tip, across, ankle_clearance, pivot_clearance) -> float:  # pragma: no cover - compiled
    """How far the foot's heel is up from standing flat (radians; as `heel_rise` measures it,
    growing past the vertical); 0 for a foot with no toe line or axis across it."""
    toes = _toe_line(world_rot, world_pos, ankle, pivot, tip)
    k = _across_world(world_rot, ankle, across)
    level = np.hypot(k[0], k[2])
    if level < 1e-12 or _dot(toes, toes) < 1e-24:
        return 0.0
    return _rise_angle(toes, k, level, ankle_clearance, pivot_clearance)


@njit(cache=True, error_model="numpy")
def _rise_angle(toes, k, level, ankle_clearance, pivot_clearance) -> float:  # pragma: no cover - compiled
    """How far the heel is up from standing flat (radians): the toes' elevation standing flat (from
    the clearances) less their elevation in the pose, measured along the foot's level forward (k x
    up, k the foot's axis across it in the world, `level` its horizontal length), so it keeps
    growing as a foot pitches past vertical."""
    flat = np.arcsin(min(max((pivot_clearance - ankle_clearance) / np.sqrt(_dot(toes, toes)), -1.0), 1.0))
    return flat - np.arctan2(toes[1], (toes[2] * k[0] - toes[0] * k[2]) / level)


@njit(cache=True, error_model="numpy", inline="always")
def _across_world(world_rot, ankle, across):  # pragma: no cover - compiled
    """The foot's axis across it (`across`, in the ankle's frame: `across_axes`) in the world, as a
    tuple: what its heading, its heel rise and its laying flat turn it about."""
    r = world_rot[ankle]
    return (_dot(r[0], across), _dot(r[1], across), _dot(r[2], across))


@njit(cache=True, error_model="numpy")
def _scaled_rotation(rotation, share, out):  # pragma: no cover - compiled
    """out = `rotation` with its angle scaled by `share`, about the same axis (the angle from both
    its sine and its cosine, and the axis of unit length: arccos alone loses half the digits of a
    small angle)."""
    axis = (rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1])
    twice_sine = np.sqrt(_dot(axis, axis))
    if twice_sine < 1e-12:  # none (or a half turn, which a lock's offset is not)
        _set_identity(out)
        return
    angle = np.arctan2(twice_sine, rotation[0, 0] + rotation[1, 1] + rotation[2, 2] - 1.0)
    axis = _scaled(axis, twice_sine)
    _axis_rotation(axis, np.sin(share * angle), 1.0 - np.cos(share * angle), out)


@njit(cache=True, error_model="numpy")
def settle_feet(still, planted, weights, points, headings, settling, world_rot, world_pos, joints, feet, tips, across, threshold,
                step, height,
                lifts):  # pragma: no cover - compiled
    """A closing step: the first time a stand's pose is `still` with both feet planted and locked
    in since a foot landed, each foot whose locked point is more than `threshold` from where the
    stand's pose puts it (its generated pivot, horizontally) steps there, the further first and
    one at a time: its point (and the heading it is held to) moves to the generated one along a
    smoothstep over 1 / `step` frames while the foot is lifted by up to `height` (a half sine;
    written into `lifts` (2,), 0 for a foot not stepping). `settling` (2,): 0 a foot that may
    step, in (0, 1) how far its step is, CLOSED one that has stepped or needed none (until it
    lands again). A stop leaves the feet where its last, braked steps landed them, staggered, and
    the lock held them there through the stand: the body stood between feet its pose did not
    have, a heel risen, and the next start's first step set off from them (docs/evaluate.md, "A
    stop that closes its feet"). Only then: a stand's pose drifting a few centimetres over
    seconds is held, as before. A step under way finishes even if the stand ends (its lift never
    drops in a frame)."""
    lifts[0], lifts[1] = 0.0, 0.0
    moving = 0 if 0.0 < settling[0] < CLOSED else 1 if 0.0 < settling[1] < CLOSED else -1
    if moving < 0:
        if not (still and planted[0] and planted[1] and weights[0] == 1.0 and weights[1] == 1.0):
            return
        far = threshold
        for f in range(2):
            if settling[f] == 0.0:
                pivot = _pivot_at(world_rot, world_pos, joints[f, 2], feet[f, -1], tips[f])
                away = np.hypot(points[f, 0] - pivot[0], points[f, 2] - pivot[2])
                if away > far:
                    moving, far = f, away
        if moving < 0:  # none is far: the stand holds them where they are
            for f in range(2):
                if settling[f] == 0.0:
                    settling[f] = CLOSED
            return
    f = moving
    before = ease(settling[f])
    # n steps of 1 / n may sum to a hair under 1 (at 25 and 60 fps: 0.9999999999999999), whose
    # ease is 1: the step ends there, not in a frame after it that divides 0 by 0
    settling[f] = 1.0 if settling[f] + step > 1.0 - 1e-9 else settling[f] + step
    # the share of the way still to go that stays to go (none once the way was all gone)
    keep = (1.0 - ease(settling[f])) / (1.0 - before) if before < 1.0 else 0.0
    pivot = _pivot_at(world_rot, world_pos, joints[f, 2], feet[f, -1], tips[f])
    for i in (0, 2):
        points[f, i] = pivot[i] + (points[f, i] - pivot[i]) * keep
    turn = (headings[f] - foot_heading(world_rot, joints[f, 2], across[f]) + np.pi) % (2.0 * np.pi) - np.pi
    headings[f] -= turn * (1.0 - keep)
    lifts[f] = height * np.sin(np.pi * settling[f])
    if settling[f] >= 1.0:
        settling[f] = CLOSED


@njit(cache=True, error_model="numpy")
def foot_heading(world_rot, ankle, across) -> float:  # pragma: no cover - compiled
    """Which way the foot points, about the vertical (radians; 0 along +z), from its axis
    `across` (in the ankle's frame: `across_axes`), which pitching does not turn."""
    r = world_rot[ankle]
    x = r[0, 0] * across[0] + r[0, 1] * across[1] + r[0, 2] * across[2]
    z = r[2, 0] * across[0] + r[2, 1] * across[1] + r[2, 2] * across[2]
    return np.arctan2(-z, x)


@njit(cache=True, error_model="numpy")
def hold_heading(rotations, world_rot, world_pos, knee, ankle, foot, across, heading, share):  # pragma: no cover - compiled
    """A planted foot turned about the vertical through its ankle, `share` of the way back to the
    heading it landed with: a foot that yaws in the generated walk would swing its toes and heel
    about its locked toes, sliding them (skate 3-20% lower on the shipped model's walks with
    it). Its joints' world transforms follow; the ankle's local rotation takes the turn."""
    turn = heading - foot_heading(world_rot, ankle, across)  # `foot`: the ankle and the joints below it, pivot last
    turn = share * ((turn + np.pi) % (2.0 * np.pi) - np.pi)
    if turn != 0.0:  # about +y: +z turns towards +x
        turn_foot(rotations, world_rot, world_pos, knee, ankle, foot, 0.0, 1.0, 0.0, np.cos(turn), np.sin(turn))


@njit(cache=True, error_model="numpy")
def lay_flat(rotations, world_rot, world_pos, knee, ankle, foot, tip, across, ankle_clearance, pivot_clearance,
             share):  # pragma: no cover - compiled
    """A planted foot whose toes are up (its pivot higher above its clearance than the ankle is
    above its own) pitched down about its ankle, `share` of the way to flat. Real feet roll flat
    soon after the heel lands and stay so while the other foot swings; an extrapolated style
    can stand on its heels through the whole stance, its toes in the air and the swinging foot
    passing below them (the lowest foot joint then sweeps along at the swing's speed). Its
    joints' world transforms follow; the ankle's local rotation takes the turn. A toe-less
    foot's toes are its `tip` (`_toe_line`); a foot with neither has none to lay flat."""
    vx, vy, vz = _toe_line(world_rot, world_pos, ankle, foot[-1], tip)
    if vx == 0.0 and vy == 0.0 and vz == 0.0:
        return
    toes_up = vy - (pivot_clearance - ankle_clearance)
    if toes_up <= 0.0:
        return
    # about the foot's axis across it (up x toes for a flat foot; as the heading and the heel rise
    # read it, so the turn leaves the heading held): a positive turn pitches the toes down. The
    # toes turned by t are at height  along_k + a cos t + b sin t:  solved for the height wanted
    k = _across_world(world_rot, ankle, across)
    if _dot(k, k) < 1e-12:
        return
    v = (vx, vy, vz)
    along_k = _dot(v, k) * k[1]
    a = vy - along_k  # the height of the toes' part the turn moves
    b = _cross(k, v)[1]
    spread = np.hypot(a, b)
    wanted = vy - share * toes_up - along_k
    if spread < 1e-12 or abs(wanted) >= spread:
        return
    phi = np.arctan2(b, a)
    gap = np.arccos(wanted / spread)
    pitch = (phi - gap + np.pi) % (2.0 * np.pi) - np.pi
    other = (phi + gap + np.pi) % (2.0 * np.pi) - np.pi
    if abs(other) < abs(pitch):
        pitch = other
    turn_foot(rotations, world_rot, world_pos, knee, ankle, foot, k[0], k[1], k[2], np.cos(pitch), np.sin(pitch))


@njit(cache=True, error_model="numpy")
def turn_foot(rotations, world_rot, world_pos, knee, ankle, foot, kx, ky, kz, c, s):  # pragma: no cover - compiled
    """The foot (the ankle and the joints below it) turned about its ankle, about the unit axis
    (kx, ky, kz) by the angle of cosine c and sine s: its joints' world transforms follow and the
    ankle's local rotation takes the turn. In place, nothing allocated: the heading hold and the
    flat foot run it for a planted foot every frame."""
    cx, cy, cz = world_pos[ankle, 0], world_pos[ankle, 1], world_pos[ankle, 2]
    for j in foot:
        for col in range(3):
            world_rot[j, 0, col], world_rot[j, 1, col], world_rot[j, 2, col] = _turned(
                kx, ky, kz, c, s, world_rot[j, 0, col], world_rot[j, 1, col], world_rot[j, 2, col])
        x, y, z = _turned(kx, ky, kz, c, s, world_pos[j, 0] - cx, world_pos[j, 1] - cy, world_pos[j, 2] - cz)
        world_pos[j, 0], world_pos[j, 1], world_pos[j, 2] = cx + x, cy + y, cz + z
    _product_t(world_rot[knee], world_rot[ankle], rotations[ankle])  # the knee is the ankle's parent (limbs.py)


@njit(cache=True, error_model="numpy", inline="always")
def _turned(kx, ky, kz, c, s, x, y, z):  # pragma: no cover - compiled
    """(x, y, z) turned about the unit axis (kx, ky, kz) by the angle of cosine c and sine s
    (Rodrigues: v c + (k x v) s + k (k . v)(1 - c))."""
    along = (kx * x + ky * y + kz * z) * (1.0 - c)
    return (x * c + (ky * z - kz * y) * s + kx * along, y * c + (kz * x - kx * z) * s + ky * along,
            z * c + (kx * y - ky * x) * s + kz * along)


@njit(cache=True, error_model="numpy")
def _targets(world_rot, world_pos, joints, feet, across, tips, pivot_ground, ground, locking, pulls, points, planted, landed, held,
             hold_step,
             swing_lift, on_floor, extension, rises, rise_step, targets, turns, angles, holding):  # pragma: no cover - compiled
    """Each ankle's target (2, 3), each foot's heel-rise turn (2, 3, 3) and angle (2,), and how far
    its lowest joint is held down (2,), written into `targets`, `turns`, `angles` and `holding`: a
    foot whose lock is blended in rises on its toes where its leg would otherwise stretch past its
    generated extension, its rise within `rise_step` of the frame before's (`rises`), coming down
    at that pace after its lock has gone; its hold within `hold_step` of the frame before's (`held`)."""
    for f in range(2):
        # the other foot planted but its lowest point not yet down: this one hands over to it
        handing_over = planted[1 - f] and _sole_lift(world_rot, world_pos, feet[1 - f], tips[1 - f], ground[1 - f],
                                                     pivot_ground[1 - f]) >= on_floor
        holding[f] = min(1.0, held[f] + hold_step) if planted[f] or handing_over else max(0.0, held[f] - hold_step)
        lock_target(world_rot, world_pos, joints[f], feet[f], tips[f], ground[f], pivot_ground[f], locking[f], points[f],
                    ease(landed[f]), ease(holding[f]),
                    swing_lift, targets[f], pulls[f])
        _set_identity(turns[f])
        angles[f] = 0.0
        if locking[f] > 0.0 or rises[f] > 0.0:
            clearance = (ground[f, 0], pivot_ground[f])
            low = max(rises[f] - rise_step, 0.0)
            high = min(rises[f] + rise_step, MAX_HEEL_RISE) if locking[f] > 0.0 else low
            angles[f] = heel_rise(world_rot, world_pos, joints[f], feet[f, -1], tips[f], across[f], clearance, on_floor,
                                  targets[f],
                                  extension[f], low, high, turns[f])
        # a foot released in a run's flight (a walk's other foot is down), or held by its pull alone (a
        # walk's foot given back in joint space): no further than its leg as made
        if (not planted[f] and not planted[1 - f] and locking[f] > 0.0) or (locking[f] == 0.0 and pulls[f] > 0.0):
            within_reach(targets[f], world_pos[joints[f, 0]], extension[f])


@njit(cache=True, error_model="numpy")
def within_reach(target, hip, extension):  # pragma: no cover - compiled
    """A released foot's ankle `target` brought in towards the `hip`, in place, to no further than
    the leg's generated `extension`, where the other foot is not planted either (a run's flight;
    in a walk the other foot is down, and brought in, a trailing foot's toes left the floor
    before the landing one's were down): its lock, blending out, pulled it back towards the
    point it held while the generated foot went on, and past a run's toe-off (the foot made
    pointing straight down, no heel rise left to take it) the leg was stretched straight for a
    frame, the knee from 31 degrees of bend to 2 and back to 20 (19 cm/frame^2, against 12 in
    the real runs)."""
    gap = _sub(target, hip)
    distance = np.sqrt(_dot(gap, gap))
    if distance > extension > 0.0:
        for i in range(3):
            target[i] = hip[i] + gap[i] * (extension / distance)


@njit(cache=True, nogil=True, error_model="numpy")
def lock_crowd(rotations, translations, shares, world_rot, world_pos, weights, points, headings, drop, previous, rises,
               settling, landed, held, offsets, released, releasing, pulls, locking, standing, parents, joints, feet, across, tips, pivot_ground, ground, reach, parent_rot,
               root, fps, cm,
               swing_lift):  # pragma: no cover - compiled
    """Every character's `lock_frame`, then the world transforms of the adjusted poses."""
    work = lock_work()
    for n in range(rotations.shape[0]):
        lock_frame(rotations[n], translations[n], shares[n], world_rot[n], world_pos[n], weights[n], points[n], headings[n],
                   drop[n : n + 1], previous[n], rises[n], settling[n], landed[n], held[n], offsets[n], released[n], releasing[n], pulls[n], locking[n],
                   standing[n], parents, joints, feet,
                   across, tips, pivot_ground, ground, reach, parent_rot, root, fps, cm, swing_lift, work)
    _compose(parents, rotations, translations, world_rot, world_pos)
