"""``posekit seam tune``: fit a cell's profile from recorded episodes (:mod:`posekit.seam.frontend.profile`).

Two ways, the same model as the particle filter's (:mod:`posekit.seam.engine.ekf`):

**From the laser innovations** (default; no reference needed). The particle filter's state-space model run as a
linearised filter gives the lasers' likelihood by its prediction-error decomposition; the walk per tool axis, the
laser noise and the latency per sensor maximise it (a coarse scan of the latency, then L-BFGS-B on the log of the
scales), and the inverse Hessian of the negative log-likelihood gives each value's 1σ. The joint noise comes from
the encoders (the white part of ``q - q̄``: its second difference has variance ``6 σ²``). The plateau, its tails and
the pose jitter are about the robot's absolute error, which the lasers do not see on every axis: they are kept
from the base profile (unless the filter's estimates leave that plateau: then it is widened to them and said so).

**From the errors** (``with_truth``; ``truth.csv``, e.g. a laser tracker). The offset of the true pose from the
modelled motion, ``δ_k = log((D_k Fk(q̄_k))⁻¹ T_true,k)`` per tool axis, is a random walk plus white jitter under the
filter's model: a local-level Kalman filter per axis gives both by maximum likelihood. Each laser's noise and
latency come from its residual at the true pose (the latency minimises the residual, its 1σ from the curvature).
The plateau is the paper's "largest expected error": the tightest ``d0 + kd ‖f‖`` above every offset of the truth
from ``Fk(q + Cj(τ))`` (the rotation plateau the bending ellipsoid), widened to the one-sided 99 % prediction bound
of the next episode's largest offset; the tails are the spread of the episodes' largest offsets, ``max_force_n``
the largest force seen.

A value the data do not pin (its 1σ above a quarter of its value; for a latency above a quarter of the sample
period; kd when the force spans less than 20 % of its largest value; one episode for the tails) keeps the base
profile's value, and the result says why. :func:`tune_profile` returns a :class:`TuneResult`; :func:`tune_report`
formats it.
"""

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
from scipy.optimize import minimize, minimize_scalar
from scipy.stats import t as student_t

from posekit.errors import ConfigError, EstimationError
from posekit.geometry import invert_transform, rotation_vector_from_matrix
from posekit.seam.engine import _kernels as _k
from posekit.seam.engine.densities import joint_compliance
from posekit.seam.engine.ekf import EpisodeArrays, LinearisedEpisode, reading_mounts
from posekit.seam.frontend.profile import (
    AXES,
    ProfileModel,
    episode_record,
    profile_data,
    profile_from_dict,
    resolve_profile,
)

__all__ = ["TuneResult", "TunedValue", "episode_arrays", "local_level_fit", "simulate_episodes", "tune_profile",
           "tune_report"]

#: A value is pinned when its 1σ is at most this fraction of the value (of the sample period for a latency).
PINNED = 1.0
#: The force must span at least this fraction of its largest value for kd to be fitted.
FORCE_SPAN = 0.2
_LAT_GRID_S = np.arange(0.0, 0.0501, 0.005)


@dataclass
class TunedValue:
    """One profile value as the tuner leaves it.

    Attributes
    ----------
    key : str
        Dotted profile key (``walk.z_mm``, ``sensors[0].latency_s``, ``plateau.d0_mm``).
    value, std : float
        In the key's unit; ``std`` None when kept from the base or not computable.
    pinned : bool
        Whether the data pin it (fitted) or the base profile's value was kept.
    note : str
        Why it was kept, or how it was fitted.
    """

    key: str
    value: float
    std: float | None
    pinned: bool
    note: str = ""


@dataclass
class TuneResult:
    """:func:`tune_profile`'s result: the profile and every value with its uncertainty and verdict."""

    profile: ProfileModel
    values: list = field(default_factory=list)
    method: str = "innovations"
    episodes: int = 0
    steps: int = 0
    nll: float | None = None

    @property
    def unpinned(self) -> list:
        """The values the data did not pin (kept from the base profile)."""
        return [v for v in self.values if not v.pinned]


# ----------------------------------------------------------------------------------------------- data


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


