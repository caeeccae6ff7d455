"""Seam-tracking episodes: simulate the robot, the process and the sensors; run the filter.

One episode (:func:`run_episode`):

1. the nominal program along the seam (:func:`~posekit.seam.frontend.trajectories.nominal_trajectory`)
   and its trend-filtered knot polyline (eq. 10);
2. the true robot (``simulation``): the nominal model with kinematic errors (drawn per episode); the
   motors track the joint stream ``q̄`` exactly, the process force (tool frame, slow drift +
   noise) deflects the joints (``Δq = c J_vᵀ f``) and the tool (an unmodelled Cartesian part),
   ``T_true = Fk_true(q̄ + Δq) exp(ξ_cart)``;
3. measurements: joints ``q̄ + noise + offset`` (motor side, blind to deflection), a force sensor
   (noise and bias), laser seam trackers on the true seam at the time they read it, ``laser_latency_s``
   before the sample (the true robot between samples interpolated linearly; missing without an
   intersection, beyond the range or by dropout) and optionally angles;
4. the particle filter (``cell``, ``filter``, ``profile``), timed per step.

Errors are in the nominal seam frame (DESIGN/SEAM contract): translation
``R_nomᵀ (p_est - p_true)`` in mm, rotation vector of ``R_trueᵀ R_est`` in radians (the library's
unit); :func:`metrics`, the CSV tables, the plots and the printed tables show degrees (:func:`to_degrees`).
"""

import math
import time
from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from posekit.geometry import (
    invert_transform,
    matrix_from_rotation_vector,
    rotation_vector_from_matrix,
    transform_from,
)
from posekit.robots import KinematicChain
from posekit.seam.engine.densities import bending_stretch
from posekit.seam.engine.filter import SeamParticleFilter
from posekit.seam.engine.integrity import STATUSES
from posekit.seam.engine.particles import systematic_resample
from posekit.seam.engine.seamline import SeamLine
from posekit.seam.engine.step import StepInputs
from posekit.seam.engine.trend import TrendResult, trend_filter
from posekit.seam.frontend.config import RobotConfig, SeamConfig, TrajectoryConfig, cell_from_config
from posekit.seam.frontend.trajectories import NominalTrajectory, nominal_trajectory
from posekit.verdict import status_counts

__all__ = [
    "AXES",
    "EpisodeResult",
    "SimulatedData",
    "STATUS_COLUMNS",
    "confident_wrong_fraction",
    "confident_wrong_share",
    "integrity_summary",
    "measurement_hypotheses",
    "metrics",
    "status_columns",
    "plateau_ratio",
    "pose_coords",
    "seam_frame_errors",
    "run_episode",
    "seam_knots",
    "simulate_data",
    "to_degrees",
]

AXES = ("x", "y", "z", "rx", "ry", "rz")
#: Fig. 5's seam search beyond the plateau radius (mm): the figure shows hypotheses, it weighs nothing.
_SNAPSHOT_REACH_MM = 5.0


@dataclass
class SimulatedData:
    """The simulated world of one episode (before filtering).

    Attributes
    ----------
    nominal : NominalTrajectory
    truth : ndarray, shape (T, 4, 4)
        True tool poses ``T_base_tool``, mm.
    q_meas : ndarray, shape (T, 6)
        Measured joints, rad.
    force_n : ndarray, shape (T, 3)
        True process force on the tool in the base frame, N.
    force_meas_n : ndarray, shape (T, 3)
        Force-sensor reading, base frame, N.
    laser_mm : ndarray, shape (T, S, 2)
        Laser measurements (across, along the tool axis) in mm; NaN where missing; each taken
        ``latency_s`` before its sample's time.
    angle_rad : ndarray, shape (T, S)
        Angle measurements (rad); NaN where missing or not measured.
    true_chain : KinematicChain
        The robot with kinematic errors.
    latency_s : ndarray, shape (S,)
        The true latency of each sensor (s).
    """

    nominal: NominalTrajectory
    truth: np.ndarray
    q_meas: np.ndarray
    force_n: np.ndarray
    force_meas_n: np.ndarray
    laser_mm: np.ndarray
    angle_rad: np.ndarray
    true_chain: KinematicChain
    latency_s: np.ndarray


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
        in the nominal seam frame (:func:`seam_frame_errors`).
    spread : ndarray, shape (T, 6)
        Filter spread (1σ) ``[x, y, z (mm), rx, ry, rz (rad)]`` in the estimate's frame.
    ess : ndarray, shape (T,)
    step_ms : ndarray, shape (T,)
        Wall time of each filter step, ms.
    particles : ndarray, shape (T, P, 6) or None
        P recorded particles per step (drawn by weight), coordinates as ``truth_coords`` (mm, rad).
    truth_coords, estimate_coords : ndarray, shape (T, 6)
        Offset from the nominal pose in its frame: ``R_nomᵀ (p - p_nom)`` (mm) and the rotation
        vector of ``R_nomᵀ R`` (rad) (:func:`pose_coords`).
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


