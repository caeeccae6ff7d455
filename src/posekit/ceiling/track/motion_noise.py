"""What a track's own accepted measurements say about its noise and its motion (one
:class:`~posekit.ceiling.track.types.DotState` each): the scale of the measurement noise and the
density of the white acceleration that drives the constant-velocity model (its process noise)."""

import numpy as np

from .types import DotState

__all__ = ["record_measurement", "fitted_accel_psd", "extra_psd"]


def record_measurement(st: DotState, t_s: float, z: np.ndarray, R: np.ndarray, adapt_noise: bool = True) -> None:
    """Add an accepted measurement ``z`` (2,) mm at ``t_s`` to the track's statistics
    (``st.noise_stats``) and, with ``adapt_noise``, update ``st.noise_scale``.

    The scale comes from the jitter of the accepted measurements themselves: for three
    consecutive, evenly spaced ones the second difference ``z₀ - 2 z₁ + z₂`` has covariance
    ``6 σ² I`` (plus the motion's, which only errs on the safe side), so
    ``σ² ≈ median |Δ²z|² / (6 · 2 ln 2)`` over the last 25; ``scale = σ² / (tr R / 2)``, at
    least 1. Unlike innovation statistics it does not depend on the process noise, which
    dominates the prediction at 15 frames/s. The sums of the squared second differences at lags
    1 and 2 over the whole track feed :func:`fitted_accel_psd`.
    """
    hist = st.noise_stats
    if hist is None:
        hist = st.noise_stats = {"z": [], "d2": [], "sum1": 0.0, "n1": 0, "sum2": 0.0, "n2": 0, "sum_dt3": 0.0}
    zs = hist["z"]
    if zs:
        gap = t_s - zs[-1][0]
        prev = zs[-1][0] - zs[-2][0] if len(zs) > 1 else gap
        if not 0 < gap <= 1.5 * prev:            # not consecutive frames: start again
            zs.clear()
    zs.append((t_s, np.array(z, dtype=float)))
    if len(zs) >= 3:
        (t0, z0), (t1, z1), (t2, z2) = zs[-3:]
        if abs((t2 - t1) - (t1 - t0)) <= 0.2 * (t1 - t0):
            dd = z0 - 2.0 * z1 + z2
            hist["d2"].append(float(dd @ dd))
            del hist["d2"][:-25]
            hist["sum1"] += float(dd @ dd)            # the whole track's: its manoeuvres
            hist["sum_dt3"] += (0.5 * (t2 - t0)) ** 3
            hist["n1"] += 1
            if len(zs) == 5:                          # lag 2 (five evenly spaced measurements)
                (ta, za), (tb, zb), (tc, zc) = zs[0], zs[2], zs[4]
                if abs((tc - tb) - (tb - ta)) <= 0.2 * (tb - ta):
                    dd2 = za - 2.0 * zb + zc
                    hist["sum2"] += float(dd2 @ dd2)
                    hist["n2"] += 1
        else:
            zs[:] = zs[-1:]
        del zs[:-4]
    if len(hist["d2"]) >= 8:
        var = float(np.median(hist["d2"])) / (6.0 * 2.0 * np.log(2.0))
        hist["noise_var"] = var
        if adapt_noise:
            trR = float(R[0, 0] + R[1, 1]) / st.noise_scale
            st.noise_scale = float(np.clip(var / max(trR / 2.0, 1e-12), 1.0, 400.0))


def fitted_accel_psd(st: DotState) -> float:
    """The spectral density q̂ (mm²/s³ per axis) of the white acceleration noise that the track's
    own accepted measurements show, NaN until 8 second differences of each lag are in.

    For measurements Δt apart, the second difference at lag L, ``z(t - LΔt) - 2 z(t) + z(t +
    LΔt)``, of a constant-velocity motion driven by white acceleration of density q, measured
    with independent noise σ per axis, has ``E|Δ²z|² = 2 · ⅔ q (LΔt)³ + 12 σ²``. The means of
    lags 1 and 2 over the whole track (its manoeuvres: starts, stops, turns) give both:
    ``q̂ = 3 (m₂ - m₁) / (28 Δt³)``, at least 0.
    """
    h = st.noise_stats
    if not h or min(h.get("n1", 0), h.get("n2", 0)) < 8:
        return float("nan")
    m1, m2 = h["sum1"] / h["n1"], h["sum2"] / h["n2"]
    dt3 = h["sum_dt3"] / h["n1"]
    return max(3.0 * (m2 - m1) / (28.0 * dt3), 0.0)


def extra_psd(st: DotState, q: float) -> float:
    """``max(q̂ - q, 0)``: the process noise the track's data add to the filter's ``q``."""
    qh = fitted_accel_psd(st)
    return max(qh - q, 0.0) if np.isfinite(qh) else 0.0