def tune_profile(logdirs, *, with_truth: bool = False, base=None, share_sensors: bool = False,
                 command: str = "") -> TuneResult:
    """Fit a profile from recorded episodes of one cell (see the module docstring).

    Parameters
    ----------
    logdirs : sequence of path-like
        Recorded episode folders (``setup.yaml``, ``seam.csv``, ``log.csv``, and ``truth.csv`` with
        ``with_truth``).
    with_truth : bool
        Fit from the errors against ``truth.csv`` instead of the laser innovations.
    base : ProfileModel or path, optional
        The profile whose values are kept where the data do not pin them (default: the first setup's profile,
        else the shipped default).
    share_sensors : bool
        One laser noise and one latency for every sensor (written as one sensor entry).
    command : str
        The command line, recorded in the profile.

    Returns
    -------
    TuneResult

    Raises
    ------
    ConfigError, InputFileError
        No episode, episodes of different cells, an unreadable episode; ``with_truth`` without ``truth.csv``.
    """
    from posekit.seam.frontend.logs import read_episode_log

    dirs = [Path(d) for d in logdirs]
    if not dirs:
        raise ConfigError("seam tune: expected at least one recorded episode folder, got none")
    logs = [read_episode_log(d) for d in dirs]
    _check_same_cell(logs)
    if with_truth:
        for log in logs:
            if log.truth_seam_tool is None:
                raise ConfigError(f"{log.folder}: no truth.csv; expected one per episode with --with-truth")
    base_model = resolve_profile(base, None, "--from") if base is not None else logs[0].config.profile
    S = logs[0].config.cell.sensors.count
    if not share_sensors and len(base_model.sensors) not in (1, S):
        raise ConfigError(f"base profile: {len(base_model.sensors)} sensor entries for {S} sensors")
    values: list[TunedValue] = []
    data = profile_data(base_model)
    data.pop("fitted", None)
    data.pop("notes", None)
    nS = 1 if share_sensors else S
    base_sensors = [dict(data["sensors"][min(i, len(data["sensors"]) - 1)]) for i in range(max(nS, 1))]
    data["sensors"] = base_sensors

    def put(key: str, value: float, std, pinned: bool, note: str = ""):
        values.append(TunedValue(key, float(value), None if std is None or not np.isfinite(std) else float(std),
                                 pinned, note))
        node, parts = data, key.replace("]", "").replace("[", ".").split(".")
        for p in parts[:-1]:
            node = node[int(p)] if p.isdigit() else node[p]
        if pinned:
            entry = {"value": float(value)}
            if std is not None and np.isfinite(std):
                entry["std"] = float(std)
            node[parts[-1]] = entry
        else:
            old = node[parts[-1]]
            v = old["value"] if isinstance(old, dict) else old
            node[parts[-1]] = {"value": float(v), "note": note[:300]} if note else v

    sj, sj_std = _joint_sigma(logs)
    if np.isfinite(sj) and sj > 0.0:
        put("joints.sigma_deg", math.degrees(sj), math.degrees(sj_std), True)
    else:
        put("joints.sigma_deg", 0.0, None, False, "no joint samples to estimate it from")
    work = profile_from_dict({**data, "format": "posekit-seam-profile", "version": 1}, "profile")
    if with_truth:
        nll = _fit_truth(logs, work, share_sensors, put)
    else:
        nll = _fit_innovations(logs, work, share_sensors, put)
    notes = [f"{v.key}: {v.note}" for v in values if not v.pinned and v.note]
    data["fitted"] = {"method": "truth" if with_truth else "innovations", "command": command[:2000],
                      "episodes": [episode_record(log.folder) for log in logs]}
    data["notes"] = notes[:100]
    data["format"], data["version"] = "posekit-seam-profile", 1
    model = profile_from_dict(data, "tuned profile")
    return TuneResult(model, values, "truth" if with_truth else "innovations", len(logs),
                      int(sum(len(log.time_s) for log in logs)), nll)


def _sensor_key(i: int, name: str) -> str:
    return f"sensors[{i}].{name}"