def seam_frame_errors(T_est: np.ndarray, T_true: np.ndarray, T_nom: np.ndarray) -> np.ndarray:
    """Tool-pose errors in the nominal seam frame (the errors of the paper's Fig. 8; see :func:`metrics`).

    Parameters
    ----------
    T_est, T_true, T_nom : ndarray, shape (T, 4, 4)
        Estimated, true and nominal tool poses ``T_base_tool`` per step, mm.

    Returns
    -------
    ndarray, shape (T, 6)
        ``[x, y, z]`` = ``R_nomᵀ (p_est - p_true)`` in mm (x across, y along the seam, z along the
        tool axis), then ``[rx, ry, rz]`` = rotation vector of ``R_trueᵀ R_est`` in **radians**
        (the library's unit, as in :class:`EpisodeResult`; the reports show degrees).
    """
    dp = np.matmul(np.swapaxes(T_nom[:, :3, :3], 1, 2), (T_est[:, :3, 3] - T_true[:, :3, 3])[..., None])[..., 0]
    dr = rotation_vector_from_matrix(np.matmul(np.swapaxes(T_true[:, :3, :3], 1, 2), T_est[:, :3, :3]), check=False)
    return np.concatenate([dp, dr], axis=-1)


def pose_coords(Ts: np.ndarray, T_nom: np.ndarray) -> np.ndarray:
    """Offsets of poses from nominal poses, in the nominal frame (Fig. 5 coordinates).

    Parameters
    ----------
    Ts : ndarray, shape (..., 4, 4)
        Tool poses ``T_base_tool`` (particles, truth or estimate), mm.
    T_nom : ndarray, shape (..., 4, 4)
        Nominal tool poses, broadcastable against ``Ts``, mm.

    Returns
    -------
    ndarray, shape (..., 6)
        ``R_nomᵀ (p - p_nom)`` in mm, then the rotation vector of ``R_nomᵀ R`` in **radians**.
    """
    Rn_t = np.swapaxes(T_nom[..., :3, :3], -1, -2)
    dp = np.matmul(Rn_t, (Ts[..., :3, 3] - T_nom[..., :3, 3])[..., None])[..., 0]
    dr = rotation_vector_from_matrix(np.matmul(Rn_t, Ts[..., :3, :3]), check=False)
    return np.concatenate([dp, dr], axis=-1)


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


def to_degrees(a: np.ndarray) -> np.ndarray:
    """A copy of ``[mm, mm, mm, rad, rad, rad]`` rows as ``[mm, mm, mm, deg, deg, deg]`` (the report edge).

    Parameters
    ----------
    a : array_like, shape (..., 6)
        Seam-frame errors, spreads or pose coordinates in the library's units (mm, rad).

    Returns
    -------
    ndarray, shape (..., 6)
        The same values with the last three (rotations) in degrees; float64, a new array.
    """
    a = np.array(a, dtype=np.float64, copy=True)
    a[..., 3:] = np.degrees(a[..., 3:])
    return a


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


