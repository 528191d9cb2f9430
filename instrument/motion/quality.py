"""Figures of a walk that a motion specialist would check, for real takes and generated walks alike.

Everything is found from geometry and the joint tree (`limbs`), never from joint names, and is
given in centimetres, seconds and degrees whatever the skeleton's units (guessed from the hips'
height). A foot's height is measured against its ground clearance: how high each of its joints
is when it stands on the floor (the lowest it comes in the real data), so "on the floor" means
the same for a toe joint 4 cm above the sole and an ankle 12 cm above it.

    skate     horizontal speed of the lowest foot joint in each frame, which carries the body (cm/s;
              a toe-less foot's End Site tip, where it has one, counts as a joint: limbs.foot_tip)
    contact skate  the same of each foot while its lowest joint is within CONTACT_CM of its
              clearance (also counts a shuffling swing foot, so it is only reported in --json)
    under     frames where some foot joint is more than 1 cm below its clearance (fraction)
    air       frames where both feet are more than 3 cm above their clearance (fraction)
    float     frames where both feet are off the floor, the stricter way: each foot's lowest point
              (its lowest joint in that frame, ankle or toes) more than 3 cm above the height the
              lowest point has when a foot stands on the floor in the real takes (its 1st
              percentile, limbs.sole_clearance) (fraction)
    ranges    1st to 99th percentile of the knee's flexion, and of the thigh's and upper arm's
              swing in the plane of travel (degrees)
    jitter    mean magnitude of the third difference of the joint positions (m/s^3)
    drift     change of heading per second, fitted over every stride's mean heading (deg/s)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .bvh import Motion
from .features import FeatureLayout, heading_angle, travel_direction
from .kinematics import forward_kinematics, local_transforms
from .limbs import Limbs, clearance, sole_clearance, tip_positions
from .rotations import axis_angle_matrix
from .steps import Step, is_below, segment_steps

CONTACT_CM = 2.0
UNDER_CM = 1.0
AIR_CM = 3.0
RANGE_PERCENTILES = (1.0, 99.0)

FIGURES = (
    "step_s", "step_sd_s", "stride_cm", "speed_cm_s", "skate_cm_s", "under_frac", "under_depth_cm",
    "air_frac", "float_frac", "contact_skate_cm_s", "knee_deg", "hip_deg", "shoulder_deg", "jitter_m_s3", "drift_deg_s",
)


def _angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    cos = np.einsum("ti,ti->t", a, b) / (np.linalg.norm(a, axis=1) * np.linalg.norm(b, axis=1) + 1e-12)
    return np.degrees(np.arccos(np.clip(cos, -1.0, 1.0)))


def _spread(values: np.ndarray) -> float:
    low, high = np.percentile(values, RANGE_PERCENTILES)
    return float(high - low)


def _swing(bone: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Angle of a bone in the vertical plane of travel, from pointing down (degrees), in the frames
    where that angle means something: where the bone lies nearer that plane than across it (its
    part along the plane longer than its part across). An arm held out to the side lies across
    the plane, and its angle there jumps about with a centimetre of movement: in 6 frames of a
    public CMU take (tests/data/cmu-131) a right arm held out sideways read +135 and -146 degrees,
    and that arm's range read 271 degrees where it swings through about 150. The angles are
    taken about their circular mean, so an arm passing overhead does not wrap from +180 to -180.
    A bone never near the plane (always across it) is measured in every frame, as it is."""
    along = np.einsum("ti,ti->t", bone, forward)
    down = -bone[:, 1]
    across = np.sqrt(np.maximum(np.einsum("ti,ti->t", bone, bone) - along**2 - down**2, 0.0))
    angle = np.arctan2(along, down)
    near = np.hypot(along, down) > across
    if near.any():
        angle = angle[near]
    centre = np.arctan2(np.sin(angle).mean(), np.cos(angle).mean())
    return np.degrees(centre + (angle - centre + np.pi) % (2.0 * np.pi) - np.pi)


def heading_drift(yaw: np.ndarray, steps: list[Step], fps: float) -> float:
    """How fast a walk's heading turns (deg/s, unsigned): the slope of the straight line best
    fitting the mean heading of each stride (every two steps in a row) against its time.

    The hips sway their heading by up to 24 degrees within a step; a stride's mean heading does
    not depend on where in that sway a step was found to start, so the figure neither follows
    a frame's error in the step ends nor rests on the first and last step alone (the heading at
    one step start against another's gave 0.00 to 0.16 deg/s for one 12 s walk measured from 30
    start frames in a row, this 0.00 to 0.01)."""
    times, headings = stride_headings(yaw, steps, fps)
    return float(abs(np.polyfit(times, headings, 1)[0])) if len(times) >= 2 else float("nan")


