"""Test oracle: the foot lock as it was written in plain Python before the pose path was compiled
(instrument.synthesis.footlock), kept to check that the compiled lock makes the same poses; and
the one-character pose stream it ran in (instrument.synthesis.posing before CrowdPoses).
See instrument.synthesis.contact's docstring for what the lock does. It restates the lock of
feet with toe joints (the shipped model's, on which it is compared) and of feet that are their
ankle alone, rolling about their End Site's tip (`tip_clearance` given: limbs.foot_tip,
footlock.FootLock.tips; compared on a toe-less re-rig of the shared walks)."""

from __future__ import annotations

import numpy as np
from numba import njit

from instrument.motion.features import FeatureLayout, restore_local
from instrument.motion.kinematics import forward_kinematics
from instrument.motion.limbs import centimetres_per_unit, find_limbs, foot_tip
from instrument.synthesis.posing import Pose
from instrument.synthesis.contact import (BLEND_FRAMES, CONTACT_CM, CONTACT_SPEED_CM_S, HOLD_FRAMES, NEARLY_STRAIGHT,
                                          POSSIBLE, PLANTED, REFERENCE_FPS, SWING_BENT, SWING_CM)
from instrument.synthesis.follow import STRENGTH
from instrument.synthesis.footlock import (CLOSED, HEEL_RISE_SPEED, LANDING_PACE, MAX_HEEL_RISE, RELEASE_FRAMES, SETTLE_CM,
                                           SETTLE_LIFT_CM, SETTLE_SECONDS, SETTLE_STILL_CM_S, STRETCH)


def EASE(x: float) -> float:
    return x * x * (3.0 - 2.0 * x)  # smoothstep: the lock starts and ends with zero speed


def _toe_line(world_rot: np.ndarray, world_pos: np.ndarray, leg, tip: np.ndarray | None) -> np.ndarray:
    """The ankle to the point its heel rises about: its pivot joint, or for a foot that is its
    ankle alone, its End Site's `tip` (in the ankle's frame); zeros for such a foot without one."""
    if leg.pivot == leg.ankle and tip is not None:
        return world_rot[leg.ankle] @ tip
    return world_pos[leg.pivot] - world_pos[leg.ankle]


def _across(world_rot: np.ndarray, world_pos: np.ndarray, leg, tip: np.ndarray | None = None) -> np.ndarray:
    """A foot's axis across it in its ankle's frame: level and to the side of its toe line
    (`_toe_line`) in the template pose (`world_rot`, `world_pos`); zeros for a foot without toes."""
    toes = _toe_line(world_rot, world_pos, leg, tip)
    if np.hypot(toes[0], toes[2]) <= 1e-9:
        return np.zeros(3)
    across = np.cross([0.0, 1.0, 0.0], toes)
    return world_rot[leg.ankle].T @ (across / np.linalg.norm(across))


def _heading(world_rot: np.ndarray, leg, across: np.ndarray) -> float:
    """Which way a foot points, about the vertical (0 along +z), from its axis across it."""
    side = world_rot[leg.ankle] @ across
    return float(np.arctan2(-side[2], side[0]))


class _Follow:
    """The body following its stance foot (instrument.synthesis.follow), written out plainly for
    one character: each frame the body takes `strength` of each planted foot's horizontal slide
    in the generated pose, weighted by its lock's eased blend (both planted: their mean)."""

    def __init__(self):
        self.offset = np.zeros(3)
        self.previous: np.ndarray | None = None

    def step(self, pivots: np.ndarray, blend: np.ndarray, strength: float) -> np.ndarray:
        if self.previous is not None:
            weights = [EASE(float(b)) for b in blend]
            total = max(sum(weights), 1.0)
            for f in range(2):
                slide = pivots[f] - self.previous[f]
                self.offset[0] -= strength * weights[f] / total * slide[0]
                self.offset[2] -= strength * weights[f] / total * slide[2]
        self.previous = np.array(pivots, dtype=np.float64)
        return self.offset.copy()


def _swing_share(world_pos: np.ndarray, leg) -> float:
    """How much of SWING_CM a swinging foot keeps: all of it on a bent knee, none on a straight one."""
    thigh, shin = world_pos[leg.knee] - world_pos[leg.hip], world_pos[leg.ankle] - world_pos[leg.knee]
    cos = thigh @ shin / (np.linalg.norm(thigh) * np.linalg.norm(shin) + 1e-12)
    return min(1.0, float(np.arccos(min(max(cos, -1.0), 1.0))) / SWING_BENT)


@njit
def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:  # pragma: no cover - compiled
    """The smallest rotation taking direction a to direction b (Rodrigues)."""
    a = a / np.sqrt(np.sum(a * a))
    b = b / np.sqrt(np.sum(b * b))
    axis = np.cross(a, b)
    s = np.sqrt(np.sum(axis * axis))
    c = np.sum(a * b)
    if s < 1e-12:
        return np.eye(3)
    k = axis / s
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + s * K + (1.0 - c) * (K @ K)