def _fit_innovations(logs, work: ProfileModel, share: bool, put) -> float:
    """Walk, laser noise and latency by the linearised filter's likelihood (see the module docstring)."""
    from posekit.seam.frontend.config import cell_from_config

    prof = work.to_model()
    cell = cell_from_config(logs[0].config.cell)
    S = cell.n_sensors
    if S == 0:
        raise ConfigError("seam tune: the episodes have no laser sensor; expected at least one to fit from")
    eps = [LinearisedEpisode(cell, prof, episode_arrays(log), _knots(log)) for log in logs]
    nS = 1 if share else S
    stamped = np.zeros(S, bool)
    for log in logs:
        if log.reading_time_s is not None:
            stamped |= np.all(np.isfinite(log.reading_time_s) | ~np.isfinite(log.laser_mm[..., 0]), axis=0)
    declared = np.array([s.latency_s is not None for s in cell.sensors])
    fit_lat = ~(stamped | declared)
    if share:
        fit_lat = np.array([fit_lat.all()])
    jitter = prof.jitter
    walk0 = np.maximum(prof.walk, 1e-6)
    sig0 = np.maximum(prof.sensor_sigma_mm(nS), 1e-4)
    lat0 = np.where(declared, [s.latency_s or 0.0 for s in cell.sensors], prof.sensor_latency_s(S))
    lat0 = lat0[:1] if share else lat0

    def expand(v):
        return np.full(S, float(v[0])) if share else np.asarray(v, dtype=np.float64)

    cache: dict = {}

    def total(walk, sig, lat, only=None):
        key = tuple(np.round(expand(lat), 9))
        if key not in cache:
            cache.clear()
            cache[key] = [e.mounts(expand(lat)) for e in eps]
        Ms = cache[key]
        out = 0.0
        for j, (e, M) in enumerate(zip(eps, Ms)):
            if only is not None and j != only:
                continue
            try:
                out += e.nll(walk, expand(sig), expand(lat), jitter, M)
            except np.linalg.LinAlgError:
                return np.inf
        return out

    nl = int(fit_lat.sum())

    def unpack(x):
        walk = np.exp(x[:6])
        sig = np.exp(x[6:6 + nS])
        lat = lat0.copy()
        lat[fit_lat] = x[6 + nS:6 + nS + nl]
        return walk, sig, lat

    bounds = [(math.log(1e-7), math.log(10.0))] * 6 + [(math.log(1e-5), math.log(10.0))] * nS + [(0.0, 0.2)] * nl
    lo_b, hi_b = np.array(bounds).T

    def f(x, only=None):
        if np.any(x < lo_b) or np.any(x > hi_b):
            return np.inf
        return total(*unpack(x), only=only)

    # 1. the latency scanned with the base walk and noise (the likelihood is not convex in it)
    lat_start = lat0.copy()
    if nl:
        scores = [total(walk0, sig0, np.where(fit_lat, L, lat0)) for L in _LAT_GRID_S]
        lat_start = np.where(fit_lat, _LAT_GRID_S[int(np.argmin(scores))], lat0)
    x0 = np.r_[np.log(walk0), np.log(sig0), lat_start[fit_lat]]
    # 2. all together (Nelder-Mead: the likelihood of a linearised filter has small steps where a reading's
    # knot window changes, which finite-difference gradients trip on)
    res = minimize(f, x0, method="Nelder-Mead",
                   options={"maxfev": 40 * x0.size, "xatol": 1e-3, "fatol": 1e-2, "adaptive": True})
    x = res.x
    # 3. 1σ per parameter: the curvature of the likelihood along it, or where the episodes disagree more than it
    # says (a misspecified model is over-confident), the spread of the episodes' own gradients over it
    std = _curvature_std(lambda xx: np.array([f(xx, only=j) for j in range(len(eps))]), x,
                         np.r_[np.full(6 + nS, 0.1), np.full(nl, 1e-3)])
    walk, sig, lat = unpack(x)
    at_bound = [abs(x[i] - lo) < 1e-3 or abs(x[i] - hi) < 1e-3 for i, (lo, hi) in enumerate(bounds)]
    h = float(np.median(np.concatenate([e.dt[1:] for e in eps]))) if eps[0].steps > 1 else 0.01
    for a, name in enumerate(AXES):
        value = walk[a] if a < 3 else math.degrees(walk[a])
        s = value * std[a]
        pinned = np.isfinite(s) and s <= PINNED * value and not at_bound[a]
        put(f"walk.{name}", value, s, pinned,
            "" if pinned else "the lasers do not pin it (flat likelihood along this axis): the base profile's")
    for i in range(nS):
        s = sig[i] * std[6 + i]
        pinned = np.isfinite(s) and s <= PINNED * sig[i]
        put(_sensor_key(i, "sigma_mm"), sig[i], s, pinned, "" if pinned else "not pinned by the data")
    j = 0
    for i in range(nS):
        if not fit_lat[i]:
            why = "given by the log's m{k}_t_s stamps" if (stamped[i] if not share else stamped.all()) else \
                "declared in setup.yaml (it applies)"
            put(_sensor_key(i, "latency_s"), float(lat[i]), None, False, why)
            continue
        s = std[6 + nS + j]
        pinned = np.isfinite(s) and s <= PINNED * h and not at_bound[6 + nS + j]
        put(_sensor_key(i, "latency_s"), float(lat[i]), s, pinned,
            "" if pinned else f"not pinned: 1σ {s * 1e3:.3g} ms (a straight seam at constant speed cannot show it)")
        j += 1
    # the plateau stays the base's unless the linearised filter's poses leave it
    _check_plateau(eps, walk, expand(sig), expand(lat), jitter, prof, put)
    for name in AXES:
        put(f"jitter.{name}", 0.0, None, False, "the lasers cannot tell it from their noise: the base profile's")
    return float(res.fun)