def mean_turn_rate(yaw: np.ndarray, steps: list[Step], fps: float) -> float:
    """How fast a motion turns on average (yaw's units a second, + as yaw rises; NaN without
    steps or shorter than a stride): the mean heading over its last stride's frames less that
    over its first's, over the time between their middles. A stride is two of its steps' mean
    frames, so the sway of the hips' heading within it (up to 24 degrees a step) averages out.

    The heading at the last step's end less that at the first's start moved with where a step
    was found: a turn take cut a frame shorter lost its last step (the foot signal's extremum
    at its end no longer stood out), and the rate went from 26.1 to 34.4 deg/s (Bandai's
    turn-left_active_001 at 30 fps; the first to the last footfall of one foot still went from
    26.2 to 32.1 at 60 fps: a take turns little as it walks in and out of its turn). This takes
    the motion's frames from its first to its last: a frame more or less at either end moves it
    by at most 2.2% at 30 fps, 0.9% at 60 (every Bandai turn take cut by one to three frames at
    its end or one or two at its start; the step ends moved 11 of the 112 by 25% or more)."""
    if not steps:
        return float("nan")
    width = int(round(2.0 * np.mean([step.frames for step in steps])))
    if len(yaw) <= width:
        return float("nan")
    sums = np.concatenate([[0.0], np.cumsum(yaw)])
    first, last = sums[width] / width, (sums[-1] - sums[-1 - width]) / width
    return float((last - first) / ((len(yaw) - width) / fps))


def stride_headings(yaw: np.ndarray, steps: list[Step], fps: float) -> tuple[np.ndarray, np.ndarray]:
    """The middle time (s) and mean heading (degrees) of every stride (two steps in a row)."""
    strides = [(a.start, b.end) for a, b in zip(steps, steps[1:]) if b.start == a.end]
    times = np.array([(start + end - 1) / 2.0 for start, end in strides]) / fps
    headings = np.degrees([yaw[start:end].mean() for start, end in strides])
    return times, headings


def limb_ranges(pos: np.ndarray, yaw: np.ndarray, limbs: Limbs, root: int) -> dict[str, float]:
    """`knee_deg`, `hip_deg` and `shoulder_deg` (NaN without arms) of world positions (T, J, 3)
    whose root heads `yaw` (T,) radians: each the mean over both sides of its 1st to 99th
    percentile range. Training calibrates the range filter with it (synthesis/widen.py)."""
    forward = travel_direction(axis_angle_matrix("y", yaw), np.gradient(pos[:, root], axis=0))
    knees, hips = [], []
    for leg in limbs.legs:
        thigh = pos[:, leg.knee] - pos[:, leg.hip]
        shin = pos[:, leg.ankle] - pos[:, leg.knee]
        knees.append(_spread(_angle(thigh, shin)))
        hips.append(_spread(_swing(thigh, forward)))
    shoulders = [_spread(_swing(pos[:, e] - pos[:, s], forward)) for s, e in limbs.arms]
    return {"knee_deg": float(np.mean(knees)), "hip_deg": float(np.mean(hips)),
            "shoulder_deg": float(np.mean(shoulders)) if shoulders else float("nan")}


def skate(pos: np.ndarray, limbs: Limbs, fps: float, tips: np.ndarray | None = None) -> float:
    """How fast the foot point carrying the body (the lowest of both feet's joints in each frame,
    and of toe-less feet's tips (T, tips, 3) where given: `limbs.tip_positions`) moves over the
    floor, on average, in the units of the world positions `pos` (T, J, 3) per second. Training's
    range calibration holds it no higher (training/widen.py). A toe-less foot's ankle alone rises
    as its heel rolls up about its tip, which the foot lock holds still: counted without the
    tip, that roll read as skate."""
    points = pos[:, list(limbs.feet[0] + limbs.feet[1])]
    if tips is not None:
        points = np.concatenate([points, tips], axis=1)
    lowest = np.argmin(points[:, :, 1], axis=1)
    moving = np.linalg.norm(np.gradient(points[:, :, [0, 2]], axis=0), axis=2) * fps
    return float(moving[np.arange(len(pos)), lowest].mean())