@njit
def _axis_rotation(axis: np.ndarray, angle: float) -> np.ndarray:  # pragma: no cover - compiled
    k = axis / np.sqrt(np.sum(axis * axis))
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


@njit
def _leg_swings(hip, knee, ankle, target, toes):  # pragma: no cover - compiled
    """Two-bone IK, as world rotations of the thigh (about the hip) and the shin (about the
    knee, applied after the thigh's) that take the ankle to `target`, or as near as the leg
    allows: the knee bends about its own hinge (the axis across its generated bend; for a
    straight leg, across the line to the toes) to the angle the law of cosines gives, then the
    hip swings the leg onto the target. A generated leg bent a little backwards (less than
    NEARLY_STRAIGHT, the toes' side telling which way is forward) is bent forward through
    straight, not further back, so a leg shortened from nearly straight never folds the wrong
    way and flips back a frame later; a clearer bend is the knee's own (a swinging foot's toes
    may point anywhere)."""
    thigh_vector, shin_vector = knee - hip, ankle - knee
    upper = np.sqrt(np.sum(thigh_vector**2))
    lower = np.sqrt(np.sum(shin_vector**2))
    reach = target - hip
    distance = min(max(np.sqrt(np.sum(reach * reach)), abs(upper - lower) + 1e-6), (upper + lower) * 0.9999)
    forward = np.cross(toes, thigh_vector)  # the axis a knee bends forward about (the shin back, the knee towards the toes)
    hinge = np.cross(thigh_vector, shin_vector)
    now = np.arccos(min(max(np.sum(thigh_vector * shin_vector) / (upper * lower), -1.0), 1.0))  # 0: straight
    if np.sqrt(np.sum(hinge * hinge)) < 1e-3 * upper * lower:  # straight: the knee bends forward
        hinge, now = forward, 0.0
    elif now < NEARLY_STRAIGHT and np.sum(hinge * forward) < 0.0:  # bent a little backwards: bent forward through straight
        hinge, now = -hinge, -now
    if np.sqrt(np.sum(hinge * hinge)) < 1e-12:
        return np.eye(3), np.eye(3)
    cos_new = min(max((upper**2 + lower**2 - distance**2) / (2.0 * upper * lower), -1.0), 1.0)
    bend = _axis_rotation(hinge, np.pi - np.arccos(cos_new) - now)
    swing = _rotation_between(thigh_vector + bend @ shin_vector, reach)
    return swing, swing @ bend @ swing.T


def _scaled_rotation(rotation: np.ndarray, share: float) -> np.ndarray:
    """`rotation` with its angle scaled by `share`, about the same axis."""
    axis = np.array([rotation[2, 1] - rotation[1, 2], rotation[0, 2] - rotation[2, 0], rotation[1, 0] - rotation[0, 1]])
    if np.linalg.norm(axis) < 1e-12:
        return np.eye(3)
    return _axis_rotation(axis, share * np.arctan2(np.linalg.norm(axis), np.trace(rotation) - 1.0))


def _pitch_to_height(toes: np.ndarray, axis: np.ndarray, height: float) -> float | None:
    """The turn about `axis` (unit) nearest 0 that brings the `toes` vector's height to `height`,
    found numerically (a scan, then bisection) to check the compiled closed form; None if none does."""
    def excess(angle: float) -> float:
        return float((_axis_rotation(axis, angle) @ toes)[1] - height)

    angles = np.linspace(-np.pi, np.pi, 721)
    values = np.array([excess(a) for a in angles])
    crossings = np.flatnonzero(np.sign(values[1:]) != np.sign(values[:-1]))
    if not len(crossings):
        return None
    best = None
    for i in crossings:
        low, high = angles[i], angles[i + 1]
        for _ in range(80):
            middle = (low + high) / 2.0
            low, high = (middle, high) if np.sign(excess(middle)) == np.sign(values[i]) else (low, middle)
        root = (low + high) / 2.0
        if best is None or abs(root) < abs(best):
            best = root
    return best


