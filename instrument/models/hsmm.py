"""Left-to-right hidden semi-Markov models over labelled segments: E-step statistics, ML and MAP updates.

Every training segment is one step (one label), and the model of that label must pass through
all its states in order, each for at least one frame. The forward-backward pass therefore runs
over states rather than frames: alpha[i][k, e] is the log probability that states 0..i cover the
first e frames of segment k. All segments of a label are processed at once as padded tensors of
shape (segments, frames + 1, frames + 1), indexed by a state's start and end frame.

Output densities are diagonal Gaussians; durations are Gaussian densities evaluated at whole
frame counts, as in HTS. The EM updates maximise the expected complete-data log-likelihood for
exactly that scoring (variance floors included), so the likelihood never decreases.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

LOG_2PI = float(np.log(2.0 * np.pi))
NEG_INF = -np.inf


@dataclass(frozen=True)
class HSMM:
    """Parameters of one model (one style, or the average), for every label.

    means, variances: (labels, states, features); duration_means, duration_variances: (labels, states), in frames.
    """

    means: np.ndarray
    variances: np.ndarray
    duration_means: np.ndarray
    duration_variances: np.ndarray


@dataclass
class Statistics:
    """Sufficient statistics gathered by the E-step for one label: occupancy-weighted sums."""

    loglik: float
    frames: int
    occupancy: np.ndarray  # (states,)
    first: np.ndarray  # (states, features): sum of gamma * o
    second: np.ndarray  # (states, features): sum of gamma * o^2
    duration_count: np.ndarray  # (states,)
    duration_first: np.ndarray  # (states,)
    duration_second: np.ndarray  # (states,)


def pad_segments(segments: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """(segments, max_frames, features) zero-padded, and each segment's length."""
    lengths = np.array([len(s) for s in segments], dtype=np.int64)
    padded = np.zeros((len(segments), int(lengths.max()), segments[0].shape[1]))
    for k, s in enumerate(segments):
        padded[k, : len(s)] = s
    return padded, lengths


def gaussian_loglik(obs: np.ndarray, means: np.ndarray, variances: np.ndarray) -> np.ndarray:
    """log N(o; mu_i, diag var_i) for obs (..., F) against (states, F): (..., states)."""
    precision = 1.0 / variances
    flat = obs.reshape(-1, obs.shape[-1])
    quad = (flat**2) @ precision.T - 2.0 * flat @ (means * precision).T + np.sum(means**2 * precision, axis=1)
    const = np.sum(np.log(variances), axis=1) + obs.shape[-1] * LOG_2PI
    return (-0.5 * (quad + const)).reshape(obs.shape[:-1] + (means.shape[0],))


def duration_logpdf(means: np.ndarray, variances: np.ndarray, max_frames: int) -> np.ndarray:
    """(states, max_frames + 1): log density of each whole duration d; d = 0 is impossible."""
    d = np.arange(max_frames + 1, dtype=np.float64)
    out = -0.5 * ((d[None] - means[:, None]) ** 2 / variances[:, None] + np.log(variances[:, None]) + LOG_2PI)
    out[:, 0] = NEG_INF
    return out


def _logsumexp(x: np.ndarray, axis: int) -> np.ndarray:
    top = np.max(x, axis=axis, keepdims=True)
    safe = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        out = np.log(np.sum(np.exp(x - safe), axis=axis, keepdims=True)) + safe
    return np.squeeze(out, axis=axis)


