"""Style adaptation: each style model from the average model lambda 0, by EM on the style's own data.

Every style keeps lambda 0's states (state 3 of "elderly" and of "youthful" are the same phase of
the step), which is what makes interpolating and extrapolating between styles meaningful. Each
EM iteration re-aligns the style's steps under the style's current model (not lambda 0's), then
re-estimates in two layers:

1. Shared linear transforms (CSMAPLR-like, diagonal): every feature's mean moves as
   a * mu + b and its variance scales by s, and every state duration by r, with one (a, b, s, r)
   shared by a class of states. The classes form a tree: all states, then each label's states,
   then each state alone. A node's transform is estimated with its parent's as prior (structural
   MAP), so a node with little data keeps its parent's transform. With one take per style this
   moves all states together from a few steps, where per-state MAP has almost nothing to move.
2. MAP on top: each state's parameters pulled toward the transformed model with a weight of
   `tau` frames, so with plenty of data every state follows its own statistics.

The prior weights are amounts of data, and a second of walking is 30 frames at 30 fps but 120 at
120 fps (the frames are not more independent for being finer: the same motion, sampled more
often). So `tau` is stated in frames at REFERENCE_FPS and counts `tau * fps / REFERENCE_FPS` of
the model's frames: with 16 frames at 120 fps, a style's data outweighed its prior four times
sooner than at 30 fps and a 120 fps model's styles came out other than a 30 fps model's of the
same takes (docs/evaluate.md, "Settings in frames"). Durations are counted in steps (one per
state visit whatever the rate), so their weight `tau / 2` is not scaled.

The tree depth and `tau` are chosen per style and per unit (walk, run, turn, stand) by two-fold
held-out likelihood of that unit's own steps (alternate takes of the unit, or the halves of a
single take), so a user never tunes them, and a run learnt from one take is not held to the
prior the walk chose. State durations never fall below a floor taken from
the data (see duration_floor), and the floor does not lengthen the step (floored_keeping_length).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, fields, replace

import numpy as np

from ..models.hsmm import HSMM, Floors, Statistics, expected_statistics, log_likelihood, map_update
from ..models.units import unit_labels
from ..motion.features import REFERENCE_FPS

DEPTHS = (None, 0, 1, 2)  # None: no transform (MAP only); 0: one class; 1: one per label; 2: one per state
TAUS = (16.0, 64.0, 256.0)  # MAP prior weights tried, in frames at REFERENCE_FPS (0.53, 2.1, 8.5 s of data)
ONE_TAKE_MIN_TAU = 64.0  # a walk from a single take: no smaller weight (see choose_settings)
FLOOR_SHARE = 0.5  # a state's duration stays above this share of its lambda 0 share of the style's step
MIN_STATE_SECONDS = 2.0 / REFERENCE_FPS  # and above this (2 frames at 30 fps), where the style's steps are long enough
MIN_STEPS_TO_CHOOSE = 4  # fewer steps of a unit's foot than this: no held-out choice (see adapt_styles)
TOLERANCE = 0.05  # EM stops when the log-likelihood per frame gains less than this (it is in the hundreds)


@dataclass(frozen=True)
class Settings:
    depth: int | None = 0  # regression class tree level of the transforms (see DEPTHS)
    # MAP weight on top of the transforms (frames at REFERENCE_FPS), also each class's prior weight on its parent's transform
    tau: float = 64.0
    iterations: int = 6  # EM iterations at most (1: one pass on lambda 0's alignment)
    floor_share: float = FLOOR_SHARE  # 0: no duration floor

    @property
    def tau_duration(self) -> float:
        """Prior weight of durations, in steps: tau / 2, the ratio of the original one-pass MAP (10, 5)."""
        return self.tau / 2.0


DEFAULT = Settings()
# the adaptation re-aligned EM replaced, for comparisons
ONE_PASS_MAP = Settings(depth=None, tau=10.0, iterations=1, floor_share=0.0)


# a take as the adaptation reads it: its unit, and per label its step segments
TakeSteps = tuple[str, list[list[np.ndarray]]]
_FIELDS = tuple(f.name for f in fields(HSMM))  # means, variances, duration means and variances


@dataclass(frozen=True)
class UnitChoice:
    """The settings a unit's labels are adapted with, and how they were chosen."""
    settings: Settings
    heldout_loglik_per_frame: float | None  # of the chosen settings on the unit's own held-out steps; None if not chosen
    # "takes" (alternate takes of the unit), "halves" (of its one take); not chosen: "few" (too few
    # steps of a foot to split: the walk's depth, the smallest tau), "default" (DEFAULT: the walk
    # itself has too few), "fixed" (given)
    folds: str

    def to_dict(self) -> dict:
        return {"depth": self.settings.depth, "tau": self.settings.tau,
                "heldout_loglik_per_frame": self.heldout_loglik_per_frame, "folds": self.folds}


