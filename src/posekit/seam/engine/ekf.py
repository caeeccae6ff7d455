"""The particle filter's model as a linearised (extended Kalman) filter: the likelihood ``posekit seam tune`` fits.

The particle filter and this filter share one state-space model (:mod:`posekit.seam.engine.filter`): the tool pose
moves with the program's increment and the modelled deflection (``U_k = D_k T+ D_{k-1}⁻¹``) plus a random walk of
``walk² ds`` per tool axis (``ds`` the program's travel over the step); the robot density caps the covariance at its plateau (eq. 8: flat inside, so it
informs nothing there); each laser reading is the in-plane error of eq. 9 at the reading's time (the sensor's
effective mount ``Fk(q̄(t))⁻¹ Fk(q̄(t - L)) T_tool_sensor``) with variance ``σ² + jitter`` through the sensor's
lever. Run once over an episode it gives the prediction-error decomposition of the lasers' likelihood,
``-log p(m_1..m_T) = Σ_k ½ (e_kᵀ S_k⁻¹ e_k + log det S_k + m_k log 2π)``, the criterion a Kalman-filter tuner
maximises over the walk, the laser noise and the latency (:mod:`posekit.seam.frontend.tune`).

:class:`LinearisedEpisode` precomputes what does not depend on those parameters (the robot density of every step,
the modelled motion, the knots); :meth:`LinearisedEpisode.nll` is one compiled pass (:func:`._linear.ekf_pass`).
"""

from dataclasses import dataclass

import numpy as np

from posekit.geometry import invert_transform
from posekit.seam.engine import _linear as _l
from posekit.seam.engine.densities import joint_compliance, robot_measurement
from posekit.seam.engine.step import jitter_variances
from posekit.seam.model import Cell, Profile

__all__ = ["EpisodeArrays", "LinearisedEpisode", "reading_mounts"]

_STEP_T = 1e-3  # mm, central-difference step of the laser Jacobian
_STEP_R = 1e-5  # rad


@dataclass
class EpisodeArrays:
    """One episode's samples as the filter reads them.

    Attributes
    ----------
    time_s : ndarray, shape (T,)
    q_ref, q_meas : ndarray, shape (T, n)
        Program and measured joints (rad).
    force_base_n : ndarray, shape (T, 3)
        Measured force on the tool, base frame (N).
    laser_mm : ndarray, shape (T, S, 2)
        Readings in their sensor frames (mm; NaN: none).
    reading_lag_s : ndarray, shape (T, S) or None
        How long before the sample each reading was taken when stamped (s; NaN: the sensor's latency).
    """

    time_s: np.ndarray
    q_ref: np.ndarray
    q_meas: np.ndarray
    force_base_n: np.ndarray
    laser_mm: np.ndarray
    reading_lag_s: np.ndarray | None = None


def reading_mounts(chain, mounts, time_s, q_ref, latency_s, reading_lag_s=None, T_nominal=None) -> np.ndarray:
    """Every reading's effective mount ``Fk(q̄(t_k))⁻¹ Fk(q̄(t_k - L)) T_tool_sensor``, shape (T, S, 4, 4), mm.

    Parameters
    ----------
    chain : KinematicChain
        The robot with its tool.
    mounts : ndarray, shape (S, 4, 4)
        ``T_tool_sensor`` (mm).
    time_s : ndarray, shape (T,)
    q_ref : ndarray, shape (T, n)
        The program's joints (rad), interpolated linearly in time (the earliest before the first sample).
    latency_s : array_like, shape (S,)
        Each sensor's latency (s).
    reading_lag_s : ndarray, shape (T, S), optional
        The readings' own lags where stamped (s; NaN: the latency).
    T_nominal : ndarray, shape (T, 4, 4), optional
        ``Fk(q_ref)`` when already computed.
    """
    t = np.asarray(time_s, dtype=np.float64)
    q_ref = np.asarray(q_ref, dtype=np.float64)
    Tn = chain.forward_kinematics(q_ref, check=False) if T_nominal is None else T_nominal
    Tn_inv = None
    S = mounts.shape[0]
    out = np.empty((t.shape[0], S, 4, 4))
    for i in range(S):
        lag = np.full(t.shape[0], float(latency_s[i]))
        if reading_lag_s is not None:
            given = reading_lag_s[:, i]
            lag = np.where(np.isfinite(given), given, lag)
        if not np.any(lag != 0.0):
            out[:, i] = mounts[i]
            continue
        if Tn_inv is None:
            Tn_inv = invert_transform(Tn, check=False)
        tq = t - lag
        q = np.stack([np.interp(tq, t, q_ref[:, j]) for j in range(q_ref.shape[1])], -1)
        out[:, i] = np.matmul(np.matmul(Tn_inv, chain.forward_kinematics(q, check=False)), mounts[i])
    return out