def _heel_rise(world_rot: np.ndarray, world_pos: np.ndarray, leg, toes: np.ndarray, across: np.ndarray,
               clearance: tuple[float, float], on_floor: float, target: np.ndarray, allowed: float, low: float,
               high: float) -> tuple[np.ndarray, np.ndarray, float]:
    """The foot's turn about its toe line's end (`toes`: `_toe_line`) that raises the heel until the leg
    reaches no further than `allowed` (less of the way where the toes are higher above their
    clearance than the heel above its own, none from `on_floor` higher), and the ankle's target
    after it, found numerically (a scan of the rise, then bisection) to check the compiled
    closed form: the smallest rise that reaches, else the one in [0, MAX_HEEL_RISE] that comes
    nearest; then held in [low, high] and to at most MAX_HEEL_RISE from standing flat. Also the
    angle. `clearance`: the ankle's and the toe line end's heights standing on the floor."""
    axis = world_rot[leg.ankle] @ across  # lifting the heel about the foot's axis across it
    if np.linalg.norm(axis[[0, 2]]) < 1e-12:
        return np.eye(3), target, 0.0
    drop = clearance[1] - clearance[0]  # the toes' height below the ankle's, standing flat
    length = np.linalg.norm(toes)
    forward = np.cross(axis, [0.0, 1.0, 0.0])  # level, towards the toes of a flat foot
    forward /= np.linalg.norm(forward)
    risen = np.arcsin(np.clip(drop / length, -1, 1)) - np.arctan2(toes[1], toes @ forward)
    high = min(high, max(MAX_HEEL_RISE - risen, 0.0))
    angle = float(np.clip(_needed_rise(world_pos, leg, toes, axis, clearance, on_floor, target, allowed), min(low, high), high))
    if angle <= 0.0:
        return np.eye(3), target, 0.0
    turn = _axis_rotation(axis, angle)
    return turn, target + toes + turn @ -toes, angle


def _needed_rise(world_pos, leg, toes, axis, clearance, on_floor, target, allowed) -> float:
    hip = world_pos[leg.hip]
    toe, back = target + toes, -toes
    toes_up = toes[1] - (clearance[1] - clearance[0])  # the toes' lift above the heel's, each above its clearance
    share = min(max(1.0 - toes_up / on_floor, 0.0), 1.0)
    reach = np.linalg.norm(target - hip)
    if share <= 0.0 or reach <= allowed:
        return 0.0
    allowed = reach - share * (reach - allowed)

    def excess(angle: float) -> float:
        return float(np.linalg.norm(toe + _axis_rotation(axis, angle) @ back - hip) - allowed)

    def bisect(low: float, high: float, below) -> float:
        for _ in range(80):
            middle = (low + high) / 2.0
            low, high = (low, middle) if below(middle) else (middle, high)
        return (low + high) / 2.0

    angles = np.linspace(0.0, MAX_HEEL_RISE, 2001)
    values = np.array([excess(a) for a in angles])
    reached = np.flatnonzero(values <= 0.0)
    if len(reached):
        i = reached[0]
        angle = bisect(angles[i - 1], angles[i], lambda a: excess(a) <= 0.0)
    else:
        i = int(np.argmin(values))
        if i == 0:
            return 0.0
        unit = axis / np.linalg.norm(axis)

        def rising(angle: float) -> bool:  # the reach's derivative, d|x|^2 = 2 x . (unit x R back)
            turned = _axis_rotation(axis, angle) @ back
            return float((toe + turned - hip) @ np.cross(unit, turned)) > 0.0

        angle = MAX_HEEL_RISE if i == len(angles) - 1 else bisect(angles[i - 1], angles[i + 1], rising)
    return angle


