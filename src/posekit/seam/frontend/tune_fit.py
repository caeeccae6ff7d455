"""The numerical pieces ``posekit seam tune`` shares between its two ways (:mod:`.tune`, :mod:`.tune_truth`): an
episode's arrays and knots, the joint noise from the encoders, a local-level model's maximum-likelihood fit, and
1σ from a criterion's curvature."""

import math

import numpy as np
from scipy.optimize import minimize

from posekit.errors import ConfigError
from posekit.seam.engine import _kernels as _k
from posekit.seam.engine.ekf import EpisodeArrays

__all__ = ["FORCE_SPAN", "PINNED", "episode_arrays", "local_level_fit"]

#: A value is pinned when its 1σ is at most this fraction of the value (of the sample period for a latency).
PINNED = 1.0
#: The force must span at least this fraction of its largest value for kd to be fitted.
FORCE_SPAN = 0.2
_LAT_GRID_S = np.arange(0.0, 0.0501, 0.005)


def episode_arrays(log) -> EpisodeArrays:
    """An :class:`~posekit.seam.engine.ekf.EpisodeArrays` of a recorded episode (the force turned into the base
    frame by the measured pose, as :class:`~posekit.seam.frontend.tracker.SeamTracker` does)."""
    from posekit.seam.frontend.config import cell_from_config

    chain = cell_from_config(log.config.cell).chain
    R = chain.forward_kinematics(log.q, check=False)[:, :3, :3]
    f = np.einsum("tij,tj->ti", R, log.force_tool_n)
    lag = None if log.reading_time_s is None else log.time_s[:, None] - log.reading_time_s
    return EpisodeArrays(log.time_s, log.qref, log.q, f, log.laser_mm, lag)


def _check_same_cell(logs) -> None:
    first = logs[0]
    m0 = first.config.cell.sensors.resolved_mounts()
    for log in logs[1:]:
        c = log.config.cell
        m = c.sensors.resolved_mounts()
        same = (c.robot.label == first.config.cell.robot.label and m.shape == m0.shape and np.allclose(m, m0)
                and np.allclose(c.robot.tool_matrix(), first.config.cell.robot.tool_matrix())
                and c.compliance_rad_per_nm == first.config.cell.compliance_rad_per_nm)
        if not same:
            raise ConfigError(f"{log.folder}: another cell than {first.folder} (robot, tool, sensor mounts or "
                              "compliance differ); expected episodes of one cell")


def _knots(log) -> np.ndarray:
    from posekit.seam.engine.trend import trend_filter

    f = log.config.filter
    return trend_filter(log.seam_mm, lam=f.trend_lambda, eps_mm=f.trend_eps_mm).polyline


def _joint_sigma(logs) -> tuple[float, float]:
    """Encoder noise (rad) and its 1σ: the second difference of ``q - q̄`` has variance ``6 σ²`` for white noise
    (the program and the servo's smooth lag cancel)."""
    d2 = np.concatenate([np.diff(log.q - log.qref, n=2, axis=0)[~log.interpolated[2:]].ravel() for log in logs])
    d2 = d2[np.isfinite(d2)]
    if d2.size < 10:
        return math.nan, math.nan
    s = math.sqrt(float(np.mean(d2 * d2)) / 6.0)
    return s, s / math.sqrt(2.0 * d2.size / 3.0)  # second differences overlap: ~N/3 independent


# ----------------------------------------------------------------------------------------------- helpers


