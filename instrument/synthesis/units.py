"""The engine's units stage: which motion unit each character's next steps are of.

A model holds units (models/units.py: walk, run, turn-left, turn-right, stand), each a right and a
left step's labels. As HTS concatenates phone models along a label sequence, the planner
(stream.py) strings steps together, and this stage decides, frame by frame, the unit of the steps
after the current one (`Crowd.counters[:, UNIT]`): the one the performer's gait names, and for a
walk steered hard enough, turning steps. A change therefore shows in the very next frame's
look-ahead (the window MLPG solves), and takes the body at the next step boundary: the step under
way is finished, so a run never stops in mid-flight. ST-MLPG joins the last step of one unit and
the first of the next as it joins any two steps; the foot lock keeps the feet planted through it.

Turning steps are taken in proportion to the steering: with `turn` at f times the rate the
character's turning steps turn (their duration-weighted mean yaw rate in its own lambda*, made at
each retune: `retune`, times its cadence, as the drive scales the steps' yaw), about a share f of
the steps are turning ones, chosen by error diffusion of the heading (`_turns`): the heading the
steps owe is measured from the frames as driven (`made`) against a walk's step of the same foot
(the walk sways one way a step and back the next, 13 degrees a step in lambda 0, 6 to 48 at x2 of
a style and at speed 2), and a step turns when what it will turn (as that label's step turned when
last taken, else by its means) past the walk's step brings the heading owed nearer 0. The turning
steps need not turn alike (youthful x2's left turn: its right step 4 degrees past the walk's, its
left 13; masculine x2's right turn at speed 2: its right step 36 past, its left 17 back). So over
a few steps the walk turns at the rate asked for and no step is half of each (`synth` at a
share of each style's own rate, speeds 0.5 to 2: 0.92 to 1.20 times what it asks; the versions
before, shared out by lambda 0's rate or by a gain predicted from the means, and why they missed:
docs/evaluate.md, "A turn shared out by the character's own turns", "A turn shared out at any
pace"). The heading owed is held within a turning step's larger gain past the walk's and the turn
over a stride (past that the drive gives it over the step under way), and cleared where no step
turns that way, where every step turns, or when the side changes, so a debt run up where the
steps could not keep up is not paid later at another rate.
Steering beyond what every step turning gives, a run steered (there are no turning runs in the
data), or a model without turning steps adds the rest as yaw rate (the engine's drive, as before
units); a standing character does not turn.

A change needs notice to be smooth: the window MLPG solves bends the motion towards the new
unit's means only from the frame it first sees them. Told a frame before its step ends, a run
stopped dead (a toe's velocity jumped 44 cm/frame^2, against 12 in the real runs); told 5 frames
or more before, it jumped 10 to 11 (measured on the shipped model, normal at weight 1, the change
moved frame by frame through a step). So a change that comes less than NOTICE_SECONDS before the
step under way ends lets one more step of the old unit come first (`Crowd.counters[:, NEXT]`):
the plan shows the new unit at once, one step further on.

A body setting off from a stand accelerates: its root's travel (the drive's speeds) is eased in
from 0 over its first step (the frames the step is planned to take), as a person's first step
covers about half a stride. Taken at full speed from the first frame (no take starts walking, so
the model has no start), the body shot forward (0 to 77 cm/s in a frame) and, half the times,
left its planted foot behind until the lock let go: a stance foot skated 4.9 m/s for a few frames.

Its legs take that half step too. From the frame a standing body still is told to move, the
engine holds the pose it stood in (`stride` 0: the window MLPG already bends the stand's last
frames towards the step's first state, and feminine x2's feet as made went 7-8 cm either side
of where the lock held them), and through the first step draws the step's pose from that one by
the same share as the travel (`starting`). Over a step eased in from rest the body covers
half the step's ground, and the stance foot, swept from where it stood by the same share, moves
back under the body as fast as the body moves on: it stays where the stand left it, where the
lock holds it. Told to stand again before that first step began (`resumed`), the body never left
its stand, so nothing of it changes: the engine puts the stream's last two frames back as they
were when it was told to move (its stand goes on from the pose it held, not from frames bent
towards the step, which took 20 frames to come back), and its pose eases back in from the held
one over STOP_SECONDS (`held`), as a stand's after a stop eases in from its means.
That share is a smootherstep (6x^5 - 15x^4 + 10x^3), not the smoothstep a stop brakes by: the
step's pose is drawn from the stood one at the share's rate times how far apart they are, and a
run's first step ends with its stance foot at toe-off, a stride behind where it stood (70 cm at
normal x2). The smoothstep's rate in the step's last frames (0.09, 0.06, 0.02 a frame over a
10-frame step) still swept that foot back at 6, 4 and 1 cm a frame as it rose (it went on at
-2 and +3 cm a frame, against 8 and 11 in the steady run), and the next step's swing took it
forward at 15 and 27: Toes_L jumped 15 cm/frame^2 as made, against 11.8 at the same point of
the steady run. The smootherstep's rate there is 0.08, 0.03, 0.004 (its rate of change, too, is
0 where the step ends), and the travel takes the same curve, so the body still covers half the
step's ground (docs/evaluate.md, "A run's first toe-off let go at a step's pace").

With the step's full swing from the first frame, the stance foot as made swept back at a
walk's pace under a body only setting off, away from where the lock held it (up to 9 cm), the
heel rose up to 39 deg, and when the other foot landed and the lock let go, the rise collapsed
in 2-3 frames and the knee caught up
(a joint jumping up to 14.5 cm/frame^2 against 5.5 in the walk itself). Eased in over a fixed
0.5 s instead of the step, the ground the body covers in the step is not half the step's when
the step is longer or shorter, and the stance foot ends it away from its lock (feminine's start
jumped 5.4 cm/frame^2 against 5.0, feminine x2's 10.1 against 6.6).

A body stopping brakes the same way, over the steps it still takes: from the frame its coming
unit becomes the stand, its travel is eased out so that it reaches 0 as the last step ends (the
frames left at the plan's durations, one more step's when the change waits for it), or over
STOP_SECONDS when fewer frames are left, the last of them in the stand's first frames. The stand
holds the root's travel at 0; cut there at once, a run stopped dead (the hips from 11 cm a frame
to none: every joint's velocity jumped by that much) while the window's root speeds were still
easing down from the run's. A stop called off before the stand eases back in from wherever its
braking had got to.

A body that brakes also shortens its steps: the engine draws each stopping body's pose towards
the stand's (its stride mean) by the share its travel has lost (`stride`: the same smoothstep),
so the stance foot moves back under the body no faster than the body slows, and the swinging
foot lands shorter. Braked with the steps' full swing, the last step landed the swinging foot
a stride ahead of a body that had stopped, and the stand's pose pulled it back under the hips
at 10-14 cm a frame, stopped dead in one as the stand began (a toe's velocity jumped 12 cm/frame^2
against 5-6 in the takes of the styles it happened to). A stop told less than STOP_SECONDS
before its step ends takes one more, braked, step (the change waits, as NOTICE_SECONDS has a
late one wait): braked within the rest of the step, the foot about to land was pulled back as it
landed; with one more step, the other foot comes up beside it, a closing step as people stop.
Once the body stands still (its travel 0), the stride eases back to 1 over STOP_SECONDS, where
the stand's pose and its stride mean differ only by its sway. A stop called off before its stand
takes its stride back up no faster than its level, as it braked: over STOP_SECONDS on its own, the
stride ran ahead of the travel and swept the stance foot back faster than the body sped up, and
the lock, holding the foot where it was, let it snap back as it let go (docs/evaluate.md,
"Changes part-way"). Its planted leg takes a share of its own (`_rejoin`): with the rest's, the
share rose through the end of the stance, where the foot as made is furthest behind the hips,
and swept it behind where the lock held it (youthful's walk called off 17 frames after the stop:
27 cm; a toe jumped 10.7 cm/frame^2 as the lock let go, 1.9 times the steady walk's). It goes to
the share that puts the foot as made where the lock holds it as it lets go, then to the rest's
over its swing, fastest as the foot passes under the hips (6.2 there; docs/evaluate.md, "A stop
called off lets its planted foot go where the lock holds it").

A run's first step pushes off only while its stance foot is down: a walk's stance foot is planted
through the whole step, a run's lifts part of the way (its toe-off; then both feet are in the
air). Eased over the whole step, the stride was still at its steepest when a run's stance foot
lifted, and swept that foot back as it rose. So a body setting off eases its travel and its
stance leg's stride (`leg_shares`, the leg's features: limbs.leg_columns) in up to the first
state of flight after that foot is down (`pushing_states`: every state of a walk's step), and
the rest of its pose over the step as before: the stance foot's sweep has stopped as it lifts,
and a body in flight no longer speeds up (a run's travel holds there: below). The whole pose so eased swept the swinging leg instead; the stance leg alone with the travel
over the whole step left the lock holding a foot swept back against the body. A start stopped
before it is done brakes its legs with its travel (`halting`) until the rest of the pose is
drawn in as far (docs/evaluate.md, "A run pushes off until its toe-off").

A unit with flight (a run) sets off over two pushes, as a body speeds up only while a foot is
down: at full speed by its first toe-off, the hips' speed rose at 19-28 m/s^2 (normal x2,
active and its x2, feminine and masculine x2; the steady runs peak at 4-10). Its travel rises
over the first step's push to that push's share of the two pushes' frames (`first_share`: about
a half, as under an even force), holds through the flight, and rises to 1 over the second step's
push; each leg follows the travel while it is the stance leg and eases over its step while it
swings (the first step's swinging leg reaches the share as it lands, the first stance leg goes
on from it to 1 over the second step, its swing), each by a smootherstep; the rest of the pose
eases over both steps. The peak fell to 10-14 m/s^2 (docs/evaluate.md, "A run sets off over two
pushes"). A walk's start is as above, to the digit.
"""

