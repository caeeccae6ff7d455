"""Small builders for the seam tests: a configuration with a profile's values replaced, and the engine's three
inputs (cell, filter settings, fitted profile) from it."""

import numpy as np

from posekit.seam.engine.filter import SeamParticleFilter
from posekit.seam.frontend.config import apply_overrides, cell_from_config, config_from_dict


def config(data: dict | None = None, **overrides):
    """``config_from_dict(data)`` with dotted ``overrides`` (``**{"profile.walk.z_mm": 0.1}``)."""
    cfg = config_from_dict(data or {})
    return apply_overrides(cfg, overrides) if overrides else cfg


def make_filter(cfg, seam_polyline, seed=0, **kw) -> SeamParticleFilter:
    """The engine's particle filter of a configuration."""
    return SeamParticleFilter(cell_from_config(cfg.cell), cfg.filter.settings(), cfg.profile_model(),
                              np.asarray(seam_polyline, dtype=np.float64), seed, **kw)


def effective_samples(hits) -> np.ndarray:
    """Per column of ``hits (T, k)`` (0/1 per step, e.g. "the error is within 2σ"), the number of independent
    samples the ``T`` autocorrelated steps are worth: ``T / τ`` with ``τ = 1 + 2 Σ ρ_j`` the integrated
    autocorrelation time (the sum stops at the first lag whose ρ is not positive); a column without variation
    counts as ``T / τ_max`` with the largest τ of the others (at least 1)."""
    x = np.asarray(hits, dtype=np.float64)
    T = x.shape[0]
    taus = np.full(x.shape[1], np.nan)
    for a in range(x.shape[1]):
        c = x[:, a] - x[:, a].mean()
        v = float(c @ c)
        if v == 0.0:
            continue
        tau = 1.0
        for j in range(1, T // 2):
            rho = float(c[:-j] @ c[j:]) / v
            if rho <= 0.0:
                break
            tau += 2.0 * rho
        taus[a] = tau
    fill = np.nanmax(taus) if np.isfinite(taus).any() else 1.0
    return T / np.where(np.isfinite(taus), taus, max(fill, 1.0))


def coverage_band(n_eff, p: float, z: float = 3.0):
    """``(lo, hi)``: the band a coverage of true value ``p`` falls in with probability ≈ Φ(z) per side when
    measured on ``n_eff`` independent samples (binomial, normal approximation: ``p ± z sqrt(p (1 - p) / n)``)."""
    half = z * np.sqrt(p * (1.0 - p) / np.asarray(n_eff, dtype=np.float64))
    return p - half, p + half