@dataclass
class StyleReport:
    units: dict[str, UnitChoice]  # each unit the style has (always its walk): its settings and how chosen
    loglik_per_frame: list[float] = field(default_factory=list)  # per EM iteration, full data, the walk's settings
    min_duration: float = 0.0  # shortest state duration mean of the adapted model (frames)

    @property
    def settings(self) -> Settings:
        """The walk's settings (the gestures' too): what the style-level metadata records."""
        return self.units["walk"].settings

    @property
    def heldout_loglik_per_frame(self) -> float | None:
        """Of the walk's settings on its held-out steps; None if not chosen by held-out likelihood."""
        return self.units["walk"].heldout_loglik_per_frame

    def to_dict(self) -> dict:
        return {**asdict(self.settings), "heldout_loglik_per_frame": self.heldout_loglik_per_frame,
                "loglik_per_frame": self.loglik_per_frame, "min_duration": self.min_duration,
                "units": {unit: choice.to_dict() for unit, choice in self.units.items()}}


def _classes(depth: int, labels: int, states: int) -> list[list[np.ndarray]]:
    """The regression class tree down to `depth`: per level, a list of index arrays over the
    flattened (label, state) axis."""
    everything = np.arange(labels * states)
    per_label = [everything[k * states : (k + 1) * states] for k in range(labels)]
    levels = [[everything], per_label, [np.array([i]) for i in everything]]
    return levels[: depth + 1]


def _transform_node(mu, var, dmu, dvar, occ, first, second, dcount, dfirst, parent, weight, duration_weight, spread):
    """One class's (a, b, s, r) from its states' statistics with the parent's transform as prior.

    mu, var, first, second: (n, F); occ, dmu, dvar, dcount, dfirst: (n,). `weight` is the prior's
    weight in the model's frames (spread over the class's states as pseudo-data drawn from the
    parent's transformed model), `duration_weight` the durations' in steps; `spread` (F,) keeps
    the slope's prior from vanishing when the class's means are all alike (one state)."""
    a_p, b_p, s_p, r_p = parent
    n = len(occ)
    pseudo = weight / n
    count = occ + pseudo  # (n,)
    target = first + pseudo * (a_p * mu + b_p)  # pseudo-frames sit at the parent's transformed means
    g = count[:, None] / var
    g00 = (g * mu**2).sum(0) + weight * spread
    g01 = (g * mu).sum(0)
    g11 = g.sum(0)
    k0 = (mu * target / var).sum(0) + weight * spread * a_p
    k1 = (target / var).sum(0)
    det = g00 * g11 - g01**2
    a = (g11 * k0 - g01 * k1) / det
    b = (g00 * k1 - g01 * k0) / det
    moved = a * mu + b
    residual = ((second - 2 * moved * first + occ[:, None] * moved**2) / var).sum(0)
    s = (residual + weight * s_p) / (occ.sum() + weight)
    dpseudo = duration_weight / n  # durations: steps, as tau_duration
    r = ((dmu * dfirst / dvar).sum() + dpseudo * r_p * (dmu**2 / dvar).sum()) / (
        (dmu**2 * dcount / dvar).sum() + dpseudo * (dmu**2 / dvar).sum())
    return a, b, s, r


