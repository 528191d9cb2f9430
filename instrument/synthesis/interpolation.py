"""Style space: lambda* from per-style weights, as offsets from the average model lambda 0.

A weight of 0 leaves a style out, 1 gives that style's model, 0 < w < 1 inhibits it, w > 1
exaggerates it and w < 0 inverts it; several weights blend. Means (of outputs and durations)
move linearly along the offsets. Variances move in log space, so they stay positive for any
weights (a linear sum, as in hts_engine, goes negative under extrapolation), and each stays
within the span the models themselves have (the least and the largest of lambda 0's and the
styles' for that state and dimension): between the styles a log variance moves as the means do,
but past them (x2, -1) its extrapolation has nothing in the data behind it. lambda 0 is in the
span because every mix between the styles is (a weight moving out past them meets the bound
where it already is, no jump); the bound is only applied past them. Unbounded, an
inverted run's root speed variances reached 120-470 cm/s (its styles' 11-40, the average's 66-76)
against delta variances of a few cm/s a frame, so the window MLPG barely pulled the speed
towards the run's: a run set off from a stand took 4 to 7 steps to reach speed. A crowd
character's own offset moves its variances on from the bounded performance's, and far out
(beyond the span, or with a wide spread) a variance changes at most 10^4 times from lambda 0's
so the solver stays well conditioned.

Weights can also be given per body part: the static dimensions fall into groups derived from
the skeleton (the root's motion, the legs, the upper body), and each style may weigh each group
differently ("legs youthful, upper body elderly"). Durations follow the overall weights.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from numba import njit

from ..models.modelfile import Model
from ..motion.bvh import Motion
from ..motion.features import ROOT_FEATURES, FeatureLayout
from ..motion.kinematics import forward_kinematics, local_transforms
from .cores import LEAST_PER_LIGHT_PART, over_cores, parts
from .parameters import GROUPS

MAX_LOG_VARIANCE_CHANGE = float(np.log(1e4))  # extreme weights may scale a variance 10^4 times, no more


@dataclass(frozen=True)
class StyleSpace:
    """lambda 0 and the style offsets, flattened over (label, state) for fast gathering.

    Means and log variances are stacked (axis "kind": 0 means, 1 log variances), so one
    matrix product moves both when the weights change."""

    style_names: tuple[str, ...]
    labels: int
    states: int
    base: np.ndarray  # (2, labels * states, 3D) lambda 0's means and log variances
    offsets: np.ndarray  # (styles, 2, labels * states, 3D) each style's, minus lambda 0's
    duration_base: np.ndarray  # (2, labels * states) the same for the state durations
    duration_offsets: np.ndarray  # (styles, 2, labels * states)
    group_masks: np.ndarray  # (groups, 3D) which observation dimensions belong to each group
    log_variance_span: np.ndarray  # (2, labels * states, 3D) the least and largest log variance offset (0: lambda 0)
    max_step: np.ndarray  # (D,) largest frame-to-frame change of each static feature in the data


@dataclass(frozen=True)
class Lambda:
    """An interpolated model, ready for generation."""

    means: np.ndarray  # (labels * states, 3D)
    precisions: np.ndarray  # (labels * states, 3D)
    duration_means: np.ndarray  # (labels, states) in frames
    duration_variances: np.ndarray  # (labels, states)


def body_groups(layout: FeatureLayout) -> np.ndarray:
    """(groups, D) masks over the static features: root motion, legs, upper body.

    A leg is a subtree under the root that reaches near the ground in the template pose (its
    lowest joint is below a third of the root's height above the lowest point); the rest is
    upper body.
    """
    skeleton = layout.skeleton
    template = Motion(skeleton, np.asarray(layout.template)[None], 30.0)
    positions = forward_kinematics(skeleton, *local_transforms(template))[1][0]
    height = positions[:, 1] - positions[:, 1].min()
    parents = skeleton.parents
    top_child = {}
    for j in range(len(parents)):
        chain = j
        while parents[chain] >= 0 and parents[chain] != layout.root:
            chain = parents[chain]
        if parents[chain] == layout.root:
            top_child[j] = chain
    lowest = {}
    for j, child in top_child.items():
        lowest[child] = min(lowest.get(child, np.inf), height[j])
    legs = {child for child, low in lowest.items() if low < height[layout.root] / 3.0}
    masks = np.zeros((len(GROUPS), layout.dimension), dtype=bool)
    masks[0, : len(ROOT_FEATURES)] = True
    for k, joint in enumerate(layout.joints):
        columns = slice(len(ROOT_FEATURES) + 3 * k, len(ROOT_FEATURES) + 3 * k + 3)
        masks[1 if top_child.get(joint) in legs else 2, columns] = True
    return masks


def style_space(model: Model) -> StyleSpace:
    labels, states = len(model.labels), model.states
    flat = lambda a: a.reshape(a.shape[:-3] + (labels * states, a.shape[-1]))  # noqa: E731
    base = np.stack([flat(model.average.means), np.log(flat(model.average.variances))])
    duration_base = np.stack([model.average.duration_means.reshape(-1), np.log(model.average.duration_variances.reshape(-1))])
    styles = len(model.style_names)
    masks = np.tile(body_groups(model.layout), (1, 3))
    log_offsets = np.log(flat(model.styles.variances)) - base[1]
    span = np.stack([np.minimum(log_offsets.min(axis=0), 0.0), np.maximum(log_offsets.max(axis=0), 0.0)])
    return StyleSpace(
        style_names=tuple(model.style_names),
        labels=labels,
        states=states,
        base=base,
        offsets=np.stack([flat(model.styles.means), log_offsets], axis=1) - np.stack([base[0], np.zeros_like(base[1])]),
        duration_base=duration_base,
        duration_offsets=np.stack([model.styles.duration_means.reshape(styles, -1),
                                   np.log(model.styles.duration_variances.reshape(styles, -1))], axis=1) - duration_base,
        group_masks=masks,
        log_variance_span=span,
        max_step=model.static_step_max,
    )


def part_weights_per_group(weights: np.ndarray, part_weights: np.ndarray) -> np.ndarray:
    """The one rule for body-part weights: (..., styles, groups), each group's own weight where
    it is given and the style's overall weight where it is NaN. Interpolation, the range filter
    and the foot contact all read part weights through this."""
    weights = np.asarray(weights, dtype=np.float64)
    return np.where(np.isnan(part_weights), weights[..., None], part_weights)


def past_the_styles(mixes: np.ndarray) -> bool:
    """Whether a mix (styles, groups) of the weights is past the styles (a weight below 0, or a
    group's adding up to more than 1): where the log variances' change is bounded to the span."""
    return bool((mixes < 0.0).any() or (mixes.sum(axis=0) > 1.0).any())


def _log_variance_change(space: StyleSpace, weights: np.ndarray, per_dim: np.ndarray, parts: bool, bounded: bool
                         ) -> np.ndarray:
    """(labels * states, 3D) how far lambda*'s log variances move from lambda 0's at one mix
    (`_mix_per_dimension`'s `per_dim` and `bounded`; `parts`: part weights were given), within
    the span of the models' own (`StyleSpace.log_variance_span`) past the styles. Made whole only
    where the bound on it is loose (`StyleInterpolation.__call__`'s slow branches); the means'
    change is never needed whole, so it is not made."""
    log_offsets = space.offsets[:, 1]
    if parts:
        change = np.einsum("sf,skf->kf", per_dim, log_offsets)
    else:
        change = (np.asarray(weights, dtype=np.float64) @ log_offsets.reshape(len(log_offsets), -1)).reshape(
            log_offsets.shape[1:])
    if bounded:  # a convex mix needs no bound
        np.maximum(change, space.log_variance_span[0], out=change)  # (two passes: half np.clip's time)
        np.minimum(change, space.log_variance_span[1], out=change)
    return change


def _mix_per_dimension(space: StyleSpace, weights: np.ndarray, part_weights: np.ndarray | None
                       ) -> tuple[np.ndarray, bool]:
    """(styles, 3D) the weight of each style in each observation dimension (the overall weight,
    or its group's part weight), and whether the mix is past the styles (a weight below 0, or
    a group's adding up to more than 1), where the log variances' change is bounded to the span
    (`_log_variance_change`'s rule)."""
    weights = np.asarray(weights, dtype=np.float64)
    if part_weights is None:
        mixes = weights[:, None]
        per_dim = np.repeat(mixes, space.group_masks.shape[1], axis=1)
    else:
        mixes = part_weights_per_group(weights, part_weights)
        per_dim = mixes @ space.group_masks
    return per_dim, past_the_styles(mixes)


def _duration_change(space: StyleSpace, weights: np.ndarray) -> np.ndarray:
    """(2, labels * states) how far the duration pdfs move from lambda 0's (they follow the overall weights)."""
    weights = np.asarray(weights, dtype=np.float64)
    return (weights @ space.duration_offsets.reshape(len(weights), -1)).reshape(space.duration_base.shape)


@njit(cache=True, nogil=True)
def _shared_rows(per_dim, offsets, base, span, bounded, limit, rows, means, precisions):  # pragma: no cover - compiled
    """Rows `rows` of the shared tables: lambda 0's means plus the mix's change, and the
    precisions exp(-(lambda 0's log variances + the change)), the change bounded to `span` when
    `bounded`, and to +-limit (`clipped_precisions`' rule); per_dim (styles, 3D) each style's
    weight in each dimension. Every retune makes the shared tables here, whichever way the
    crowd's own are made: a crowd's lead (no offset of its own) then has a lone character's
    numbers to the bit (the same sums in the same order, the same exp; numpy's exp on an
    AVX-512 machine differs from this one in the last bit). One pass over the
    rows asked for, where numpy's product, sum and exp made five over every row (and the
    rows of a gesture can wait until one plays: `StyleInterpolation.complete`), reading the
    offsets of the styles in the mix only (a performer's faders mostly rest at 0; the offsets
    are megabytes, out of the cache by the time a change comes). Adding a style weighed 0 would
    add 0.0 to each sum: leaving it out changes no bit."""
    styles, width = per_dim.shape
    mean_change = np.empty(width)
    log_change = np.empty(width)
    weighed = np.zeros(styles, dtype=np.bool_)  # a style weighed 0 everywhere adds nothing: its offsets go unread
    for s in range(styles):
        for f in range(width):
            weighed[s] |= per_dim[s, f] != 0.0
    for r in rows:
        mean_change[:] = 0.0
        log_change[:] = 0.0
        for s in range(styles):
            if not weighed[s]:
                continue
            for f in range(width):
                mean_change[f] += per_dim[s, f] * offsets[s, 0, r, f]
                log_change[f] += per_dim[s, f] * offsets[s, 1, r, f]
        for f in range(width):
            change = log_change[f]
            if bounded:
                change = min(max(change, span[0, r, f]), span[1, r, f])
            change = min(max(change, -limit), limit)
            means[r, f] = base[0, r, f] + mean_change[f]
            precisions[r, f] = np.exp(-(base[1, r, f] + change))


class StyleInterpolation:
    """The engine's interpolation stage: lambda* of every character, batched.

    Character n walks at the performed weights plus `spread` times its own style offset (a
    crowd's cast; zeros for a single character). lambda*'s change is linear in the weights (part
    weights too), so a character's change is the performance's plus spread times its offset's,
    made once here (`CrowdLambda`'s own factors): a moving fader then costs only the shared
    factors, one small table, and no pass over the crowd's (megabytes)."""

    def __init__(self, space: StyleSpace, offsets: np.ndarray, later: np.ndarray | None = None):
        self.space = space
        styles = len(space.style_names)
        self.offsets = np.asarray(offsets, dtype=np.float64)  # (N, styles)
        self.offset_change = (self.offsets @ space.offsets.reshape(styles, -1)).reshape((-1,) + space.base.shape)
        self.offset_duration_change = (self.offsets @ space.duration_offsets.reshape(styles, -1)).reshape(
            (-1,) + space.duration_base.shape)
        self._spread: float | None = None
        self._own_reach = float(np.abs(self.offset_change[:, 1]).max(initial=0.0))  # the largest log variance offset
        self._mean_term = self._precision_factor = None
        self._clip_spread: float | None = None  # the spread `_clip_own` (spread times the log variance offsets) is for
        self._clip_own: np.ndarray | None = None
        # (styles,) the largest log variance offset of each style: bounds a mix's change before it is made
        self._style_reach = np.abs(space.offsets[:, 1]).reshape(styles, -1).max(axis=1)
        self._span_reach = float(np.abs(space.log_variance_span).max(initial=0.0))
        rows = space.labels * space.states
        self._later = np.zeros(rows, dtype=np.bool_) if later is None else np.asarray(later, dtype=np.bool_)
        self._now_rows = np.flatnonzero(~self._later)  # the rows a retune makes; `complete` makes the others
        self._later_rows = np.flatnonzero(self._later)
        self._pending: _LaterRows | None = None  # the last call's rows left for later
        self._older: _LaterRows | None = None  # the call's before it: retired when its arrays are made again
        self._shared: list[tuple[np.ndarray, np.ndarray]] = []  # the shared tables' arrays, made again in place

    def __call__(self, weights: np.ndarray, part_weights: np.ndarray | None, spread: float
                 ) -> tuple[CrowdLambda, np.ndarray, np.ndarray]:
        """Every character's lambda* (its two factors) and its duration means and variances (N,
        labels, states)."""
        space = self.space
        if spread != self._spread:  # kept while the spread stays: what it adds, and its factor on the precisions
            self._spread = spread
            self._mean_term = spread * self.offset_change[:, 0]
            self._precision_factor = np.exp(-spread * self.offset_change[:, 1])
            self._plain = ~(self._mean_term.any(axis=(1, 2)) | (self._precision_factor != 1.0).any(axis=(1, 2)))
        limit = MAX_LOG_VARIANCE_CHANGE
        per_dim, bounded = _mix_per_dimension(space, weights, part_weights)
        reach = float(np.abs(per_dim).max(axis=1) @ self._style_reach)  # no log variance change is larger
        if bounded:
            reach = min(reach, self._span_reach)
        # the shared tables, made row by row in one pass, the rows `later` left for `complete`
        means, precisions = self._tables()
        if self._older is not None:  # these arrays were its tables: its rows must not land in these
            self._older.retire()
        _shared_rows(per_dim, space.offsets, space.base, space.log_variance_span, bounded, limit, self._now_rows, means,
                     precisions)
        rest = _LaterRows(space, self._later_rows, per_dim, bounded, means, precisions) if len(self._later_rows) else None
        self._older, self._pending = self._pending, rest
        duration_change = _duration_change(space, weights)
        if reach + abs(spread) * self._own_reach <= limit:
            # no variance at its limit: exp(-(a + b)) = exp(-a) exp(-b), the second kept while the spread stays
            tables = CrowdLambda(self._mean_term, means, self._precision_factor, precisions, self._plain, rest=rest)
        else:  # the bound above is loose: the change made whole says whether a variance is at its limit
            log_change = _log_variance_change(space, weights, per_dim, part_weights is not None, bounded)
            if np.abs(log_change).max() + abs(spread) * self._own_reach <= limit:  # none is: two factors
                tables = CrowdLambda(self._mean_term, means, self._precision_factor, precisions, self._plain, rest=rest)
            else:  # some variance at its limit: a character's precisions cannot be two factors
                # made whole for every character, they cost a crowd of 32 some 20 ms a frame while a
                # fader moved past the styles (1,000: most of a second): the shared table holds the
                # precisions of a character with no offset of its own (`plain`), and the stream makes
                # another's rows from its log offset as its window reads them (`clip_*`, stream.py `_gather`)
                if self._clip_spread != spread:
                    self._clip_spread, self._clip_own = spread, np.multiply(self.offset_change[:, 1], spread)
                tables = CrowdLambda(self._mean_term, means, self._clip_own, precisions, self._plain, log_change,
                                     space.base[1], limit, rest=rest)
        shape = (len(self.offsets), space.labels, space.states)
        means, variances = np.empty(shape), np.empty(shape)
        flat_means, flat_variances = means.reshape(len(means), -1), variances.reshape(len(means), -1)
        # a crowd's part by part over the cores (each character's numbers its own: the same bits in any part)
        over_cores(_duration_part, [(space.duration_base, duration_change, self.offset_duration_change[a:b], spread, limit,
                                     flat_means[a:b], flat_variances[a:b]) for a, b in parts(len(means), LEAST_PER_LIGHT_PART)])
        return tables, means, variances


    def complete(self) -> None:
        """The rows the last call left (`later`: a gesture's, which only a playing gesture reads),
        made into the same tables: the same numbers as if made with the others."""
        if self._pending is not None:
            self._pending()

    def _tables(self) -> tuple[np.ndarray, np.ndarray]:
        """The shared means and precisions to make: two pairs of arrays in turn, so the tables a
        call hands over are never the last call's (whose holders may still read them), and no
        table is allocated a call."""
        shape = self.space.base.shape[1:]
        if len(self._shared) < 2:
            self._shared.append((np.empty(shape), np.empty(shape)))
            return self._shared[-1]
        self._shared.reverse()
        return self._shared[0]


class _LaterRows:
    """One call's rows of the shared tables left for later (`later`: a gesture's), made into that
    call's tables the first time they are asked for. It is the `rest` of the tables the call
    hands over, so a holder of the last call's tables, read after a newer call, completes its
    own rows, not the newer call's. The call after next makes its arrays again (the tables
    alternate between two pairs: `StyleInterpolation._tables`) and retires it first, so a holder
    of tables two calls old can no longer write its rows into a newer call's."""

    def __init__(self, space: StyleSpace, rows: np.ndarray, per_dim: np.ndarray, bounded: bool, means: np.ndarray,
                 precisions: np.ndarray):
        self.space, self.rows, self.per_dim, self.bounded = space, rows, per_dim, bounded
        self.tables: tuple[np.ndarray, np.ndarray] | None = (means, precisions)  # None: made, or retired

    def __call__(self) -> None:
        if self.tables is not None:
            means, precisions = self.tables
            self.tables = None
            space = self.space
            _shared_rows(self.per_dim, space.offsets, space.base, space.log_variance_span, self.bounded,
                         MAX_LOG_VARIANCE_CHANGE, self.rows, means, precisions)

    def retire(self) -> None:
        """Its tables' arrays are another call's now: its rows are not to be made."""
        self.tables = None


def _duration_part(base: np.ndarray, shared: np.ndarray, own: np.ndarray, spread: float, limit: float, means: np.ndarray,
                   variances: np.ndarray) -> None:
    """Some characters' duration means and variances (`_duration_tables`, then numpy's exp of the
    log variances, as the shared tables' exp: one character's bits; both let go of the GIL)."""
    _duration_tables(base, shared, own, spread, limit, means, variances)
    np.exp(variances, out=variances)


@njit(cache=True, nogil=True)
def _duration_tables(base, shared, own, spread, limit, means, log_variances):  # pragma: no cover - compiled
    """Every character's duration means and log variances (N, labels * states): lambda 0's plus
    the performed change plus `spread` times the character's own, the log variances' change
    clipped to +-limit; the same operations in the same order as numpy's elementwise form (one
    pass, where that form took six over the crowd: a millisecond a retune for 1,000 characters)."""
    for n in range(means.shape[0]):
        for k in range(means.shape[1]):
            means[n, k] = base[0, k] + (shared[0, k] + spread * own[n, 0, k])
            change = shared[1, k] + spread * own[n, 1, k]
            log_variances[n, k] = base[1, k] + min(max(change, -limit), limit)


@dataclass(frozen=True)
class CrowdLambda:
    """lambda* of N characters, (N, labels * states, 3D) each, kept as two factors: a character's
    means are its own term plus the term all share, its precisions its own factor times the
    shared one. The character's own factors move only with the spread, the shared ones with the
    performed weights, so a moving fader rewrites two small tables, not megabytes per character:
    the stream puts a character's tables together in the cache as it solves its window."""

    mean_own: np.ndarray  # (N, labels * states, 3D)
    mean_shared: np.ndarray  # (labels * states, 3D)
    precision_own: np.ndarray  # (N, labels * states, 3D)
    precision_shared: np.ndarray  # (labels * states, 3D)
    plain: np.ndarray  # (N,) bool: the character's own term is 0 and factor 1 (its lambda* is the shared one)
    # where some variance is at its limit (`limit` above 0), precisions are not two factors:
    # precision_own is then each character's log variance offset (spread times its own), and a
    # character's precisions are exp(-(clip_base + clip(precision_own + clip_change, -limit, limit)))
    # (precision_shared: those of a character with no offset, `plain`)
    clip_change: np.ndarray | None = None  # (labels * states, 3D) the performed weights' log variance change
    clip_base: np.ndarray | None = None  # (labels * states, 3D) lambda 0's log variances
    limit: float = 0.0
    # makes the shared tables' rows left for later (a gesture's: `StyleInterpolation.complete`); the
    # whole tables below are read through it (the stream reads the rows it solves, made by then)
    rest: Callable[[], None] | None = None

    @property
    def means(self) -> np.ndarray:
        if self.rest is not None:
            self.rest()
        return self.mean_own + self.mean_shared

    @property
    def precisions(self) -> np.ndarray:
        if self.rest is not None:
            self.rest()
        if not self.limit:
            return self.precision_own * self.precision_shared
        whole = clipped_precisions(self.precision_own + self.clip_change, self.clip_base, self.limit)
        whole[self.plain] = self.precision_shared
        return whole


def clipped_precisions(log_change: np.ndarray, log_base: np.ndarray, limit: float) -> np.ndarray:
    """exp(-(log_base + clip(log_change, -limit, limit))): the precisions of log variances
    `log_base` (K,...) moved by `log_change` (..., K,...), each move within +-limit
    (MAX_LOG_VARIANCE_CHANGE). `CrowdLambda.precisions` is made by it; the shared tables
    (`_shared_rows`) and the stream's `_gather` make a row the same way, with the same exp."""
    log_change = np.ascontiguousarray(log_change, dtype=np.float64)
    log_base = np.ascontiguousarray(log_base, dtype=np.float64)
    out = np.empty_like(log_change)
    _clipped_exp(log_change.reshape(-1, log_base.size), log_base.reshape(-1), limit, out.reshape(-1, log_base.size))
    return out


@njit(cache=True, nogil=True)
def _clipped_exp(log_change, log_base, limit, out):  # pragma: no cover - compiled
    """`clipped_precisions` compiled: numba's exp, the one the stream and the shared tables use."""
    for n in range(log_change.shape[0]):
        for k in range(log_change.shape[1]):
            out[n, k] = np.exp(-(min(max(log_change[n, k], -limit), limit) + log_base[k]))


def interpolate(space: StyleSpace, weights: np.ndarray, part_weights: np.ndarray | None = None) -> Lambda:
    """lambda* of one character at style weights (styles,) and optional per-group weights
    (styles, groups), NaN entries following the overall weight: the engine's interpolation
    stage for a single character (what the tests and the benchmarks' fixed solves use)."""
    styles = len(space.style_names)
    tables, duration_means, duration_variances = StyleInterpolation(space, np.zeros((1, styles)))(
        weights, part_weights, 0.0)
    return Lambda(tables.means[0], tables.precisions[0], duration_means[0], duration_variances[0])
