"""The particle filter on SE(3) for the tool pose relative to the seam (paper Algorithm 1).

One step: propagate every particle with the nominal increment and force-dependent noise
(eq. 3); weight with the robot measurement (eq. 5, 8) and each available laser (and angle)
measurement (eq. 9); normalise the log-weights (recovering from vanishing weights); estimate
the weighted mean on SE(3) and its spread; resample by name when the effective sample size
falls below ``ess_threshold · N``.

When one update would leave fewer than ``anneal_ess · N`` effective particles (the laser
likelihood is far narrower than the cloud: at start-up, at a seam feature), the likelihood
is applied in tempered stages ``ℓ^β₁ ℓ^β₂ ...`` (β chosen for an ESS of N/2), each followed by
a kernel resampling step that moves the copies by Gaussian noise of ``anneal_jitter²`` times
the cloud's 6-D covariance (with its correlations); at most ``anneal_stages`` stages. Without
it the cloud collapses onto the one particle nearest the truth and the small transition noise
cannot move it for hundreds of steps.

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
from posekit.geometry import matrix_from_rotation_vector, transform_from
from posekit.seam.engine import _kernels as _k
from posekit.seam.engine.densities import (
    angle_loglik,
    joint_compliance,
    laser_loglik,
    robot_loglik,
    robot_measurement,
    transition,
)
from posekit.seam.engine.particles import (
    RESAMPLERS,
    effective_sample_size,
    normalize_log_weights,
    weighted_mean_se3,
)
from posekit.seam.engine.seamline import SeamLine
from posekit.seam.frontend.config import SeamConfig
from posekit.seam.frontend.trajectories import tool_chain

__all__ = ["SeamParticleFilter", "StepEstimate", "StepInputs"]


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


@dataclass
class StepEstimate:
    """Output of one filter step.

    Attributes
    ----------
    T : ndarray, shape (4, 4)
        Weighted mean tool pose ``T_base_tool`` (mm).
    spread : ndarray, shape (6,)
        Weighted standard deviation around the mean in its frame: x, y, z (mm), rx, ry, rz (rad).
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
    """

    T: np.ndarray
    spread: np.ndarray
    ess: float
    resampled: bool
    recovered: bool
    T_kinematic: np.ndarray
    lasers_used: int
    anneal_stages: int = 0


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
                 compliance=None):
        f = cfg.filter
        if f.resampler not in RESAMPLERS:
            raise ConfigError(f"filter.resampler: expected one of {sorted(RESAMPLERS)}, got {f.resampler!r}")
        self.cfg = cfg
        self.rng = np.random.default_rng(rng)
        self.seam = SeamLine(seam_polyline)
        self.chain = tool_chain(cfg.robot)
        self.distances_mm = np.array(cfg.sensors.resolved_distances_mm(), dtype=np.float64)
        self.seam_normal = (np.array([0.0, 0.0, -1.0]) if seam_normal is None
                            else np.asarray(seam_normal, dtype=np.float64))
        if compliance is None and f.compliance_rad_per_nm > 0.0:
            compliance = joint_compliance(f.compliance_rad_per_nm)
        self.compliance = compliance
        self._resample = RESAMPLERS[f.resampler]
        deg = math.pi / 180.0
        self._sigma_r = f.sigma_r_deg * deg
        self._k_force_r = f.k_force_r * deg
        self._robot_kw = {
            "joint_sigma_rad": f.joint_sigma_deg * deg, "floor_t_mm": f.robot_floor_t_mm,
            "floor_r_rad": f.robot_floor_r_deg * deg, "d0_mm": f.d0_mm, "kd_mm_per_n": f.kd_mm_per_n,
            "d0_rad": f.d0_deg * deg, "kd_rad_per_n": f.kd_deg_per_n * deg, "bending": f.bending_plateau,
        }
        self._angle_sigma = cfg.sensors.angle and f.angle_sigma_deg * deg
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
        """Draw the particles around ``T_center`` (4, 4) with the initial spread; uniform weights."""
        f = self.cfg.filter
        xi = self.rng.standard_normal((self.n, 6))
        xi[:, :3] *= f.init_sigma_t_mm
        xi[:, 3:] *= math.radians(f.init_sigma_r_deg)
        offsets = transform_from(matrix_from_rotation_vector(xi[:, 3:]), xi[:, :3], check=False)
        self.T = np.matmul(np.asarray(T_center, dtype=np.float64), offsets)
        self.logw = np.full(self.n, -math.log(self.n))

    def _loglik(self, T: np.ndarray, inputs: StepInputs, meas) -> tuple[np.ndarray, int]:
        """Total measurement log-likelihood of particles ``T (N, 4, 4)`` and the lasers used."""
        f = self.cfg.filter
        ll = robot_loglik(T, meas)
        used = 0
        if inputs.laser_mm is not None and self.distances_mm.size:
            Tn = inputs.T_nominal
            for i, dist in enumerate(self.distances_mm):
                m = inputs.laser_mm[i]
                if not (np.isfinite(m[0]) and np.isfinite(m[1])):
                    continue
                centre = Tn[:3, 3] + Tn[:3, :3] @ np.array([m[0], dist, m[1]])
                knots = self.seam.window(centre, Tn[:3, 1], f.search_window_mm)
                ll += laser_loglik(T, m, dist, self.seam, knots, f.laser_sigma_mm, f.search_window_mm)
                used += 1
        if self._angle_sigma and inputs.angle_rad is not None:
            for a in np.asarray(inputs.angle_rad, dtype=np.float64):
                if np.isfinite(a):
                    ll += angle_loglik(T, a, self.seam_normal, self._angle_sigma)
        return ll, used

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

    def _kernel_resample(self, T: np.ndarray, w: np.ndarray, h: float, shrink: bool, cloud=None) -> np.ndarray:
        """Resample by ``w`` from a Gaussian kernel density of the cloud, in the tangent space at
        its weighted mean: ``ξ' = a ξ_i + (1 - a) μ + h L z``, ``L Lᵀ = Σ`` the weighted
        covariance of the offsets ``ξ`` (6-D, with the correlations), ``z`` standard normal.

        ``shrink`` (Liu & West): ``a = √(1 - h²)``, the mean and covariance are kept; else
        ``a = 1``, the covariance grows by ``1 + h²`` (the moves between tempering stages).
        The correlations matter: a seam measurement pins combinations (across position with
        yaw, height with pitch) and leaves others free (along the seam, the rotation about
        it); noise axis by axis would break the pinned combinations, the next update would
        discard those copies and the cloud would collapse in the free directions as well.
        ``cloud``: :meth:`_cloud` of ``(T, w)`` when already computed.
        """
        T_mean, _, xi, mu, L = self._cloud(T, w) if cloud is None else cloud
        idx = self._resample(w, self.rng)
        z = self._noise
        self.rng.standard_normal(out=z, dtype=np.float32)
        out = np.empty_like(T)
        _k.kernel_move(T_mean, xi, idx, mu, math.sqrt(1.0 - h * h) if shrink else 1.0, h * L, z, out)
        return out

    def step(self, inputs: StepInputs) -> StepEstimate:
        """Propagate, weight, estimate and (if needed) resample; see the module docstring."""
        f = self.cfg.filter
        force = np.asarray(inputs.force_n, dtype=np.float64)
        fn = math.sqrt(float(force @ force))
        # 1. state transition (eq. 3)
        self.T = transition(self.T, inputs.T_increment, f.sigma_t_mm + f.k_force_t * fn,
                            self._sigma_r + self._k_force_r * fn, self.rng, noise_buffer=self._noise)
        # 2. measurement update: robot (eq. 5, 8) + lasers (eq. 9) + angles
        with np.errstate(invalid="ignore"):  # non-finite readings: every weight vanishes, recovered below
            meas = robot_measurement(self.chain, np.asarray(inputs.q_meas, dtype=np.float64), force,
                                     compliance=self.compliance, **self._robot_kw)
            ll, used = self._loglik(self.T, inputs, meas)
        norm = normalize_log_weights(self.logw + ll)
        ess = effective_sample_size(norm.w)
        # 2b. a likelihood far narrower than the cloud (start-up, a feature): temper it in stages
        stages = 0
        remaining = 1.0
        while (not norm.recovered and ess < f.anneal_ess * self.n and stages < f.anneal_stages):
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
        cloud = self._cloud(self.T, w) if h > 0.0 else None  # the mean pass also gives the kernel
        T_mean, spread = weighted_mean_se3(self.T, w) if cloud is None else cloud[:2]
        # 4. resample (regularised: see _kernel_resample)
        if resampled:
            self.T = (self._kernel_resample(self.T, w, h, shrink=True, cloud=cloud) if h > 0.0
                      else self.T[self._resample(w, self.rng)])
            self.logw = np.full(self.n, -math.log(self.n))
            self.resamplings += 1
        else:
            self.logw = norm.logw
        return StepEstimate(T_mean, spread, ess, bool(resampled), norm.recovered, meas.T_mean, used, stages)

    @property
    def weights(self) -> np.ndarray:
        """Normalised weights ``exp(logw)``, shape (N,)."""
        return np.exp(self.logw)