def _check_plateau(eps, walk, sig, lat, jitter, prof, put) -> None:
    peak_t = peak_r = 0.0
    for e in eps:
        _, T_est, _ = e.run(walk, sig, lat, jitter)
        off = np.linalg.norm(T_est[:, :3, 3] - e.K[:, :3, 3], axis=1) - e.d_t
        peak_t = max(peak_t, float(np.max(off)))
        dr = rotation_vector_from_matrix(T_est[:, :3, :3] @ np.swapaxes(e.K[:, :3, :3], 1, 2), check=False)
        peak_r = max(peak_r, float(np.max(np.linalg.norm(dr, axis=1) - e.d_r)))
    for key, over, unit, base in (("plateau.d0_mm", peak_t, 1.0, prof.d0_mm),
                                  ("plateau.d0_deg", peak_r, math.degrees(1.0), math.degrees(prof.d0_rad))):
        if over > 0.0:
            put(key, base + over * unit, None, True,
                f"the filter's poses leave the base plateau by {over * unit:.3g}: widened to them")
        else:
            put(key, base, None, False, "the lasers do not see every axis of the robot's error: the base "
                                        "profile's (fit with --with-truth to measure it)")
    for key in ("plateau.kd_mm_per_n", "plateau.kd_deg_per_n", "plateau.tail_mm", "plateau.tail_deg",
                "plateau.max_force_n"):
        put(key, 0.0, None, False, "the base profile's (fit with --with-truth to measure it)")


def _offsets(log, cell):
    """Per step: the truth's offset from the modelled motion ``(D_k Fk(q̄_k))⁻¹ T_true,k`` in the tool frame
    ``(T, 6)`` (mm, rad), from the kinematic pose ``Fk(q + Cj(τ))`` ``(T, 3)`` translation (base) and
    rotation vector ``(T, 3)`` (base), and the measured force in the base frame ``(T, 3)``."""
    from posekit.seam.engine.densities import robot_measurement

    chain = cell.chain
    arr = episode_arrays(log)
    cj = joint_compliance(cell.compliance_rad_per_nm) if cell.compliance_rad_per_nm > 0.0 else None
    Tn = chain.forward_kinematics(log.qref, check=False)
    truth = np.matmul(Tn, log.truth_seam_tool)
    n = len(log.time_s)
    X = np.empty((n, 4, 4))
    K = np.empty((n, 4, 4))
    eye = np.eye(3)
    for k in range(n):
        meas = robot_measurement(chain, log.q[k], arr.force_base_n[k], joint_sigma_rad=0.0, floor_t_mm=1.0,
                                 floor_r_rad=1.0, d0_mm=0.0, kd_mm_per_n=0.0, d0_rad=0.0, kd_rad_per_n=0.0,
                                 compliance=cj)
        K[k] = meas.T_mean
        X[k] = Tn[k] if meas.T_deflection is None else meas.T_deflection @ Tn[k]
    Xi = invert_transform(X, check=False)
    rel = np.matmul(Xi, truth)
    delta = np.hstack([rel[:, :3, 3], rotation_vector_from_matrix(rel[:, :3, :3], check=False)])
    dt_base = truth[:, :3, 3] - K[:, :3, 3]
    dr_base = rotation_vector_from_matrix(truth[:, :3, :3] @ np.swapaxes(K[:, :3, :3], 1, 2), check=False)
    del eye
    return delta, dt_base, dr_base, arr.force_base_n, truth, Tn


def _envelope(f: np.ndarray, e: np.ndarray) -> tuple[float, float]:
    """The tightest line ``d0 + kd f`` (both >= 0) above every ``(f_k, e_k)``, minimising its mean over ``f``."""
    from scipy.optimize import linprog

    res = linprog(c=[1.0, float(np.mean(f))], A_ub=np.c_[-np.ones_like(f), -f], b_ub=-e,
                  bounds=[(0.0, None), (0.0, None)], method="highs")
    if not res.success:
        return float(np.max(e)), 0.0
    return float(res.x[0]), float(res.x[1])