def transformed(average: HSMM, stats: list[Statistics], depth: int, weight: float, duration_weight: float,
                floors: Floors) -> HSMM:
    """lambda 0 moved by the structural-MAP transforms of the class tree down to `depth`, each class's
    transform pulled toward its parent's by `weight` frames of the model (`duration_weight` steps)."""
    labels, states, features = average.means.shape
    mu = average.means.reshape(-1, features)
    var = average.variances.reshape(-1, features)
    dmu, dvar = average.duration_means.ravel(), average.duration_variances.ravel()
    occ = np.concatenate([s.occupancy for s in stats])
    first = np.concatenate([s.first for s in stats])
    second = np.concatenate([s.second for s in stats])
    dcount = np.concatenate([s.duration_count for s in stats])
    dfirst = np.concatenate([s.duration_first for s in stats])
    spread = ((mu - mu.mean(0)) ** 2 / var).mean(0) + 1e-6
    identity = (np.ones(features), np.zeros(features), np.ones(features), 1.0)
    node_of = [identity] * (labels * states)  # the transform each state gets from the deepest level so far
    for level in _classes(depth, labels, states):
        fresh = list(node_of)
        for members in level:
            parent = node_of[members[0]]  # every member of a class shares its parent class
            t = _transform_node(mu[members], var[members], dmu[members], dvar[members], occ[members], first[members],
                                second[members], dcount[members], dfirst[members], parent, weight, duration_weight, spread)
            for i in members:
                fresh[i] = t
        node_of = fresh
    a, b, s = (np.stack([t[k] for t in node_of]) for k in range(3))
    r = np.array([t[3] for t in node_of])
    means = (a * mu + b).reshape(average.means.shape)
    variances = np.maximum(s * var, floors.variance).reshape(average.variances.shape)
    dmeans = (r * dmu).reshape(average.duration_means.shape)
    dvars = np.maximum(r**2 * dvar, floors.duration_variance).reshape(average.duration_variances.shape)
    return HSMM(means, variances, dmeans, dvars)


def duration_floor(average: HSMM, segments: list[list[np.ndarray]], share: float, fps: float = REFERENCE_FPS) -> np.ndarray:
    """(labels, states), in frames at `fps`: the larger of `share` of each state's lambda 0 share
    of this style's mean step, and MIN_STATE_SECONDS unless the style's short steps (10th
    percentile of length) cannot give every state that long. 0 where `share` is 0. (The second
    floor was 2 frames at any rate: at 120 fps, 17 ms, below the share of every state, so it never
    held and a 120 fps style's short states could shrink to a quarter of a 30 fps one's.)"""
    floor = np.zeros_like(average.duration_means)
    for k, label in enumerate(segments):
        if label and share > 0:
            lengths = np.array([len(s) for s in label], dtype=np.float64)
            proportional = share * average.duration_means[k] * lengths.mean() / average.duration_means[k].sum()
            floor[k] = np.maximum(proportional, min(MIN_STATE_SECONDS * fps, np.percentile(lengths, 10) / floor.shape[1]))
    return floor


def m_step(average: HSMM, stats: list[Statistics | None], settings: Settings, floors: Floors, floor: np.ndarray,
           fps: float = REFERENCE_FPS) -> HSMM:
    """Transforms over the class tree, then MAP toward the transformed model, then the duration
    floor; the prior weighs `settings.tau` frames at REFERENCE_FPS, as many of the model's `fps`
    as last as long (durations: `tau_duration` steps)."""
    complete = [s if s is not None else _empty(average) for s in stats]
    tau = settings.tau * (fps / REFERENCE_FPS)
    prior = average if settings.depth is None else transformed(average, complete, settings.depth, tau,
                                                               settings.tau_duration, floors)
    parameters = []
    for k, s in enumerate(complete):
        p = (prior.means[k], prior.variances[k], prior.duration_means[k], prior.duration_variances[k])
        parameters.append(map_update(s, p, floors, tau, settings.tau_duration) if s.frames else p)
    means, variances, dmeans, dvars = (np.stack([p[i] for p in parameters]) for i in range(4))
    return HSMM(means, variances, floored_keeping_length(dmeans, floor), dvars)