def forward_backward(
    obs: np.ndarray, lengths: np.ndarray, means: np.ndarray, variances: np.ndarray, dur_means: np.ndarray, dur_vars: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """For padded segments of one label: per-segment log-likelihood (K,), frame occupancy
    (K, T, states), and the posterior mass of each (state, start, end) summed over segments
    (states, T + 1, T + 1)."""
    segments, frames, _ = obs.shape
    states = means.shape[0]
    emission = gaussian_loglik(obs, means, variances)  # (K, T, N)
    valid = np.arange(frames)[None, :] < lengths[:, None]
    emission = np.where(valid[..., None], emission, 0.0)
    cumulative = np.concatenate([np.zeros((segments, 1, states)), np.cumsum(emission, axis=1)], axis=1)  # (K, T+1, N)
    start = np.arange(frames + 1)[:, None]
    end = np.arange(frames + 1)[None, :]
    span = end - start  # duration of a state covering [start, end)
    durations = duration_logpdf(dur_means, dur_vars, frames)  # (N, T+1)
    allowed = span >= 1

    def segment_score(i: int) -> np.ndarray:
        """log score of state i covering [s, e): output likelihood plus duration, (K, T+1, T+1)."""
        score = cumulative[:, None, :, i] - cumulative[:, :, None, i] + durations[i][np.clip(span, 0, frames)][None]
        return np.where(allowed[None], score, NEG_INF)

    scores = [segment_score(i) for i in range(states)]
    alpha = np.full((states + 1, segments, frames + 1), NEG_INF)
    alpha[0, :, 0] = 0.0  # alpha[i] is before state i starts; alpha[0] = nothing covered yet
    for i in range(states):
        alpha[i + 1] = _logsumexp(alpha[i][:, :, None] + scores[i], axis=1)
    loglik = alpha[states, np.arange(segments), lengths]
    beta = np.full((states + 1, segments, frames + 1), NEG_INF)
    beta[states, np.arange(segments), lengths] = 0.0
    for i in range(states - 1, -1, -1):
        beta[i] = _logsumexp(scores[i] + beta[i + 1][:, None, :], axis=2)
    occupancy = np.zeros((segments, frames, states))
    spans = np.zeros((states, frames + 1, frames + 1))
    for i in range(states):
        posterior = np.exp(alpha[i][:, :, None] + scores[i] + beta[i + 1][:, None, :] - loglik[:, None, None])
        spans[i] = posterior.sum(axis=0)
        started = np.cumsum(posterior.sum(axis=2), axis=1)  # states begun at or before t
        ended = np.cumsum(posterior.sum(axis=1), axis=1)  # states over at or before t
        occupancy[:, :, i] = (started - ended)[:, :frames]
    return loglik, occupancy, spans


def expected_statistics(model: HSMM, label: int, segments: list[np.ndarray], batch: int = 512) -> Statistics:
    """E-step for one label over its segments (processed in batches to bound memory)."""
    states, features = model.means.shape[1], model.means.shape[2]
    stats = Statistics(0.0, 0, np.zeros(states), np.zeros((states, features)), np.zeros((states, features)),
                       np.zeros(states), np.zeros(states), np.zeros(states))
    for first in range(0, len(segments), batch):
        obs, lengths = pad_segments(segments[first : first + batch])
        loglik, occupancy, spans = forward_backward(
            obs, lengths, model.means[label], model.variances[label], model.duration_means[label], model.duration_variances[label]
        )
        stats.loglik += float(loglik.sum())
        stats.frames += int(lengths.sum())
        stats.occupancy += occupancy.sum(axis=(0, 1))
        stats.first += np.einsum("ktn,ktf->nf", occupancy, obs)
        stats.second += np.einsum("ktn,ktf->nf", occupancy, obs**2)
        size = spans.shape[1]
        span = (np.arange(size)[None, :] - np.arange(size)[:, None]).clip(0)
        for n in range(states):
            mass = np.bincount(span.ravel(), weights=spans[n].ravel(), minlength=size)
            d = np.arange(size)
            stats.duration_count[n] += mass.sum()
            stats.duration_first[n] += (mass * d).sum()
            stats.duration_second[n] += (mass * d**2).sum()
    return stats


def log_likelihood(model: HSMM, label: int, segments: list[np.ndarray], batch: int = 512) -> tuple[float, int]:
    """Total log-likelihood of the segments under one label's model, and their frame count."""
    total, frames = 0.0, 0
    for first in range(0, len(segments), batch):
        obs, lengths = pad_segments(segments[first : first + batch])
        loglik, _, _ = forward_backward(
            obs, lengths, model.means[label], model.variances[label], model.duration_means[label], model.duration_variances[label]
        )
        total += float(loglik.sum())
        frames += int(lengths.sum())
    return total, frames


def uniform_statistics(segments: list[np.ndarray], states: int) -> Statistics:
    """Statistics of a hard split of every segment into equal parts: the EM starting point."""
    features = segments[0].shape[1]
    stats = Statistics(0.0, 0, np.zeros(states), np.zeros((states, features)), np.zeros((states, features)),
                       np.zeros(states), np.zeros(states), np.zeros(states))
    for seg in segments:
        bounds = np.linspace(0, len(seg), states + 1).round().astype(int)
        for n in range(states):
            part = seg[bounds[n] : bounds[n + 1]]
            d = len(part)
            stats.occupancy[n] += d
            stats.first[n] += part.sum(axis=0)
            stats.second[n] += (part**2).sum(axis=0)
            stats.duration_count[n] += 1
            stats.duration_first[n] += d
            stats.duration_second[n] += d * d
        stats.frames += len(seg)
    return stats


@dataclass(frozen=True)
class Floors:
    variance: np.ndarray  # (features,)
    duration_variance: float = 0.5


def map_update(stats: Statistics, prior: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None,
               floors: Floors, tau: float = 0.0, tau_duration: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Means, variances, duration means and variances for one label.

    With no prior (or tau = 0) this is the maximum-likelihood M-step. With a prior (the average
    model's parameters) each state's estimate is pulled toward it with the weight of `tau` frames
    (`tau_duration` steps for durations), so a style with little data stays near the average.
    """
    if prior is None:
        tau = tau_duration = 0.0
        prior = (np.zeros_like(stats.first), np.ones_like(stats.first), np.zeros_like(stats.duration_first),
                 np.ones_like(stats.duration_first))
    p_mean, p_var, p_dmean, p_dvar = prior
    weight = (tau + stats.occupancy)[:, None]
    means = (tau * p_mean + stats.first) / weight
    variances = (tau * (p_var + p_mean**2) + stats.second) / weight - means**2
    variances = np.maximum(variances, floors.variance[None])
    dweight = tau_duration + stats.duration_count
    dmeans = (tau_duration * p_dmean + stats.duration_first) / dweight
    dvars = (tau_duration * (p_dvar + p_dmean**2) + stats.duration_second) / dweight - dmeans**2
    dvars = np.maximum(dvars, floors.duration_variance)
    return means, variances, dmeans, dvars