def simulate_data(cfg: SeamConfig, seed: int) -> SimulatedData:
    """Simulate the true tool poses and all measurements of one episode.

    Parameters
    ----------
    cfg : SeamConfig
        ``trajectory``, ``cell`` (robot, sensor mounts) and ``simulation`` (the world) are used.
    seed : int
        Episode seed; the same seed gives the same numbers.

    Returns
    -------
    SimulatedData
    """
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 1]))
    n = nt.q.shape[0]
    chain = nt.chain
    sim = cfg.simulation
    true_chain = chain.perturbed(sim.kinematic_error_mm, math.radians(sim.kinematic_error_deg), rng)
    # process force in the tool frame: mean, slow drift, white noise; then base frame
    phase = rng.uniform(0.0, 2.0 * np.pi)
    drift = 1.0 + sim.force_drift * np.sin(2.0 * np.pi * np.arange(n) / n + phase)
    f_T = np.asarray(sim.force_n)[None, :] * drift[:, None] + sim.force_noise_n * rng.standard_normal((n, 3))
    R_nom = nt.T_nominal[:, :3, :3]
    f_W = np.matmul(R_nom, f_T[..., None])[..., 0]
    # joint deflection through the true robot's Jacobian, Cartesian (unmodelled) deflection
    J = true_chain.geometric_jacobian(nt.q)  # (T, 6, 6)
    tau = np.matmul(np.swapaxes(J[:, :3, :], 1, 2), f_W[..., None])[..., 0]  # N·mm
    q_arm = nt.q + sim.joint_compliance_rad_per_nm * 1e-3 * tau

    def truth_at(q, f_tool):
        xi = np.zeros((q.shape[0], 6))
        xi[:, :3] = sim.cartesian_compliance_mm_per_n * f_tool
        xi[:, 3:] = math.radians(sim.cartesian_compliance_deg_per_n) * np.cross([0.0, 0.0, 1.0], f_tool)
        cartesian = transform_from(matrix_from_rotation_vector(xi[:, 3:]), xi[:, :3], check=False)
        return np.matmul(true_chain.forward_kinematics(q), cartesian)

    truth = truth_at(q_arm, f_T)
    q_meas = nt.q + math.radians(sim.joint_noise_deg) * rng.standard_normal(nt.q.shape)
    offset = np.zeros(nt.q.shape[1])
    k = min(len(sim.encoder_offset_deg), offset.size)
    offset[:k] = np.radians(sim.encoder_offset_deg[:k])
    q_meas = q_meas + offset
    force_meas = f_W + sim.force_sensor_noise_n * rng.standard_normal((n, 3))
    force_meas += np.matmul(R_nom, np.asarray(sim.force_sensor_bias_n, dtype=np.float64))
    # laser sensors on the true seam, each at the time it reads (the true robot interpolated between samples)
    sc = cfg.cell.sensors
    mounts = sc.resolved_mounts()  # T_tool_sensor (S, 4, 4)
    latency = sim.latencies_s(mounts.shape[0]) if mounts.shape[0] else np.zeros(0)
    laser = np.full((n, mounts.shape[0], 2), np.nan)
    angle = np.full((n, mounts.shape[0]), np.nan)
    seam = SeamLine(nt.seam)
    for i, M in enumerate(mounts):  # over the sensors (<= 4): the true sensor frames T_true M
        if latency[i] > 0.0:
            t_read = nt.t_s - latency[i]
            interp = lambda a: np.stack([np.interp(t_read, nt.t_s, a[:, j]) for j in range(a.shape[1])], -1)  # noqa: E731
            T_read = truth_at(interp(q_arm), interp(f_T))
        else:
            T_read = truth
        S = np.matmul(T_read, M)
        origin, R_S = S[:, :3, 3], S[:, :3, :3]
        hit = seam.intersect(origin, R_S[:, :, 1])
        e = hit.point - origin
        m = np.stack([(e * R_S[:, :, 0]).sum(1), (e * R_S[:, :, 2]).sum(1)], axis=1)
        m += sim.laser_noise_mm * rng.standard_normal((n, 2))
        ok = hit.found & (np.abs(m).max(axis=1) <= sim.laser_range_mm)
        ok &= rng.random(n) >= sim.laser_dropout
        laser[ok, i] = m[ok]
        if sc.angle:
            nu = nt.seam_normal
            R_true = T_read[:, :3, :3]
            a = np.arctan2(R_true[:, :, 0] @ nu, R_true[:, :, 2] @ nu)
            a += math.radians(sim.angle_noise_deg) * rng.standard_normal(n)
            angle[ok, i] = a[ok]
    return SimulatedData(nt, truth, q_meas, f_W, force_meas, laser, angle, true_chain, latency)


