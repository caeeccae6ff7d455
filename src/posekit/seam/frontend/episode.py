"""One simulated episode: the simulated cell, the particle filter over it, and its per-step record.

:func:`run_episode`:

1. the world of the episode (:func:`~posekit.seam.frontend.simulate.simulate_data`: the true robot,
   the process force, the measurements) and the trend-filtered knot polyline of the nominal seam
   (eq. 10, :func:`seam_knots`);
2. the particle filter (``cell``, ``filter``, ``profile``), timed per step, started about
   :func:`~posekit.seam.frontend.simulate.start_offset`;
3. the record (:class:`EpisodeResult`): estimates, spreads, statuses, errors in the nominal seam
   frame (:mod:`posekit.seam.frontend.seam_frame`), the truth's offset over the filter's robot
   plateau (:func:`plateau_ratio`) and optionally particles and the Fig. 5 hypotheses
   (:func:`measurement_hypotheses`).

Pooled metrics of episodes: :mod:`posekit.seam.frontend.episode_metrics`.
"""

import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from posekit.geometry import invert_transform, rotation_vector_from_matrix
from posekit.seam.engine.densities import bending_stretch
from posekit.seam.engine.filter import SeamParticleFilter
from posekit.seam.engine.particles import systematic_resample
from posekit.seam.engine.step import StepInputs
from posekit.seam.engine.trend import TrendResult, trend_filter
from posekit.seam.frontend.config import RobotConfig, SeamConfig, TrajectoryConfig, cell_from_config
from posekit.seam.frontend.seam_frame import pose_coords, seam_frame_errors
from posekit.seam.frontend.simulate import SimulatedData, simulate_data, start_offset
from posekit.seam.frontend.trajectories import nominal_trajectory

__all__ = ["EpisodeResult", "measurement_hypotheses", "plateau_ratio", "run_episode", "seam_knots"]

#: Fig. 5's seam search beyond the plateau radius (mm): the figure shows hypotheses, it weighs nothing.
_SNAPSHOT_REACH_MM = 5.0


@dataclass
class EpisodeResult:
    """One simulated episode and its estimates (see SEAM.md).

    Attributes
    ----------
    t_s : ndarray, shape (T,)
    truth, estimate, kinematic, nominal : ndarray, shape (T, 4, 4)
        True, filtered, kinematics-only (robot measurement mean) and nominal tool poses, mm.
    seam : ndarray, shape (K, 3)
        True seam polyline (base frame, mm).
    error, kinematic_error : ndarray, shape (T, 6)
        ``[x, y, z (mm), rx, ry, rz (rad)]`` of the estimate / kinematic pose against the truth
        in the nominal seam frame
        (:func:`~posekit.seam.frontend.seam_frame.seam_frame_errors`).
    spread : ndarray, shape (T, 6)
        Filter spread (1σ) ``[x, y, z (mm), rx, ry, rz (rad)]`` in the estimate's frame.
    ess : ndarray, shape (T,)
    step_ms : ndarray, shape (T,)
        Wall time of each filter step, ms.
    particles : ndarray, shape (T, P, 6) or None
        P recorded particles per step (drawn by weight), coordinates as ``truth_coords`` (mm, rad).
    truth_coords, estimate_coords : ndarray, shape (T, 6)
        Offset from the nominal pose in its frame: ``R_nomᵀ (p - p_nom)`` (mm) and the rotation
        vector of ``R_nomᵀ R`` (rad) (:func:`~posekit.seam.frontend.seam_frame.pose_coords`).
    knots_kept : int
        Vertices of the trend-filter polyline the filter searches.
    trend_max_error_mm : float
    laser_mm : ndarray, shape (T, S, 2)
        The laser measurements (NaN = missing).
    resampled : ndarray of bool, shape (T,)
    recoveries : int
        Steps at which all weights vanished (reset to uniform).
    seed : int
    config : SeamConfig
    status : ndarray of str, shape (T,)
        Per step ``tracking``, ``degraded`` or ``lost`` (:mod:`posekit.seam.engine.integrity`).
    reason : list of (str or None), length T
        Which consistency test failed at each step (None when tracking).
    plateau_ratio : ndarray, shape (T,)
        The truth's offset from the kinematic pose over the filter's robot-density plateau radius
        (:func:`plateau_ratio`; above 1: outside, the filter's model does not describe the cell).
    """

    t_s: np.ndarray
    truth: np.ndarray
    estimate: np.ndarray
    kinematic: np.ndarray
    nominal: np.ndarray
    seam: np.ndarray
    error: np.ndarray
    kinematic_error: np.ndarray
    spread: np.ndarray
    ess: np.ndarray
    step_ms: np.ndarray
    particles: np.ndarray | None
    knots_kept: int
    trend_max_error_mm: float
    truth_coords: np.ndarray
    estimate_coords: np.ndarray
    laser_mm: np.ndarray
    resampled: np.ndarray
    recoveries: int
    seed: int
    config: SeamConfig
    status: np.ndarray | None = None
    reason: list | None = None
    snapshot: dict | None = None  # Fig. 5 measurement hypotheses of one step (run_episode with record_particles)
    plateau_ratio: np.ndarray | None = None  # per step: the truth's offset over the filter's robot plateau radius


