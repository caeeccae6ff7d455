"""The particle filter on SE(3) for the tool pose relative to the seam (paper Algorithm 1).

One step: propagate every particle with the nominal increment, moved by the change of the deflection
the compliance model predicts from the measured force (``filter.compliance_rad_per_nm``:
``D_k T+ D_{k-1}⁻¹``, ``D = Fk(q + Cj(τ)) Fk(q)⁻¹``), and force-dependent noise (eq. 3); weight
with the robot measurement (eq. 5, 8) and each available laser (and angle) measurement (eq. 9);
normalise the log-weights (recovering from vanishing weights); estimate the weighted mean on SE(3)
and its spread; resample by name when the effective sample size falls below ``ess_threshold · N``.

When one update would leave fewer than ``anneal_ess · N`` effective particles (the laser
likelihood is far narrower than the cloud: at start-up, at a seam feature), the likelihood
is applied in tempered stages ``ℓ^β₁ ℓ^β₂ ...`` (β chosen for an ESS of N/2), each followed by
a kernel resampling step that moves the copies by Gaussian noise of ``anneal_jitter²`` times
the cloud's 6-D covariance (with its correlations); at most ``anneal_stages`` stages. Without
it the cloud collapses onto the one particle nearest the truth and the small transition noise
cannot move it for hundreds of steps.

The first step draws the cloud from the robot density itself (``init_from_robot``: the plateau of
radius ``d(f)`` and its tails around the kinematic pose, the paper's "prior distribution": before
any laser reading the tool is anywhere the robot can be). The transition width follows the force
rate (``transition_force: rate``, paper eq. 3 ``p(x+ | x, ḟ)``: ``σ = σ0 + k_rate ‖Δf̃‖`` with
``f̃`` the force low-passed over ``force_rate_smoothing`` steps) or its magnitude
(``magnitude``), plus the step's travel ``s``: ``s (k_travel + k_load_travel ‖f‖)`` (the robot's
error and its deflection under load change with the configuration), all times
``reacquire_transition_scale`` after a step that was not ``tracking`` (the data contradicted the
model: a wider walk lets the cloud re-acquire; issue 15, a start 8 mm / 3° off, 10 runs: 117
steps ``lost`` instead of 412 without the widening). The unloaded part of the width and the load's
part are scaled per tool axis (``axis_scale_*``, ``load_axis_scale_*``: the pose error drifts
unlike on each axis), except for ``reacquire_isotropic_steps`` after a ``lost`` step; the whole
width is multiplied by an adaptive gain (``walk_adapt_*``: covariance matching, the lasers' NIS
averaged over steps steers it within 1 .. ``walk_adapt_max``; it is kept, not updated, while the
track is not ``tracking``). Until the first laser reading the estimate is the kinematic pose (the
centre of the symmetric robot density). Every step carries a ``status``
(``tracking``/``degraded``/``lost``) from :mod:`posekit.seam.engine.integrity`.

The reported spread is at least the one the data support (``spread_bound``,
:mod:`posekit.seam.engine.spread_bound`: a Kalman covariance from the lasers' Jacobian at the
estimate, capped at the robot plateau, reset when the track is lost); the integrity test uses
the cloud's own spread. The bound weighs each laser reading with the true σ (``bound_inflation`` 0, the
default), and for ``bound_reacquire_steps`` after a ``lost`` step with the variance the particles use
(``bound_inflation_reacquire``), while the reported spread shrinks by at most ``spread_shrink_reacquire`` per
step: a cloud rebuilt from few survivors may be off in directions the lasers have not seen again, and the bound
at the true σ contracted faster than that estimate follows when a seam corner brought the information (issue
15: after a wrong start, the tails tracking 3-4σ off were such steps, 200-480 steps after the loss). A run that
never lost the track keeps the bound at the true σ and reports ``max(cloud, bound)`` scaled per axis by the bound's
``ratio`` (the error of a walk wider than the drift, ``bound_drift_share``; the bound also carries the particles' own
noise, ``bound_particle_noise``: :mod:`posekit.seam.engine.spread_bound`). The cloud itself is
kept at least ``cloud_floor`` times the bound's covariance (:func:`floor_factor`: Gaussian noise of
covariance ``(c P - Σ_cloud)+`` in the tangent space at its mean, added in the resampling move,
nothing where the cloud is wider): a cloud
narrower than what the data support cannot move where new information puts the pose (25 kN, seed
5: the rx/ry cloud fell to 0.36 of the bound and the estimate stayed 3σ off for ~100 steps). The
seam is searched at least as far as the robot density reaches (plateau + 3 tails + the rotation
plateau times the sensor's lever; ``search_window_mm`` is the minimum): under 25 kN the tool is
10 mm off the seam.

The laser likelihood (eq. 9) is evaluated with the variance ``σ² + min(c Var_w(e), 3σ²)`` per sensor
(``c`` = 0.5, ``Var_w(e)`` the spread of the particles' in-plane errors under the predicted cloud): a
cloud of a few hundred particles, each standing for a kernel of the regularised resampling, cannot
represent a likelihood as narrow as the laser noise (the update degenerates, tempering jitters the
cloud along the seam); the measurement model itself (integrity test, spread bound) keeps ``σ``.

Resampling is regularised (``regularize_h``, Liu & West's kernel with shrinkage): the copies
are drawn from a Gaussian kernel density of the weighted cloud that keeps its mean and
covariance. The lasers leave directions free (along the seam, the rotation about it; on the
steep yz seam that rotation is mostly the yaw); plain resampling lets copies of a few
ancestors take over there, and the cloud shrinks and wanders inside the robot plateau.
"""

