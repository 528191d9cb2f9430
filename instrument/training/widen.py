"""Training's half of the full-range filter: how far each feature's swing must be scaled.

For the average model and for each style, every static feature's range (1st to 99th
percentile) is measured in the real walking frames and in a walk the model makes with the
filter off, and the log of their ratio stored (`train_range`); once the body's height is set
(training/height.py), the knees', hips' and shoulders' factors are calibrated on the walk as the
instrument plays it, feet planted (`calibrate_range`). What the factors mean and
how the engine applies them is described in `instrument.synthesis.widen`.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.ndimage import uniform_filter1d

from ..motion.bvh import Motion
from ..motion.features import ROOT_FEATURES, heading_angle, restore
from ..motion.kinematics import forward_kinematics, local_transforms
from ..motion.limbs import find_limbs, tip_positions
from ..motion.quality import limb_ranges, skate
from ..synthesis.engine import Engine, render
from ..synthesis.stream import Controls
from .little import data_weight, pulled_factors
from ..synthesis.widen import CALIBRATED_LIMIT, KEPT, LIMIT, stride_means, without_range

TRAINING_SECONDS = 20.0  # each generated walk measured in training (its first SETTLE_SECONDS dropped)
SETTLE_SECONDS = 2.0  # of a made walk left out: it starts from rest
RANGE_PERCENTILES = (1.0, 99.0)  # a feature's range, as `instrument evaluate` measures a joint's
CALIBRATION_ROUNDS = 3  # the legs' and shoulders' factors corrected on a played walk this many times
CALIBRATION_SECONDS = 12.0  # each calibration walk, after SETTLE_SECONDS from rest


def settle_frames(fps: float) -> int:
    """The frames of a made walk at `fps` left out from its start (SETTLE_SECONDS). They were 60
    frames, and the walk measured 600, at any rate: at 120 fps that was 0.5 s from rest and 4.5 s
    of walk, some 9 strides whose 1st-99th percentile range is not a 30 fps model's 34 strides'."""
    return int(round(SETTLE_SECONDS * fps))


def _spread(values: np.ndarray) -> np.ndarray:
    """Each column's range between its 1st and 99th percentiles: the peaks a viewer sees, which
    MLPG rounds off more than it lowers the variance (matching variances left the knee 5-18%
    short of the takes' range)."""
    low, high = np.percentile(values, RANGE_PERCENTILES, axis=0)
    return high - low


def _generated_range(model, weights: np.ndarray) -> np.ndarray:
    """Range of each feature of a walk the model makes at `weights` (the range filter off),
    about its stride mean."""
    frames, _, engine = _made_walk(model, weights)
    return _spread(frames - stride_means(engine.stream.base, engine.stream.means)[0])


def _made_walk(model, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, Engine]:
    """The walk `_generated_range` measures: the static features the model makes at `weights`
    with the range filter off over TRAINING_SECONDS, the first SETTLE_SECONDS left out, each
    frame's state id, and the engine that made them."""
    engine = Engine(without_range(model))
    controls = Controls(weights)
    frames, ids = [], []
    for _ in range(int(round(TRAINING_SECONDS * model.fps))):
        frames.append(engine.next_features(controls)[0])
        ids.append(engine.frame_ids[0])
    settle = settle_frames(model.fps)
    return np.array(frames)[settle:], np.array(ids)[settle:], engine


def _real_range(takes, dimension: int) -> np.ndarray | None:
    """Each feature's range in the walking frames (inside steps) of each take about its stride
    mean (the average over the stride around it, as the made walk's is about its stride mean: a
    take's slower changes, turning, speeding up, settling, are not swing the model should make),
    averaged over the takes by their walking frames."""
    total, count = np.zeros(dimension), 0
    for take in takes:  # None when no take has a step: nothing to match
        if not take.steps:
            continue
        stride = max(3, int(round(2.0 * np.mean([s.frames for s in take.steps]))))
        static = take.observations[:, :dimension]
        mean = uniform_filter1d(static, stride, axis=0, mode="nearest")
        rows = np.concatenate([np.arange(s.start, s.end) for s in take.steps])
        total += _spread(static[rows] - mean[rows]) * len(rows)
        count += len(rows)
    return total / count if count else None


# The figures of `limb_ranges` whose joints' factors are calibrated on the played walk, each with its
# bound. The legs' keep the features' LIMIT: on the public CMU set a knee widened past 2x (to its
# takes' range) took the hip from -4% to -8% of its takes' and the skate from 0.43x to 0.56x (the
# lock bends what the knee adds); the arms move nothing the lock holds.
CALIBRATED = {"knee_deg": LIMIT, "hip_deg": LIMIT, "shoulder_deg": CALIBRATED_LIMIT}
# The legs' figures, calibrated together through their measured sensitivities (`_calibrate_legs`)
# after the knees' and shoulders' own ratios.
COUPLED = ("hip_deg", "knee_deg")
PROBE = 0.1  # the change of a leg's log factors by which its figures' sensitivities are measured
# a calibrated walk's feet may skate as much as the walk's before, or this share of its takes' own skate
SKATE_ALLOWANCE = 0.5


def _calibrated_columns(layout, limbs) -> dict[str, list[int]]:
    """The feature columns of the joints each calibrated figure turns: both knees' rotations for
    the knee, both thighs' (at the hip joint) for the hip, both shoulders' (where the upper arm
    starts) for the shoulder; a figure whose joints the layout leaves out (a skeleton without
    arms, or legs the layout does not model) is not calibrated."""
    joints = {"knee_deg": [leg.knee for leg in limbs.legs], "hip_deg": [leg.hip for leg in limbs.legs],
              "shoulder_deg": [shoulder for shoulder, _ in limbs.arms]}
    columns = {figure: [len(ROOT_FEATURES) + 3 * layout.joints.index(j) + a for j in joints[figure] if j in layout.joints
                        for a in range(3)] for figure in CALIBRATED}
    return {figure: found for figure, found in columns.items() if found}


def _widen(log_factors: np.ndarray, found: list[int], figure: str, step: float) -> None:
    """The log factors of a calibrated figure's columns `found` moved by `step` (in place), held
    within the figure's bound (CALIBRATED)."""
    bound = CALIBRATED[figure]
    log_factors[found] = np.clip(log_factors[found] + step, -bound, bound)


def _limb_figures(motion, limbs, layout) -> dict[str, float]:
    """The knees', hips' and shoulders' ranges of a walk in degrees, and its feet's skate (in the
    skeleton's units per second, a toe-less foot's tip among its points: the lock's), as
    `instrument evaluate` measures them."""
    world_rot, world_pos = forward_kinematics(motion.skeleton, *local_transforms(motion))
    root = layout.root
    return limb_ranges(world_pos, heading_angle(world_rot[:, root]), limbs, root) | {
        "skate": skate(world_pos, limbs, motion.fps, tip_positions(world_rot, world_pos, limbs, layout))}


def _miss(real: dict[str, float], made: dict[str, float], figures) -> float:
    """How far a played walk is from the takes: its largest log ratio over those of `figures`
    the takes have (inf where the walk has not)."""
    misses = [abs(np.log(real[f] / made[f])) for f in figures if np.isfinite(real[f]) and real[f] > 0]
    return float(max(misses, default=0.0)) if all(np.isfinite(misses)) else np.inf


def _leg_step(sensitivity: np.ndarray, wanted: np.ndarray) -> np.ndarray:
    """The change of the legs' log factors (one per COUPLED figure's joints) that moves their
    figures' logs by `wanted`, by the measured `sensitivity` (figures x factors), least squares
    where it is singular and no larger than LIMIT."""
    step = np.linalg.lstsq(sensitivity, wanted, rcond=1e-3)[0]
    largest = np.abs(step).max(initial=0.0)
    return step * (LIMIT / largest) if largest > LIMIT else step


def _calibrate_limbs(model, takes, log_factors: np.ndarray, weights: np.ndarray, extras_with) -> None:
    """Moves the knees', hips' and shoulders' log factors (in place) so that the walk the
    instrument plays at `weights`, feet planted, bends its knees and swings its thighs and upper
    arms through the takes' ranges, as `instrument evaluate` measures them (a figure it cannot
    measure is left as the features gave it).

    First the knees and the shoulders, each by its own ratio, CALIBRATION_ROUNDS times. The foot
    lock keeps a planted leg's generated bend where it can (a heel rises instead), but a swinging
    foot kept off the floor bends its knee more, so the features' range alone left the played knee
    up to 13% short (elderly). An upper arm's swing is the turn of the shoulder, collar and spine
    together, and where takes swing their arms differently the states average them nearly away:
    the shoulder features' range ratio, bounded at LIMIT, left a public capture's swing 32% short
    (tests/data/cmu-131; docs/evaluate.md): the shoulders' factors, measured on the walk itself,
    are bounded at CALIBRATED_LIMIT instead. Then the hips with the knees (`_calibrate_legs`).
    `extras_with(log_factors)` gives the model's extras with these factors in their place."""
    layout = model.layout
    limbs = find_limbs(layout.skeleton, layout.root, np.asarray(layout.template))
    chosen = [t for t in takes if t.steps]
    if limbs is None or not chosen:
        return
    columns = _calibrated_columns(layout, limbs)
    if not columns:  # neither the legs nor the shoulders are modelled
        return
    measured = [_limb_figures(restore(t.observations[:, : layout.dimension], layout, model.fps), limbs, layout)
                for t in chosen]
    frames_of = [t.frames for t in chosen]
    real = {figure: float(np.average([m[figure] for m in measured], weights=frames_of)) for figure in [*columns, "skate"]}

    def played() -> dict[str, float]:
        trial = replace(model, extras=extras_with(log_factors))
        settle = settle_frames(model.fps)
        made = render(trial, Controls(weights), settle + int(round(CALIBRATION_SECONDS * model.fps)))
        return _limb_figures(Motion(made.skeleton, made.channels[settle:], made.fps), limbs, layout)

    for _ in range(CALIBRATION_ROUNDS):
        made = played()
        for figure in (f for f in ("knee_deg", "shoulder_deg") if f in columns):
            step = np.log(real[figure] / made[figure])
            if np.isfinite(step):  # a walk too short or too still to measure: keep what the features gave
                _widen(log_factors, columns[figure], figure, step)
    legs = [f for f in COUPLED if f in columns and np.isfinite(real[f]) and real[f] > 0]
    if len(legs) == len(COUPLED):
        _calibrate_legs(log_factors, real, {f: columns[f] for f in legs}, played)


def _calibrate_legs(log_factors: np.ndarray, real: dict[str, float], columns: dict[str, list[int]], played) -> None:
    """Moves the hips' and knees' log factors (in place) together toward the takes' hip and knee
    ranges: a planted thigh's swing is the lock's geometry, the foot staying where it landed while
    the body travels on, so a thigh swung wider by its features lands its foot further ahead and
    ends its stance further forward, and a knee bent more at toe-off turns the thigh forward. On
    the shipped model, widening elderly's thighs by 10% narrowed its played hip from 25.7 to 22.8
    deg (docs/evaluate.md), and the hips corrected by their own ratio did not converge. So the
    figures' sensitivities to each leg's factors are measured once on the played walk (`played()`
    with the factors in place; PROBE: two more walks), then CALIBRATION_ROUNDS Newton steps are
    played, and the factors of the walk nearest the takes (`_miss`) among those whose feet skate
    no more than the walk's before, or than SKATE_ALLOWANCE of the takes' own, are kept: calibrated
    at any cost, a re-rigged feminine walk's skate went from 0.37x its takes' to 1.43x; held to the
    walk's before alone, a lock whose feet skate a tenth of the takes' kept no step at all (a
    toe-less elderly walk at 0.13 cm/s against its takes' 1.8: its hips 13% short of theirs)."""
    figures = list(columns)
    start = log_factors.copy()

    def moved(factors: np.ndarray, figure: str, step: float) -> np.ndarray:
        out = factors.copy()
        _widen(out, columns[figure], figure, step)
        return out

    def play(factors: np.ndarray) -> dict[str, float]:
        log_factors[:] = factors
        return played()

    made = play(start)
    best, nearest = start, _miss(real, made, figures)
    sliding = max(made["skate"], SKATE_ALLOWANCE * real["skate"]) if np.isfinite(real["skate"]) else made["skate"]
    if not np.isfinite(nearest):
        log_factors[:] = start
        return
    sensitivity = np.empty((len(figures), len(figures)))
    for k, lever in enumerate(figures):
        probed = play(moved(start, lever, PROBE))
        sensitivity[:, k] = [np.log(probed[f] / made[f]) / PROBE for f in figures]
    current = start
    if np.isfinite(sensitivity).all():
        for _ in range(CALIBRATION_ROUNDS):
            wanted = np.array([np.log(real[f] / made[f]) for f in figures])
            if not np.isfinite(wanted).all():
                break
            for lever, step in zip(figures, _leg_step(sensitivity, wanted)):
                current = moved(current, lever, step)
            made = play(current)
            miss = _miss(real, made, figures)
            if miss < nearest and made["skate"] <= sliding:
                best, nearest = current, miss
    log_factors[:] = best


def train_range(model, takes) -> dict[str, np.ndarray]:
    """Model-file arrays `range_average` (D,) and `range_styles` (styles, D): the log ratio of
    each feature's range in the data to its range in a walk the model makes, before the legs'
    and shoulders' calibration (`calibrate_range`), which plays the walk on the floor the body stands on and so
    runs after the body's height is set (training/height.py)."""
    dimension = model.layout.dimension
    names = model.style_names

    def log_factor(chosen, weights):
        real = _real_range(chosen, dimension)
        if real is None:  # no walking frames (takes too short for a step): that walk is left as made
            return np.zeros(dimension)
        made = _generated_range(model, weights)
        out = np.log(np.maximum(real, 1e-12) / np.maximum(made, 1e-12))
        out[list(KEPT)] = 0.0
        return np.clip(out, -LIMIT, LIMIT)

    average = log_factor(takes, np.zeros(len(names)))
    styles = np.stack([log_factor([t for t in takes if t.style == name], np.eye(len(names))[s]) for s, name in enumerate(names)])
    return {"range_average": average, "range_styles": styles}


def calibrate_range(model, takes, little_tau: float | None = None) -> dict[str, np.ndarray]:
    """`model`'s range arrays (`train_range`'s) with the knees', hips' and shoulders' factors calibrated on the walk as
    it is played (`_calibrate_limbs`), by the model as it stands (its body's height set: a
    calibration before the height moved fitted the legs to a walk whose stance legs the lock
    bent or stretched to reach a floor the shift then moved). With `little_tau` (steps) each
    style's factors are then pulled toward the average's by the amount of its data
    (training/little.py)."""
    names = model.style_names
    average = np.array(model.extras["range_average"], dtype=np.float64)
    styles = np.array(model.extras["range_styles"], dtype=np.float64)

    def extras_with(_changed: np.ndarray) -> dict:  # the factors are calibrated in place, in these arrays
        return dict(model.extras) | {"range_average": average, "range_styles": styles}

    _calibrate_limbs(model, takes, average, np.zeros(len(names)), extras_with)
    for s, name in enumerate(names):
        _calibrate_limbs(model, [t for t in takes if t.style == name], styles[s], np.eye(len(names))[s], extras_with)
    if little_tau is not None:
        for s, name in enumerate(names):
            steps = sum(len(t.steps) for t in takes if t.style == name)
            styles[s] = pulled_factors(styles[s], average, data_weight(steps, little_tau))
    return {"range_average": average, "range_styles": styles}