def walk_figures(motion: Motion, layout: FeatureLayout, limbs: Limbs, ground: np.ndarray, cm: float,
                 sole: float | None = None) -> dict[str, float]:
    """The figures of one walk (see the module's docstring); NaN where a walk has too few steps.
    `ground` is each foot joint's clearance (limbs.clearance) and `sole` the foot's lowest point's
    (limbs.sole_clearance), both in the skeleton's units; without `sole`, the lowest of the
    joints' clearances stands for it (never below the real one, so `float` counts no more)."""
    world_rot, world_pos = forward_kinematics(motion.skeleton, *local_transforms(motion))
    pos = world_pos * cm
    fps = motion.fps
    seconds = motion.frames / fps
    yaw = heading_angle(world_rot[:, layout.root], layout.heading_reference)
    root = pos[:, layout.root]
    steps = segment_steps(motion, layout).steps
    out = dict.fromkeys(FIGURES, float("nan"))
    if steps:
        durations = np.array([s.frames for s in steps]) / fps
        travel = np.array([np.linalg.norm((root[s.end - 1] - root[s.start])[[0, 2]]) * s.frames / (s.frames - 1) for s in steps])
        out["step_s"], out["step_sd_s"] = float(durations.mean()), float(durations.std())
        out["stride_cm"] = float(2.0 * travel.mean())
        out["speed_cm_s"] = float(travel.sum() / durations.sum())
        out["drift_deg_s"] = heading_drift(yaw, steps, fps)
    # feet: lift above the ground clearance, contact, skate, floor
    lifts, speeds = [], []
    for f, foot in enumerate(limbs.feet):
        heights = pos[:, list(foot), 1] - ground[f] * cm
        lowest = np.argmin(heights, axis=1)
        lifts.append(heights[np.arange(motion.frames), lowest])
        horizontal = np.linalg.norm(np.gradient(pos[:, list(foot)][:, :, [0, 2]], axis=0), axis=2) * fps
        speeds.append(horizontal[np.arange(motion.frames), lowest])
    lift, speed = np.array(lifts), np.array(speeds)
    tips = tip_positions(world_rot, world_pos, limbs, layout)  # a toe-less foot's tip: a point the lock holds it by
    out["skate_cm_s"] = skate(pos, limbs, fps, None if tips is None else tips * cm)
    contact = lift < CONTACT_CM
    out["contact_skate_cm_s"] = float(speed[contact].mean()) if contact.any() else float("nan")
    out["under_frac"] = float((lift < -UNDER_CM).any(axis=0).mean())
    out["under_depth_cm"] = float(max(0.0, -lift.min()))
    out["air_frac"] = float((lift > AIR_CM).all(axis=0).mean())
    floor = (float(np.min(ground)) if sole is None else sole) * cm
    soles = np.array([pos[:, list(foot), 1].min(axis=1) for foot in limbs.feet]) - floor
    out["float_frac"] = float((soles > AIR_CM).all(axis=0).mean())
    out |= limb_ranges(pos, yaw, limbs, layout.root)
    body = pos[:, [j for j in range(pos.shape[1]) if j == layout.root or is_below(motion, j, layout.root)]]
    if motion.frames > 3:
        out["jitter_m_s3"] = float(np.linalg.norm(np.diff(body, 3, axis=0), axis=2).mean() * fps**3 / 100.0)
    out["seconds"] = seconds
    return out


@dataclass(frozen=True)
class TakeFloors:
    """Where each take's floor is, and the floor a model learnt from them stands on.

    A capture's floor is not always level from take to take: in the public CMU takes
    (tests/data/cmu-131) the feet's lowest points stand 3.5 cm higher in take 02 than in take
    01. One floor for all takes (the lowest take's) then found no foot of take 02 within 2 cm
    of it: no contact in training, feet "in the air" in `evaluate`. So each take is measured
    against its own floor (its own 1st percentiles), and a made walk, whose body height the
    model learnt from all of them, against their mean weighted by frames."""

    ground: list[np.ndarray]  # per take, (2, foot joints) clearance (limbs.clearance of that take alone)
    sole: list[float]  # per take, its feet's lowest point standing (limbs.sole_clearance of that take)
    mean_ground: np.ndarray  # (2, foot joints), the takes' weighted by their frames
    mean_sole: float


def take_floors(positions: list[np.ndarray], limbs: Limbs) -> TakeFloors:
    """Each take's floor from its world positions (T, J, 3) alone, and their mean."""
    ground = [clearance([p], limbs) for p in positions]
    sole = [sole_clearance([p], limbs) for p in positions]
    frames = np.array([len(p) for p in positions], dtype=np.float64)
    return TakeFloors(ground, sole, np.average(np.array(ground), axis=0, weights=frames),
                      float(np.average(sole, weights=frames)))


def pooled(figures: list[dict[str, float]]) -> dict[str, float]:
    """Figures of several walks as one, each weighted by its length."""
    weights = np.array([f["seconds"] for f in figures])
    out = {}
    for key in FIGURES:
        values = np.array([f[key] for f in figures])
        ok = np.isfinite(values)
        out[key] = float(np.average(values[ok], weights=weights[ok])) if ok.any() else float("nan")
    out["seconds"] = float(weights.sum())
    return out