import math
from dataclasses import dataclass

import numpy as np

from posekit.errors import ConfigError
from posekit.geometry import invert_transform, matrix_from_rotation_vector, transform_from
from posekit.seam.engine import _kernels as _k
from posekit.seam.engine.densities import (
    angle_loglik,
    joint_compliance,
    robot_loglik,
    robot_measurement,
    transition,
)
from posekit.seam.engine.integrity import IntegrityMonitor, innovation_nis, robot_consistency
from posekit.seam.engine.particles import (
    RESAMPLERS,
    effective_sample_size,
    normalize_log_weights,
    weighted_mean_se3,
)
from posekit.seam.engine.seamline import SeamLine
from posekit.seam.engine.spread_bound import InformationBound
from posekit.seam.frontend.config import SeamConfig
from posekit.seam.frontend.trajectories import tool_chain

# The laser likelihood's variance per sensor is ``σ² + min(c · Var_w(e), cap · σ²)``: ``Var_w(e)`` the
# spread of the particles' in-plane errors under the predicted cloud (weighted by the robot density),
# ``c = filter.laser_inflation`` (0.5, about the resampling kernel's h² = 0.25, doubled: measured best), the added
# variance capped at ``filter.laser_inflation_cap · σ²`` (3: σ_eff <= 2σ: under 25 kN the predicted cloud is wide and an
# uncapped inflation discounts the lasers). Issue 15, ``posekit seam simulate --runs 10 --seed 0``: xy RMSE
# x/y 0.082/0.084 -> 0.063/0.062 mm, rx/ry 0.162/0.198 -> 0.153/0.191 deg; yz y/z 0.23/0.80 -> 0.10/0.27 mm.

__all__ = ["SeamParticleFilter", "StepEstimate", "StepInputs", "floor_factor"]


@dataclass
class StepInputs:
    """Everything the filter reads at one time step.

    Attributes
    ----------
    T_increment : ndarray, shape (4, 4)
        Nominal increment ``Fk(q̄+) Fk(q̄)^-1`` (base frame, mm); identity at the first step.
    T_nominal : ndarray, shape (4, 4)
        Nominal tool pose ``Fk(q̄+)`` (centres the laser seam search), mm.
    q_meas : ndarray, shape (n,)
        Measured joints, rad.
    force_n : ndarray, shape (3,)
        Measured process force on the tool in the base frame, N.
    laser_mm : ndarray, shape (S, 2), optional
        Laser measurements (across, along the tool axis) in mm, one row per sensor, NaN rows
        where a sensor has no measurement.
    angle_rad : ndarray, shape (S,), optional
        Angle measurements (rad), NaN where missing.
    """

    T_increment: np.ndarray
    T_nominal: np.ndarray
    q_meas: np.ndarray
    force_n: np.ndarray
    laser_mm: np.ndarray | None = None
    angle_rad: np.ndarray | None = None


def floor_factor(P: np.ndarray, L: np.ndarray) -> np.ndarray | None:
    """A factor ``B (6, 6)``, ``B Bᵀ = (P - L Lᵀ)+``, of what a cloud of covariance ``L Lᵀ`` lacks to cover ``P``.

    Parameters
    ----------
    P : ndarray, shape (6, 6)
        The covariance to cover (tool-frame tangent space: mm², rad²).
    L : ndarray, shape (6, 6)
        Cholesky factor of the cloud's weighted covariance (same space).

    Returns
    -------
    ndarray, shape (6, 6), or None
        ``V diag(√λ+)`` from the eigen-decomposition of ``P - L Lᵀ`` (its negative part dropped: the
        cloud keeps what it has where it is wider); None when nothing is missing or ``P`` is not finite.
    """
    if not np.isfinite(P).all():
        return None
    lam, V = np.linalg.eigh(P - L @ L.T)
    if not lam.max() > 0.0:
        return None
    return V * np.sqrt(np.clip(lam, 0.0, None))[None, :]