def _hessian_std(f, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """1σ of each parameter from the inverse of ``f``'s Hessian at ``x`` (central differences); inf where the
    Hessian is not positive there."""
    n = x.size
    H = np.empty((n, n))
    f0 = f(x)
    for i in range(n):
        ei = np.zeros(n)
        ei[i] = steps[i]
        fp, fm = f(x + ei), f(x - ei)
        H[i, i] = (fp - 2.0 * f0 + fm) / steps[i] ** 2
        for j in range(i):
            ej = np.zeros(n)
            ej[j] = steps[j]
            H[i, j] = H[j, i] = (f(x + ei + ej) - f(x + ei - ej) - f(x - ei + ej) + f(x - ei - ej)) / (
                4.0 * steps[i] * steps[j])
    out = np.full(n, np.inf)
    if not np.isfinite(H).all():
        return out
    lam, V = np.linalg.eigh(0.5 * (H + H.T))
    ok = lam > 1e-12 * max(1.0, float(np.abs(lam).max()))
    cov = (V[:, ok] / lam[ok]) @ V[:, ok].T
    var = np.diag(cov).copy()
    # a direction the likelihood does not curve along leaves its parameters unpinned
    flat = np.abs(V[:, ~ok]).max(axis=1) > 0.1 if (~ok).any() else np.zeros(n, bool)
    out = np.where(flat | (var <= 0.0), np.inf, np.sqrt(np.clip(var, 0.0, None)))
    return out


def _curvature_std(fe, x: np.ndarray, steps: np.ndarray) -> np.ndarray:
    """Per parameter, ``max(1 / √c, √(Σ_e g_e²) / c)``: ``c`` the curvature of ``Σ_e fe(x)_e`` along it and ``g_e``
    each episode's slope (central differences of ``steps``); inf where it does not curve upwards."""
    f0 = fe(x).sum()
    out = np.full(x.size, np.inf)
    for i in range(x.size):
        d = np.zeros(x.size)
        d[i] = steps[i]
        fp, fm = fe(x + d), fe(x - d)
        c = (fp.sum() - 2.0 * f0 + fm.sum()) / steps[i] ** 2
        if not (np.isfinite(c) and c > 0.0):
            continue
        g = (fp - fm) / (2.0 * steps[i])
        out[i] = max(1.0 / math.sqrt(c), math.sqrt(float(np.sum(g * g))) / c) if np.isfinite(g).all() else np.inf
    return out


def local_level_fit(series: list, dss: list) -> tuple[float, float, float, float]:
    """Maximum-likelihood random walk and white noise of a scalar offset: ``y_k = s_k + r ε_k``,
    ``s_{k+1} = s_k + q √ds η_k`` (a local-level Kalman filter, every series its own start).

    Parameters
    ----------
    series : list of ndarray, shape (T_i,)
        The offsets (one per episode).
    dss : list of ndarray, shape (T_i,)
        The travel of the step before each sample (mm; the first ignored).

    Returns
    -------
    q, q_std, r, r_std : float
        ``q`` per √mm and ``r`` per sample, with their 1σ (inf when not curved).
    """
    ys = [np.ascontiguousarray(y, dtype=np.float64) for y in series]
    ds = [np.ascontiguousarray(d, dtype=np.float64) for d in dss]
    scale = max(float(np.std(np.concatenate([np.diff(y) for y in ys]))), 1e-12)

    def nll(x):
        q2, r2 = math.exp(2.0 * x[0]), math.exp(2.0 * x[1])
        return sum(_k.local_level_nll(y, d, q2, r2) for y, d in zip(ys, ds))

    x0 = np.log([scale / math.sqrt(max(float(np.mean(ds[0][1:])), 1e-6)), scale])
    best = min((minimize(nll, x0 + np.array([a, b]), method="Nelder-Mead",
                         options={"xatol": 1e-4, "fatol": 1e-6, "maxiter": 2000}) for a, b in ((0, 0), (-2, 0), (0, -2))),
               key=lambda r: r.fun)
    x = best.x
    std = _hessian_std(nll, x, np.array([1e-3, 1e-3]))
    q, r = math.exp(x[0]), math.exp(x[1])
    return q, q * std[0], r, r * std[1]


# ----------------------------------------------------------------------------------------------- tuning


def _sensor_key(i: int, name: str) -> str:
    return f"sensors[{i}].{name}"