class FootLock:
    """One character's planted feet, carried from frame to frame (see the module's docstring)."""

    def __init__(self, layout: FeatureLayout, ground: np.ndarray, fps: float, tip_clearance: float | None = None):
        self.layout, self.fps = layout, fps
        self.limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
        # a toe-less foot's End Site tip (in its ankle's frame) and its clearance, where the model has one
        self.tips = [None if tip_clearance is None else foot_tip(layout, leg) for leg in self.limbs.legs]
        self.tip_clearance = tip_clearance
        self.ground = np.asarray(ground, dtype=np.float64)
        self.parents = layout.skeleton.parents
        self.weight = np.zeros(2)  # how far each foot's lock is blended in
        self.lock = np.full((2, 3), np.nan)  # world point each foot is locked to
        self.heading = np.zeros(2)  # each locked foot's heading at landing (ankle to pivot, about the vertical)
        self.drop = 0.0  # how far the body is lowered for a planted leg to reach its target
        self.rise = np.zeros(2)  # each foot's heel rise in the frame before
        self.rise_step = HEEL_RISE_SPEED / fps  # how far a rise may change in a frame
        self.parent_rot = layout.template_pose[2]  # the root's parent's world rotation
        template_rot, template = (a[0] for a in forward_kinematics(layout.skeleton, layout.template_pose[0][None],
                                                                   layout.template_pose[1][None]))
        self.cm = centimetres_per_unit(layout, template)
        self.across = [_across(template_rot, template, leg, tip) for leg, tip in zip(self.limbs.legs, self.tips)]
        self.swing_lift = SWING_CM / self.cm  # in the skeleton's units
        self.previous = np.full((2, 3), np.nan)  # each pivot's generated position in the frame before
        self.settling = np.zeros(2)  # each foot's closing step: 0 may take one, (0, 1) how far, CLOSED
        # the lock's times are frames at REFERENCE_FPS, the same time at this rate: a frame's share of them
        self.blend_step = REFERENCE_FPS / fps / BLEND_FRAMES  # of a lock's blend in or out
        self.hold_step = REFERENCE_FPS / fps / HOLD_FRAMES  # of the swing lift's going, or the hold's on the floor
        self.drop_share = 1.0 - (1.0 - 1.0 / BLEND_FRAMES) ** (REFERENCE_FPS / fps)  # of the way to the body's drop
        self.landed = np.zeros(2)  # how far each foot's swing lift has gone since it was planted
        self.held = np.zeros(2)  # how far each foot's lowest joint is held on the floor
        # each held foot's lock as local rotation offsets (made^T @ locked) at hip, knee and ankle, and
        # its toes' world turn (locked @ made^T), as of its last fully locked frame; and how much of them a
        # walk's released foot still carries (1..0), given back in joint space over RELEASE_FRAMES
        self.offsets = np.tile(np.eye(3), (2, 4, 1, 1))
        self.released = np.tile(np.eye(3), (2, 4, 1, 1))  # the offsets a released foot gives back (its offsets then)
        self.releasing = np.zeros(2)
        self.release_step = REFERENCE_FPS / fps / RELEASE_FRAMES
        self.locking = np.zeros(2)  # the weight the lock's target holds each foot with (from none at a release in joint space)
        # the share of the lock's horizontal pull on each foot's pivot: in on an ease-out curve while
        # planted, out on a smoothstep while not, each frame moving along its curve from where it is
        self.pulls = np.zeros(2)

    def toes(self, f: int, world_rot: np.ndarray, world_pos: np.ndarray) -> np.ndarray:
        """Foot f's toe line (`_toe_line`)."""
        return _toe_line(world_rot, world_pos, self.limbs.legs[f], self.tips[f])

    def pivots(self, world_rot: np.ndarray, world_pos: np.ndarray) -> np.ndarray:
        """(2, 3) the points the lock holds: each pivot joint, or a toe-less foot's tip."""
        return np.array([world_pos[leg.pivot] if self.tips[f] is None else world_pos[leg.ankle] + world_rot[leg.ankle] @ self.tips[f]
                         for f, leg in enumerate(self.limbs.legs)])

    def pivot_ground(self, f: int) -> float:
        """The clearance of foot f's toe line's end: its pivot joint's, or its tip's."""
        leg = self.limbs.legs[f]
        return self.ground[f][list(leg.foot).index(leg.pivot)] if self.tips[f] is None else self.tip_clearance

    def _points(self, f: int, world_rot: np.ndarray, world_pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Foot f's points' heights and their clearances: its joints', and its tip's where it has one."""
        foot = list(self.limbs.legs[f].foot)
        heights, grounds = world_pos[foot, 1], np.asarray(self.ground[f], dtype=float)
        if self.tips[f] is None:
            return heights, grounds
        tip = world_pos[self.limbs.legs[f].ankle, 1] + self.toes(f, world_rot, world_pos)[1]
        return np.append(heights, tip), np.append(grounds, self.tip_clearance)

    def lift(self, f: int, world_rot: np.ndarray, world_pos: np.ndarray) -> float:
        """Height of foot f's lowest point above its own clearance."""
        heights, grounds = self._points(f, world_rot, world_pos)
        return float(np.min(heights - grounds))

    def sole(self, f: int, world_rot: np.ndarray, world_pos: np.ndarray) -> float:
        """Height of foot f's lowest point above the lowest of its clearances."""
        heights, grounds = self._points(f, world_rot, world_pos)
        return float(np.min(heights) - np.min(grounds))

    def apply(self, rotations: np.ndarray, translations: np.ndarray, shares: np.ndarray,
              standing: bool = False) -> tuple[np.ndarray, ...]:
        """Local rotations (J, 3, 3) of one frame, adjusted, the translations (J, 3), and their
        world rotations and positions; `shares` (2,) says how surely each foot is planted in
        the frame's state; `standing`: the frame is of a stand (its feet close up)."""
        rotations = rotations.copy()
        world_rot, world_pos = forward_kinematics(self.layout.skeleton, rotations[None], translations[None])
        world_rot, world_pos = world_rot[0], world_pos[0]
        made = [[rotations[j].copy() for j in (leg.hip, leg.knee, leg.ankle)] + [world_rot[leg.pivot].copy()]
                for leg in self.limbs.legs]  # the legs as made, which a held foot's offsets are measured from
        planted, speeds = self._planted(shares, world_rot, world_pos)
        still = standing and bool((speeds < SETTLE_STILL_CM_S).all())  # NaN (first frame): not still
        step = self.blend_step
        # landing from flight (the other foot neither planted nor held): its lock comes in faster
        pace = [LANDING_PACE * step if self.weight[1 - f] == 0.0 and not planted[1 - f] else step for f in range(2)]
        landing = [planted[f] and self.weight[f] == 0.0 for f in range(2)]
        for f in range(2):
            if not planted[f] and self.weight[f] == 1.0 and planted[1 - f]:  # a walk's foot let go from its full lock: in joint space
                self.releasing[f], self.rise[f], self.held[f], self.locking[f] = 1.0, 0.0, 0.0, 0.0
                self.released[f] = self.offsets[f]
        for f, leg in enumerate(self.limbs.legs):
            self.weight[f] = min(1.0, self.weight[f] + pace[f]) if planted[f] else max(0.0, self.weight[f] - step)
            if planted[f]:  # along an ease-out curve 1 - (1 - a)^2, from where the pull is on it
                along = min(1.0, 1.0 - np.sqrt(max(0.0, 1.0 - self.pulls[f])) + pace[f])
                self.pulls[f] = 1.0 - (1.0 - along) ** 2
            else:  # along smoothstep, from where the pull is on it (its inverse: 1/2 - sin(asin(1 - 2p) / 3))
                self.pulls[f] = EASE(max(0.0, 0.5 - np.sin(np.arcsin(np.clip(1.0 - 2.0 * self.pulls[f], -1.0, 1.0)) / 3.0) - step))
            step_in = self.hold_step if planted[f] else -self.hold_step  # the swing lift goes as the foot is planted
            self.landed[f] = min(max(self.landed[f] + step_in, 0.0), 1.0)
            if self.releasing[f] > 0.0:
                self.releasing[f] = max(0.0, self.releasing[f] - self.release_step)
                self.landed[f] = max(self.landed[f], self.releasing[f])  # the swing lift comes in as the offsets go
                world_rot, world_pos = self._release(f, rotations, translations, world_rot, world_pos,
                                                     EASE(self.releasing[f]))
            # the IK's weight: the weight's pace, from none at a walk's release (given back in joint space)
            self.locking[f] = min(1.0, self.locking[f] + pace[f]) if planted[f] else max(0.0, self.locking[f] - step)
        for f, leg in enumerate(self.limbs.legs):
            if landing[f]:  # locked where it is shown, any release of it applied
                self.lock[f] = self.pivots(world_rot, world_pos)[f]
                self.heading[f] = _heading(world_rot, leg, self.across[f])
                self.settling[f] = 0.0  # landed; and the other foot, if closed up, may be closed up again
                if self.settling[1 - f] == CLOSED:
                    self.settling[1 - f] = 0.0
        lifts = self._settle(still, planted, world_rot, world_pos)
        for f, leg in enumerate(self.limbs.legs):
            if self.locking[f] > 0.0:  # the foot turned about the vertical through its ankle, back to its landing heading
                turn = EASE(self.locking[f]) * ((self.heading[f] - _heading(world_rot, leg, self.across[f]) + np.pi)
                                               % (2 * np.pi) - np.pi)
                yaw = _axis_rotation(np.array([0.0, 1.0, 0.0]), turn)
                ankle = world_pos[leg.ankle].copy()
                for j in leg.foot:
                    world_rot[j] = yaw @ world_rot[j]
                    world_pos[j] = ankle + yaw @ (world_pos[j] - ankle)
                rotations[leg.ankle] = world_rot[leg.knee].T @ world_rot[leg.ankle]
        for f, leg in enumerate(self.limbs.legs):  # alone on the floor, a planted foot is pitched flat about its ankle
            # (a released other foot, its lock still blending out, does not keep it from standing flat)
            share = EASE(self.locking[f]) * (1.0 - (EASE(self.locking[1 - f]) if planted[1 - f] else 0.0))
            toes = self.toes(f, world_rot, world_pos)
            up = toes[1] - (self.pivot_ground(f) - self.ground[f][list(leg.foot).index(leg.ankle)])
            axis = world_rot[leg.ankle] @ self.across[f]  # pitched about its axis across it
            if share > 0.0 and toes.any() and up > 0.0 and np.linalg.norm(axis) > 1e-12:
                angle = _pitch_to_height(toes, axis, toes[1] - share * up)
                if angle is None:
                    continue
                pitch = _axis_rotation(axis, angle)
                ankle = world_pos[leg.ankle].copy()
                for j in leg.foot:
                    world_rot[j] = pitch @ world_rot[j]
                    world_pos[j] = ankle + pitch @ (world_pos[j] - ankle)
                rotations[leg.ankle] = world_rot[leg.knee].T @ world_rot[leg.ankle]
        extension = [np.linalg.norm(world_pos[leg.ankle] - world_pos[leg.hip]) for leg in self.limbs.legs]
        targets, turns = self._targets(world_rot, world_pos, planted, extension)
        # a planted leg that cannot reach its target even on its toes (an exaggerated style can
        # lift the hips): the body comes down, eased over a few frames so it does not bob
        need = 0.0
        for f, leg in enumerate(self.limbs.legs):
            if planted[f]:
                stretched = max(extension[f], STRETCH * (leg.thigh + leg.shin))
                need = max(need, np.linalg.norm(targets[f] - world_pos[leg.hip]) - stretched)
        self.drop += (max(need, 0.0) - self.drop) * self.drop_share
        if self.drop > 1e-9:
            translations = translations.copy()
            translations[self.layout.root] -= np.array([0.0, self.drop, 0.0]) @ self.parent_rot
            world_pos = world_pos - np.array([0.0, self.drop, 0.0])
            targets, turns = self._targets(world_rot, world_pos, planted, extension)
        self.rise = self.next_rise  # the rises of the targets taken, and the holds
        self.held = self.next_held
        for f in range(2):  # a closing step's foot off the floor
            targets[f][1] += lifts[f]
        for f, leg in enumerate(self.limbs.legs):
            if leg.pivot != leg.ankle and not np.array_equal(turns[f], np.eye(3)):  # the toes keep their world rotation
                rotations[leg.pivot] = (turns[f] @ world_rot[self.parents[leg.pivot]]).T @ world_rot[leg.pivot]
            world_rot[leg.ankle] = turns[f] @ world_rot[leg.ankle]
            if np.linalg.norm(targets[f] - world_pos[leg.ankle]) > 1e-9:
                self._solve(f, rotations, world_rot, world_pos, targets[f])
            elif not np.array_equal(turns[f], np.eye(3)):  # the ankle where it was made, the foot turned all the same
                rotations[leg.ankle] = world_rot[leg.knee].T @ world_rot[leg.ankle]
        world_rot, world_pos = forward_kinematics(self.layout.skeleton, rotations[None], translations[None])
        for f, leg in enumerate(self.limbs.legs):  # a fully held foot's lock as offsets from the leg as made, for its release
            if planted[f] and self.weight[f] == 1.0:
                for k, j in enumerate((leg.hip, leg.knee, leg.ankle)):
                    self.offsets[f, k] = made[f][k].T @ rotations[j]
                self.offsets[f, 3] = world_rot[0, leg.pivot] @ made[f][3].T
        return rotations, translations, world_rot[0], world_pos[0]

    def _risen(self, f: int, world_rot: np.ndarray, world_pos: np.ndarray) -> float:
        """How far foot f's heel is up from standing flat (radians, growing past the vertical)."""
        leg = self.limbs.legs[f]
        toes = self.toes(f, world_rot, world_pos)
        k = world_rot[leg.ankle] @ self.across[f]
        level, length = np.hypot(k[0], k[2]), np.linalg.norm(toes)
        if level < 1e-12 or length < 1e-12:
            return 0.0
        flat = np.arcsin(np.clip((self.pivot_ground(f) - self.ground[f][0]) / length, -1.0, 1.0))
        return float(flat - np.arctan2(toes[1], (toes[2] * k[0] - toes[0] * k[2]) / level))

    def _release(self, f: int, rotations: np.ndarray, translations: np.ndarray, world_rot: np.ndarray,
                 world_pos: np.ndarray, share: float) -> tuple[np.ndarray, np.ndarray]:
        """A walk's released foot given back in joint space (footlock.release_joints): `share` of
        each offset (its angle scaled about its axis) on the rotations made; the foot pitched back
        about its ankle to MAX_HEEL_RISE from flat (or as made, if more); the toes their world
        rotation as made turned by `share` of the lock's turn of them. Returns the new world transforms."""
        leg = self.limbs.legs[f]
        made = self._risen(f, world_rot, world_pos)
        toes_made = world_rot[leg.pivot].copy()
        for k, j in enumerate((leg.hip, leg.knee, leg.ankle)):
            rotations[j] = rotations[j] @ _scaled_rotation(self.released[f, k], share)
        world_rot, world_pos = (a[0] for a in forward_kinematics(self.layout.skeleton, rotations[None], translations[None]))
        excess = self._risen(f, world_rot, world_pos) - max(MAX_HEEL_RISE, made)
        axis = world_rot[leg.ankle] @ self.across[f]
        if excess > 0.0 and np.hypot(axis[0], axis[2]) > 1e-12:
            pitch = _axis_rotation(axis, -excess)
            ankle = world_pos[leg.ankle].copy()
            for j in leg.foot:
                world_rot[j] = pitch @ world_rot[j]
                world_pos[j] = ankle + pitch @ (world_pos[j] - ankle)
            rotations[leg.ankle] = world_rot[leg.knee].T @ world_rot[leg.ankle]
        if leg.pivot != leg.ankle:
            rotations[leg.pivot] = world_rot[self.parents[leg.pivot]].T @ (_scaled_rotation(self.released[f, 3], share)
                                                                           @ toes_made)
            world_rot, world_pos = (a[0] for a in forward_kinematics(self.layout.skeleton, rotations[None],
                                                                     translations[None]))
        return world_rot, world_pos

    def _settle(self, still: bool, planted: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray) -> np.ndarray:
        """A closing step (footlock.settle_feet): the first time since a landing that a still stand
        has both feet locked in, each foot locked more than SETTLE_CM from where the pose puts it
        steps there, the further first, lifted along a half sine; returns each foot's lift."""
        lifts = np.zeros(2)
        stepping = [f for f in range(2) if 0.0 < self.settling[f] < CLOSED]
        if not stepping:
            if not (still and planted.all() and (self.weight == 1.0).all()):
                return lifts
            away = {f: np.hypot(*(self.lock[f] - self.pivots(world_rot, world_pos)[f])[[0, 2]]) for f in range(2)
                    if self.settling[f] == 0.0}
            over = {f: d for f, d in away.items() if d > SETTLE_CM / self.cm}
            if not over:
                for f in away:
                    self.settling[f] = CLOSED
                return lifts
            stepping = [max(over, key=over.get)]
        f = stepping[0]
        before = EASE(self.settling[f])
        self.settling[f] = min(self.settling[f] + 1.0 / (SETTLE_SECONDS * self.fps), 1.0)
        if self.settling[f] > 1.0 - 1e-9:  # n steps of 1 / n summing a hair under 1 end the step
            self.settling[f] = 1.0
        keep = (1.0 - EASE(self.settling[f])) / (1.0 - before) if before < 1.0 else 0.0
        goal = self.pivots(world_rot, world_pos)[f]
        self.lock[f][[0, 2]] = goal[[0, 2]] + (self.lock[f] - goal)[[0, 2]] * keep
        turn = (self.heading[f] - _heading(world_rot, self.limbs.legs[f], self.across[f]) + np.pi) % (2 * np.pi) - np.pi
        self.heading[f] -= turn * (1.0 - keep)
        lifts[f] = SETTLE_LIFT_CM / self.cm * np.sin(np.pi * self.settling[f])
        if self.settling[f] >= 1.0:
            self.settling[f] = CLOSED
        return lifts

    def _planted(self, shares: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A foot is planted where its state says so, or where the state allows it and the
        generated foot is on the floor and nearly still (as the data's contact was labelled);
        and each generated pivot's horizontal speed (cm/s), which the closing step reads too."""
        planted = shares >= PLANTED
        pivots = self.pivots(world_rot, world_pos)
        speed = np.hypot(*(pivots - self.previous)[:, [0, 2]].T) * self.fps * self.cm
        self.previous = pivots
        for f, leg in enumerate(self.limbs.legs):
            if not planted[f] and shares[f] >= POSSIBLE:
                lift = self.lift(f, world_rot, world_pos) * self.cm
                planted[f] = lift < CONTACT_CM and speed[f] < CONTACT_SPEED_CM_S  # NaN speed (first frame): False
        if not planted.any() and shares.max() > 0.0:  # a walk has a foot on the floor: the likelier one
            planted[int(np.argmax(shares))] = True
        return planted, speed

    def _target(self, f: int, leg, world_rot: np.ndarray, world_pos: np.ndarray, held: float) -> np.ndarray:
        """Where the ankle should be: the lock blended in horizontally, the lowest foot joint on
        the floor while planted, never below it, and a little above it while swinging; a
        released foot rises as generated, but while it hands over to the other (planted, its
        lowest point not yet down) its lowest joint comes off the floor only as its lock blends
        out. The swing lift goes (as the foot is planted) and the hold on the floor (as it is
        released, not handing over) over HOLD_FRAMES frames at REFERENCE_FPS, eased: `held` is
        how far the hold has come this frame, self.landed how far the lift has gone."""
        lift = self.lift(f, world_rot, world_pos)
        target = world_pos[leg.ankle].copy()
        w = EASE(self.locking[f])
        down = EASE(held) * w * lift if held > 0.0 else 0.0
        if self.pulls[f] > 0:  # a foot released in joint space too: its pivot held where it was locked as the lock goes
            pull = self.lock[f] - self.pivots(world_rot, world_pos)[f]
            target[[0, 2]] += self.pulls[f] * pull[[0, 2]]
        target[1] -= down
        lowest_after = lift - down
        floor = (1.0 - EASE(self.landed[f])) * (1.0 - w) * self.swing_lift * _swing_share(world_pos, leg)
        if lowest_after < floor:
            target[1] += floor - lowest_after
        return target

    def _targets(self, world_rot: np.ndarray, world_pos: np.ndarray, planted: np.ndarray,
                 extension: list[float]) -> tuple[list, list]:
        """Each ankle's target, and each foot's heel-rise turn where its lock is blended in or its
        heel still up from it."""
        targets, turns, self.next_rise, self.next_held = [], [], np.zeros(2), np.zeros(2)
        for f, leg in enumerate(self.limbs.legs):
            sole = self.sole(1 - f, world_rot, world_pos)  # the other foot's lowest point
            holding = planted[f] or (planted[1 - f] and sole >= CONTACT_CM / self.cm)  # planted, or handing over
            self.next_held[f] = min(1.0, self.held[f] + self.hold_step) if holding else max(0.0, self.held[f] - self.hold_step)
            target = self._target(f, leg, world_rot, world_pos, self.next_held[f])
            turn = np.eye(3)
            if self.locking[f] > 0 or self.rise[f] > 0:  # after its lock, a heel comes down at the same pace
                low = max(self.rise[f] - self.rise_step, 0.0)
                high = min(self.rise[f] + self.rise_step, MAX_HEEL_RISE) if self.locking[f] > 0 else low
                clearance = (self.ground[f][0], self.pivot_ground(f))
                turn, target, self.next_rise[f] = _heel_rise(world_rot, world_pos, leg, self.toes(f, world_rot, world_pos),
                                                             self.across[f], clearance, CONTACT_CM / self.cm, target,
                                                             extension[f], low, high)
            released = self.locking[f] == 0.0 and self.pulls[f] > 0.0  # in joint space, its pivot still pulled
            if (not planted[f] and not planted[1 - f] and self.locking[f] > 0) or released:  # the leg no longer than made
                gap = target - world_pos[leg.hip]
                if np.linalg.norm(gap) > extension[f] > 0.0:
                    target = world_pos[leg.hip] + gap * (extension[f] / np.linalg.norm(gap))
            targets.append(target)
            turns.append(turn)
        return targets, turns

    def _solve(self, f: int, rotations: np.ndarray, world_rot: np.ndarray, world_pos: np.ndarray, target: np.ndarray) -> None:
        """Leg IK in place on the local rotations: hip and knee swung, the ankle keeping its world rotation."""
        leg = self.limbs.legs[f]
        toes = self.toes(f, world_rot, world_pos)
        thigh, shin = _leg_swings(world_pos[leg.hip], world_pos[leg.knee], world_pos[leg.ankle], target, toes)
        # the hip is the knee's parent and the knee the ankle's (limbs.py): below the hip everything
        # turns with the thigh, below the knee also with the shin
        hip_world = thigh @ world_rot[leg.hip]
        knee_world = shin @ thigh @ world_rot[leg.knee]
        rotations[leg.hip] = self._parent_world(leg.hip, world_rot).T @ hip_world
        rotations[leg.knee] = hip_world.T @ knee_world
        rotations[leg.ankle] = knee_world.T @ world_rot[leg.ankle]

    def _parent_world(self, joint: int, world_rot: np.ndarray) -> np.ndarray:
        parent = int(self.parents[joint])
        return world_rot[parent] if parent >= 0 else np.eye(3)


class PoseStream:
    """Turns each frame of static features into a Pose, carrying the root's path across frames."""

    def __init__(self, layout: FeatureLayout, fps: float, lock: FootLock | None = None):
        self.layout, self.fps = layout, fps
        self.lock = lock  # plants the feet when the frame says how surely each is planted
        self.follow = _Follow()  # the body follows its stance foot
        self.position = np.zeros(3)
        self.heading = 0.0
        self.index = 0

    def next(self, static: np.ndarray, contact_shares: np.ndarray | None = None, follow_strength: float | None = None) -> Pose:
        rotations, translations, (self.position, self.heading) = restore_local(
            static[None], self.layout, self.fps, self.position, self.heading
        )
        if self.lock is not None and contact_shares is not None:
            translations = self._follow(rotations, translations, follow_strength)
            pose = Pose(self.index, self.index / self.fps, *self.lock.apply(rotations[0], translations[0], contact_shares))
        else:
            world_rot, world_pos = forward_kinematics(self.layout.skeleton, rotations, translations)
            pose = Pose(self.index, self.index / self.fps, rotations[0], translations[0], world_rot[0], world_pos[0])
        self.index += 1
        return pose

    def _follow(self, rotations: np.ndarray, translations: np.ndarray, strength: float | None) -> np.ndarray:
        """The frame's translations with the body moved after its stance foot, by the lock's
        blend of each foot so far."""
        world_rot, world_pos = (a[0] for a in forward_kinematics(self.layout.skeleton, rotations, translations))
        offset = self.follow.step(self.lock.pivots(world_rot, world_pos), self.lock.weight,
                                  STRENGTH if strength is None else strength)
        moved = translations.copy()
        moved[0, self.layout.root] += offset @ self.lock.parent_rot  # world to the root's parent's frame
        return moved