from __future__ import annotations

import numpy as np

from ..models.modelfile import Model
from ..motion.features import ROOT_FEATURES
from ..motion.limbs import leg_columns
from .contact import PLANTED, flight_states
from .parameters import GAITS
from .stream import ELAPSED, LABEL, NEXT, STATE, UNIT, Crowd

YAW = ROOT_FEATURES.index("root.yaw_rate")
NOTICE_SECONDS = 0.2  # the least notice a unit change takes at the coming step boundary
START_SECONDS = 0.5  # a body moving again before its stop stood still reaches its gait's travel over this
# the shortest a body brakes over: braked over the 6 frames a step may have left when the stop
# comes, a run at 4.2 m/s (active x2) would change its speed by up to 105 cm/s in a frame (the
# smoothstep's steepest is 1.5 times its mean), against 62 in its steady run
STOP_SECONDS = 0.4
TURNING = {1: "turn-left", -1: "turn-right"}  # the turning unit of each side (+1 steers left)


def planted_shares(model: Model) -> np.ndarray | None:
    """(labels, states, 2) how sure the average model is that each foot is down in each state
    (its contact statistics), or None for a model without them."""
    shares = (getattr(model, "extras", {}) or {}).get("contact_average")
    if shares is None or np.shape(shares) != (len(model.labels), model.states, 2):
        return None
    return np.asarray(shares, dtype=np.float64)


def pushing_states(model: Model) -> tuple[np.ndarray, np.ndarray]:
    """Per label (labels,): how many of its first states its stance foot pushes in (up to the
    first state of flight after the foot is down: a run's toe-off; every state of a unit without
    flight, a walk's), and which foot that is (the one more often down over the step in the
    average model: 0 or 1, the legs' order). Flight is contact.flight_states' (a state of a unit
    more often in the air than on both feet, planting neither foot), so no threshold of its own is
    asked of a capture. A model without contact statistics: every state, foot 0."""
    shares = planted_shares(model)
    labels, states = len(model.labels), model.states
    if shares is None:
        return np.full(labels, states), np.zeros(labels, dtype=np.int64)
    flight = flight_states(shares.reshape(-1, 2), (model.metadata.get("contact") or {}).get("air"), states,
                           len(model.units)).reshape(labels, states)
    foot = shares.sum(axis=1).argmax(axis=1)
    down = np.cumsum(shares[np.arange(labels), :, foot] >= PLANTED, axis=1) > 0  # from the state it is down
    lifted = flight & down
    return np.where(lifted.any(axis=1), lifted.argmax(axis=1), states), foot