def _rotation_envelope(f: np.ndarray, par: np.ndarray, perp: np.ndarray, kd_fixed: float | None) -> tuple[float, float]:
    """The bending plateau ``|Δ⊥|² / (d0 + kd f)² + |Δ∥|² / d0² <= 1`` around every rotation offset, with the
    smallest ``d0 + kd f̄`` (kd given, or the least for each d0 on a scan of d0)."""
    fbar = float(np.mean(f))
    lo = max(float(np.max(par)) * (1.0 + 1e-9), 1e-9)
    hi = max(lo, float(np.max(np.hypot(par, perp)))) * 4.0 + 1e-9

    def kd_for(d0):
        room = 1.0 - (par / d0) ** 2
        need = perp / np.sqrt(np.clip(room, 1e-12, None))  # d0 + kd f >= need
        if kd_fixed is not None:
            return kd_fixed if np.all(d0 + kd_fixed * f >= need - 1e-15) else math.inf
        with np.errstate(divide="ignore", invalid="ignore"):
            k = np.where(f > 0.0, (need - d0) / f, np.where(need > d0, math.inf, 0.0))
        return max(0.0, float(np.max(k)))

    grid = np.geomspace(lo, hi, 400)
    cost = np.array([d0 + kd_for(d0) * fbar for d0 in grid])
    i = int(np.argmin(cost))
    if not np.isfinite(cost[i]):
        return float(hi), kd_fixed or 0.0
    return float(grid[i]), float(kd_for(grid[i]))


def _fit_truth(logs, work: ProfileModel, share: bool, put) -> float:
    """Walk, jitter, laser noise, latency and plateau from the errors against ``truth.csv``."""
    from posekit.seam.frontend.config import cell_from_config

    prof = work.to_model()
    cell = cell_from_config(logs[0].config.cell)
    parts = [_offsets(log, cell) for log in logs]
    dts = [np.r_[0.0, np.diff(log.time_s)] for log in logs]
    dss = [np.r_[0.0, np.linalg.norm(np.diff(p[5][:, :3, 3], axis=0), axis=1)] for p in parts]
    # 1. the jitter per tool axis: the white part of a local-level model of the offset from the modelled motion
    jitter = np.zeros(6)
    for a, name in enumerate(AXES):
        q, qs, r, rs = local_level_fit([p[0][:, a] for p in parts], dss)
        k = 1.0 if a < 3 else math.degrees(1.0)
        pin_r = bool(np.isfinite(rs) and rs <= PINNED * r)
        jitter[a] = r if pin_r else 0.0
        put(f"jitter.{name}", r * k if pin_r else 0.0, rs * k if pin_r else None, True,
            "" if pin_r else "below what the data resolve: 0")
    # 2. each laser's noise and latency from its residual at the true pose
    h = float(np.median(np.concatenate([d[1:] for d in dts])))
    sig, lat = _fit_lasers_truth(logs, cell, parts, share, h, put)
    # 3. the plateau: the largest offset of the truth from the kinematics with the compliance model
    f = np.concatenate([np.linalg.norm(p[3], axis=1) for p in parts])
    et = np.concatenate([np.linalg.norm(p[1], axis=1) for p in parts])
    dr = np.concatenate([p[2] for p in parts])
    fb = np.concatenate([p[3] for p in parts])
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(f[:, None] > 0.0, fb / f[:, None], 0.0)
    par = np.abs(np.einsum("ij,ij->i", dr, u))
    perp = np.linalg.norm(dr - par[:, None] * u * np.sign(np.einsum("ij,ij->i", dr, u))[:, None], axis=1)
    span = float(np.max(f) - np.min(f)) if f.size else 0.0
    fmax = float(np.max(f)) if f.size else 0.0
    wide = fmax > 0.0 and span >= FORCE_SPAN * fmax
    if wide:
        d0, kd = _envelope(f, et)
        d0r, kdr = _rotation_envelope(f, par, perp, None)
        put("plateau.kd_mm_per_n", kd, None, True, "the envelope of the offsets over the force")
        put("plateau.kd_deg_per_n", math.degrees(kdr), None, True, "the envelope of the offsets over the force")
    else:
        kd, kdr = prof.kd_mm_per_n, prof.kd_rad_per_n
        d0 = max(0.0, float(np.max(et - kd * f)))
        d0r, _ = _rotation_envelope(f, par, perp, kdr)
        why = f"the force spans {span:.0f} of {fmax:.0f} N (less than {FORCE_SPAN:.0%}): the base profile's"
        put("plateau.kd_mm_per_n", kd, None, False, why)
        put("plateau.kd_deg_per_n", math.degrees(kdr), None, False, why)
    if len(parts) >= 2:
        # the paper's "largest expected error" of the next episode, not only of these: each episode's largest
        # offset, and the one-sided 99 % prediction bound of a next one (mean + t s sqrt(1 + 1/n)) over the largest
        # seen widens the envelope
        pt = np.array([float(np.max(np.linalg.norm(p[1], axis=1))) for p in parts])
        pr = np.array([float(np.max(np.linalg.norm(p[2], axis=1))) for p in parts])
        n = len(parts)
        t = float(student_t.ppf(0.99, n - 1)) * math.sqrt(1.0 + 1.0 / n)
        d0 += max(0.0, float(pt.mean() + t * pt.std(ddof=1) - pt.max()))
        d0r *= max(1.0, float(pr.mean() + t * pr.std(ddof=1)) / float(pr.max()))
        why = f"the largest offset of the truth from the kinematics, to the 99 % prediction bound of {n} episodes"
    else:
        why = "the largest offset of the truth from the kinematics in the one episode"
    put("plateau.d0_mm", d0, None, True, why)
    put("plateau.d0_deg", math.degrees(d0r), None, True, why)
    put("plateau.max_force_n", fmax, None, True, "the largest force in the data")
    if len(parts) >= 2:
        tail_t, tail_r = max(float(np.std(pt, ddof=1)), 1e-6), max(float(np.std(pr, ddof=1)), 1e-9)
        put("plateau.tail_mm", tail_t, None, True, "the spread of the episodes' largest offsets")
        put("plateau.tail_deg", math.degrees(tail_r), None, True, "the spread of the episodes' largest offsets")
    else:
        tail_t, tail_r = prof.tail_mm, prof.tail_rad
        put("plateau.tail_mm", prof.tail_mm, None, False, "one episode: the base profile's")
        put("plateau.tail_deg", math.degrees(prof.tail_rad), None, False, "one episode: the base profile's")
    # 4. the walk: the one whose linearised filter reports spreads its errors against the truth bear out (the
    # log score of its posterior at the truth, per axis)
    fitted = replace(prof, jitter=jitter, laser_sigma_mm=sig, latency_s=lat, d0_mm=d0, kd_mm_per_n=kd, d0_rad=d0r,
                     kd_rad_per_n=kdr, tail_mm=tail_t, tail_rad=tail_r, max_force_n=fmax)
    return _fit_walk_truth(logs, cell, fitted, parts, put)