@dataclass
class StepEstimate:
    """Output of one filter step.

    Attributes
    ----------
    T : ndarray, shape (4, 4)
        Weighted mean tool pose ``T_base_tool`` (mm).
    spread : ndarray, shape (6,)
        Reported standard deviation around the mean in its frame: x, y, z (mm), rx, ry, rz (rad):
        the cloud's weighted standard deviation, at least the spread bound's
        (``filter.spread_bound``; :mod:`posekit.seam.engine.spread_bound`).
    ess : float
        Effective sample size after the measurement update, in [1, N].
    resampled : bool
        Whether the particles were resampled at this step.
    recovered : bool
        Whether all weights vanished and were reset to uniform at this step.
    T_kinematic : ndarray, shape (4, 4)
        The robot measurement mean ``Fk(q + Cj(τ))`` (kinematics-only pose), mm.
    lasers_used : int
        Number of laser measurements used.
    anneal_stages : int
        Tempering stages used at this step (0 when the update was not degenerate).
    status : str
        ``tracking``, ``degraded`` or ``lost`` (:mod:`posekit.seam.engine.integrity`).
    reason : str or None
        Which consistency test failed (None when tracking).
    nis : float
        Normalised innovation squared of this step's laser readings (0 without readings).
    ess_update : float
        ESS of the measurement update before tempering, in [1, N].
    """

    T: np.ndarray
    spread: np.ndarray
    ess: float
    resampled: bool
    recovered: bool
    T_kinematic: np.ndarray
    lasers_used: int
    anneal_stages: int = 0
    status: str = "tracking"
    reason: str | None = None
    nis: float = 0.0
    ess_update: float = math.nan