def smootherstep(x: np.ndarray) -> np.ndarray:
    """6x^5 - 15x^4 + 10x^3: from 0 to 1 with no jump in rate nor in its change at either end."""
    return x * x * x * (x * (x * 6.0 - 15.0) + 10.0)


def smoothstep_of(y: np.ndarray) -> np.ndarray:
    """The x whose smoothstep (3x^2 - 2x^3) is y, for y in [0, 1]: where a level eased by a
    smootherstep stands on the smoothstep's curve, so a body that stops while it still sets off
    brakes from the travel and stride it had, not from a jump to its level's smoothstep."""
    return 0.5 - np.sin(np.arcsin(np.clip(1.0 - 2.0 * y, -1.0, 1.0)) / 3.0)


def unit_turn_rates(yaw: np.ndarray, duration_means: np.ndarray, turn_units: dict[int, int]) -> dict[int, np.ndarray]:
    """Per side (+1 left), (N,) rad/s the turning steps of N characters turn at that way: the
    duration-weighted mean yaw rate of the unit's two labels, from each character's yaw rate means
    and duration means (N, labels, states). A turn a style inverts comes out negative."""
    out = {}
    for side, k in turn_units.items():
        means, durations = yaw[:, 2 * k:2 * k + 2], duration_means[:, 2 * k:2 * k + 2]
        out[side] = side * (means * durations).sum(axis=(1, 2)) / durations.sum(axis=(1, 2))
    return out