_WALK_BOUNDS = (math.log(1e-7), math.log(10.0))
#: The median of a χ² variable with one degree of freedom.
_CHI2_1_MEDIAN = 0.454936


def _log_score(eps, Ms, truths, prof):
    """``score(x, only=None)``: per episode ``Σ_k Σ_axis ½ (e² / v + log v)`` of the linearised filter's posterior
    at the truth for the walk ``exp(x)`` (6,) (``e`` the truth in the estimate's tangent frame, ``v`` the
    filter's variance plus the jitter²): a proper scoring rule, least when the reported variance is the error's."""
    S = Ms[0].shape[1]
    sig, lat = prof.sensor_sigma_mm(S), prof.sensor_latency_s(S)
    j2 = prof.jitter ** 2

    def score(x):
        walk = np.exp(x)
        out = np.empty(len(eps))
        for i, (e, M, Tt) in enumerate(zip(eps, Ms, truths)):
            try:
                _, T_est, P = e.run(walk, sig, lat, prof.jitter, M)
            except np.linalg.LinAlgError:
                return np.full(len(eps), np.inf)
            rel = np.matmul(invert_transform(T_est, check=False), Tt)
            err = np.hstack([rel[:, :3, 3], rotation_vector_from_matrix(rel[:, :3, :3], check=False)])
            v = P + j2
            out[i] = float(np.sum(0.5 * (err * err / v + np.log(v))))
        return np.where(np.isfinite(out), out, np.inf)

    return score