def measurement_hypotheses(Ts: np.ndarray, T_tool_sensor: np.ndarray, m_mm) -> np.ndarray:
    """Where each particle believes its sensor saw the seam (the paper's Fig. 5 hypotheses).

    Parameters
    ----------
    Ts : ndarray, shape (N, 4, 4)
        Particle tool poses ``T_base_tool``, mm.
    T_tool_sensor : ndarray, shape (4, 4)
        The sensor mount, mm (the laser plane is the sensor's x–z plane).
    m_mm : array_like, shape (2,)
        The reading ``(x, z)`` in the sensor frame, mm.

    Returns
    -------
    ndarray, shape (N, 3)
        ``m̂_i = T_i T_tool_sensor [m_x, 0, m_z, 1]`` in the base frame, mm.
    """
    m = np.array([float(m_mm[0]), 0.0, float(m_mm[1]), 1.0])
    return np.matmul(np.matmul(Ts, np.asarray(T_tool_sensor, dtype=np.float64)), m)[:, :3]


def _snapshot(pf, inc: np.ndarray, k: int, data, Tn: np.ndarray) -> dict | None:
    """Fig. 5 data at step ``k``: the cloud propagated by the nominal increment (before step k's
    update), the first available reading's hypotheses and their laser log-likelihoods."""
    from posekit.seam.engine.densities import laser_loglik

    mounts = pf.mounts
    sigma = pf.profile.sensor_sigma_mm(mounts.shape[0])
    for i in range(mounts.shape[0]):
        m = data.laser_mm[k, i]
        if not np.all(np.isfinite(m)):
            continue
        Ts = np.matmul(inc, pf.T)
        S = Tn[k] @ mounts[i]
        centre = S[:3, :3] @ np.array([m[0], 0.0, m[1]]) + S[:3, 3]
        radius = pf.profile.d0_mm + _SNAPSHOT_REACH_MM
        window = pf.seam.window(centre, S[:3, 1], radius)
        ll = laser_loglik(np.matmul(Ts, mounts[i]), m, 0.0, pf.seam, window, float(sigma[i]), radius)
        return {"step": k, "sensor": i, "hypotheses": measurement_hypotheses(Ts, mounts[i], m),
                "loglik": ll, "prior_w": pf.weights.copy(), "T_nominal": Tn[k].copy(),
                "truth_point": measurement_hypotheses(data.truth[k][None], mounts[i], m)[0],
                "sensor_origin": (data.truth[k] @ mounts[i])[:3, 3]}
    return None


@lru_cache(maxsize=16)
def _knots_cached(traj: TrajectoryConfig, robot: RobotConfig, lam: float, eps: float, extra: float) -> TrendResult:
    nt = nominal_trajectory(traj, robot, extra)
    res = trend_filter(nt.seam, lam=lam, eps_mm=eps)
    for a in (res.z, res.knots, res.polyline):
        a.setflags(write=False)
    return res


def seam_knots(cfg: SeamConfig) -> TrendResult:
    """The trend-filtered nominal seam of ``cfg`` (cached; arrays read-only)."""
    return _knots_cached(cfg.trajectory, cfg.cell.robot, cfg.filter.trend_lambda, cfg.filter.trend_eps_mm,
                         cfg.trajectory.seam_extension_mm)


