"""Particle-set primitives on SE(3): log-weights, effective sample size, resampling, mean.

Particles are one array ``Ts (N, 4, 4)`` of rigid transforms and one array ``logw (N,)`` of
log-weights. Resamplers share one signature ``resample(w, rng) -> indices (N,)`` and are chosen
by name from :data:`RESAMPLERS`; all work on the cumulative sum with ``np.searchsorted``
(filterpy's loops are the counter-example). Nothing here loops over particles in Python.
"""

from collections.abc import Callable
from typing import NamedTuple

import numpy as np

from posekit.errors import ConfigError
from posekit.seam.engine._cloud_kernels import mean_spread_kernel

__all__ = [
    "RESAMPLERS",
    "NormalizedWeights",
    "effective_sample_size",
    "normalize_log_weights",
    "resample",
    "residual_resample",
    "stratified_resample",
    "systematic_resample",
    "weighted_mean_se3",
]


class NormalizedWeights(NamedTuple):
    """Result of :func:`normalize_log_weights`.

    logw : ndarray, shape (N,)
        Log-weights with ``logsumexp(logw) == 0``.
    w : ndarray, shape (N,)
        The weights ``exp(logw)``, summing to 1.
    recovered : bool
        True when no weight was usable (all -inf or NaN) and the set was reset to uniform.
    """

    logw: np.ndarray
    w: np.ndarray
    recovered: bool


def normalize_log_weights(logw) -> NormalizedWeights:
    """Normalise log-weights; recover from vanishing weights instead of failing.

    NaN and ``+inf`` entries (an overflowed likelihood is not trusted) count as ``-inf``
    (weight 0). When every weight is 0, the weights are reset to uniform and ``recovered``
    is True.

    Parameters
    ----------
    logw : array_like, shape (N,)
        Unnormalised log-weights.

    Returns
    -------
    NormalizedWeights
    """
    logw = np.asarray(logw, dtype=np.float64)
    n = logw.shape[0]
    top = logw.max() if n else np.nan
    if np.isfinite(top):  # fast path: no NaN (max would be NaN), no +inf, some weight > 0
        w = np.exp(logw - top)
        total = w.sum()
        w /= total
        return NormalizedWeights(logw - (top + np.log(total)), w, False)
    logw = np.where(np.isnan(logw) | (logw == np.inf), -np.inf, logw)
    top = logw.max() if n else -np.inf
    if not np.isfinite(top):
        uniform = np.full(n, -np.log(n))
        return NormalizedWeights(uniform, np.full(n, 1.0 / n), True)
    w = np.exp(logw - top)
    total = w.sum()
    w /= total
    return NormalizedWeights(logw - top - np.log(total), w, False)


def effective_sample_size(w) -> float:
    """Effective sample size ``1 / Σ w_i²`` of normalised weights ``w (N,)``; in [1, N]."""
    w = np.asarray(w, dtype=np.float64)
    return float(1.0 / np.dot(w, w))


def _from_positions(w: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Indices ``i`` with ``cumsum[i-1] <= u < cumsum[i]`` for sorted ``positions`` in [0, 1)."""
    c = np.cumsum(w)
    c[-1] = 1.0  # guard against round-off: every position < 1 finds an index
    return np.searchsorted(c, positions, side="right")


def systematic_resample(w, rng=None, *, offset: float | None = None) -> np.ndarray:
    """Systematic resampling: one uniform offset, positions ``(offset + i) / N``.

    Parameters
    ----------
    w : array_like, shape (N,)
        Normalised weights.
    rng : numpy.random.Generator or int or None
        Source of the offset.
    offset : float in [0, 1), optional
        Use this offset instead of drawing one (for cross-checks).

    Returns
    -------
    indices : ndarray of int, shape (N,)
        Ancestor indices in [0, N), sorted.
    """
    w = np.asarray(w, dtype=np.float64)
    n = w.shape[0]
    u = np.random.default_rng(rng).random() if offset is None else float(offset)
    return _from_positions(w, (u + np.arange(n)) / n)


def stratified_resample(w, rng=None, *, uniforms=None) -> np.ndarray:
    """Stratified resampling: one uniform per stratum, positions ``(u_i + i) / N``.

    Parameters
    ----------
    w : array_like, shape (N,)
        Normalised weights.
    rng : numpy.random.Generator or int or None
        Source of the N uniforms.
    uniforms : array_like, shape (N,), optional
        Uniforms in [0, 1) that replace the draws (for cross-checks).

    Returns
    -------
    indices : ndarray of int, shape (N,)
        Ancestor indices in [0, N), sorted.
    """
    w = np.asarray(w, dtype=np.float64)
    n = w.shape[0]
    u = np.random.default_rng(rng).random(n) if uniforms is None else np.asarray(uniforms, float)
    return _from_positions(w, (u + np.arange(n)) / n)


def residual_resample(w, rng=None) -> np.ndarray:
    """Residual resampling: ``floor(N w_i)`` copies of each particle, the rest drawn
    (multinomially, by sorted uniforms) from the residual weights ``N w_i - floor(N w_i)``.

    Parameters
    ----------
    w : array_like, shape (N,)
        Normalised weights.
    rng : numpy.random.Generator or int or None
        Source of the draws for the residual part.

    Returns
    -------
    indices : ndarray of int, shape (N,)
        Ancestor indices in [0, N), the deterministic copies first.
    """
    w = np.asarray(w, dtype=np.float64)
    n = w.shape[0]
    copies = np.floor(n * w).astype(np.int64)
    fixed = np.repeat(np.arange(n), copies)
    rest = n - fixed.shape[0]
    if rest == 0:
        return fixed
    residual = n * w - copies
    residual /= residual.sum()
    u = np.sort(np.random.default_rng(rng).random(rest))
    return np.concatenate([fixed, _from_positions(residual, u)])


#: Resampling schemes by name, all ``fn(w (N,), rng) -> indices (N,)``.
RESAMPLERS: dict[str, Callable] = {
    "systematic": systematic_resample,
    "stratified": stratified_resample,
    "residual": residual_resample,
}


def resample(name: str, w, rng=None) -> np.ndarray:
    """Ancestor indices ``(N,)`` drawn by the resampler ``name`` (one of :data:`RESAMPLERS`).

    Raises
    ------
    ConfigError
        Unknown name.
    """
    try:
        fn = RESAMPLERS[name]
    except (KeyError, TypeError):
        raise ConfigError(
            f"unknown resampler {name!r}, expected one of {sorted(RESAMPLERS)}"
        ) from None
    return fn(w, rng)


def weighted_mean_se3(Ts: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean of rigid transforms and the spread around it.

    Translation: the weighted mean of the positions. Rotation: the chordal L2 mean, the
    rotation nearest (SVD projection) to ``Σ w_i R_i``; one compiled pass. Spread: weighted standard deviation
    of each particle's offset from the mean expressed in the mean's frame, translation
    ``R̄ᵀ (p_i - p̄)`` (mm) and rotation vector of ``R̄ᵀ R_i`` (rad).

    Parameters
    ----------
    Ts : ndarray, shape (N, 4, 4)
        Particle poses, e.g. ``T_base_tool``, translation in mm.
    w : ndarray, shape (N,)
        Normalised weights (sum 1).

    Returns
    -------
    T_mean : ndarray, shape (4, 4)
        Mean pose in the same frame as ``Ts``.
    spread : ndarray, shape (6,)
        ``[sx, sy, sz (mm), srx, sry, srz (rad)]`` in the mean's frame.
    """
    return mean_spread_kernel(np.ascontiguousarray(Ts, dtype=np.float64), np.ascontiguousarray(w, dtype=np.float64))