def _fit_walk_truth(logs, cell, prof, parts, put) -> float:
    """The walk per tool axis whose linearised filter reports spreads its errors against the truth bear out (the
    least log score, :func:`_log_score`); its 1σ from the score's curvature or, where the episodes disagree more,
    the spread of their own slopes (:func:`_curvature_std`). An axis along which a walk e times wider or narrower
    changes the score by less than one unit of log-likelihood does not depend on it (the robot plateau bounds
    it): not pinned."""
    eps = [LinearisedEpisode(cell, prof, episode_arrays(log), _knots(log)) for log in logs]
    lat = prof.sensor_latency_s(cell.n_sensors)
    Ms = [e.mounts(lat) for e in eps]
    score = _log_score(eps, Ms, [p[4] for p in parts], prof)

    def total(x):
        return float(np.sum(score(x)))

    res = minimize(total, np.log(np.clip(prof.walk, 1e-6, 10.0)), method="L-BFGS-B", bounds=[_WALK_BOUNDS] * 6,
                   options={"maxiter": 200, "ftol": 1e-10, "eps": 1e-4})
    x = res.x
    f0 = total(x)
    steep = np.zeros(6, bool)
    for a in range(6):
        for sgn in (-1.0, 1.0):
            xx = x.copy()
            xx[a] = np.clip(xx[a] + sgn, *_WALK_BOUNDS)
            steep[a] |= abs(total(xx) - f0) >= 1.0
    std_log = _curvature_std(score, x, np.full(6, 0.1))
    walk = np.exp(x)
    pinned = steep & np.isfinite(std_log) & (std_log <= PINNED)
    # the particle filter itself on the same episodes: its errors against the truth over its reported variance, per
    # axis; the walk of a pinned axis is scaled by that ratio (a filter's reported variance grows about linearly
    # with its walk), three times
    effective = np.where(pinned, walk, prof.walk)
    for _ in range(3):
        ratio = _particle_variance_ratio(logs, replace(prof, walk=effective))
        effective = np.where(pinned, effective * np.clip(ratio, 0.1, 100.0), effective)
    for a, name in enumerate(AXES):
        k = 1.0 if a < 3 else math.degrees(1.0)
        value, sd = effective[a] * k, effective[a] * k * std_log[a]
        why = ("the errors do not depend on it (the robot plateau bounds this axis)" if not steep[a] else
               f"1σ {walk[a] * k * std_log[a]:.3g}")
        put(f"walk.{name}", value, sd, bool(pinned[a]), "" if pinned[a] else why + ": the base profile's")
    return f0


def _particle_variance_ratio(logs, profile) -> np.ndarray:
    """``(6,)``: per axis the median over every step of the episodes of ``e² / s²`` over the median of a χ² with one
    degree of freedom (0.455: 1 for Gaussian errors of variance ``s²``, robust to the start's transient), ``e`` the
    particle filter's error against the truth in the seam frame and ``s`` its reported spread, run with
    ``profile`` (each episode's own filter settings and seed)."""
    from posekit.seam.frontend.simulate import seam_frame_errors
    from posekit.seam.frontend.tracker import SeamTracker

    z2 = []
    for log in logs:
        tr = SeamTracker(log.config, log.seam_mm, seed=log.setup.seed, seam_normal=log.setup.seam_normal)
        tr.profile = profile
        T = np.empty((len(log.time_s), 4, 4))
        nom = np.empty_like(T)
        spread = np.empty((len(log.time_s), 6))
        for k in range(len(log.time_s)):
            r = tr.step(log.time_s[k], log.qref[k], log.q[k], log.force_tool_n[k],
                        laser_mm=log.laser_mm[k] if log.laser_mm.shape[1] else None,
                        reading_time_s=None if log.reading_time_s is None else log.reading_time_s[k])
            T[k], nom[k], spread[k] = r.T_base_tool, r.T_nominal, r.spread
        err = seam_frame_errors(T, np.matmul(nom, log.truth_seam_tool), nom)
        z2.append((err / spread) ** 2)
    return np.median(np.concatenate(z2), axis=0) / _CHI2_1_MEDIAN