class SeamParticleFilter:
    """Particle filter for the 6-DoF tool pose ``T_base_tool``.

    Parameters
    ----------
    cfg : SeamConfig
        ``filter`` (densities, particles, resampling), ``sensors`` (distances, angle) and
        ``robot`` (model, tool) sections are used.
    seam_polyline : array_like, shape (K, 3)
        Nominal seam polyline in the base frame (the trend-filter knots), mm.
    rng : numpy.random.Generator or int or None
    T_init : array_like, shape (4, 4), optional
        Centre of the initial particle cloud (spread ``init_sigma_t_mm``,
        ``init_sigma_r_deg`` in the tool frame); call :meth:`reset` otherwise.
    seam_normal : array_like, shape (3,), optional
        Workpiece surface normal (base frame) for the angle measurement.
    compliance : callable ``Cj(q (n,), τ (n,) N·mm) -> Δq (n,) rad``, optional
        Compliance model hook of eq. (5); default: ``filter.compliance_rad_per_nm`` as a
        diagonal model (none when 0).
    sensor_mounts : array_like, shape (S, 4, 4), optional
        ``T_tool_sensor`` of each laser sensor (mm; the laser plane is the sensor's x–z plane);
        default: ``cfg.sensors`` (its mounts, or ``distances_mm`` ahead along tool y).

    Attributes
    ----------
    T : ndarray, shape (N, 4, 4)
        The particles.
    logw : ndarray, shape (N,)
        Normalised log-weights.
    recoveries : int
        How many times vanishing weights were reset to uniform.
    resamplings : int
        How many times the particles were resampled.
    annealings : int
        Tempering stages used so far (see :meth:`step`).
    """

    def __init__(self, cfg: SeamConfig, seam_polyline, rng=None, *, T_init=None, seam_normal=None,
                 compliance=None, sensor_mounts=None):
        f = cfg.filter
        if f.resampler not in RESAMPLERS:
            raise ConfigError(f"filter.resampler: expected one of {sorted(RESAMPLERS)}, got {f.resampler!r}")
        self.cfg = cfg
        self.rng = np.random.default_rng(rng)
        self.seam = SeamLine(seam_polyline)
        self.chain = tool_chain(cfg.robot)
        self.distances_mm = np.array(cfg.sensors.resolved_distances_mm(), dtype=np.float64)
        if sensor_mounts is None:
            if hasattr(cfg.sensors, "resolved_mounts"):
                sensor_mounts = cfg.sensors.resolved_mounts()
            else:
                sensor_mounts = np.repeat(np.eye(4)[None], self.distances_mm.size, axis=0)
                sensor_mounts[:, 1, 3] = self.distances_mm
        # T_tool_sensor per sensor: where the sensor pose enters the laser density (_kernels._plane_error)
        self.sensor_mounts = np.ascontiguousarray(np.asarray(sensor_mounts, dtype=np.float64).reshape(-1, 4, 4))
        self.mounts = self.sensor_mounts  # alias (front end)
        self._lever = np.linalg.norm(self.sensor_mounts[:, :3, 3], axis=1)  # mm, tool centre to sensor
        self.seam_normal = (np.array([0.0, 0.0, -1.0]) if seam_normal is None
                            else np.asarray(seam_normal, dtype=np.float64))
        if compliance is None and f.compliance_rad_per_nm > 0.0:
            compliance = joint_compliance(f.compliance_rad_per_nm)
        self.compliance = compliance
        self._resample = RESAMPLERS[f.resampler]
        deg = math.pi / 180.0
        self._sigma_r = f.sigma_r_deg * deg
        self._k_force_r = f.k_force_r * deg
        self._k_rate_r = getattr(f, "k_rate_r_deg_per_n", 0.0) * deg
        self._rate = getattr(f, "transition_force", "magnitude") == "rate"
        self._axis_t = np.asarray(f.axis_scale_t, dtype=np.float64)
        self._axis_r = np.asarray(f.axis_scale_r, dtype=np.float64)
        self._load_axis_t = np.asarray(f.load_axis_scale_t, dtype=np.float64)
        self._load_axis_r = np.asarray(f.load_axis_scale_r, dtype=np.float64)
        self._prev_force = None
        self._prev_deflection = None
        self._lasers_seen = 0
        self._last_status = "tracking"
        self._walk_gain = 1.0  # the walk's adaptive factor (filter.walk_adapt_rate)
        self._prev_spread = None
        self._nis_avg = 1.0  # the NIS per degree of freedom, averaged over walk_adapt_window steps
        self.integrity = IntegrityMonitor(f.particles, getattr(f, "integrity_window", 10),
                                          getattr(f, "integrity_alpha_degraded", 1e-3),
                                          getattr(f, "integrity_alpha_lost", 1e-7),
                                          getattr(f, "integrity_ess_min", 0.002),
                                          getattr(f, "integrity_recovery", 0), f.plateau_max_force_n)
        self._robot_kw = {
            "joint_sigma_rad": f.joint_sigma_deg * deg, "floor_t_mm": f.robot_floor_t_mm,
            "floor_r_rad": f.robot_floor_r_deg * deg, "d0_mm": f.d0_mm, "kd_mm_per_n": f.kd_mm_per_n,
            "d0_rad": f.d0_deg * deg, "kd_rad_per_n": f.kd_deg_per_n * deg, "bending": f.bending_plateau,
        }
        self._angle_sigma = cfg.sensors.angle and f.angle_sigma_deg * deg
        # the spread the data support (engine/spread_bound.py): reported where the cloud is narrower
        q_bound = float(getattr(f, "spread_bound", 0.0))
        self._bound = InformationBound(f.laser_sigma_mm, q_bound) if q_bound > 0.0 else None
        self._readings: list = []
        self._reading_sensor: list = []
        self._sig_eff: dict = {}
        self.n = f.particles
        self.recoveries = 0
        self.resamplings = 0
        self.annealings = 0
        self.T = np.repeat(np.eye(4)[None], self.n, axis=0)
        self._noise = np.empty((self.n, 6), np.float32)
        self.logw = np.full(self.n, -math.log(self.n))
        if T_init is not None:
            self.reset(T_init)

    def reset(self, T_center) -> None:
        """Draw the particles around ``T_center`` (4, 4) with the initial spread; uniform weights.

        The cloud's centre is ``T_center`` moved by ``filter.init_offset_mm`` / ``init_offset_deg``
        (tool frame; zero by default). The integrity window and the force history are cleared."""
        f = self.cfg.filter
        off_t = np.asarray(getattr(f, "init_offset_mm", (0.0, 0.0, 0.0)), dtype=np.float64)
        off_r = np.radians(np.asarray(getattr(f, "init_offset_deg", (0.0, 0.0, 0.0)), dtype=np.float64))
        T_center = np.asarray(T_center, dtype=np.float64)
        if off_t.any() or off_r.any():
            T_center = T_center @ transform_from(matrix_from_rotation_vector(off_r), off_t, check=False)
        self.integrity.reset()
        if self._bound is not None:
            self._bound.reset()
        self._prev_force = None
        self._prev_deflection = None
        self._lasers_seen = 0
        self._last_status = "tracking"
        self._walk_gain = 1.0  # the walk's adaptive factor (filter.walk_adapt_rate)
        self._prev_spread = None
        self._nis_avg = 1.0  # the NIS per degree of freedom, averaged over walk_adapt_window steps
        self._sig_eff = {}
        self._offset = transform_from(matrix_from_rotation_vector(off_r), off_t, check=False)
        self._init_pending = bool(getattr(f, "init_from_robot", False))
        xi = self.rng.standard_normal((self.n, 6))
        xi[:, :3] *= f.init_sigma_t_mm
        xi[:, 3:] *= math.radians(f.init_sigma_r_deg)
        offsets = transform_from(matrix_from_rotation_vector(xi[:, 3:]), xi[:, :3], check=False)
        self.T = np.matmul(np.asarray(T_center, dtype=np.float64), offsets)
        self.logw = np.full(self.n, -math.log(self.n))

    def _draw_from_robot(self, meas) -> np.ndarray:
        """Particles ``(N, 4, 4)`` drawn from the robot measurement density (eq. 8) of one step:
        the uniform plateau (a ball of radius ``d_t`` in translation, the ellipsoid
        ``‖A_r Δr‖ <= d_r`` in rotation, base frame) plus its Gaussian tails, around the
        kinematic pose moved by ``init_offset`` (tool frame). The paper's prior: before any laser
        reading the pose is anywhere the robot can be, up to its largest expected error."""
        n = self.n
        rng = self.rng

        def ball(d):
            u = rng.standard_normal((n, 3))
            u /= np.linalg.norm(u, axis=1, keepdims=True)
            return u * (d * rng.random(n) ** (1.0 / 3.0))[:, None]

        dt = ball(meas.d_t_mm) + rng.standard_normal((n, 3)) @ np.linalg.cholesky(meas.Sigma_t).T
        br = ball(meas.d_r_rad)
        if meas.A_r is not None:
            br = np.linalg.solve(meas.A_r, br.T).T
        dr = br + rng.standard_normal((n, 3)) @ np.linalg.cholesky(meas.Sigma_r).T
        centre = meas.T_mean @ self._offset
        out = np.empty((n, 4, 4))
        out[:] = np.eye(4)
        out[:, :3, :3] = np.matmul(matrix_from_rotation_vector(dr), centre[:3, :3])
        out[:, :3, 3] = centre[:3, 3] + dt
        return out

    def _loglik(self, T: np.ndarray, inputs: StepInputs, meas, errors: bool = False):
        """Total measurement log-likelihood of particles ``T (N, 4, 4)`` and the lasers used.

        With ``errors``, also the robot part alone ``(N,)`` and the laser in-plane errors
        ``(N, 2 S_used)`` (mm, NaN where a particle's plane meets no seam) for the integrity test.
        """
        f = self.cfg.filter
        ll = robot_loglik(T, meas)
        ll_robot = ll.copy() if errors else None
        used = 0
        cols = []
        if errors:
            self._readings = []
            self._reading_sensor = []  # the sensor index of each reading in _readings
        if inputs.laser_mm is not None and self.sensor_mounts.shape[0]:
            Tn = inputs.T_nominal
            sig = f.laser_sigma_mm
            inv = 0.5 / (sig * sig)
            # the seam is searched at least as far as the robot density reaches (plateau + 3 tails; the
            # rotation plateau times the sensor's lever): a 25 kN force moves the tool 10 mm off the seam
            reach = meas.d_t_mm + 3.0 * math.sqrt(max(float(np.trace(meas.Sigma_t)), 0.0))
            lever = self._lever
            const = -math.log(2.0 * math.pi * sig * sig)
            wr = None
            c_infl = float(f.laser_inflation)
            cap = float(f.laser_inflation_cap)
            for i, M in enumerate(self.sensor_mounts):
                m = inputs.laser_mm[i]
                if not (np.isfinite(m[0]) and np.isfinite(m[1])):
                    continue
                S = Tn @ M
                centre = S[:3, 3] + S[:3, :3] @ np.array([m[0], 0.0, m[1]])
                lo, hi = self.seam.window(centre, S[:3, 1], max(f.search_window_mm, reach + meas.d_r_rad * lever[i]))
                if errors:
                    self._readings.append((float(m[0]), float(m[1]), M, lo, hi))
                    self._reading_sensor.append(i)
                E = np.empty((T.shape[0], 2))
                if lo < 0:
                    E.fill(np.nan)
                else:
                    _k.laser_error_kernel(T, float(m[0]), float(m[1]), M, self.seam.points, lo, hi, E)
                e2 = (E * E).sum(axis=1)
                if c_infl > 0.0:
                    if errors:  # the variance is fixed for the step (the tempering stages reuse it)
                        if wr is None:
                            wr = normalize_log_weights(self.logw + ll_robot).w
                        mom_m, mom_c = np.empty(2), np.empty((2, 2))
                        found = _k.weighted_moments_kernel(E, wr, mom_m, mom_c) > 0.0
                        v = 0.5 * (mom_c[0, 0] + mom_c[1, 1]) if found else 0.0
                        self._sig_eff[i] = sig * sig + min(c_infl * v, cap * sig * sig)
                    s2 = self._sig_eff.get(i, sig * sig)
                    ll += -math.log(2.0 * math.pi * s2) - (0.5 / s2) * np.where(np.isnan(e2), f.search_window_mm ** 2, e2)
                else:
                    ll += const - inv * np.where(np.isnan(e2), f.search_window_mm ** 2, e2)
                if errors:
                    cols.append(E)
                used += 1
        if self._angle_sigma and inputs.angle_rad is not None:
            for a in np.asarray(inputs.angle_rad, dtype=np.float64):
                if np.isfinite(a):
                    ll += angle_loglik(T, a, self.seam_normal, self._angle_sigma)
        if errors:
            return ll, used, ll_robot, (np.hstack(cols) if cols else np.empty((T.shape[0], 0)))
        return ll, used

    def _deflected_increment(self, T_increment: np.ndarray, meas) -> np.ndarray:
        """The step's increment with the change of the modelled deflection, ``D_k T+ D_{k-1}⁻¹`` (4, 4).

        ``D = Fk(q + Cj(τ)) Fk(q)⁻¹`` (:class:`~posekit.seam.engine.densities.RobotMeasurement`'s
        ``T_deflection``, base frame): the tool moves with the deflection the measured force predicts, so
        the walk covers only what the compliance model does not explain. ``T+`` unchanged without a
        compliance model, at the first step, or where a deflection is not finite (kept from the last
        finite one)."""
        D = meas.T_deflection
        if D is None or not np.isfinite(D).all():
            return T_increment
        prev, self._prev_deflection = self._prev_deflection, D
        if prev is None:
            return T_increment
        return D @ T_increment @ invert_transform(prev, check=False)

    def _temper(self, ll: np.ndarray, remaining: float, target: float) -> float:
        """Largest exponent ``β <= remaining`` with ``ESS(logw + β ll) >= target`` (bisection)."""
        def ess(beta):
            return effective_sample_size(normalize_log_weights(self.logw + beta * ll).w)

        if ess(remaining) >= target:
            return remaining
        lo, hi = 0.0, remaining
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            if ess(mid) >= target:
                lo = mid
            else:
                hi = mid
        return max(lo, 1e-6 * remaining)

    def _cloud(self, T: np.ndarray, w: np.ndarray):
        """Weighted mean ``T_mean (4, 4)`` and ``spread (6,)`` (as :func:`weighted_mean_se3`),
        the tangent offsets ``xi (N, 6)`` of the particles from the mean
        (``[R̄ᵀ (p_i - p̄), log(R̄ᵀ R_i)]``, mm, rad), their weighted mean ``mu (6,)`` and the
        Cholesky factor ``L (6, 6)`` of their weighted covariance (with the correlations)."""
        xi = np.empty((T.shape[0], 6))
        L = np.empty((6, 6))
        T_mean, spread, mu = _k.cloud_kernel(T, w, xi, L)
        return T_mean, spread, xi, mu, L

    def _kernel_resample(self, T: np.ndarray, w: np.ndarray, h: float, shrink: bool, cloud=None,
                         extra=None) -> np.ndarray:
        """Resample by ``w`` from a Gaussian kernel density of the cloud, in the tangent space at
        its weighted mean: ``ξ' = a ξ_i + (1 - a) μ + h L z``, ``L Lᵀ = Σ`` the weighted
        covariance of the offsets ``ξ`` (6-D, with the correlations), ``z`` standard normal.

        ``shrink`` (Liu & West): ``a = √(1 - h²)``, the mean and covariance are kept; else
        ``a = 1``, the covariance grows by ``1 + h²`` (the moves between tempering stages).
        The correlations matter: a seam measurement pins combinations (across position with
        yaw, height with pitch) and leaves others free (along the seam, the rotation about
        it); noise axis by axis would break the pinned combinations, the next update would
        discard those copies and the cloud would collapse in the free directions as well.
        ``cloud``: :meth:`_cloud` of ``(T, w)`` when already computed. ``extra``: a factor ``B``
        (6, 6) of a covariance added on top (the cloud floor): the kernel is ``h² Σ + B Bᵀ``.
        """
        cloud = self._cloud(T, w) if cloud is None else cloud
        L = cloud[4]
        K = h * L
        if extra is not None:
            try:
                K = np.linalg.cholesky(h * h * (L @ L.T) + extra @ extra.T)
            except np.linalg.LinAlgError:  # a cloud collapsed to one point and nothing to add: the plain kernel
                pass
        return self._move(cloud, self._resample(w, self.rng), math.sqrt(1.0 - h * h) if shrink else 1.0, K)

    def _move(self, cloud, idx: np.ndarray, a: float, B: np.ndarray) -> np.ndarray:
        """New particles ``T_mean exp(a ξ_idx + (1 - a) μ + B z)`` from :meth:`_cloud`'s ``cloud``, ``z`` standard
        normal (drawn here): ancestors ``idx (N,)``, shrinkage ``a``, noise factor ``B (6, 6)``."""
        T_mean, _, xi, mu, _ = cloud
        z = self._noise
        self.rng.standard_normal(out=z, dtype=np.float32)
        out = np.empty_like(self.T)
        _k.kernel_move(T_mean, xi, idx, mu, a, np.ascontiguousarray(B, dtype=np.float64), z, out)
        return out

    def step(self, inputs: StepInputs) -> StepEstimate:
        """Propagate, weight, estimate and (if needed) resample; see the module docstring."""
        f = self.cfg.filter
        force = np.asarray(inputs.force_n, dtype=np.float64)
        # 1. state transition (eq. 3): the width grows with the force rate (default) or magnitude
        force_norm = math.sqrt(float(force @ force))  # N; NaN stays NaN for the integrity monitor
        fn = force_norm
        if self._rate:
            tau = f.force_rate_smoothing
            f_new = force
            if tau > 0.0 and self._prev_force is not None:
                f_new = self._prev_force + (force - self._prev_force) / (1.0 + tau)
            df = 0.0 if self._prev_force is None else float(np.linalg.norm(f_new - self._prev_force))
            if math.isfinite(df):
                self._prev_force = f_new
            else:
                df = 0.0
            base_t = f.sigma_t_mm + f.k_rate_t_mm_per_n * df
            base_r = self._sigma_r + self._k_rate_r * df
        else:
            base_t = f.sigma_t_mm + f.k_force_t * fn
            base_r = self._sigma_r + self._k_force_r * fn
        # the robot's error changes as its configuration does: per mm travelled, and more so under load
        travel = float(np.linalg.norm(inputs.T_increment[:3, 3]))
        load_t = load_r = 0.0
        if travel > 0.0 and math.isfinite(travel):
            fn = fn if math.isfinite(fn) else 0.0
            base_t += travel * f.k_travel_t_mm_per_mm
            base_r += travel * math.radians(f.k_travel_r_deg_per_mm)
            load_t = travel * f.k_load_travel_t * fn
            load_r = travel * math.radians(f.k_load_travel_r * fn)
        # re-acquired lately (the integrity monitor counts the steps since the last lost one): the cloud was rebuilt
        # from few survivors
        since = self.integrity.since_lost
        reacquiring = since is not None and since < f.reacquire_isotropic_steps
        after_loss = since is not None and since < f.bound_reacquire_steps  # the reported spread's regime
        if self._last_status != "tracking":
            # the last step's data did not agree with the model: widen the walk on every axis so the cloud
            # can re-acquire (process-noise inflation on a failed consistency test)
            sig_t = (base_t + load_t) * f.reacquire_transition_scale
            sig_r = (base_r + load_r) * f.reacquire_transition_scale
        elif reacquiring:
            # re-acquired lately: the cloud was rebuilt from few survivors, keep the walk isotropic for a while
            sig_t = base_t + load_t
            sig_r = base_r + load_r
        else:
            # per tool axis (filter.axis_scale_*, load_axis_scale_*): the pose error does not drift alike on every
            # axis, unloaded or under load
            sig_t = base_t * self._axis_t + load_t * self._load_axis_t
            sig_r = base_r * self._axis_r + load_r * self._load_axis_r
        sig_t = sig_t * self._walk_gain
        sig_r = sig_r * self._walk_gain
        with np.errstate(invalid="ignore"):  # non-finite readings: every weight vanishes, recovered below
            meas = robot_measurement(self.chain, np.asarray(inputs.q_meas, dtype=np.float64), force,
                                     compliance=self.compliance, **self._robot_kw)
        self.T = transition(self.T, self._deflected_increment(inputs.T_increment, meas), sig_t, sig_r, self.rng,
                            noise_buffer=self._noise)
        # 2. measurement update: robot (eq. 5, 8) + lasers (eq. 9) + angles
        with np.errstate(invalid="ignore"):
            if self._init_pending and np.isfinite(meas.T_mean).all():
                self.T = self._draw_from_robot(meas)  # the prior: where the robot can be
                self._init_pending = False
            ll, used, ll_robot, E = self._loglik(self.T, inputs, meas, errors=True)
            # integrity: the lasers' innovations under the cloud before the lasers weight it
            nis, dof = (innovation_nis(E, normalize_log_weights(self.logw + ll_robot).w, f.laser_sigma_mm)
                        if used else (0.0, 0))
        norm = normalize_log_weights(self.logw + ll)
        ess = effective_sample_size(norm.w)
        ess_update = ess
        # 2b. a likelihood far narrower than the cloud (start-up, a feature): temper it in stages
        stages = 0
        remaining = 1.0
        # a filter that has lost the track (the model cannot explain the data) gets 2 stages, not
        # the full budget: tempering cannot make inconsistent data consistent, it only costs time
        max_stages = f.anneal_stages if self._last_status != "lost" else min(f.anneal_stages, 2)
        while (not norm.recovered and ess < f.anneal_ess * self.n and stages < max_stages):
            beta = self._temper(ll, remaining, 0.5 * self.n)
            self.T = self._kernel_resample(self.T, normalize_log_weights(self.logw + beta * ll).w,
                                           f.anneal_jitter, shrink=False)
            self.logw = np.full(self.n, -math.log(self.n))
            remaining -= beta
            ll, used = self._loglik(self.T, inputs, meas)
            norm = normalize_log_weights(self.logw + remaining * ll)
            ess = effective_sample_size(norm.w)
            stages += 1
        self.annealings += stages
        # 3. normalise (recover from vanishing weights), estimate
        self.recoveries += norm.recovered
        w = norm.w
        resampled = ess < f.ess_threshold * self.n
        h = f.regularize_h if resampled else 0.0
        floor = f.cloud_floor > 0.0 and self._bound is not None and not norm.recovered
        # the mean pass also gives the resampling kernel and the covariance the floor compares with
        cloud = self._cloud(self.T, w) if (h > 0.0 or floor) else None
        T_mean, spread = weighted_mean_se3(self.T, w) if cloud is None else cloud[:2]
        self._lasers_seen += used
        if self._lasers_seen == 0 and not norm.recovered:
            # no laser reading yet (none since reset, or no sensor): the robot measurement is the only
            # information, and the mean of its symmetric density (eq. 8) is its centre, the kinematic
            # pose. The cloud's own mean random-walks inside the flat plateau (10 default xy runs
            # without sensors: x 0.62 vs 0.56 mm RMSE); the cloud still gives the spread.
            T_mean = meas.T_mean.copy()
        m_t, m_r = robot_consistency(T_mean, spread, meas)
        extra = None  # a factor B of the covariance the floor adds, (c P - Σ_cloud)+ = B Bᵀ
        if self._bound is not None and np.isfinite(T_mean).all():
            # the bound runs the particles' walk (travel terms included); spread_bound_k_travel adds to it alone
            q_t = self._bound.q_scale * sig_t + f.spread_bound_k_travel * (travel if math.isfinite(travel) else 0.0)
            # bound_inflation: the share of the particles' laser inflation the bound takes (0: the true σ)
            s2 = f.laser_sigma_mm ** 2
            infl = max(f.bound_inflation, f.bound_inflation_reacquire) if after_loss else f.bound_inflation
            sig2 = [s2 + infl * (self._sig_eff.get(i, s2) - s2) for i in self._reading_sensor]
            # the particle approximation's own noise: the weighted mean of ESS effective particles moves by the
            # cloud's covariance over ESS, which the lasers correct only where they see
            Q_pf = None
            if f.bound_particle_noise > 0.0 and cloud is not None and ess >= 1.0:
                Q_pf = (f.bound_particle_noise / ess) * (cloud[4] @ cloud[4].T)
            bound = self._bound.update(T_mean, meas, q_t, self._bound.q_scale * sig_r, self._readings,
                                       self.seam.points, sig2, drift_share=f.bound_drift_share, Q_pf=Q_pf)
            spread = np.maximum(spread, bound)
            if not after_loss:
                # the walk is wider than the pose drifts (it must re-acquire, absorb what the models miss): the
                # error of the estimate it gives is smaller than the walk's posterior, by the bound's ratio
                spread = spread * self._bound.ratio
            if floor:
                extra = floor_factor(f.cloud_floor * self._bound.P, cloud[4])
        if np.isfinite(spread).all():
            if after_loss and f.spread_shrink_reacquire > 0.0 and self._prev_spread is not None:
                # after a loss the estimate may be off where the lasers have not looked again: the spread shrinks slowly
                spread = np.maximum(spread, f.spread_shrink_reacquire * self._prev_spread)
            self._prev_spread = spread.copy()  # not the returned array: a caller may convert it in place
        # 4. resample (regularised: see _kernel_resample); the cloud kept at least as wide as the floor (one move)
        if resampled:
            if h > 0.0:
                self.T = self._kernel_resample(self.T, w, h, shrink=True, cloud=cloud, extra=extra)
            elif extra is not None:
                self.T = self._move(cloud, self._resample(w, self.rng), 1.0, extra)
            else:
                self.T = self.T[self._resample(w, self.rng)]
            self.logw = np.full(self.n, -math.log(self.n))
            self.resamplings += 1
        else:
            self.logw = norm.logw
            if extra is not None:
                self.T = self._move(cloud, np.arange(self.n), 1.0, extra)
        rep = self.integrity.update(nis, dof, m_t, m_r, ess_update, norm.recovered, force_norm)
        tests = rep.tests_status  # the walk reacts to the consistency tests, not to the robot model's force range
        if f.walk_adapt_rate > 0.0 and dof and self._last_status == "tracking" and tests == "tracking":
            # covariance matching: innovations larger than the predicted cloud says (the NIS per degree of
            # freedom, averaged over walk_adapt_window steps, above walk_adapt_nis) widen the walk, smaller ones
            # narrow it back, within 1 .. walk_adapt_max times the configured width; one reading counts at most
            # 3 (a seam feature's few large innovations do not blow the walk up)
            x = min(nis / dof, 3.0) if math.isfinite(nis) else 3.0
            self._nis_avg += (x - self._nis_avg) / f.walk_adapt_window
            self._walk_gain = min(max(self._walk_gain * math.exp(f.walk_adapt_rate * (self._nis_avg - f.walk_adapt_nis)),
                                      1.0), f.walk_adapt_max)
        self._last_status = tests
        if tests == "lost" and self._bound is not None:
            self._bound.reset()  # the information gathered before the track was lost no longer holds
        return StepEstimate(T_mean, spread, ess, bool(resampled), norm.recovered, meas.T_mean, used, stages,
                            rep.status, rep.reason, nis, ess_update)

    @property
    def weights(self) -> np.ndarray:
        """Normalised weights ``exp(logw)``, shape (N,)."""
        return np.exp(self.logw)
