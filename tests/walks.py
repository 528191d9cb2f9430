"""Walks for tests, made through the engine's stages (instrument.synthesis.engine).

`features` gives what the engine makes before posing (a walk's static features and the state of
each frame); `tune` sets a stream's tables per character from arbitrary controls, as a test of the
stream stage alone needs (the engine's own characters differ only by the cast's style offsets);
`finer` gives a model's twin at a multiple of its rate.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from instrument.models.hsmm import HSMM

from instrument.synthesis.durations import MIN_FRAMES, state_durations
from instrument.synthesis.engine import walk_features
from instrument.synthesis.interpolation import CrowdLambda, interpolate
from instrument.synthesis.stream import Controls, Crowd
from instrument.synthesis.widen import without_range


def features(model, controls: Controls, frames: int, method: str = "stream", lookahead: int | None = None, seed: int = 0,
             widen: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """`walk_features`, with the range stage off unless `widen` (`lookahead` None: the engine's default)."""
    return walk_features(model if widen else without_range(model), controls, frames, method, lookahead, seed)


def finer(model, rate: int):
    """`model` at `rate` times its frame rate, every state lasting `rate` times as many frames: the
    same steps in seconds (what settings meaning a time must not tell from the model itself). The
    static features are per second already; the delta and delta-delta streams are per frame, so
    their means shrink by `rate` and `rate`^2 and their variances by the squares."""
    dimension = model.layout.dimension
    per_frame = np.repeat([1.0, 1.0 / rate, 1.0 / rate**2], dimension)  # static, delta, delta-delta

    def longer(hsmm: HSMM) -> HSMM:
        return HSMM(hsmm.means * per_frame, hsmm.variances * per_frame**2, hsmm.duration_means * rate,
                    hsmm.duration_variances * rate**2)

    return replace(model, metadata={**model.metadata, "fps": rate * model.fps}, average=longer(model.average),
                   styles=longer(model.styles))


def tune(stream: Crowd, controls: list[Controls]) -> None:
    """Each character n of the stream takes lambda* and durations of controls[n].

    A test-side restatement, like the oracles (reference_stream.py, reference_lock.py): these are
    the per-character tables the old `Crowd.refresh` computed (each character's own lambda* made
    whole, its durations, its cadence), which the engine no longer makes: its characters differ
    only by the cast's style offsets (`StyleInterpolation`, `Crowd.tune`). Tests of the stream
    stage alone use it (through `step`) to give every character controls of its own. For one
    character it sets the numbers the engine's interpolation and durations stages set at the
    same controls, to the bit (kept whole here, not as the engine's two factors)."""
    means, precisions = stream.means, stream.precisions  # put together: each character's own, whole
    for n, control in enumerate(controls):
        lam = interpolate(stream.space, control.weights, control.part_weights)
        scale = np.ones(stream.space.states) if control.state_scale is None else np.asarray(control.state_scale, dtype=float)
        means[n], precisions[n] = lam.means, lam.precisions
        stream.tables = CrowdLambda(means, np.zeros(means.shape[1:]), precisions, np.ones(means.shape[1:]),
                                    np.zeros(len(means), dtype=bool))
        stream.base[n] = state_durations(lam.duration_means, lam.duration_variances, control.speed, scale)
        stream.sigma[n] = control.liveliness * np.sqrt(lam.duration_variances) * scale
        stream.cadence[n] = np.maximum(lam.duration_means, MIN_FRAMES).sum() / stream.base[n].sum()


def step(stream: Crowd, controls: list[Controls]) -> np.ndarray:
    """One frame of the stream stage alone, its characters at these controls (N, D)."""
    tune(stream, controls)
    return stream.step()
