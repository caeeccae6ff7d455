"""The particle filter on SE(3) for the tool pose relative to the seam (paper Algorithm 1).

It reads three things: the :class:`~posekit.seam.model.Cell` (robot with tool, sensor mounts and latencies,
compliance model), the algorithm's :class:`FilterSettings` (the ``filter`` section of a configuration: particle
count, resampling, tempering, integrity levels) and the fitted :class:`~posekit.seam.model.Profile` (walk, jitter,
plateau, tails, joint and laser noise, latency; written by ``posekit seam tune``). It holds no tuned constant.

One step:

1. propagate every particle with the program's increment ``T+ = Fk(q̄+) Fk(q̄)⁻¹`` moved by the change of the
   deflection the compliance model predicts from the measured force (``D_k T+ D_{k-1}⁻¹``,
   ``D = Fk(q + Cj(τ)) Fk(q)⁻¹``) and the profile's random walk over the step, ``N(0, diag(walk² s))`` in the
   tool frame with ``s`` the program's travel over the step (mm: the robot's error is a function of its
   configuration, eq. 3), ``reacquire_walk_scale`` times wider after a step that was not ``tracking``;
2. weight with the robot measurement (eq. 5, 8: the plateau of radius ``d0 + kd ‖f‖`` about ``Fk(q + Cj(τ))``)
   and each laser reading (eq. 9) at the time it was taken: a reading ``L`` seconds old is compared with the
   particle moved back along the program, ``T Fk(q̄(t))⁻¹ Fk(q̄(t - L))`` (the program's joints interpolated), so
   the sensor's effective mount is ``Fk(q̄(t))⁻¹ Fk(q̄(t - L)) T_tool_sensor``;
3. normalise the log-weights (recovering from vanishing weights), estimate the weighted mean on SE(3) and its
   spread, resample by name when the effective sample size falls below ``ess_threshold · N``.

A particle's laser likelihood has the variance ``σ² + j² + h² Var_w(e)``: the profile's laser noise, the pose
jitter through the sensor's lever, and the spread of the cloud's in-plane errors times the resampling kernel's
``h²`` (a particle stands for a Gaussian kernel of ``h²`` times the cloud's covariance, and the likelihood of a
kernel is the laser density widened by it). The integrity test and the spread bound use ``σ² + j²``.

When one update would leave fewer than ``anneal_ess · N`` effective particles (start-up, a seam feature), the
likelihood is applied in tempered stages ``ℓ^β₁ ℓ^β₂ ...`` (β for an ESS of N/2), each followed by a kernel
resampling move of ``regularize_h²`` times the cloud's covariance; at most ``anneal_stages`` stages (2 after a
lost step). Resampling is regularised (Liu & West's kernel with shrinkage, bandwidth ``regularize_h``): the copies
are drawn from a Gaussian kernel density of the weighted cloud that keeps its mean and covariance; the lasers leave
directions free and plain resampling lets a few ancestors take over there.

The first step draws the cloud from the robot density itself (the paper's prior: before any laser reading the
tool is anywhere the robot can be), and so does the step after the track is lost (once per loss, with the full
tempering: a cloud that no longer explains the readings is started again where the robot can be); until the first reading the estimate is the kinematic pose. The reported
spread is at least the one the data support (:mod:`posekit.seam.engine.spread_bound`, run with the same walk and
noise, reset when the track is lost), with the pose jitter added. Every step carries a status
(``tracking``/``degraded``/``lost``, :mod:`posekit.seam.engine.integrity`).
"""

import math

import numpy as np

from posekit.errors import ConfigError
from posekit.geometry import invert_transform, matrix_from_rotation_vector
from posekit.seam.engine import _cloud_kernels as _ck
from posekit.seam.engine import _kernels as _k
from posekit.seam.engine.densities import (
    angle_loglik,
    joint_compliance,
    robot_loglik,
    robot_measurement,
    transition,
)
from posekit.seam.engine.integrity import IntegrityMonitor, innovation_nis, robot_consistency
from posekit.seam.engine.offset_test import kinematic_offset
from posekit.seam.engine.particles import (
    RESAMPLERS,
    effective_sample_size,
    normalize_log_weights,
)
from posekit.seam.engine.seamline import SeamLine
from posekit.seam.engine.spread_bound import InformationBound, Readings
from posekit.seam.engine.step import FilterSettings, StepEstimate, StepInputs, jitter_variances
from posekit.seam.model import Cell, Profile