def floored_keeping_length(means: np.ndarray, floor: np.ndarray) -> np.ndarray:
    """(labels, states) duration means raised to `floor`, the frames added taken back from the
    states above it in proportion, so the step lasts as the data says. Raising alone lengthened
    steps: on takes at 15 fps (upsampled to 30, which smooths the phases apart less) adaptation
    shrank a state to half its floor and the styles' steps came out 8-9% long."""
    out = np.maximum(means, floor)
    for k in range(out.shape[0]):
        free = means[k] > floor[k]
        for _ in range(out.shape[1]):  # each round fixes at least one more state at its floor
            room = means[k].sum() - out[k][~free].sum()
            if not free.any():
                break
            if room <= 0.0:  # the floors alone are longer than the step: as short as they allow
                out[k][free] = floor[k][free]
                break
            out[k][free] = means[k][free] * room / means[k][free].sum()
            under = free & (out[k] < floor[k])
            if not under.any():
                break
            out[k][under] = floor[k][under]
            free &= ~under
    return out


def _empty(average: HSMM) -> Statistics:
    states, features = average.means.shape[1:]
    z = np.zeros(states)
    return Statistics(0.0, 0, z, np.zeros((states, features)), np.zeros((states, features)), z, z, z)


def alignment(model: HSMM, segments: list[list[np.ndarray]]) -> list[Statistics | None]:
    """E-step statistics of each label's segments under `model` (None for a label without any)."""
    return [expected_statistics(model, k, label) if label else None for k, label in enumerate(segments)]


def combined(a: list[Statistics | None], b: list[Statistics | None]) -> list[Statistics | None]:
    """Statistics of two sets of segments together (they add up)."""
    out = []
    for x, y in zip(a, b):
        if x is None or y is None:
            out.append(x or y)
        else:
            out.append(Statistics(*(getattr(x, f) + getattr(y, f) for f in Statistics.__dataclass_fields__)))
    return out


def adapt(average: HSMM, segments: list[list[np.ndarray]], floors: Floors, settings: Settings = DEFAULT,
          trace: list[float] | None = None, first: list[Statistics | None] | None = None,
          fps: float = REFERENCE_FPS) -> HSMM:
    """A style model by EM from lambda 0, each iteration re-aligning the style's steps under the
    style's current model, until its log-likelihood per frame stops rising. No segments: lambda 0.

    `first` is lambda 0's alignment of the segments if already computed. Without `trace` the
    last iteration is not scored (the held-out choice scores on other data). `fps`: the
    segments' rate, which the prior's weight and the duration floor are measured in."""
    if not any(segments):
        return average
    floor = duration_floor(average, segments, settings.floor_share, fps)
    stats = first or alignment(average, segments)
    best, previous = average, -np.inf
    for iteration in range(1, settings.iterations + 1):
        model = m_step(average, stats, settings, floors, floor, fps)
        if trace is None and iteration == settings.iterations:
            return model
        stats = alignment(model, segments)
        per_frame = sum(s.loglik for s in stats if s) / sum(s.frames for s in stats if s)
        if trace is not None:
            trace.append(per_frame)
        if per_frame < previous:
            return best  # the floor or the prior cost likelihood: keep the better model
        if per_frame - previous < TOLERANCE:
            return model
        best, previous = model, per_frame
    return best


def heldout_score(model: HSMM, segments: list[list[np.ndarray]]) -> tuple[float, int]:
    total, frames = 0.0, 0
    for k, label in enumerate(segments):
        if label:
            ll, n = log_likelihood(model, k, label)
            total, frames = total + ll, frames + n
    return total, frames


def _merge(takes: list[list[list[np.ndarray]]]) -> list[list[np.ndarray]]:
    """Per-take segments (take, label, segment) as one list of segments per label."""
    return [[seg for take in takes for seg in take[k]] for k in range(len(takes[0]))]


