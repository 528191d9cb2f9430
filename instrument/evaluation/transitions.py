"""Stopping and starting: a walk or a run that stops, stands and sets off again, measured.

One sequence per gait and weighting, through the engine frame by frame with the gait changed
part-way (sequence.py): MOVE_SECONDS of the gait (after the settling half second), STAND_SECONDS
of stand, MOVE_SECONDS of the gait again. From it, two transitions:

    <gait>->stand  stop_s, stop_steps: from the command until every foot joint stays under
                   FEET_STILL_CM_S for the rest of the stand (the last step has landed; a stand's
                   feet move well under 3 cm/s, a stepping foot at a metre a second), and how
                   many of the gait's steps the body was in on the way (the one under way counts)
    stand-><gait>  speed_s, speed_steps: from the command until the hips' speed, over a window of
                   one step, reaches SPEED_SHARE of the gait's steady speed (the sequence's first
                   part), and the steps begun on the way

and for each, over its window (the command to WINDOW_AFTER s after it is done, or to the next
command if it is never done): `slide_cm_s` the mean speed of the lowest foot joint (the skate of
quality.py) over the frames a foot is on the ground (a run's flight is no slide), `jump_cm_f2`
the largest joint velocity jump (sequence.velocity_jumps), with the joint (`jump_joint`) and
when after the command (`jump_s`), and `air_frames` the frames with both feet in the air.

Both carry `gait_jump_cm_f2`, the largest jump of the gait itself at those weights: the same
gait from rest, never told to stop, over STEADY_SECONDS after the settling (its first MOVE_SECONDS
are the sequence's own first part, frame for frame). At a weight past the styles (x2, -1) the
gait's own swing may jump more than any real take (a swing of the same duration over more range
is more acceleration): what a transition must not add is a jump beyond that (targets.py). It is
not read from the sequence after the start: that walk may not have settled yet (feminine x2's
jumped 9.1 there, its steady walk 7.8), which would loosen the bound by what is judged.
"""

from __future__ import annotations

import numpy as np

from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.kinematics import world_positions
from ..synthesis.engine import Controls, default_controls
from ..synthesis.parameters import GAITS
from .assessment import SETTLE_SECONDS
from .sequence import Sequence, horizontal_speed, render_forks, render_sequence, velocity_jumps

MOVE_SECONDS = 4.0
STAND_SECONDS = 4.0
FEET_STILL_CM_S = 10.0  # every foot joint slower than this: no foot is stepping
SPEED_SHARE = 0.9  # "at speed": this share of the steady speed
WINDOW_AFTER = 1.0  # s after a transition is done that its window still covers
PARTWAY_STEPS = 2.0  # a change part-way comes up to this many of the gait's steps after the first command
PARTWAY_EVERY = 3  # frames between the timings swept
PARTWAY_AFTER = 2.0  # steps of the gait each change part-way is played for after its second command
PARTWAY_CHANGES = ("stop called off", "start stopped")  # the changes part-way, as their figures are named
STEADY_SECONDS = 8.0  # the steady gait whose largest jump a transition past the styles is held to (as units.UNIT_SECONDS)


def transition_sequence(model: Model, gait: str, weights: dict[str, float]) -> Sequence:
    """`gait`, stand, `gait` again, each for its seconds, from rest."""
    return transition_forks(model, gait, weights)[0]


def transition_forks(model: Model, gait: str, weights: dict[str, float],
                     partway: bool = False) -> tuple[Sequence, list[Sequence], list[Sequence]]:
    """`transition_sequence`, and with `partway` the sweep of changes part-way
    (`partway_timings`) forked from it: the stops called off (`gait` again) and the starts
    stopped (stand again) `delay` frames after the command, each played for `partway_frames`
    (two lists, empty without `partway`)."""
    fps = model.fps
    moving = default_controls(model, weights, gait=GAITS.index(gait))
    standing = default_controls(model, weights, gait=GAITS.index("stand"))
    settle = int(round(SETTLE_SECONDS * fps))
    stop_at = settle + int(round(MOVE_SECONDS * fps))
    start_at = stop_at + int(round(STAND_SECONDS * fps))
    stops: list[tuple[int, Controls, int]] = []
    starts: list[tuple[int, Controls, int]] = []
    if partway:
        length, delays = partway_frames(model, gait), partway_timings(model, gait)
        stops = [(stop_at + delay, moving, length) for delay in delays]
        starts = [(start_at + delay, standing, length) for delay in delays]
    sequence, forks = render_forks(model, [(moving, stop_at), (standing, start_at - stop_at),
                                           (moving, int(round(MOVE_SECONDS * fps)))], stops + starts)
    return sequence, forks[:len(stops)], forks[len(stops):]