__all__ = ["SeamParticleFilter"]

#: Steps of ``(time_s, q_ref)`` the filter keeps to evaluate the robot at a reading's time (0.64 s at 100 Hz; a
#: reading older than the oldest kept takes its joints).
_HISTORY = 64


class SeamParticleFilter:
    """Particle filter for the 6-DoF tool pose ``T_base_tool`` (see the module docstring).

    Parameters
    ----------
    cell : Cell
        Robot with tool, sensors (mounts, declared latencies), compliance model.
    settings : FilterSettings
    profile : Profile
    seam_polyline : array_like, shape (K, 3)
        Nominal seam polyline in the base frame (the trend-filter knots), mm.
    rng : numpy.random.Generator or int or None
    T_init : array_like, shape (4, 4), optional
        Where the cloud is before the first step (it is then drawn from the robot density); call
        :meth:`reset` otherwise.
    T_offset : array_like, shape (4, 4), optional
        The first cloud is drawn about the kinematic pose times this (tool frame): a deliberately wrong start
        (the simulator's ``simulation.start_offset_*``); identity by default.
    seam_normal : array_like, shape (3,), optional
        Workpiece surface normal (base frame) for the angle readings; default ``-z``.
    compliance : callable ``Cj(q (n,), τ (n,) N·mm) -> Δq (n,) rad``, optional
        Compliance model of eq. (5); default ``cell.compliance_rad_per_nm`` as a diagonal model (none when 0).
    degraded_reason : str, optional
        Every step is ``degraded`` at best, with this reason (:class:`~posekit.seam.engine.integrity.
        IntegrityMonitor`'s ``degraded_reason``: the profile was fitted on another cell).

    Attributes
    ----------
    T : ndarray, shape (N, 4, 4)
        The particles.
    logw : ndarray, shape (N,)
        Normalised log-weights.
    recoveries, resamplings, annealings : int
        Steps whose weights all vanished, resampling steps, tempering stages so far.
    """

    def __init__(self, cell: Cell, settings: FilterSettings, profile: Profile, seam_polyline, rng=None, *,
                 T_init=None, T_offset=None, seam_normal=None, compliance=None, degraded_reason=None):
        if settings.resampler not in RESAMPLERS:
            raise ConfigError(f"filter.resampler: expected one of {sorted(RESAMPLERS)}, got {settings.resampler!r}")
        self.cell = cell
        self.settings = settings
        self.profile = profile
        self.rng = np.random.default_rng(rng)
        self.seam = SeamLine(seam_polyline)
        self.chain = cell.chain
        self.mounts = np.ascontiguousarray(cell.mounts)
        S = self.mounts.shape[0]
        self._n_sensors = S
        self._lever = np.linalg.norm(self.mounts[:, :3, 3], axis=1)  # mm, tool centre to sensor
        self._latency = cell.latencies(profile)
        self._sigma2 = profile.sensor_sigma_mm(S) ** 2
        self._jitter = np.asarray(profile.jitter, dtype=np.float64)
        self._scale = np.asarray(profile.spread_scale, dtype=np.float64)
        self._walk = np.asarray(profile.walk, dtype=np.float64)
        self.seam_normal = (np.array([0.0, 0.0, -1.0]) if seam_normal is None
                            else np.asarray(seam_normal, dtype=np.float64))
        if compliance is None and cell.compliance_rad_per_nm > 0.0:
            compliance = joint_compliance(cell.compliance_rad_per_nm)
        self.compliance = compliance
        self._resample = RESAMPLERS[settings.resampler]
        self._robot_kw = {
            "joint_sigma_rad": profile.joint_sigma_rad, "floor_t_mm": profile.tail_mm,
            "floor_r_rad": profile.tail_rad, "d0_mm": profile.d0_mm, "kd_mm_per_n": profile.kd_mm_per_n,
            "d0_rad": profile.d0_rad, "kd_rad_per_n": profile.kd_rad_per_n, "bending": True,
        }
        self._angle_sigma = profile.angle_sigma_rad if cell.angle else 0.0
        bias_mean, bias_dof = profile.sensor_bias(S)
        self.integrity = IntegrityMonitor(settings.particles, settings.integrity_window,
                                          settings.integrity_alpha_degraded, settings.integrity_alpha_lost,
                                          settings.integrity_ess_min, settings.integrity_recovery,
                                          profile.max_force_n, settings.integrity_window_long,
                                          *profile.sensor_nis(S), degraded_reason=degraded_reason,
                                          bias_window=profile.bias_window, bias_mean=bias_mean, bias_dof=bias_dof,
                                          offset_mean=profile.offset_mean, offset_sd=profile.offset_sd,
                                          offset_samples=profile.offset_samples)
        self._bound = InformationBound()
        self._offset = np.eye(4) if T_offset is None else np.asarray(T_offset, dtype=np.float64)
        self.n = settings.particles
        self.recoveries = 0
        self.resamplings = 0
        self.annealings = 0
        self.T = np.repeat(np.eye(4)[None], self.n, axis=0)
        self._noise = np.empty((self.n, 6), np.float32)
        self.logw = np.full(self.n, -math.log(self.n))
        # time_s and q_ref of the last _HISTORY steps, oldest first (the readings' times): _hist_n of the rows used
        self._hist_t = np.empty(_HISTORY)
        self._hist_q = np.empty((_HISTORY, 0))
        self._hist_n = 0
        self.reset(np.eye(4) if T_init is None else T_init)

    def reset(self, T_center) -> None:
        """Put every particle at ``T_center`` (4, 4) with uniform weights; the next step draws the cloud from
        the robot density. The integrity window, the spread bound and the histories are cleared."""
        self.integrity.reset()
        self._bound.reset()
        self._prev_deflection = None
        self._hist_n = 0
        self._lasers_seen = 0
        self._last_status = "tracking"
        self._init_pending = True
        self.T = np.repeat(np.asarray(T_center, dtype=np.float64)[None], self.n, axis=0)
        self.logw = np.full(self.n, -math.log(self.n))

    # ------------------------------------------------------------------------------------ helpers

    def _draw_from_robot(self, meas) -> np.ndarray:
        """Particles ``(N, 4, 4)`` drawn from the robot measurement density (eq. 8) of one step: the uniform
        plateau (a ball of radius ``d_t`` in translation, the ellipsoid ``‖A_r Δr‖ <= d_r`` in rotation, base
        frame) plus its Gaussian tails, about the kinematic pose moved by ``T_offset`` (tool frame)."""
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

    def _reading_mounts(self, inputs: StepInputs) -> np.ndarray:
        """Effective mounts ``(S, 4, 4)``: ``Fk(q̄(t))⁻¹ Fk(q̄(t - L)) T_tool_sensor`` per sensor (mm), the
        program's joints interpolated linearly between the steps kept (the earliest one before them)."""
        lag = self._latency
        if inputs.reading_lag_s is not None:  # the readings' own stamps; NaN: the sensor's latency
            given = np.asarray(inputs.reading_lag_s, dtype=np.float64)
            lag = np.where(np.isfinite(given), given, self._latency)
        if not np.any(lag > 0.0) or self._hist_n < 2:
            return self.mounts
        times, qs = self._hist_t[:self._hist_n], self._hist_q[:self._hist_n]
        t_now = times[-1]
        out = self.mounts.copy()
        T_now_inv = None
        for i, L in enumerate(lag):
            if not (L > 0.0 and math.isfinite(L)):
                continue
            t = t_now - L
            q = np.empty(qs.shape[1])
            if not (math.isfinite(t) and _k.interp_columns(t, times, qs, q)):   # NumPy's, where times go back
                q = np.array([np.interp(t, times, qs[:, j]) for j in range(qs.shape[1])])
            if T_now_inv is None:
                T_now_inv = invert_transform(inputs.T_nominal, check=False)
            out[i] = T_now_inv @ self.chain.forward_kinematics(q, check=False) @ self.mounts[i]
        return out

    def _remember(self, t: float, q_ref) -> None:
        """Keep ``(t, q_ref)`` as the newest row of the history (the oldest dropped once it holds _HISTORY)."""
        q = np.asarray(q_ref, dtype=np.float64).reshape(-1)
        if self._hist_q.shape[1] != q.shape[0]:
            self._hist_q = np.empty((_HISTORY, q.shape[0]))
            self._hist_n = 0
        if self._hist_n == _HISTORY:
            self._hist_t[:-1] = self._hist_t[1:]
            self._hist_q[:-1] = self._hist_q[1:]
            self._hist_n -= 1
        self._hist_t[self._hist_n] = t
        self._hist_q[self._hist_n] = q
        self._hist_n += 1

    def _deflected_increment(self, T_increment: np.ndarray, meas) -> np.ndarray:
        """The step's increment with the change of the modelled deflection, ``D_k T+ D_{k-1}⁻¹`` (4, 4).

        ``D = Fk(q + Cj(τ)) Fk(q)⁻¹`` (base frame): the tool moves with the deflection the measured force
        predicts, so the walk covers only what the compliance model does not explain. ``T+`` unchanged without
        a compliance model, at the first step, or where a deflection is not finite (kept from the last finite
        one)."""
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
        """Weighted mean ``T_mean (4, 4)``, ``spread (6,)``, the tangent offsets ``xi (N, 6)`` of the particles
        from the mean (mm, rad), their weighted mean ``mu (6,)`` and the Cholesky factor ``L (6, 6)`` of their
        weighted covariance."""
        xi = np.empty((T.shape[0], 6))
        L = np.empty((6, 6))
        T_mean, spread, mu = _ck.cloud_kernel(T, w, xi, L)
        return T_mean, spread, xi, mu, L

    def _kernel_resample(self, T: np.ndarray, w: np.ndarray, h: float, shrink: bool, cloud=None) -> np.ndarray:
        """Resample by ``w`` from a Gaussian kernel density of the cloud in the tangent space at its weighted
        mean: ``ξ' = a ξ_i + (1 - a) μ + h L z``, ``L Lᵀ`` the weighted covariance of the offsets (6-D, with the
        correlations: a seam reading pins combinations and leaves others free), ``z`` standard normal.
        ``shrink`` (Liu & West): ``a = √(1 - h²)``, mean and covariance kept; else ``a = 1`` (the tempering
        moves: the covariance grows by ``1 + h²``)."""
        cloud = self._cloud(T, w) if cloud is None else cloud
        a = math.sqrt(1.0 - h * h) if shrink else 1.0
        return self._move(cloud, self._resample(w, self.rng), a, h * cloud[4])

    def _move(self, cloud, idx: np.ndarray, a: float, B: np.ndarray) -> np.ndarray:
        """New particles ``T_mean exp(a ξ_idx + (1 - a) μ + B z)`` from :meth:`_cloud`'s ``cloud``, ``z`` standard
        normal (drawn here): ancestors ``idx (N,)``, shrinkage ``a``, noise factor ``B (6, 6)``."""
        T_mean, _, xi, mu, _ = cloud
        z = self._noise
        self.rng.standard_normal(out=z, dtype=np.float32)
        out = np.empty_like(self.T)
        _ck.kernel_move(T_mean, xi, idx, mu, a, np.ascontiguousarray(B, dtype=np.float64), z, out)
        return out

    def _readings(self, inputs: StepInputs, meas, mounts: np.ndarray) -> tuple[Readings, np.ndarray, list]:
        """The step's readings with their knot windows, searched about the kinematic pose as far as the robot
        density reaches (plateau, 3 tails and the rotation plateau times the sensor's lever), that search
        radius per reading (mm: the error charged to a particle whose plane meets no seam), and the index of the
        sensor of each reading."""
        S = mounts.shape[0]
        if inputs.laser_mm is None or S == 0:
            return Readings.none(), np.empty(0), []
        reach = meas.d_t_mm + 3.0 * math.sqrt(max(float(np.trace(meas.Sigma_t)), 0.0))
        jit = jitter_variances(mounts, self._jitter)
        mx, mz, Ms, lo, hi, r2, radius, sensor = [], [], [], [], [], [], [], []
        for i in range(S):
            m = inputs.laser_mm[i]
            if not (np.isfinite(m[0]) and np.isfinite(m[1])):
                continue
            Sp = meas.T_mean @ mounts[i]
            centre = Sp[:3, 3] + Sp[:3, :3] @ np.array([m[0], 0.0, m[1]])
            rad = reach + meas.d_r_rad * self._lever[i]
            a, b = self.seam.window(centre, Sp[:3, 1], rad)
            mx.append(float(m[0]))
            mz.append(float(m[1]))
            Ms.append(mounts[i])
            lo.append(a)
            hi.append(b)
            r2.append(self._sigma2[i] + jit[i])
            radius.append(rad)
            sensor.append(i)
        if not mx:
            return Readings.none(), np.empty(0), []
        return Readings(mx, mz, np.stack(Ms), lo, hi, np.stack(r2)), np.array(radius), sensor

    def _loglik(self, T: np.ndarray, rd: Readings, inputs: StepInputs, meas, errors: bool = False):
        """Total measurement log-likelihood of particles ``T (N, 4, 4)``; with ``errors`` also the robot part
        alone ``(N,)`` and the laser in-plane errors ``(N, 2 S_used)`` (mm, NaN where a particle's plane meets
        no seam) for the integrity test. The laser variance of each reading is fixed at the first call of the
        step (the tempering stages reuse it)."""
        ll = robot_loglik(T, meas)
        ll_robot = ll.copy() if errors else None
        cols = []
        h2 = self.settings.regularize_h ** 2
        wr = None
        for i in range(len(rd)):
            E = np.empty((T.shape[0], 2))
            if rd.lo[i] < 0:
                E.fill(np.nan)
            else:
                _k.laser_error_kernel(T, rd.mx[i], rd.mz[i], rd.mounts[i], self.seam.points, int(rd.lo[i]),
                                      int(rd.hi[i]), E)
            if errors:
                s2 = 0.5 * (rd.r2[i, 0] + rd.r2[i, 1])
                if h2 > 0.0:
                    if wr is None:
                        wr = normalize_log_weights(self.logw + ll_robot).w
                    mom_m, mom_c = np.empty(2), np.empty((2, 2))
                    found = _ck.weighted_moments_kernel(E, wr, mom_m, mom_c) > 0.0
                    s2 += h2 * 0.5 * (mom_c[0, 0] + mom_c[1, 1]) if found else 0.0
                self._s2[i] = s2
                cols.append(E)
            s2 = self._s2[i]
            miss = self._miss2[i]
            e2 = (E * E).sum(axis=1)
            ll += -math.log(2.0 * math.pi * s2) - (0.5 / s2) * np.where(np.isnan(e2), miss, e2)
        if self._angle_sigma and inputs.angle_rad is not None:
            for a in np.asarray(inputs.angle_rad, dtype=np.float64):
                if np.isfinite(a):
                    ll += angle_loglik(T, a, self.seam_normal, self._angle_sigma)
        if errors:
            return ll, ll_robot, (np.hstack(cols) if cols else np.empty((T.shape[0], 0)))
        return ll

    # ------------------------------------------------------------------------------------ the step

    def step(self, inputs: StepInputs) -> StepEstimate:
        """Propagate, weight, estimate and (if needed) resample; see the module docstring."""
        st = self.settings
        t = float(inputs.time_s)
        self._remember(t, inputs.q_ref)
        force = np.asarray(inputs.force_n, dtype=np.float64)
        force_norm = math.sqrt(float(force @ force))  # N; NaN stays NaN for the integrity monitor
        # 1. state transition (eq. 3): the profile's walk over the step's travel, wider after a step not tracking
        travel = float(np.linalg.norm(np.asarray(inputs.T_increment, dtype=np.float64)[:3, 3]))
        travel = travel if math.isfinite(travel) else 0.0
        scale = st.reacquire_walk_scale if self._last_status != "tracking" else 1.0
        sig = self._walk * (math.sqrt(travel) * scale)
        with np.errstate(invalid="ignore"):
            meas = robot_measurement(self.chain, np.asarray(inputs.q_meas, dtype=np.float64), force,
                                     compliance=self.compliance, **self._robot_kw)
        self.T = transition(self.T, self._deflected_increment(inputs.T_increment, meas), sig[:3], sig[3:],
                            self.rng, noise_buffer=self._noise)
        # 2. measurement update: robot (eq. 5, 8) + lasers at their readings' times (eq. 9) + angles
        with np.errstate(invalid="ignore"):
            drawn = self._init_pending and np.isfinite(meas.T_mean).all()
            if drawn:
                self.T = self._draw_from_robot(meas)  # the prior: where the robot can be
                self._init_pending = False
            rd, radius, sensor = self._readings(inputs, meas, self._reading_mounts(inputs))
            used = len(rd)
            self._s2 = np.empty(used)
            self._miss2 = radius * radius
            ll, ll_robot, E = self._loglik(self.T, rd, inputs, meas, errors=True)
            # integrity: the lasers' innovations under the cloud before the lasers weight it
            signed = np.full(2 * self._n_sensors, np.nan)
            if used:
                nis, dof, r = innovation_nis(E, normalize_log_weights(self.logw + ll_robot).w, rd.r2.reshape(-1),
                                             per_component=True, signed=True)
                signed[np.repeat(2 * np.asarray(sensor), 2) + np.tile([0, 1], used)] = r
            else:
                nis, dof = 0.0, 0
            components = signed * signed
        norm = normalize_log_weights(self.logw + ll)
        ess = effective_sample_size(norm.w)
        ess_update = ess
        # 2b. a likelihood far narrower than the cloud (start-up, a feature): temper it in stages; a filter that
        # has lost the track gets 2 (tempering cannot make inconsistent data consistent, it only costs time)
        stages = 0
        remaining = 1.0
        max_stages = st.anneal_stages if (drawn or self._last_status != "lost") else min(st.anneal_stages, 2)
        while not norm.recovered and ess < st.anneal_ess * self.n and stages < max_stages:
            beta = self._temper(ll, remaining, 0.5 * self.n)
            self.T = self._kernel_resample(self.T, normalize_log_weights(self.logw + beta * ll).w,
                                           st.regularize_h, shrink=False)
            self.logw = np.full(self.n, -math.log(self.n))
            remaining -= beta
            ll = self._loglik(self.T, rd, inputs, meas)
            norm = normalize_log_weights(self.logw + remaining * ll)
            ess = effective_sample_size(norm.w)
            stages += 1
        self.annealings += stages
        # 3. normalise (recover from vanishing weights), estimate
        self.recoveries += norm.recovered
        w = norm.w
        resampled = ess < st.ess_threshold * self.n
        h = st.regularize_h if resampled else 0.0
        cloud = self._cloud(self.T, w)
        T_mean, spread = cloud[0], cloud[1]
        self._lasers_seen += used
        if self._lasers_seen == 0 and not norm.recovered:
            # no laser reading yet: the robot measurement is the only information, and the mean of its symmetric
            # density (eq. 8) is its centre, the kinematic pose (the cloud's own mean wanders in the plateau)
            T_mean = meas.T_mean.copy()
        m_t, m_r = robot_consistency(T_mean, spread, meas)
        if np.isfinite(T_mean).all():
            # the particle approximation's own noise: the mean of ESS effective particles moves by the cloud's
            # covariance over ESS, which the lasers correct only where they see
            Q_pf = (cloud[4] @ cloud[4].T) / ess if ess >= 1.0 else None
            bound = self._bound.update(T_mean, meas, sig * sig, rd, self.seam.points, Q_pf)
            spread = np.maximum(spread, bound)
        spread = np.hypot(spread * self._scale, self._jitter)
        # 4. resample (regularised: see _kernel_resample)
        if resampled:
            if h > 0.0:
                self.T = self._kernel_resample(self.T, w, h, shrink=True, cloud=cloud)
            else:
                self.T = self.T[self._resample(w, self.rng)]
            self.logw = np.full(self.n, -math.log(self.n))
            self.resamplings += 1
        else:
            self.logw = norm.logw
        rep = self.integrity.update(nis, dof, m_t, m_r, ess_update, norm.recovered, force_norm, components, signed,
                                    kinematic_offset(T_mean, meas.T_mean) if self.integrity.tests_offset else None)
        self.report = rep  # the step's consistency statistics (IntegrityReport)
        # the walk reacts to the consistency tests, not to the force range
        previous, self._last_status = self._last_status, rep.tests_status
        if rep.tests_status == "lost":
            self._bound.reset()  # the information gathered before the track was lost no longer holds
            if previous != "lost":
                # the cloud no longer explains the data: draw it again from the robot density (about the kinematic
                # pose itself) at the next step, once per loss
                self._init_pending = True
                self._offset = np.eye(4)
        return StepEstimate(T_mean, spread, ess, bool(resampled), norm.recovered, meas.T_mean, used, stages,
                            rep.status, rep.reason, nis, ess_update, components, signed)

    @property
    def weights(self) -> np.ndarray:
        """Normalised weights ``exp(logw)``, shape (N,)."""
        return np.exp(self.logw)