class LinearisedEpisode:
    """An episode prepared for the linearised filter (see the module docstring).

    Parameters
    ----------
    cell : Cell
    profile : Profile
        Its plateau, tails and joint noise shape the robot density (they are not tuned here).
    data : EpisodeArrays
    knots_mm : array_like, shape (K, 3)
        The seam polyline the lasers are compared with (base frame, mm).
    """

    def __init__(self, cell: Cell, profile: Profile, data: EpisodeArrays, knots_mm):
        self.cell = cell
        self.data = data
        self.points = np.ascontiguousarray(knots_mm, dtype=np.float64)
        chain = cell.chain
        n = data.time_s.shape[0]
        cj = joint_compliance(cell.compliance_rad_per_nm) if cell.compliance_rad_per_nm > 0.0 else None
        self.T_nominal = chain.forward_kinematics(np.asarray(data.q_ref, dtype=np.float64), check=False)
        self.K = np.empty((n, 4, 4))
        self.U = np.empty((n, 4, 4))
        self.Sigma_t = np.empty((n, 3, 3))
        self.Sigma_r = np.empty((n, 3, 3))
        self.A_inv = np.empty((n, 3, 3))
        self.d_t = np.empty(n)
        self.d_r = np.empty(n)
        kw = {"joint_sigma_rad": profile.joint_sigma_rad, "floor_t_mm": profile.tail_mm,
              "floor_r_rad": profile.tail_rad, "d0_mm": profile.d0_mm, "kd_mm_per_n": profile.kd_mm_per_n,
              "d0_rad": profile.d0_rad, "kd_rad_per_n": profile.kd_rad_per_n, "bending": True}
        D_prev = None
        for k in range(n):
            meas = robot_measurement(chain, np.asarray(data.q_meas[k], dtype=np.float64),
                                     np.asarray(data.force_base_n[k], dtype=np.float64), compliance=cj, **kw)
            self.K[k] = meas.T_mean
            self.Sigma_t[k] = meas.Sigma_t
            self.Sigma_r[k] = meas.Sigma_r
            self.A_inv[k] = np.eye(3) if meas.A_r is None else np.linalg.inv(meas.A_r)
            self.d_t[k] = meas.d_t_mm
            self.d_r[k] = meas.d_r_rad
            inc = np.eye(4) if k == 0 else self.T_nominal[k] @ invert_transform(self.T_nominal[k - 1], check=False)
            D = meas.T_deflection
            if D is not None and D_prev is not None:
                inc = D @ inc @ invert_transform(D_prev, check=False)
            D_prev = D if D is not None else D_prev
            self.U[k] = inc
        self.dt = np.r_[0.0, np.diff(np.asarray(data.time_s, dtype=np.float64))]
        self.ds = np.r_[0.0, np.linalg.norm(np.diff(self.T_nominal[:, :3, 3], axis=0), axis=1)]  # mm travelled
        self.mounts0 = np.ascontiguousarray(cell.mounts)
        self.lever = np.linalg.norm(self.mounts0[:, :3, 3], axis=1) if self.mounts0.size else np.zeros(0)
        self.laser = np.ascontiguousarray(data.laser_mm, dtype=np.float64)

    @property
    def steps(self) -> int:
        """Number of samples T."""
        return int(self.U.shape[0])

    def mounts(self, latency_s) -> np.ndarray:
        """Effective mounts ``(T, S, 4, 4)`` for the sensors' latencies ``(S,)`` (:func:`reading_mounts`)."""
        d = self.data
        return reading_mounts(self.cell.chain, self.mounts0, d.time_s, d.q_ref, latency_s, d.reading_lag_s,
                              self.T_nominal)

    def run(self, walk, sigma_mm, latency_s, jitter, mounts: np.ndarray | None = None):
        """One pass of the linearised filter.

        Parameters
        ----------
        walk : array_like, shape (6,)
            Random walk per tool axis (mm/√mm, rad/√mm of travel).
        sigma_mm, latency_s : array_like, shape (S,)
            Laser noise (mm) and latency (s) per sensor.
        jitter : array_like, shape (6,)
            White pose jitter (mm, rad).
        mounts : ndarray, shape (T, S, 4, 4), optional
            :meth:`mounts` of ``latency_s`` when already computed.

        Returns
        -------
        nll : float
            The lasers' negative log-likelihood.
        T_est : ndarray, shape (T, 4, 4)
            The filter's pose after each step (mm).
        P_diag : ndarray, shape (T, 6)
            Its variances (mm², rad², tool frame).
        """
        Ms = self.mounts(latency_s) if mounts is None else mounts
        r2 = (np.asarray(sigma_mm, dtype=np.float64) ** 2)[:, None] + jitter_variances(self.mounts0, jitter)
        q2 = np.asarray(walk, dtype=np.float64) ** 2
        out_T = np.empty((self.steps, 4, 4))
        out_P = np.empty((self.steps, 6))
        nll = _l.ekf_pass(self.U, self.K[0], self.K, self.Sigma_t, self.Sigma_r, self.A_inv, self.d_t, self.d_r,
                          self.laser, np.ascontiguousarray(Ms), np.ascontiguousarray(r2), q2, self.ds, self.points,
                          np.ascontiguousarray(self.lever, dtype=np.float64), _STEP_T, _STEP_R, out_T, out_P)
        return float(nll), out_T, out_P

    def nll(self, walk, sigma_mm, latency_s, jitter, mounts: np.ndarray | None = None) -> float:
        """The lasers' negative log-likelihood of :meth:`run` (inf when it breaks down)."""
        value = self.run(walk, sigma_mm, latency_s, jitter, mounts)[0]
        return value if np.isfinite(value) else np.inf