def start_offset(cfg: SeamConfig) -> np.ndarray:
    """``simulation.start_offset_*`` as a tool-frame transform (4, 4): where the first cloud is drawn about."""
    sim = cfg.simulation
    return transform_from(matrix_from_rotation_vector(np.radians(sim.start_offset_deg)),
                          np.asarray(sim.start_offset_mm, dtype=np.float64), check=False)


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


def _plateau_metrics(results: list[EpisodeResult]) -> dict:
    """``plateau_ratio_max`` and ``outside_plateau_runs`` of :func:`metrics` (none without the ratios)."""
    ratios = [r.plateau_ratio for r in results if r.plateau_ratio is not None and r.plateau_ratio.size]
    if len(ratios) < len(results):
        return {}
    peak = np.array([float(np.max(x)) for x in ratios])
    return {"plateau_ratio_max": float(round(float(peak.max()), 6)),
            "outside_plateau_runs": float(round(float(np.mean(peak > 1.0)), 6))}


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


def _rmse(errors: np.ndarray) -> np.ndarray:
    return np.sqrt(np.nanmean(errors ** 2, axis=0))


def metrics(results: list[EpisodeResult]) -> dict:
    """Pooled accuracy and speed of episodes: the ``metrics.json`` of ``posekit seam simulate``.

    Returns
    -------
    dict
        ``rmse_mm {x, y, z}``, ``rmse_deg {rx, ry, rz}``, ``kinematic_rmse_mm``,
        ``kinematic_rmse_deg``, ``step_ms_median``, ``step_ms_p95``, ``runs``, ``steps``,
        ``particles``, ``sensors``, ``sensor_distances_mm``, ``trajectory``, ``resampler``,
        ``knots_kept``, ``trend_max_error_mm``, ``recoveries``, ``laser_missing_fraction``,
        ``spread_median_mm``, ``spread_median_deg``; ``status_counts`` ``{tracking, degraded,
        lost}`` (steps over all runs), ``coverage_2sigma`` ``{x, y, z, rx, ry, rz}`` (fraction of
        steps whose absolute error <= 2 × the reported spread) and ``tracking_beyond_3sigma`` (fraction
        of the steps whose error exceeds 3 × the reported spread on some axis that are
        ``tracking``; null when there are none) and ``confident_wrong`` (the fraction of all steps
        that are ``tracking`` and beyond 3 × the spread: :func:`confident_wrong_fraction`);
        ``plateau_ratio_max`` (the largest offset of the truth from the kinematic pose in radii
        of the filter's robot plateau, :func:`plateau_ratio`) and ``outside_plateau_runs`` (the
        fraction of runs whose truth leaves the plateau at some step: the filter's ``d0``/``kd``
        do not describe the simulated robot, paper eq. 7).
    """
    if not results:
        from posekit.errors import EstimationError

        raise EstimationError("metrics: expected at least one episode result, got none")
    cfg = results[0].config
    err = to_degrees(_rmse(np.concatenate([r.error for r in results])))  # the metrics.json edge: mm, deg
    kin = to_degrees(_rmse(np.concatenate([r.kinematic_error for r in results])))
    step = np.concatenate([r.step_ms for r in results])
    spread = to_degrees(np.median(np.concatenate([r.spread for r in results]), axis=0))
    laser = np.concatenate([r.laser_mm.reshape(-1, 2) for r in results])
    cov, counts, beyond = integrity_summary(results)

    def fl(v):
        return float(round(float(v), 6))

    return {
        "rmse_mm": {a: fl(v) for a, v in zip(AXES[:3], err[:3])},
        "rmse_deg": {a: fl(v) for a, v in zip(AXES[3:], err[3:])},
        "kinematic_rmse_mm": {a: fl(v) for a, v in zip(AXES[:3], kin[:3])},
        "kinematic_rmse_deg": {a: fl(v) for a, v in zip(AXES[3:], kin[3:])},
        "step_ms_median": fl(np.median(step)),
        "step_ms_p95": fl(np.percentile(step, 95)),
        "runs": len(results),
        "steps": int(results[0].t_s.shape[0]),
        "particles": cfg.filter.particles,
        "sensors": cfg.cell.sensors.count,
        "sensor_distances_mm": list(cfg.cell.sensors.resolved_distances_mm()),
        "trajectory": cfg.trajectory.kind,
        "resampler": cfg.filter.resampler,
        "knots_kept": results[0].knots_kept,
        "trend_max_error_mm": fl(results[0].trend_max_error_mm),
        "recoveries": int(sum(r.recoveries for r in results)),
        "laser_missing_fraction": fl(np.mean(~np.isfinite(laser[:, 0]))) if laser.size else 0.0,
        "spread_median_mm": {a: fl(v) for a, v in zip(AXES[:3], spread[:3])},
        "spread_median_deg": {a: fl(v) for a, v in zip(AXES[3:], spread[3:])},
        "status_counts": counts,
        "coverage_2sigma": {a: fl(v) for a, v in zip(AXES, cov)},
        "tracking_beyond_3sigma": None if beyond is None else fl(beyond),
        "confident_wrong": fl(confident_wrong_fraction(results)),
        **_plateau_metrics(results),
    }