def unit_folds(takes: list[TakeSteps], units: Sequence[str]) -> tuple[list[list[list[np.ndarray]]], dict[str, str]]:
    """The style's steps in two folds, each unit split on its own, and how ("takes" or "halves").

    A unit is split by alternate takes of that unit where each fold then holds a step of each of
    its feet, so its choice is judged on takes the adaptation never saw; otherwise (one take, or
    takes of a step or two that leave a fold without one foot's steps) by the first and second
    half of its steps (in each label). Split over all the style's takes together, a one-take run
    lay in one fold, and was scored only where no run had been adapted. A take's other labels
    (a standing take's gestures) go with it. `units` are the model's, in the order of its labels."""
    folds: list[list[list[np.ndarray]]] = [[[] for _ in takes[0][1]] for _ in range(2)]
    how = {}
    for unit in dict.fromkeys(u for u, _ in takes):
        mine = [segments for u, segments in takes if u == unit]
        feet = unit_labels(units, unit) if unit in units else range(0)  # a unit left out of the model has none
        parts = [_merge(mine[0::2]), _merge(mine[1::2])] if len(mine) >= 2 else []
        how[unit] = "takes" if parts and all(part[k] for part in parts for k in feet) else "halves"
        if how[unit] == "halves":
            every = _merge(mine)
            parts = [[label[: len(label) // 2] for label in every], [label[len(label) // 2 :] for label in every]]
        for fold, part in zip(folds, parts):
            for k, label in enumerate(part):
                fold[k] += label
    return folds, how


def choose_settings(average: HSMM, takes: list[TakeSteps], units: Sequence[str], floors: Floors,
                    fps: float = REFERENCE_FPS) -> tuple[dict[str, UnitChoice], list[Statistics | None] | None]:
    """Each unit's tree depth, then tau, with the best two-fold held-out log-likelihood per
    frame of that unit's own steps (and lambda 0's alignment of all the style's steps, computed
    on the way; None, and nothing computed, where no unit can be chosen, so such a style is
    adapted from an alignment of all its steps at once, as before units were chosen apart).
    Units with too few steps of a foot (MIN_STEPS_TO_CHOOSE) are left out: the caller gives
    them the walk's choice.

    Every candidate is adapted on all the training fold's units (the shared transforms learn from
    them all), and each unit scores it on its own held-out steps. Chosen on all the style's
    steps together, the walk decided for every unit and a one-take run could not take part
    (docs/evaluate.md, "A run from one take a style"). A walk split in the halves of its one take
    does not let tau below ONE_TAKE_MIN_TAU: those halves are alike (one performer, one session),
    which rewards fitting the take, and issue 30's one-take walks were measured with it. Other
    units' halves are not held so: a run's one take (35 to 40 frames a label, under the floor)
    kept a third of itself at tau 64, and on every shared style's 11 other run takes tau 16
    explains the runs better than 64 at every depth (docs/evaluate.md, "A run from one take a style")."""
    folds, how = unit_folds(takes, units)
    merged = _merge([segments for _, segments in takes])
    chosen = [u for u in units if u in how and min(len(merged[k]) for k in unit_labels(units, u)) >= MIN_STEPS_TO_CHOOSE]
    if not chosen:
        return {}, None
    firsts = [alignment(average, fold) for fold in folds]  # lambda 0's alignment, the same for every candidate
    scored: dict[Settings, dict[str, float]] = {}

    def score(settings: Settings) -> dict[str, float]:
        """Held-out log-likelihood per frame of each chosen unit's steps (each candidate adapted once)."""
        if settings not in scored:
            total, frames = dict.fromkeys(chosen, 0.0), dict.fromkeys(chosen, 0)
            for train, test in ((0, 1), (1, 0)):
                model = adapt(average, folds[train], floors, settings, first=firsts[train], fps=fps)
                for unit in chosen:
                    mine = unit_labels(units, unit)
                    ll, n = heldout_score(model, [label if k in mine else [] for k, label in enumerate(folds[test])])
                    total[unit], frames[unit] = total[unit] + ll, frames[unit] + n
            scored[settings] = {unit: total[unit] / max(frames[unit], 1) for unit in chosen}
        return scored[settings]

    choices = {}
    for unit in chosen:
        taus = TAUS if how[unit] == "takes" or unit != "walk" else tuple(t for t in TAUS if t >= ONE_TAKE_MIN_TAU)
        quick = replace(DEFAULT, iterations=2, tau=taus[0])
        depth = max(DEPTHS, key=lambda d: score(replace(quick, depth=d))[unit])
        by_tau = {tau: score(replace(quick, depth=depth, tau=tau))[unit] for tau in taus}
        tau = max(by_tau, key=by_tau.get)
        choices[unit] = UnitChoice(replace(DEFAULT, depth=depth, tau=tau), by_tau[tau], how[unit])
    return choices, combined(*firsts)


def adapt_styles(average: HSMM, takes_per_style: dict[str, list[TakeSteps]], floors: Floors,
                 warnings: list[str], fixed: Settings | None = None, fps: float = REFERENCE_FPS,
                 units: Sequence[str] = ("walk",)) -> tuple[HSMM, dict[str, StyleReport]]:
    """All style models stacked on a leading style axis (in the order of `takes_per_style`, whose
    values are per take its unit and, per label, its step segments at `fps`), with what was
    chosen and measured for each. `units` are the model's, in the order of its labels (the labels
    after theirs, gestures', are adapted with the walk's settings). `fixed` skips the held-out
    choice.

    Each unit's labels come from an adaptation of all the style's steps with that unit's
    settings, so a run still learns the shared transforms from the walk; one adaptation is run per
    distinct setting. A unit with too few steps of a foot to split (MIN_STEPS_TO_CHOOSE: a run of
    fewer than 4, 1 to 3, steps a foot) takes the walk's depth and the smallest tau, TAUS[0]: on
    the shared runs, a one-take run split anyway (halves of 1 or 2 steps) chose no transform for
    normal (409.5 per frame on its 11 other takes, against 441.8 with the tree), and at the
    walk's depth tau 16 was the best of the three for every style's other run takes. A style
    whose walk is too small is adapted with DEFAULT, and warned of."""
    models, reports = [], {}
    for style, takes in takes_per_style.items():
        segments = _merge([s for _, s in takes])
        choices, first = ({}, None) if fixed is not None else choose_settings(average, takes, units, floors, fps)
        walk = choices.get("walk")
        if walk is None:
            walk = UnitChoice(fixed or DEFAULT, None, "fixed" if fixed else "default")
            if fixed is None:
                fewest = min(len(label) for label in segments[:2])
                warnings.append(f"style {style!r} has only {fewest} walking steps of one foot: too few to choose the "
                                "adaptation of its walk by held-out likelihood, its walk takes one shared transform")
        few = walk if fixed is not None else UnitChoice(replace(walk.settings, tau=TAUS[0]), None, "few")
        per_unit = {u: choices.get(u, walk if u == "walk" else few)
                    for u in units if u == "walk" or any(segments[k] for k in unit_labels(units, u))}
        trace: list[float] = []
        adapted = {walk.settings: adapt(average, segments, floors, walk.settings, trace, first, fps)}
        for choice in per_unit.values():
            if choice.settings not in adapted:
                adapted[choice.settings] = adapt(average, segments, floors, choice.settings, first=first, fps=fps)
        model = stitched(adapted, [per_unit[u].settings if u in per_unit else walk.settings for u in units],
                         walk.settings)
        models.append(model)
        reports[style] = StyleReport(per_unit, trace, float(model.duration_means.min()))
    stacked = HSMM(*(np.stack([getattr(m, f) for m in models]) for f in _FIELDS))
    return stacked, reports


def stitched(adapted: dict[Settings, HSMM], unit_settings: Sequence[Settings], rest: Settings) -> HSMM:
    """One style model from its adaptations (one per distinct setting): each unit's two labels
    (right and left step, in the order of `unit_settings`) from the adaptation with that unit's
    settings, every later label (the gestures') from `rest`'s. The adaptations all learn from all
    the style's steps, so a unit's labels differ only in the prior they were pulled toward."""
    labels = len(next(iter(adapted.values())).means)
    per_label = [unit_settings[k // 2] if k < 2 * len(unit_settings) else rest for k in range(labels)]
    return HSMM(*(np.stack([getattr(adapted[s], f)[k] for k, s in enumerate(per_label)]) for f in _FIELDS))