def run_episode(cfg: SeamConfig, seed: int | None = None, *, record_particles: int = 0,
                data: SimulatedData | None = None) -> EpisodeResult:
    """Simulate one episode and run the particle filter over it.

    Parameters
    ----------
    cfg : SeamConfig
    seed : int, optional
        Episode seed (default ``cfg.seed``); same seed, same numbers (except ``step_ms``).
    record_particles : int
        Record this many particles per step (drawn by weight) for density plots; 0: none.
    data : SimulatedData, optional
        Reuse already simulated data (same cfg and seed).

    Returns
    -------
    EpisodeResult
    """
    seed = cfg.seed if seed is None else int(seed)
    data = simulate_data(cfg, seed) if data is None else data
    nt = data.nominal
    knots = seam_knots(cfg)
    rng = np.random.default_rng(np.random.SeedSequence([seed, 2]))
    Tn = nt.T_nominal
    n = Tn.shape[0]
    pf = SeamParticleFilter(cell_from_config(cfg.cell), cfg.filter.settings(), cfg.profile_model(), knots.polyline,
                            rng, T_init=Tn[0], T_offset=start_offset(cfg), seam_normal=nt.seam_normal)
    estimate = np.empty((n, 4, 4))
    kinematic = np.empty((n, 4, 4))
    spread = np.empty((n, 6))
    status = np.empty(n, dtype=object)  # tracking | degraded | lost (engine/integrity.py)
    reason = [None] * n
    ess = np.empty(n)
    step_ms = np.empty(n)
    resampled = np.zeros(n, bool)
    rec = int(record_particles)
    particles = np.empty((n, rec, 6)) if rec > 0 else None
    rec_rng = np.random.default_rng(np.random.SeedSequence([seed, 3]))
    snapshot = None
    # Fig. 5 step: the bend's corner, else the middle of the episode
    snap_at = (int(np.searchsorted(nt.u_mm, cfg.trajectory.bend_at * cfg.trajectory.length_mm))
               if cfg.trajectory.kind == "bend" else n // 2)
    eye = np.eye(4)
    has_lasers = data.laser_mm.shape[1] > 0
    for k in range(n):
        inc = eye if k == 0 else Tn[k] @ invert_transform(Tn[k - 1], check=False)
        inputs = StepInputs(inc, Tn[k], data.q_meas[k], data.force_meas_n[k], float(nt.t_s[k]), nt.q[k],
                            data.laser_mm[k] if has_lasers else None,
                            data.angle_rad[k] if cfg.cell.sensors.angle and has_lasers else None)
        if rec and snapshot is None and k >= snap_at:
            snapshot = _snapshot(pf, inc, k, data, Tn)
        t0 = time.perf_counter()
        est = pf.step(inputs)
        step_ms[k] = (time.perf_counter() - t0) * 1e3
        estimate[k] = est.T
        kinematic[k] = est.T_kinematic
        spread[k] = est.spread
        status[k] = est.status
        reason[k] = est.reason
        ess[k] = est.ess
        resampled[k] = est.resampled
        if rec:
            idx = systematic_resample(pf.weights, rec_rng)[:: max(1, pf.n // rec)][:rec]
            if idx.shape[0] < rec:
                idx = np.resize(idx, rec)
            particles[k] = pose_coords(pf.T[idx], Tn[k])
    truth = data.truth
    return EpisodeResult(
        t_s=nt.t_s.copy(), truth=truth, estimate=estimate, kinematic=kinematic, nominal=Tn.copy(),
        seam=nt.seam.copy(), error=seam_frame_errors(estimate, truth, Tn),
        kinematic_error=seam_frame_errors(kinematic, truth, Tn), spread=spread, ess=ess, step_ms=step_ms,
        particles=particles, knots_kept=int(knots.knots.shape[0]), trend_max_error_mm=knots.max_error_mm,
        truth_coords=pose_coords(truth, Tn), estimate_coords=pose_coords(estimate, Tn),
        laser_mm=data.laser_mm, resampled=resampled, recoveries=pf.recoveries, seed=seed, config=cfg,
        status=status.astype(str), reason=reason, snapshot=snapshot,
        plateau_ratio=plateau_ratio(cfg, truth, kinematic, data.force_meas_n),
    )


def plateau_ratio(cfg: SeamConfig, truth: np.ndarray, kinematic: np.ndarray, force_n: np.ndarray) -> np.ndarray:
    """How far the true pose lies from the kinematic pose, in radii of the filter's robot plateau.

    The paper chooses the plateau radius ``d = d0 + kd ‖f‖`` as the largest expected positioning
    error (eq. 7); a simulated cell whose truth leaves it is one the filter's model does not
    describe (a user's robot with the PUMA 560 defaults: the reported spread then misses the
    error). The plateau is the filter's: a ball of radius ``d_t`` in translation, in rotation
    ``‖A_r Δr‖ <= d_r`` with ``Δr = log(R_true R_kinᵀ)`` (base frame; the radius along the force is the
    profile's ``d0_deg``, :func:`~posekit.seam.engine.densities.robot_measurement`).

    Parameters
    ----------
    cfg : SeamConfig
    truth, kinematic : ndarray, shape (T, 4, 4)
        True poses and the robot measurement means ``Fk(q + Cj(τ))`` (mm).
    force_n : ndarray, shape (T, 3)
        The measured force per step, N (what the filter's plateau is computed from).

    Returns
    -------
    ndarray, shape (T,)
        ``max(‖Δt‖ / d_t, ‖A_r Δr‖ / d_r)`` per step (inf where a radius is 0 and the offset is not).
    """
    p = cfg.profile_model()
    force = np.asarray(force_n, dtype=np.float64)
    fn = np.linalg.norm(force, axis=1)
    d_t = p.d0_mm + p.kd_mm_per_n * fn
    d0_r = p.d0_rad
    d_r = d0_r + p.kd_rad_per_n * fn
    dt = np.linalg.norm(truth[:, :3, 3] - kinematic[:, :3, 3], axis=1)
    dr = rotation_vector_from_matrix(truth[:, :3, :3] @ np.swapaxes(kinematic[:, :3, :3], 1, 2), check=False)
    # A_r dr = dr + s (u . dr) u, u the force direction (the filter's plateau: along u the radius is d0)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = np.where(fn[:, None] > 0.0, force / fn[:, None], 0.0)
    dr = dr + (bending_stretch(d_r, d0_r) * np.einsum("ij,ij->i", u, dr))[:, None] * u
    with np.errstate(invalid="ignore", divide="ignore"):
        r_t = np.where(dt > 0.0, dt / d_t, 0.0)
        nr = np.linalg.norm(dr, axis=1)
        r_r = np.where(nr > 0.0, nr / d_r, 0.0)
    return np.maximum(r_t, r_r)
