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
                   part), and the steps begun on the way; the same start is also told
                   EARLIER_STARTS frames sooner (forks of the sequence), so that it sets off from
                   either of the stand's pieces, on either foot: the worst of the six
                   (`sooner_frames`: how much sooner the one with the largest jump was told)

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
EARLIER_STARTS = (3, 6, 9, 12, 15)  # frames before the sequence's start that the same start is also told at
STEADY_SECONDS = 8.0  # the steady gait whose largest jump a transition past the styles is held to (as units.UNIT_SECONDS)


def transition_sequence(model: Model, gait: str, weights: dict[str, float]) -> Sequence:
    """`gait`, stand, `gait` again, each for its seconds, from rest."""
    return transition_forks(model, gait, weights)[0]


def transition_forks(model: Model, gait: str, weights: dict[str, float],
                     partway: bool = False) -> tuple[Sequence, list[Sequence], list[Sequence], list[Sequence]]:
    """`transition_sequence`, and forked from it: with `partway` the sweep of changes part-way
    (`partway_timings`): the stops called off (`gait` again) and the starts stopped (stand again)
    `delay` frames after the command, each played for `partway_frames` (two lists, empty without
    `partway`); and the same start told EARLIER_STARTS frames sooner, each played for MOVE_SECONDS.
    A stand alternates its two pieces (right, left) every 0.3-0.5 s, and a start's first step is
    the other foot's: told at one moment only, half the starts a performer makes went unmeasured
    (feminine's told 9-15 frames sooner jumped 7.4 against its takes' 5.1, told as measured 5.0)."""
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
    moves = int(round(MOVE_SECONDS * fps))
    earlier = [(start_at - frames, moving, moves) for frames in EARLIER_STARTS]
    sequence, forks = render_forks(model, [(moving, stop_at), (standing, start_at - stop_at), (moving, moves)],
                                   stops + starts + earlier)
    return sequence, forks[:len(stops)], forks[len(stops):len(stops) + len(starts)], forks[len(stops) + len(starts):]


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
    sequence, stops, starts, earlier = transition_forks(model, gait, weights, partway)
    fps = model.fps
    stop_at, start_at = sequence.changes
    settle = int(round(SETTLE_SECONDS * fps))
    half_step = max(1, int(round(step_frames(model, gait) / 2)))
    main = _Played(sequence, model, measure, half_step)
    steady = float(main.paced[settle + half_step:stop_at - half_step].mean())
    still = settled(~main.stepping[stop_at:start_at])
    stopped = None if still is None else stop_at + still
    stop = {"steady_cm_s": steady,
            "stop_s": float("nan") if stopped is None else (stopped - stop_at) / fps,
            "stop_steps": float("nan") if stopped is None else float(_steps(sequence.labels, main.moving, stop_at, stopped))}
    # the start told at each moment: the largest jump's figures, with the most steps, time and slide
    # of any, and the largest share of frames with both feet up (its frames and window together)
    told = [main.start(start_at, start_at, steady)] + [
        _Played(fork, model, measure, half_step).start(fork.changes[-1], start_at, steady) for fork in earlier]
    airiest = max(told, key=lambda figures: figures["air_frames"] / max(figures["window_frames"], 1.0))
    start = max(told, key=lambda figures: figures["jump_cm_f2"]) | {
        key: _worst([figures[key] for figures in told]) for key in ("speed_steps", "speed_s", "slide_cm_s")} | {
        "air_frames": airiest["air_frames"], "window_frames": airiest["window_frames"], "timings": float(len(told))}
    own = {"gait_jump_cm_f2": steady_jump(model, gait, weights, measure.cm)}
    out = {f"{gait}->stand": stop | main.window(stop_at, stopped, start_at) | own,
           f"stand->{gait}": start | own}
    called_off, stopped_again = PARTWAY_CHANGES
    partway = {change: partway_figures(forks, measure) | own
               for change, forks in ((called_off, stops), (stopped_again, starts)) if forks}
    return out, partway


class _Played:
    """One played sequence's per-frame figures, and the window figures of a change in it."""

    def __init__(self, sequence: Sequence, model: Model, measure, half_step: int):
        self.sequence, self.fps = sequence, model.fps
        positions = world_positions(sequence.motion) * measure.cm
        self.length = len(positions)
        self.paced = horizontal_speed(positions[:, model.layout.root], self.fps, half_step)
        feet = [j for foot in measure.limbs.feet for j in foot]
        self.stepping = np.max([horizontal_speed(positions[:, j], self.fps) for j in feet], axis=0) >= FEET_STILL_CM_S
        self.moving = (sequence.labels // 2) != model.units.index("stand")
        self.joint_jumps, self.air = velocity_jumps(positions, per_joint=True), measure.air(positions)
        self.jumps = self.joint_jumps.max(axis=1)
        self.skate = measure.skate(positions, self.fps)
        self.after = int(round(WINDOW_AFTER * self.fps))

    def window(self, start: int, done: int | None, end: int) -> dict:
        """The figures from `start` to WINDOW_AFTER past `done` (or to `end`, never done)."""
        stop = end if done is None else min(end, done + self.after)
        ground = ~self.air[start:stop]
        worst = start + int(np.argmax(self.jumps[start:stop]))
        return {"slide_cm_s": float(self.skate[start:stop][ground].mean()) if ground.any() else float("nan"),
                "jump_cm_f2": float(self.jumps[worst]),
                "jump_joint": self.sequence.motion.skeleton.names[int(self.joint_jumps[worst].argmax())],
                "jump_s": (worst - start) / self.fps, "air_frames": float(self.air[start:stop].sum()),
                "window_frames": float(stop - start), "finite": float(np.isfinite(self.sequence.motion.channels).all())}

    def start(self, start_at: int, planned: int, steady: float) -> dict:
        """A start told at `start_at` (`planned` - start_at frames sooner than the sequence's own):
        until the first frame at SPEED_SHARE of the steady speed, and its window."""
        fast = np.flatnonzero(self.paced[start_at:] >= SPEED_SHARE * steady)
        reached = start_at + int(fast[0]) if len(fast) else None
        return {"steady_cm_s": steady, "sooner_frames": float(planned - start_at),
                "speed_s": float("nan") if reached is None else (reached - start_at) / self.fps,
                "speed_steps": float("nan") if reached is None else float(_steps(self.sequence.labels, self.moving,
                                                                                   start_at, reached))} \
            | self.window(start_at, reached, self.length)


def _worst(values: list[float]) -> float:
    """The largest, NaN (never done) if any is."""
    return float("nan") if any(np.isnan(values)) else float(max(values))


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