def _fit_lasers_truth(logs, cell, parts, share: bool, h: float, put) -> tuple[np.ndarray, np.ndarray]:
    """Each sensor's latency (least squares of its residual at the true pose) and noise (the residual's rms)."""
    from posekit.seam.engine.seamline import SeamLine

    S = cell.n_sensors
    groups = [list(range(S))] if share else [[i] for i in range(S)]
    sig_out, lat_out = np.zeros(S), np.zeros(S)
    knots = [SeamLine(_knots(log)).points for log in logs]
    arrays = [episode_arrays(log) for log in logs]

    def residuals(sensors, L):
        out = []
        for log, part, arr, pts in zip(logs, parts, arrays, knots):
            truth, Tn = part[4], part[5]
            lat = np.zeros(S)
            lat[sensors] = L
            Ms = reading_mounts(cell.chain, cell.mounts, arr.time_s, arr.q_ref, lat, arr.reading_lag_s, Tn)
            for i in sensors:
                m = log.laser_mm[:, i]
                ok = np.isfinite(m[:, 0]) & np.isfinite(m[:, 1])
                for k in np.flatnonzero(ok):
                    E = np.empty((1, 2))
                    _k.laser_error_kernel(truth[k:k + 1], float(m[k, 0]), float(m[k, 1]), Ms[k, i], pts, 0,
                                          pts.shape[0] - 1, E)
                    out.append(E[0])
        return np.array(out).reshape(-1, 2)

    for g, sensors in enumerate(groups):
        stamped = all(log.reading_time_s is not None for log in logs)
        if stamped:
            r = residuals(sensors, 0.0)
            L, Ls = 0.0, None
            put(_sensor_key(g, "latency_s"), 0.0, None, False, "given by the log's m{k}_t_s stamps")
        else:
            def sse(L):
                r = residuals(sensors, L)
                r = r[np.isfinite(r).all(axis=1)]
                return float(np.sum(r * r)) if r.size else math.inf

            grid = np.arange(0.0, 0.0501, 0.0025)
            i = int(np.argmin([sse(L) for L in grid]))
            lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, grid.size - 1)]
            L = float(minimize_scalar(sse, bounds=(lo, hi), method="bounded", options={"xatol": 1e-6}).x)
            r = residuals(sensors, L)
            r = r[np.isfinite(r).all(axis=1)]
            s2 = float(np.mean(r * r))
            dL = 5e-4
            curv = (sse(L + dL) - 2.0 * sse(L) + sse(max(L - dL, 0.0))) / dL ** 2
            Ls = math.sqrt(2.0 * s2 / curv) if curv > 0.0 else math.inf
            pinned = np.isfinite(Ls) and Ls <= PINNED * h
            put(_sensor_key(g, "latency_s"), L, Ls, pinned,
                "" if pinned else f"not pinned: 1σ {Ls * 1e3:.3g} ms")
        r = r[np.isfinite(r).all(axis=1)]
        if r.shape[0] < 10:
            raise EstimationError(f"seam tune: sensor {sensors[0] + 1} has {r.shape[0]} readings; expected at least 10")
        sigma = float(np.sqrt(np.mean(r * r)))
        put(_sensor_key(g, "sigma_mm"), sigma, sigma / math.sqrt(2.0 * r.size), True)
        put(_sensor_key(g, "angle_sigma_deg"), 0.0, None, False, "not fitted: the base profile's")
        for i in sensors:
            sig_out[i], lat_out[i] = sigma, L
    if not groups:
        raise EstimationError("seam tune: no laser sensor to fit")
    return sig_out, lat_out


def tune_report(result: TuneResult) -> str:
    """The fitted values, one line each: key, value ± 1σ, and the verdict of those the data did not pin."""
    lines = [f"seam tune: {result.episodes} episode(s), {result.steps} samples, from "
             f"{'the errors against truth.csv' if result.method == 'truth' else 'the laser innovations'}"]
    for v in result.values:
        if v.key.endswith("latency_s"):
            val = f"{v.value * 1e3:.2f} ms" + (f" ± {v.std * 1e3:.2f}" if v.std is not None else "")
        else:
            val = f"{v.value:.4g}" + (f" ± {v.std:.2g}" if v.std is not None else "")
        tag = "" if v.pinned else "   [not pinned: " + v.note + "]"
        lines.append(f"  {v.key:<26}{val:<26}{tag}")
    return "\n".join(lines)


def simulate_episodes(cfg, runs: int, seed: int, folder) -> list:
    """Simulate ``runs`` episodes of ``cfg`` (seeds of :func:`~posekit.seam.frontend.compare.episode_seeds`) and
    write each as a recorded episode with its ``truth.csv`` into ``folder/KIND-NNN``; returns the folders (the
    data ``posekit seam tune --simulate`` fits on)."""
    from posekit.seam.frontend.compare import episode_seeds
    from posekit.seam.frontend.logs import write_episode_log
    from posekit.seam.frontend.simulate import simulate_data

    folder = Path(folder)
    out = []
    for r, s in enumerate(episode_seeds(int(seed), int(runs))):
        d = folder / f"{cfg.trajectory.kind}-{r:03d}"
        d.mkdir(parents=True, exist_ok=True)
        out.append(write_episode_log(d, cfg, simulate_data(cfg, s), s))
    return out