def step_frames(model: Model, unit: str) -> float:
    """The mean frames of a step of `unit` in the model's average voice."""
    k = model.units.index(unit)
    return float(model.average.duration_means[2 * k:2 * k + 2].sum(axis=-1).mean())


def transition_figures(model: Model, gait: str, weights: dict[str, float], measure,
                       partway: bool = False) -> tuple[dict[str, dict[str, float]], dict[str, dict[str, float]]]:
    """{"<gait>->stand": figures, "stand-><gait>": figures} of one sequence (see the module's
    text), and with `partway` {"stop called off": figures, "start stopped": figures}
    (PARTWAY_CHANGES), the worst of the sweep of changes part-way (`partway_figures`; {} without);
    `measure` is units._Measure (the limbs, scale and ground to measure with)."""
    sequence, stops, starts = transition_forks(model, gait, weights, partway)
    fps = model.fps
    positions = world_positions(sequence.motion) * measure.cm
    root = positions[:, model.layout.root]
    stop_at, start_at = sequence.changes
    settle = int(round(SETTLE_SECONDS * fps))
    half_step = max(1, int(round(step_frames(model, gait) / 2)))
    paced = horizontal_speed(root, fps, half_step)
    steady = float(paced[settle + half_step:stop_at - half_step].mean())
    feet = [j for foot in measure.limbs.feet for j in foot]
    stepping = np.max([horizontal_speed(positions[:, j], fps) for j in feet], axis=0) >= FEET_STILL_CM_S
    moving = (sequence.labels // 2) != model.units.index("stand")
    joint_jumps, air = velocity_jumps(positions, per_joint=True), measure.air(positions)
    jumps = joint_jumps.max(axis=1)
    skate = measure.skate(positions, fps)
    after = int(round(WINDOW_AFTER * fps))
    names = sequence.motion.skeleton.names

    def window(start: int, done: int | None, end: int) -> dict:
        stop = end if done is None else min(end, done + after)
        ground = ~air[start:stop]
        worst = start + int(np.argmax(jumps[start:stop]))
        return {"slide_cm_s": float(skate[start:stop][ground].mean()) if ground.any() else float("nan"),
                "jump_cm_f2": float(jumps[worst]), "jump_joint": names[int(joint_jumps[worst].argmax())],
                "jump_s": (worst - start) / fps,
                "air_frames": float(air[start:stop].sum()), "window_frames": float(stop - start), "finite": float(np.isfinite(sequence.motion.channels).all())}

    still = settled(~stepping[stop_at:start_at])
    stopped = None if still is None else stop_at + still
    stop = {"steady_cm_s": steady,
            "stop_s": float("nan") if stopped is None else (stopped - stop_at) / fps,
            "stop_steps": float("nan") if stopped is None else float(_steps(sequence.labels, moving, stop_at, stopped))}
    # start: the first frame at SPEED_SHARE of the steady speed
    fast = np.flatnonzero(paced[start_at:] >= SPEED_SHARE * steady)
    reached = start_at + int(fast[0]) if len(fast) else None
    start = {"steady_cm_s": steady,
             "speed_s": float("nan") if reached is None else (reached - start_at) / fps,
             "speed_steps": float("nan") if reached is None else float(_steps(sequence.labels, moving, start_at, reached))}
    own = {"gait_jump_cm_f2": steady_jump(model, gait, weights, measure.cm)}
    out = {f"{gait}->stand": stop | window(stop_at, stopped, start_at) | own,
           f"stand->{gait}": start | window(start_at, reached, len(positions)) | own}
    called_off, stopped_again = PARTWAY_CHANGES
    partway = {change: partway_figures(forks, measure) | own
               for change, forks in ((called_off, stops), (stopped_again, starts)) if forks}
    return out, partway


def partway_timings(model: Model, gait: str) -> range:
    """The frames after a command that the sweep of changes part-way brings the second one: from
    2 to PARTWAY_STEPS of the gait's steps, every PARTWAY_EVERY (a start eases in over one or two
    steps; a stop brakes over the rest of its step and at most one more)."""
    return range(2, int(round(PARTWAY_STEPS * step_frames(model, gait))) + 1, PARTWAY_EVERY)


def partway_frames(model: Model, gait: str) -> int:
    """The frames each change part-way is played for after its second command."""
    return int(round(PARTWAY_AFTER * step_frames(model, gait)))


def partway_figures(forks: list[Sequence], measure) -> dict[str, float]:
    """The worst of a sweep of changes part-way (each fork: its second command at its last
    change), each measured from its second command to its end: `jump_cm_f2` the largest joint
    velocity jump over every fork, with its joint (`jump_joint`), the fork's `delay_frames` (from
    the first command to the second) and when after the second command (`jump_s`);
    `slide_cm_s` the largest of the forks' stance skates (as a transition's window: the lowest
    foot joint's mean speed over the frames a foot is down), with its `slide_delay_frames`; and
    `air_frames`, the most frames with both feet in the air."""
    out = {"jump_cm_f2": -1.0, "slide_cm_s": float("nan"), "air_frames": 0.0, "timings": float(len(forks))}
    for fork in forks:
        first, second = fork.changes[-2], fork.changes[-1]
        tail = Motion(fork.motion.skeleton, fork.motion.channels[second - 2:], fork.motion.fps)
        positions = world_positions(tail) * measure.cm
        joint_jumps = velocity_jumps(positions, per_joint=True)[2:]
        air = measure.air(positions)[2:]
        skate = measure.skate(positions, tail.fps)[2:]
        worst = int(np.argmax(joint_jumps.max(axis=1)))
        jump = float(joint_jumps[worst].max())
        if jump > out["jump_cm_f2"]:
            out |= {"jump_cm_f2": jump, "jump_joint": tail.skeleton.names[int(joint_jumps[worst].argmax())],
                    "delay_frames": float(second - first), "jump_s": worst / tail.fps}
        if (~air).any():  # (a fork with no foot down has no slide: it leaves the largest as it is)
            slide = float(skate[~air].mean())
            if not slide <= out["slide_cm_s"]:  # (the first, or a larger one)
                out |= {"slide_cm_s": slide, "slide_delay_frames": float(second - first)}
        out["air_frames"] = max(out["air_frames"], float(air.sum()))
    return out


def steady_jump(model: Model, gait: str, weights: dict[str, float], cm: float) -> float:
    """The largest joint velocity jump of `gait` at `weights` from rest, after the settling."""
    settle = int(round(SETTLE_SECONDS * model.fps))
    moving = default_controls(model, weights, gait=GAITS.index(gait))
    steady = render_sequence(model, [(moving, settle + int(round(STEADY_SECONDS * model.fps)))])
    return float(velocity_jumps(world_positions(steady.motion) * cm)[settle:].max())


def settled(still: np.ndarray) -> int | None:
    """The first frame from which `still` holds to the end (None: not even the last frame)."""
    moved = np.flatnonzero(~still)
    first = int(moved[-1]) + 1 if len(moved) else 0
    return None if first >= len(still) else first


def _steps(labels: np.ndarray, moving: np.ndarray, first: int, last: int) -> int:
    """How many steps of a moving unit frames first..last (inclusive) are in (a run of one label is a step)."""
    part, walking = labels[first:last + 1], moving[first:last + 1]
    starts = np.concatenate([[True], part[1:] != part[:-1]])
    return int((starts & walking).sum())