class UnitChooser:
    """Per character: the unit of the coming steps and the yaw rate the drive adds."""

    name = "units"

    def __init__(self, model: Model, count: int):
        self.units = model.units
        self.count = count
        walk = self.units.index("walk")
        # the unit each gait plays: the model's unit of that name, else the walk
        self.gait_units = np.array([self.units.index(g) if g in self.units else walk for g in GAITS])
        self.missing = [g for g in GAITS if g not in self.units]  # gaits this model plays as a walk
        self.walk = walk
        self.stand = self.units.index("stand") if "stand" in self.units else -1
        states = model.states
        self.turn_units = {side: self.units.index(unit) for side, unit in TURNING.items() if unit in self.units}
        self.fps = float(model.fps)
        # (N, labels, states) rad/s each character's yaw rate means, and per side (N,) how fast its
        # turning steps turn that way (`unit_turn_rates`): lambda 0's until the first retune, then made
        # from the lambda* a retune left (`_retuned`) when a walk is next steered
        self.yaw = np.repeat(model.average.means[None, ..., YAW], count, axis=0)
        rates = unit_turn_rates(self.yaw[:1], model.average.duration_means[None], self.turn_units)
        self._rates = {side: np.repeat(rate, count) for side, rate in rates.items()}
        self._retuned: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._own_of: np.ndarray | None = None  # the tables' own means `_own_yaw` (N, labels * states) is the yaw of
        self._own_yaw = np.zeros((count, 0))
        # (side, turn shared, steering) `share` and `rest` are of (None: made again)
        self._steered: tuple[int, float, float] | None = None
        self.share = np.zeros(count)  # that turn over each character's full turn (its turning steps' rate), up to 1
        self.rest = np.zeros(count)  # rad/s of that turn its turning steps do not give (the drive adds it)
        self.unpaid = np.zeros(count)  # rad/s the drive adds over the step under way: the heading its steps could not give
        self.aim = np.zeros(count)  # rad/s of that turn its steps are to give (the turn less `rest`)
        # rad: the heading each character's steps still owe the turn, `aim` less what its frames turned
        # (the error diffusion's, measured: `made`), held within one turning step's worth
        self.sum = np.zeros(count)
        self.steering = False  # the walk is steered by turning steps (`made` adds each frame to `sum`)
        # rad each character's steps of each label turned when last taken whole while steered (half
        # the last, half those before; NaN: not yet, its means' yaw stands in), what the step
        # under way has turned so far, and whether it was steered from its start
        self.step_turns = np.full((count, len(model.labels)), np.nan)
        self.stepped = np.zeros(count)
        self.whole = np.zeros(count, dtype=np.bool_)
        self._side = 0  # the side steered at the last frame (+1 left; 0: not steered)
        self.turning = np.zeros(count, dtype=np.int64)  # +1 / -1: the coming step turns left / right; 0 straight
        self.step_label = np.full(count, -1)  # the label of the step under way at the last frame
        self.states = states
        self.added_yaw = np.zeros(count)  # rad/s the drive adds to each character's frame
        self.coming = np.full(count, -1)  # the unit each character's coming steps were of at the last frame
        self.notice = NOTICE_SECONDS * model.fps  # frames
        self.start_frames = START_SECONDS * model.fps
        self.stop_frames = STOP_SECONDS * model.fps
        self.level = np.ones(count)  # how far each body is eased into its travel, 0 (standing) to 1
        self.braking = np.full(count, np.inf)  # how much of its level a stopping body sheds a frame
        self.travel = np.ones(count)  # the share of its root's travel each body takes this frame
        self.stride_level = np.ones(count)  # how far each body's pose takes its step's swing, 0 to 1
        self.stride = np.ones(count)  # its smoothstep: the share of the swing the engine leaves (1: as made)
        self.shortening = False  # some body's stride is below 1 (the engine draws its pose in)
        self.start_rate = np.full(count, 1.0 / self.start_frames)  # how much of its level a moving body gains a frame
        # this frame a body standing still was told to move (the engine keeps the pose it stood in)
        self.set_off = np.zeros(count, dtype=np.bool_)
        self.setting_off = False  # some body was (a Python bool: the engine reads it every frame)
        self.starting = np.zeros(count, dtype=np.bool_)  # since then: its stride is its level, drawn from that pose
        # this frame a body told to move was told to stand again before its first step began (the
        # engine puts its stream back as it was told): its stand goes on from there
        self.resumed = np.zeros(count, dtype=np.bool_)
        self.resuming = False  # some body was (a Python bool)
        self.held = np.zeros(count, dtype=np.bool_)  # since then: its stride eases back in from the pose it held
        self._settled: tuple[int, float] | None = None  # (gait, turn) that left nothing to do frame by frame
        self.pushing, self.stance_foot = pushing_states(model)  # per label: the states its stance foot is down; which
        self.legs = leg_columns(model.layout)  # (2, D) each leg's features
        self.start_foot = np.zeros(count, dtype=np.int64)  # the stance foot of a starting body's first step
        self.start_label = np.full(count, -1)  # the label of that first step
        self.second = np.zeros(count, dtype=np.bool_)  # a two-push start is in its second step
        # the travel a starting body has at its first push's end: 1 for a unit without flight (one
        # push), else that push's share of the two pushes' frames (an even force while a foot is down)
        self.first_share = np.ones(count)
        # where its travel and legs (N, 2) were as its second step began: the second push eases on
        # from there (the first push's share, or short of it where the first step was cut short)
        self.second_from = np.ones(count)
        self.second_legs_from = np.ones((count, 2))
        self.push = np.ones(count)  # how far through its step's push a starting body is, 0 to 1
        self.push_rate = np.full(count, 1.0 / self.start_frames)  # how much of it it gains a frame
        self.swing = np.ones(count)  # how far through its step, 0 to 1 (its swinging leg's ease)
        self.swing_rate = np.full(count, 1.0 / self.start_frames)
        self.leg_shares = np.ones((count, 2))  # the share of its swing each leg of a starting body takes
        # stopped while setting off: its legs brake with its travel until they are drawn in as far as
        # the rest of its pose (a leg ahead of the rest: made to follow the rest at once, it jumped)
        self.halting = np.zeros(count, dtype=np.bool_)
        # a stop called off before its stand: the leg planted at the call-off (`rejoin_leg`) goes
        # from its share then (`rejoin_from`) to the one that lets its foot go where the lock holds
        # it (`rejoin_to`) over the frames it stays down (`rejoin_left` of `rejoin_stance`), then
        # to the rest's over its swing (`rejoin_swing`, 0 to 1 at `rejoin_swing_rate` a frame)
        self.rejoining = np.zeros(count, dtype=np.bool_)
        self.rejoin_leg = np.zeros(count, dtype=np.int64)
        self.rejoin_from, self.rejoin_to = np.ones(count), np.ones(count)
        self.rejoin_left, self.rejoin_stance = np.zeros(count), np.ones(count)
        self.rejoin_swing, self.rejoin_swing_rate = np.ones(count), np.ones(count)
        # called off again after a second stop (`halting` from a rejoin: `rejoin_halted`), the other
        # leg's gap to the rest then (`rejoin_gap`) closes as the rest comes up from `rejoin_stride`
        self.rejoin_halted = np.zeros(count, dtype=np.bool_)
        self.rejoin_gap, self.rejoin_stride = np.zeros(count), np.zeros(count)
        self.planted = planted_shares(model)  # (labels, states, 2) how surely each foot is down
        self._strides = np.ones((count, self.legs.shape[1]))  # `strides`' array, filled each frame

    def unsteered(self, gait: int, turn: float) -> str | None:
        """The turning unit this model lacks that steps steered by `turn` would be taken from:
        the gait plays the walk (`gait_units`: a gait the model lacks plays it too) and no
        `turn_units` entry answers the side, so the walk is steered by yaw rate alone, which `run`
        and `synth` say as they say a gait the model lacks. None when the model has it, the walk
        is not steered, or the gait's own unit is not the walk (a run steers by yaw rate by design)."""
        if turn == 0.0 or self.gait_units[gait] != self.walk:
            return None
        side = 1 if turn > 0 else -1
        return None if side in self.turn_units else TURNING[side]

    def __call__(self, gait: int, turn: float, stream: Crowd) -> None:
        """Set every character's coming unit for this frame's controls (before the stream's step).
        Once every character walks the gait's unit with no turning steps to choose, the same
        controls leave everything as it is: the stage costs nothing frame by frame."""
        if self._settled == (gait, turn):
            return
        counters = stream.counters
        unit = self.gait_units[gait]
        started = (counters[:, LABEL] != self.step_label) & (counters[:, STATE] == 0)
        ended = self.step_label  # the label of the step that ended where one started
        self.step_label = counters[:, LABEL].copy()
        side = 1 if turn > 0 else -1
        steered = unit == self.walk and turn != 0.0 and side in self.turn_units
        rest = self._shared(side, turn if steered else 0.0, turn, stream)
        if not steered:
            self.turning[:] = 0
            self.sum[:] = 0.0
            self.unpaid[:] = 0.0
            self.whole[:] = False
        else:
            if side != self._side:
                self.sum[:] = 0.0  # the other way's heading is no debt of this one
                self.unpaid[:] = 0.0
            if started.any():  # (a step begins every dozen frames or so: nothing to do between)
                walked = np.flatnonzero(started & (ended >= 0))
                label, whole = ended[walked], self.whole[walked]
                last = self.step_turns[walked, label]
                self.step_turns[walked, label] = np.where(
                    whole, np.where(np.isnan(last), self.stepped[walked], 0.5 * (last + self.stepped[walked])), last)
                # the steps owe the turn over the walk's sway: a step ended is measured against a walk's of its foot
                self.sum[walked] += self._step_yaw(walked, 2 * self.walk + label % 2, stream, taken=False)
                self.stepped[started] = 0.0
                self.whole[started] = True
            changed_side = (self.turning != 0) & (self.turning != side)
            decide = started | changed_side | (stream.sent == 0)
            if decide.any():
                self.turning[decide] = np.where(self._turns(np.flatnonzero(decide), side, stream), side, 0)
        self.steering = steered
        self._side = side if steered else 0
        coming = np.where(self.turning > 0, self.turn_units.get(1, unit),
                          np.where(self.turning < 0, self.turn_units.get(-1, unit), unit))
        if stream.sent == 0:
            stream.begin_in(coming)
        current = counters[:, LABEL] // 2  # the unit of the step under way (a change below leaves it)
        if stream.sent > 0 and (changed := coming != self.coming).any():  # (the steps' frames left only asked for a change)
            # a stop brakes over at least STOP_SECONDS of its steps: told later, it takes one more
            notice = np.where(coming == self.stand, max(self.notice, self.stop_frames), self.notice)
            # a change back to the unit under way goes on at once: a stop called off before its stand
            # began (made to wait a step, the body stood for one, its travel cut from where its braking
            # had got to in a frame), and a start called off before its first step began (made to wait,
            # the body took that step in place, its pose drawn to the stand's means from the one it stood in)
            calling_off = (((self.coming == self.stand) & (current != self.stand))
                           | ((coming == self.stand) & (current == self.stand)))
            # a stop called off before its stand (a body halting from a start closes its legs' gaps as it was)
            # (one halting from a rejoin, stopped and called off again, rejoins from where its legs are)
            called_off = (changed & (self.coming == self.stand) & (current != self.stand) & (coming != self.stand)
                          & (~self.halting | self.rejoin_halted))
            if called_off.any():
                self._rejoin(stream, called_off)
            late = changed & ~calling_off & (counters[:, NEXT] == 0) & (self._frames_left(stream) < notice)
            counters[late, NEXT] = self.coming[late] + 1  # the step after this one as planned, then the change
        counters[:, UNIT] = coming
        self.coming = coming
        standing = current == self.stand
        stopping = (coming == self.stand) & ~standing
        # a body standing still told to move holds the pose it stood in until its first step
        # begins, and takes that step drawn from it (its stride) as its travel eases in
        still = (coming != self.stand) & (self.level == 0.0)
        halted = self.starting & (coming == self.stand) & (self.level > 0.0)
        if halted.any():  # stopped while setting off: its levels moved onto the smoothstep braking eases by
            self.level[halted] = smoothstep_of(self.travel[halted])  # (its travel's)
            self.stride_level[halted] = smoothstep_of(self.stride[halted])
            self.halting |= halted
        self.set_off = still & ~self.starting
        self.setting_off = bool(self.set_off.any())
        # a start called off before its first step began: its stand goes on from where it was told to
        # move (the engine puts the stream back as it was), eased back in from the pose it held
        self.resumed = self.starting & (coming == self.stand) & standing & (self.level == 0.0)
        self.resuming = bool(self.resumed.any())
        self.starting = (self.starting | still) & (coming != self.stand)
        self.held = (self.held | self.resumed) & ~self.starting
        self.start_label[self.set_off] = -1
        self.second[self.set_off] = False  # (a start before this one may have ended in its second push)
        self.first_share[self.set_off] = 1.0
        first = still & ~standing
        if first.any():  # its first step has begun: its pose eases in over its pushes' steps, its travel
            # and stance leg up to the stance foot's toe-off
            self._begin_start(stream, first)
        second = (self.starting & ~first & ~self.second & (self.start_label >= 0) & (self.first_share < 1.0)
                  & (counters[:, LABEL] != self.start_label))
        if second.any():  # a two-push start's second step has begun: the rest of the way over it
            frames = np.maximum(self._frames_left(stream)[second], 1.0)
            self.start_rate[second] = (1.0 - self.level[second]) / frames
            self.swing_rate[second] = 1.0 / frames
            self.push_rate[second] = 1.0 / np.maximum(self._frames_left(stream, self.pushing)[second], 1.0)
            self.push[second] = self.swing[second] = 0.0
            self.second_from[second] = self.travel[second]
            self.second_legs_from[second] = self.leg_shares[second]
            self.second |= second
        self._ease(standing, stopping, self._frames_to_stand(stream, stopping) if stopping.any() else None)
        self.added_yaw[:] = np.where(standing, 0.0, rest + self.unpaid)
        self._settled = ((gait, turn) if not steered and stream.sent > 0 and (current == unit).all() and not self.starting.any()
                         and not self.rejoining.any()
                         and (self.level == np.where(standing, 0.0, 1.0)).all() and (self.stride_level == 1.0).all()
                         else None)  # no easing in or out

    def retune(self, mean_own: np.ndarray, mean_shared: np.ndarray, duration_means: np.ndarray) -> None:
        """Each character's lambda* as retuned (its means as two factors, `CrowdLambda`: (N,
        labels * states, 3D) and (labels * states, 3D); its duration means (N, labels, states)),
        which `turn_rates` reads: a style change's, not a frame's. Kept until a walk is steered
        (the live crowd's demo retunes every frame: made at each, they cost a crowd of 100 some
        40-90 us, 0.4-0.9 us a character)."""
        self._retuned = (mean_own, mean_shared, duration_means)
        self._steered = None

    @property
    def turn_rates(self) -> dict[int, np.ndarray]:
        """Per side (+1 left), (N,) rad/s each character's turning steps turn that way (`yaw`
        made with them), from the lambda* of the last retune."""
        if self._retuned is not None:
            mean_own, mean_shared, duration_means = self._retuned
            self._retuned = None
            if mean_own is not self._own_of:  # a character's own term moves with the spread alone: its
                # yaw column kept (gathered across a crowd of 100's tables, it cost 50-60 us)
                self._own_of, self._own_yaw = mean_own, np.ascontiguousarray(mean_own[..., YAW])
            self.yaw = (self._own_yaw + mean_shared[:, YAW]).reshape(duration_means.shape)
            self._rates = unit_turn_rates(self.yaw, duration_means, self.turn_units)
        return self._rates

    def repace(self) -> None:
        """The pace changed: the turning steps' rates scale with the cadence (the drive's), so the
        shares are made again when the walk is next steered."""
        self._steered = None

    def _shared(self, side: int, turn: float, steering: float, stream: Crowd) -> np.ndarray:
        """(N,) the yaw rate the drive adds to `steering`, besides turning steps for `turn` (rad/s;
        0: none), and `share`, how much of each character's full turn that is (1: every step
        turns; 0: none can): its turning steps' rate in lambda* times its cadence, as the drive
        scales their yaw. Made when the turn, the rates or the pace change."""
        if self._steered != (side, turn, steering):
            self._steered = (side, turn, steering)
            if turn == 0.0:
                self.share[:] = 0.0
                self.aim[:] = 0.0
            else:
                rate = self.turn_rates[side] * stream.cadence
                turning = rate > 1e-9  # a style inverted past its turns turns the other way: its drive steers
                self.share[:] = np.where(turning, np.minimum(abs(turn) / np.where(turning, rate, 1.0), 1.0), 0.0)
                self.aim[:] = side * self.share * np.where(turning, rate, 0.0)
            self.rest[:] = steering - self.aim
        return self.rest

    def made(self, yaw: np.ndarray) -> None:
        """Each character's frame as driven (its yaw rate, (N,) rad/s, the drive's steering in it):
        what its steps turned is taken from the heading they owe. Measured, not predicted: the
        window MLPG joins a turning step and a walk's step other than either's means (at speed 2
        normal's right turning step was planned 8.2 degrees past the walk's step and gave 1.7)."""
        if self.steering:
            turned = (yaw - self.added_yaw) / self.fps
            self.sum += self.aim / self.fps - turned
            self.stepped += turned

    def _step_yaw(self, rows: np.ndarray, labels: np.ndarray, stream: Crowd, taken: bool = True) -> np.ndarray:
        """(R,) rad a step of each of `labels` turns the characters `rows`: as it turned when last
        taken (`step_turns`; `taken` False: never), else by its means (its yaw rate means over its
        planned frames, at its cadence, the drive's). The window MLPG joins steps taken fast
        further from their means: at speed 2 masculine x2's left step turning right turned 29
        degrees left of the walk's, so the diffusion, trusting the means, kept taking it (0.74 of
        what it asked). The walk's step the heading is owed over stays its means': a walk's step
        taken next to a turning one turns some of its turn (normal at speed 2, measured against
        them, turned 1.10 times what it asked over 110 s)."""
        planned, at = stream.base[rows], np.arange(len(rows))
        means = stream.cadence[rows] * (self.yaw[rows, labels] * planned[at, labels]).sum(axis=1) / self.fps
        if not taken:
            return means
        turned = self.step_turns[rows, labels]
        return np.where(np.isnan(turned), means, turned)

    def _turns(self, rows: np.ndarray, side: int, stream: Crowd) -> np.ndarray:
        """Whether the coming step of each character `rows` turns: error diffusion of the heading.
        The heading owed is measured (`sum`: `made` takes what each frame turned, a step's end
        gives back what a walk's step of the same foot turns by its means, so the walk's sway,
        one way a step and back the next, is not owed); to it the step under way adds what it
        will owe (the turn over its frames, less what it turns past a walk's step of its foot:
        `_step_yaw`), and the coming step turns when that less what a turning step gives past the
        walk's is nearer 0 than without. Past what a diffusion that keeps up leaves owing, the
        drive gives the rest over the step under way (`unpaid`), so no debt is run up to be paid
        later at another rate. A turn at a character's full rate or past it turns every step;
        one it cannot turn that way (share 0) none: neither owes anything."""
        labels = stream.counters[rows, LABEL]
        planned, at = stream.base[rows], np.arange(len(rows))
        aim, share = self.aim[rows], self.share[rows]

        def owes(label: np.ndarray) -> np.ndarray:  # (R,) rad a step of `label` leaves owing, over a walk's
            walk = 2 * self.walk + label % 2
            return (aim * planned[at, label].sum(axis=1) / self.fps - self._step_yaw(rows, label, stream)
                    + self._step_yaw(rows, walk, stream, taken=False))

        units, walk = 2 * self.turn_units[side], 2 * self.walk
        # the most a diffusion that keeps up leaves owing: a turning step's gain past the walk's (the
        # larger foot's: masculine x2's right step turns 36 degrees past it, its left 17 back) and
        # the turn over a stride
        bound = (np.abs(aim) * planned[at, units:units + 2].sum(axis=(1, 2)) / self.fps
                 + np.maximum(*(np.abs(owes(np.full(len(rows), units + f)) - owes(np.full(len(rows), walk + f)))
                                for f in (0, 1))))
        under_way = 0.0 if stream.sent == 0 else owes(labels)  # (at the first frame the first step is the coming one)
        shared = (share > 0.0) & (share < 1.0)
        owed = np.where(shared, np.clip(self.sum[rows] + under_way, -bound, bound), 0.0)
        # past that, the steps cannot keep up (active x2's left turn at speed 2: its right step turns
        # right of the walk's): the drive gives the rest over the step under way
        frames = planned[at, labels].sum(axis=1)
        self.unpaid[rows] = np.where(shared, self.sum[rows] + under_way - owed, 0.0) * self.fps / np.maximum(frames, 1.0)
        self.sum[rows] = owed - under_way
        foot = labels % 2 if stream.sent == 0 else 1 - labels % 2  # the coming step's
        if_straight, if_turning = owed + owes(walk + foot), owed + owes(units + foot)
        return (share >= 1.0) | ((share > 0.0) & (np.abs(if_turning) < np.abs(if_straight)))

    def _begin_start(self, stream: Crowd, first: np.ndarray) -> None:
        """The rates of the bodies (`first`) whose first step from a standstill begins this frame:
        a unit without flight pushes once (its travel and stance leg over the step's push, the
        rest of its pose over the step); one with flight twice, its first push taking it to the
        share of the two pushes' frames it lasts (as under an even force while a foot is down),
        the rest of its pose over both steps (the next the other foot's of the same unit)."""
        label = stream.counters[first, LABEL]
        frames = self._frames_left(stream)[first]
        pushing = self._frames_left(stream, self.pushing)[first]
        two = self.pushing[label] < self.states
        following = label ^ 1  # the other foot's step of the same unit
        later = stream.base[np.flatnonzero(first), following]  # (n, states) its frames at mean durations
        later_push = (later * (np.arange(self.states) < self.pushing[following][:, None])).sum(axis=1)
        self.first_share[first] = np.where(two, pushing / np.maximum(pushing + later_push, 1e-9), 1.0)
        self.start_rate[first] = 1.0 / np.maximum(frames + np.where(two, later.sum(axis=1), 0.0), 1.0)
        self.push_rate[first] = 1.0 / np.maximum(pushing, 1.0)
        self.swing_rate[first] = 1.0 / np.maximum(frames, 1.0)
        self.start_foot[first] = self.stance_foot[label]
        self.start_label[first] = label

    def _rejoin(self, stream: Crowd, called: np.ndarray) -> None:
        """The stance leg of the bodies whose stop is called off this frame (`called`): where its
        share must be as its foot lets go so that the pose puts the foot where the lock holds it.
        A leg's swing swept by a share s puts its foot s * d ahead of the hips (d as made, going
        back at the gait's pace V through the stance); the foot, still, stays behind a body
        going on at its travel's pace. Over the stance, about its middle, the mismatch at the
        release comes to V (sum of the travel + s_from (a - mid) - s_to (b - mid)): nil for
        s_to = (sum of the travel + s_from (a - mid)) / (b - mid), whatever its way there (a now,
        b the release, the frames the foot stays down at the contact statistics' shares). Taken
        back up with the travel, the share rose through the stance's end, where d is furthest
        behind: the foot as made went 27 cm behind its lock, and snapped back as it let go."""
        counters = stream.counters
        rows = np.flatnonzero(called)
        label = counters[rows, LABEL]
        leg = self.stance_foot[label]
        base = stream.base[rows, label]  # (n, states) this step's frames at mean durations
        following = stream.base[rows, label ^ 1]  # the other foot's step of the same unit
        ahead = np.arange(self.states) >= counters[rows, STATE, None]
        left_now = base * ahead
        left_now[np.arange(len(rows)), counters[rows, STATE]] -= counters[rows, ELAPSED]
        if self.planted is None:  # the stance foot down through its step, up as it ends
            down, next_down = np.ones_like(base), np.zeros_like(base)
        else:
            down, next_down = self.planted[label, :, leg], self.planted[label ^ 1, :, leg]
        later = (following * next_down).sum(axis=1)
        stays = (left_now * down).sum(axis=1) + later  # frames the foot stays down from here
        stance = np.maximum((base * down).sum(axis=1) + later, 2.0)  # the whole stance's
        steps = np.arange(1, int(np.ceil(stays.max())) + 1)
        level = np.minimum(self.level[rows, None] + steps * self.start_rate[rows, None], 1.0)
        weight = np.clip(stays[:, None] - (steps - 1), 0.0, 1.0)  # (the last frame's part)
        # summed in order (a row's zeros past its own stance, where another row's is longer, add
        # nothing: numpy's pairwise sum would group a row's terms by the crowd's longest)
        travel = np.cumsum(level * level * (3.0 - 2.0 * level) * weight, axis=1)[:, -1]
        half = stance / 2.0
        since = stance - stays  # frames of the stance already gone
        again = self.rejoin_halted[rows]  # its legs their own shares (braked from a first call-off's)
        start = np.where(again, self.leg_shares[rows, leg], self.stride[rows])
        self.rejoin_gap[rows] = np.where(again, self.leg_shares[rows, 1 - leg] - self.stride[rows], 0.0)
        self.rejoin_stride[rows] = self.stride[rows]
        self.halting[rows] = self.rejoin_halted[rows] = False
        self.rejoin_leg[rows] = leg
        self.rejoin_from[rows] = start
        self.rejoin_to[rows] = np.clip((travel + start * (since - half)) / half, 0.0, 1.0)
        self.rejoin_left[rows] = self.rejoin_stance[rows] = np.maximum(stays, 1e-9)
        swing = left_now.sum(axis=1) + following.sum(axis=1) - stays  # to its next landing
        self.rejoin_swing[rows] = 0.0
        self.rejoin_swing_rate[rows] = 1.0 / np.maximum(swing, 1.0)
        self.rejoining |= called

    def _ease(self, standing: np.ndarray, stopping: np.ndarray, left: np.ndarray | None) -> None:
        """Each body's travel: eased in once it moves (over its first step from a standstill,
        `start_rate`; over START_SECONDS from a stop called off), and eased out while it stops,
        linearly in its level over the `left` frames before the stand begins (at least
        STOP_SECONDS' frames, the rest in the stand), so the level is 0 as it does; none while it
        stands. The travel is the level's smoothstep (a body setting off from a standstill: its
        push's smootherstep, over two pushes for a unit with flight; the rest of its pose the
        level's): no jump in speed nor in acceleration at either end. The stride follows the
        level down while the body brakes, and up while it sets off from a standstill (0 from the
        command, drawn from the pose it stood in); otherwise it comes back up over STOP_SECONDS,
        no faster than the level while the body moves (a stop called off before its stand)."""
        if left is not None:
            self.braking[stopping] = self.level[stopping] / (np.maximum(left[stopping], self.stop_frames) + 1.0)
        moving = ~standing & ~stopping
        self.braking[moving] = np.inf  # a stop that changed its mind brakes afresh next time
        self.start_rate[~moving] = 1.0 / self.start_frames
        level = np.where(moving, np.minimum(self.level + self.start_rate, 1.0),
                         np.maximum(self.level - self.braking, 0.0))
        self.level = level
        starting = bool(self.starting.any())  # some body sets off from a standstill: its ease is a smootherstep
        # the last frame's (a halting body's legs brake from them): the arrays themselves, which this
        # frame rebinds (never writes into)
        before, before_stride = self.travel, self.stride
        self.travel = level * level * (3.0 - 2.0 * level)
        if starting:  # (the rest of its pose: its level's; its travel: its push's)
            eased = smootherstep(level)
            going = moving & self.starting
            self.push = np.where(going, np.minimum(self.push + self.push_rate, 1.0), level)
            self.swing = np.where(going, np.minimum(self.swing + self.swing_rate, 1.0), level)
            share = self.first_share
            pushed, swung = smootherstep(self.push), smootherstep(self.swing)
            was = self.second_from  # the travel as the second step began (the first push's share)
            travel = np.where(self.second, was + (1.0 - was) * pushed, share * pushed)
            self.travel = np.where(self.starting, travel, self.travel)
            # each leg follows the travel while it is the stance leg, and eases over its step while it
            # swings: the first stance leg from where it was (the first push's share) to 1 over the
            # second step, the other from 0 to that share over the first; a one-push start's swinging
            # leg is the rest. A leg apart from the travel as the second step began (the first step
            # cut short by a speed-up) closes the gap over the push, with no jump
            first_leg = self.start_foot[:, None] == np.arange(2)
            stance_from = np.take_along_axis(self.second_legs_from, self.start_foot[:, None], axis=1)[:, 0]
            swinging_from = np.take_along_axis(self.second_legs_from, 1 - self.start_foot[:, None], axis=1)[:, 0]
            stance = np.where(self.second, stance_from + (1.0 - stance_from) * swung, travel)
            swinging = np.where(self.second, travel + (swinging_from - was) * (1.0 - pushed),
                                np.where(share < 1.0, share * swung, eased))
            self.leg_shares = np.where(self.starting[:, None], np.where(first_leg, stance[:, None], swinging[:, None]),
                                       self.leg_shares)
        braking = stopping | (standing & (level > 0.0))
        # a moving body comes back up no faster than its level (a stop called off before its stand
        # began: its stance foot moves back under the body as fast as the body speeds up again, as
        # braking it did as the body slowed); one standing (still), over STOP_SECONDS
        ceiling = np.where(moving, np.maximum(level, self.stride_level), 1.0)
        rising = np.minimum(self.stride_level + 1.0 / self.stop_frames, ceiling)
        stride = np.where(braking, np.minimum(self.stride_level, level), np.where(self.starting, level, rising))
        self.stride_level = stride
        self.stride = stride * stride * (3.0 - 2.0 * stride)
        self.held &= stride < 1.0
        if starting:  # done once its pose, travel and legs are all there (a first step slowed down
            # may bring its level to 1 before the second push has begun: its travel still the share)
            self.stride = np.where(self.starting, eased, self.stride)
            self.starting &= ~((level >= 1.0) & (self.travel >= 1.0) & (self.leg_shares >= 1.0).all(axis=1))
        if self.rejoining.any():
            self._rejoined(moving)
        if self.halting.any():
            self._halt(moving, before, before_stride)
        own = self.starting | self.halting | self.rejoining  # (a leg's own share may be short of the rest's 1)
        self.shortening = bool(stride.min() < 1.0) or bool(own.any() and (self.leg_shares[own] < 1.0).any())

    def _rejoined(self, moving: np.ndarray) -> None:
        """Each leg of a body whose stop was called off (`_rejoin`): the one planted then from its
        share to `rejoin_to` while it stays down, then to the rest's (`stride`) by a
        smootherstep over its swing (fastest as the foot passes under the hips, where the share
        moves it least); the other with the rest (called off a second time, closing its gap to
        the rest as the rest comes up to 1, as a halting body's legs do). Stopped again, its legs
        brake from there (`halting`), and a call-off then rejoins from where they are."""
        stopped = self.rejoining & ~moving
        self.halting |= stopped
        self.rejoin_halted |= stopped
        going = self.rejoining & moving
        self.rejoin_left[going] -= 1.0
        swinging = going & (self.rejoin_left <= 0.0)
        self.rejoin_swing[swinging] += self.rejoin_swing_rate[swinging]
        down = 1.0 - np.maximum(self.rejoin_left, 0.0) / self.rejoin_stance
        planted = self.rejoin_from + (self.rejoin_to - self.rejoin_from) * down
        swung = self.rejoin_to + (self.stride - self.rejoin_to) * smootherstep(np.minimum(self.rejoin_swing, 1.0))
        share = np.where(self.rejoin_left > 0.0, planted, swung)
        remaining = (1.0 - self.stride) / np.maximum(1.0 - self.rejoin_stride, 1e-12)  # the rest's way still to go
        other = self.stride + self.rejoin_gap * np.minimum(remaining, 1.0)  # (the rest's own, but called off twice)
        own = self.rejoin_leg[:, None] == np.arange(2)
        self.leg_shares = np.where(going[:, None], np.where(own, share[:, None], other[:, None]), self.leg_shares)
        self.rejoining = going & ((self.rejoin_swing < 1.0) | (other != self.stride))

    def _halt(self, moving: np.ndarray, before: np.ndarray, before_stride: np.ndarray) -> None:
        """A body stopped while it set off: each leg's share of its swing, and the rest's, goes
        down with its travel from where it was (`before`, `before_stride`: the last frame's travel
        and rest), as a braking body's stride does: one at or under the travel holds until the
        travel comes down to it, one above it (a start's rest ahead of its travel) goes down in
        proportion; moved again before it stands, each leg closes its gap to the rest as the
        rest comes up to 1. It is done once both legs are where the rest is."""
        halting = self.halting & ~self.starting
        brake = halting & ~moving
        travel = self.travel[:, None]
        last = np.maximum(before, 1e-12)[:, None]
        legs = self.leg_shares
        braked = np.minimum(legs, travel * np.maximum(1.0, legs / last))
        ahead = brake & (before_stride > before)  # the rest ahead of the travel: drawn down with it
        if ahead.any():
            rest = np.minimum(before_stride, self.travel * before_stride / np.maximum(before, 1e-12))
            self.stride = np.where(ahead, rest, self.stride)
            self.stride_level = np.where(ahead, smoothstep_of(self.stride), self.stride_level)
        remaining = (1.0 - self.stride) / np.maximum(1.0 - before_stride, 1e-12)  # the share of the rest's way still to go
        closing = self.stride[:, None] + (legs - before_stride[:, None]) * np.minimum(remaining, 1.0)[:, None]
        self.leg_shares = np.where(brake[:, None], braked, np.where(halting[:, None], closing, legs))
        self.halting = halting & (np.abs(self.leg_shares - self.stride[:, None]).max(axis=1) > 1e-12)
        self.rejoin_halted &= self.halting

    def strides(self) -> np.ndarray:
        """(N, D) the share of its swing each character's every feature takes (`stride`), but a
        starting (or halting) body's legs', which take their own (`leg_shares`). The same array
        each frame, overwritten."""
        out = self._strides
        out[:] = self.stride[:, None]
        own = np.flatnonzero(self.starting | self.halting | self.rejoining)
        if len(own):
            shares = self.leg_shares[own]
            out[own] = np.where(self.legs[0], shares[:, :1], np.where(self.legs[1], shares[:, 1:], self.stride[own, None]))
        return out

    def _frames_to_stand(self, stream: Crowd, stopping: np.ndarray) -> np.ndarray:
        """(N,) the frames each body still moves before its stand begins, after this one: the rest
        of its step under way, and a whole step more where the change waits for it (NEXT)."""
        counters = stream.counters
        left = self._frames_left(stream) - 1.0
        waiting = counters[:, NEXT] != 0
        if waiting.any():
            left = left + np.where(waiting, stream.base[np.arange(stream.count), counters[:, LABEL]].sum(axis=1), 0.0)
        return np.maximum(left, 0.0)

    @staticmethod
    def _frames_left(stream: Crowd, states: np.ndarray | None = None) -> np.ndarray:
        """(N,) the frames of each character's step under way still to come, at mean durations:
        to its end, or to the end of its label's first `states[label]` states."""
        counters = stream.counters
        base = stream.base[np.arange(stream.count), counters[:, LABEL]]  # (N, states)
        ahead = np.arange(base.shape[1]) >= counters[:, STATE, None]
        if states is not None:
            ahead &= np.arange(base.shape[1]) < states[counters[:, LABEL], None]
        return (base * ahead).sum(axis=1) - counters[:, ELAPSED]