#: Per-step integrity columns of ``estimates.csv`` (DESIGN.md seam contract), after the existing ones.
STATUS_COLUMNS = ("status", "std_x_mm", "std_y_mm", "std_z_mm", "std_rx_deg", "std_ry_deg", "std_rz_deg")


def status_columns(result: EpisodeResult) -> dict:
    """The per-step ``status`` and the six reported spreads of one episode, by column name.

    Returns
    -------
    dict
        :data:`STATUS_COLUMNS` -> array (T,): ``status`` (str: tracking | degraded | lost) and
        ``std_x_mm .. std_rz_deg``, the filter's 1σ per axis (mm, deg) in the estimate's frame
        (the CSV edge: ``EpisodeResult.spread`` converted from rad).
    """
    n = result.t_s.shape[0]
    status = result.status if result.status is not None else np.full(n, "tracking")
    out = {"status": np.asarray(status, dtype=str)}
    for name, col in zip(STATUS_COLUMNS[1:], to_degrees(result.spread).T):
        out[name] = col
    return out


def integrity_summary(results: list[EpisodeResult]) -> tuple[np.ndarray, dict, float | None]:
    """Honesty of the reported spread and verdicts over episodes.

    Returns
    -------
    coverage : ndarray, shape (6,)
        Fraction of steps with ``|error| <= 2 × spread`` per axis (x, y, z, rx, ry, rz).
    status_counts : dict
        ``{"tracking": int, "degraded": int, "lost": int}`` over all steps.
    tracking_beyond_3sigma : float or None
        Of the steps whose error exceeds 3 × the spread on some axis, the fraction reported
        ``tracking`` (the DESIGN "Trust" failure: a confident wrong pose); None if no such step.
    """
    err, spr, status, beyond = _pooled_steps(results)
    with np.errstate(invalid="ignore"):
        coverage = np.mean(err <= 2.0 * spr, axis=0)
    counts = status_counts(np.asarray(status).tolist(), STATUSES)
    frac = float(np.mean(status[beyond] == "tracking")) if beyond.any() else None
    return coverage, counts, frac


def confident_wrong_fraction(results: list[EpisodeResult]) -> float:
    """Fraction of all steps that are ``tracking`` while the error exceeds 3 × the reported spread on
    some axis: the confident wrong poses of DESIGN.md "Trust", counted over every step (where
    :func:`integrity_summary`'s ``tracking_beyond_3sigma`` is their share of the steps beyond 3σ)."""
    _, _, status, beyond = _pooled_steps(results)
    return confident_wrong_share(beyond, status)


def confident_wrong_share(beyond: np.ndarray, status) -> float:
    """Fraction of steps ``tracking`` among ``beyond (T,)`` (error beyond 3 × the spread on some axis)
    and ``status (T,)``: :func:`confident_wrong_fraction` of one array of steps (``seam track``)."""
    return float(np.mean(np.asarray(beyond, dtype=bool) & (np.asarray(status) == "tracking")))


def _pooled_steps(results: list[EpisodeResult]):
    """Every step of the episodes: ``|error|`` and spread ``(T, 6)``, status ``(T,)`` and whether the
    error exceeds 3 × the spread on some axis ``(T,)``."""
    err = np.abs(np.concatenate([r.error for r in results]))
    spr = np.concatenate([r.spread for r in results])
    status = np.concatenate([status_columns(r)["status"] for r in results])
    with np.errstate(invalid="ignore"):
        beyond = np.any(err > 3.0 * spr, axis=1)
    return err, spr, status, beyond
