"""The spread the data support: a linearised covariance run beside the particle cloud (issue 15, an honest spread).

The particle cloud represents the posterior only where it has particles. In directions the lasers barely see
(along the seam, the roll about it) the likelihood is flat over the robot density's plateau; a few hundred
particles cannot fill that plateau, the cloud shrinks and its spread falls far below the error.

:class:`InformationBound` runs the covariance ``P`` of a linear-Gaussian filter with the particle filter's own
model, in the tangent space of the estimate (tool frame ``[x, y, z, rx, ry, rz]``, mm and rad):

* predict: ``P ← P + diag(walk² s) + Q_pf`` — the profile's random walk over the step's travel (eq. 3), and the particle
  approximation's own noise ``Q_pf`` (the cloud's covariance over its effective sample size: the weighted mean
  of a few hundred particles wanders by it where the lasers do not pull it back);
* robot plateau: the robot density is flat inside its plateau and gives no information there, but the pose
  cannot leave it: every axis of ``P`` is capped at the plateau's variance (a uniform ball of radius ``d``:
  ``d²/5`` per axis; the rotation ellipsoid likewise) plus its Gaussian tails;
* lasers: ``P ← P - P Hᵀ (H P Hᵀ + R)⁻¹ H P`` with ``H`` the Jacobian of the step's in-plane laser errors with
  respect to the estimate's tangent offset (central differences of eq. 9's own error function) and ``R`` each
  reading's variance (the profile's laser noise plus the pose jitter through the sensor's lever).

The filter reports ``max(cloud, sqrt(diag P))`` per axis (plus the jitter). Where the lasers see the pose ``P`` is
the Kalman covariance of the same data and rarely exceeds the cloud's; where they do not, it stays near the
plateau, which is what the data support. The estimate is unchanged. Limit: ``P`` is the covariance of a
linearised filter; while the cloud converges from a wide plateau the particles' estimate can be worse than it.
"""

import math

import numpy as np

from posekit.seam.engine import _kernels as _k
from posekit.seam.engine import _linear as _l

__all__ = ["InformationBound", "Readings", "laser_jacobian", "plateau_covariance"]

_STEP_T = 1e-3  # mm, central-difference step of the Jacobian (translation)
_STEP_R = 1e-5  # rad (rotation)
_ZERO6 = np.zeros((6, 6))


class Readings:
    """The laser readings of one step as arrays for the compiled kernels.

    Attributes
    ----------
    mx, mz : ndarray, shape (S,)
        The readings in their sensor frames (mm; NaN: none).
    mounts : ndarray, shape (S, 4, 4)
        Effective mounts: the sensor in the frame of the tool pose of the step (latency included), mm.
    lo, hi : ndarray of int64, shape (S,)
        Knot windows of the seam search (``lo < 0``: the reading is not used).
    r2 : ndarray, shape (S, 2)
        Variance of each reading along the sensor's x and z axes (mm²).
    """

    __slots__ = ("hi", "lo", "mounts", "mx", "mz", "r2")

    def __init__(self, mx, mz, mounts, lo, hi, r2):
        self.mx = np.ascontiguousarray(mx, dtype=np.float64)
        self.mz = np.ascontiguousarray(mz, dtype=np.float64)
        self.mounts = np.ascontiguousarray(mounts, dtype=np.float64).reshape(-1, 4, 4)
        self.lo = np.ascontiguousarray(lo, dtype=np.int64)
        self.hi = np.ascontiguousarray(hi, dtype=np.int64)
        self.r2 = np.ascontiguousarray(r2, dtype=np.float64).reshape(-1, 2)

    @classmethod
    def none(cls) -> "Readings":
        """No reading."""
        return cls(np.empty(0), np.empty(0), np.empty((0, 4, 4)), np.empty(0), np.empty(0), np.empty((0, 2)))

    def __len__(self) -> int:
        return int(self.mx.shape[0])


def laser_jacobian(T: np.ndarray, readings: Readings, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The lasers' in-plane errors at ``T`` and their Jacobian with respect to its tangent offset.

    Parameters
    ----------
    T : ndarray, shape (4, 4)
        Pose ``T_base_tool`` at which to linearise (mm).
    readings : Readings
    points : ndarray, shape (K, 3)
        Seam knots (mm).

    Returns
    -------
    H : ndarray, shape (m, 6)
        Rows sensor x then z per used reading (mm per mm, mm per rad); readings whose plane misses the seam
        at ``T`` or a perturbed pose are dropped.
    e : ndarray, shape (m,)
        The errors ``m̂ - pi`` at ``T`` (mm).
    """
    n = len(readings)
    H = np.empty((2 * n, 6))
    e0 = np.empty(2 * n)
    r2 = np.empty(2 * n)
    m = _l.laser_rows(np.ascontiguousarray(T, dtype=np.float64), readings.mx, readings.mz, readings.mounts,
                      readings.lo, readings.hi, np.ascontiguousarray(points, dtype=np.float64), readings.r2,
                      _STEP_T, _STEP_R, H, e0, r2)
    return H[:m], e0[:m]


def plateau_covariance(meas, R_est: np.ndarray) -> np.ndarray:
    """Covariance ``(6, 6)`` of the robot density (uniform plateau + Gaussian tails) in the tool frame (NumPy).

    Parameters
    ----------
    meas : RobotMeasurement
        The step's robot density (``d_t_mm``, ``d_r_rad``, ``A_r``, ``Sigma_t``, ``Sigma_r``; base frame).
    R_est : ndarray, shape (3, 3)
        Orientation of the estimate (the tangent frame).

    Returns
    -------
    ndarray, shape (6, 6)
        Block diagonal: translation mm², rotation rad² (uniform ball of radius d: d²/5 per axis).
    """
    C = np.zeros((6, 6))
    Ct = (meas.d_t_mm ** 2 / 5.0) * np.eye(3) + meas.Sigma_t
    Ai = np.eye(3) if meas.A_r is None else np.linalg.inv(meas.A_r)
    Cr = (meas.d_r_rad ** 2 / 5.0) * (Ai @ Ai.T) + meas.Sigma_r
    C[:3, :3] = R_est.T @ Ct @ R_est
    C[3:, 3:] = R_est.T @ Cr @ R_est
    return C


class InformationBound:
    """The covariance the data support, run beside the particle cloud (see the module docstring).

    Attributes
    ----------
    P : ndarray, shape (6, 6) or None
        The covariance after the last update (None before the first).
    """

    def __init__(self):
        self.P = None

    def reset(self) -> None:
        """Forget the covariance (a new episode, or the track was lost: start again from the plateau)."""
        self.P = None

    def update(self, T_est: np.ndarray, meas, q2: np.ndarray, readings: Readings, points: np.ndarray,
               Q_pf: np.ndarray | None = None) -> np.ndarray:
        """One step: predict, cap at the robot plateau, condition on the lasers (compiled; :meth:`update_numpy`
        is the same in NumPy).

        Parameters
        ----------
        T_est : ndarray, shape (4, 4)
            The filter's estimate of the step (mm).
        meas : RobotMeasurement
            The step's robot density.
        q2 : ndarray, shape (6,)
            The walk's variance over the step per tool axis (mm², rad²).
        readings : Readings
            The step's laser readings.
        points : ndarray, shape (K, 3)
            Seam knots (mm).
        Q_pf : ndarray, shape (6, 6), optional
            The particle approximation's own noise of the step (mm², rad², tool frame).

        Returns
        -------
        ndarray, shape (6,)
            Standard deviations ``sqrt(diag P)`` (mm, rad), tool frame.
        """
        T = np.ascontiguousarray(T_est, dtype=np.float64)
        first = self.P is None or not np.isfinite(self.P).all()
        if first:
            self.P = np.zeros((6, 6))
        A_inv = np.eye(3) if meas.A_r is None else np.linalg.inv(meas.A_r)
        C = np.empty((6, 6))
        _l.plateau_cov(T, np.ascontiguousarray(meas.Sigma_t, dtype=np.float64),
                       np.ascontiguousarray(meas.Sigma_r, dtype=np.float64), A_inv, float(meas.d_t_mm),
                       float(meas.d_r_rad), C)
        Q = _ZERO6 if Q_pf is None else np.ascontiguousarray(Q_pf, dtype=np.float64)
        _l.predict_capped(self.P, C, first, np.ascontiguousarray(q2, dtype=np.float64), Q)
        n = len(readings)
        if n:
            H = np.empty((2 * n, 6))
            e0 = np.empty(2 * n)
            r2 = np.empty(2 * n)
            m = _l.laser_rows(T, readings.mx, readings.mz, readings.mounts, readings.lo, readings.hi,
                              np.ascontiguousarray(points, dtype=np.float64), readings.r2, _STEP_T, _STEP_R,
                              H, e0, r2)
            _l.kalman_update(self.P, H, e0, r2, m, np.empty(6))
        return np.sqrt(np.clip(np.diag(self.P), 0.0, None))

    def update_numpy(self, T_est: np.ndarray, meas, q2: np.ndarray, readings: Readings, points: np.ndarray,
                     Q_pf: np.ndarray | None = None) -> np.ndarray:
        """:meth:`update` in NumPy (the reference the compiled kernels are tested against)."""
        T_est = np.asarray(T_est, dtype=np.float64)
        C = plateau_covariance(meas, T_est[:3, :3])
        c = np.diag(C)
        if self.P is None or not np.isfinite(self.P).all():
            P = C.copy()
        else:
            P = self.P + np.diag(q2) + (0.0 if Q_pf is None else np.asarray(Q_pf, dtype=np.float64))
            with np.errstate(invalid="ignore", divide="ignore"):
                s = np.sqrt(np.minimum(1.0, c / np.diag(P)))
            s[~np.isfinite(s)] = 1.0
            P = P * s[:, None] * s[None, :]
        rows, errs, var = [], [], []
        for i in range(len(readings)):
            one = Readings(readings.mx[i:i + 1], readings.mz[i:i + 1], readings.mounts[i:i + 1],
                           readings.lo[i:i + 1], readings.hi[i:i + 1], readings.r2[i:i + 1])
            Hi, ei = _numpy_rows(T_est, one, points)
            if Hi.shape[0]:
                rows.append(Hi)
                errs.append(ei)
                var.append(readings.r2[i])
        if rows:
            H = np.vstack(rows)
            R = np.diag(np.concatenate(var))
            PH = P @ H.T
            P = P - PH @ np.linalg.solve(H @ PH + R, PH.T)
        self.P = 0.5 * (P + P.T)
        return np.sqrt(np.clip(np.diag(self.P), 0.0, None))


def _numpy_rows(T: np.ndarray, readings: Readings, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`laser_jacobian` with the perturbed poses built in NumPy (one reading; the reference)."""
    out = np.repeat(T[None], 13, axis=0)
    R = T[:3, :3]
    for j in range(3):
        for s, sign in ((2 * j, 1.0), (2 * j + 1, -1.0)):
            out[s, :3, 3] = T[:3, 3] + sign * _STEP_T * R[:, j]
            a = sign * _STEP_R
            G = np.eye(3)
            k, m = (j + 1) % 3, (j + 2) % 3
            G[k, k] = G[m, m] = math.cos(a)
            G[m, k], G[k, m] = math.sin(a), -math.sin(a)
            out[6 + s, :3, :3] = R @ G
    if len(readings) == 0 or readings.lo[0] < 0:
        return np.empty((0, 6)), np.empty(0)
    E = np.empty((13, 2))
    _k.laser_error_kernel(np.ascontiguousarray(out), float(readings.mx[0]), float(readings.mz[0]),
                          readings.mounts[0], np.ascontiguousarray(points, dtype=np.float64), int(readings.lo[0]),
                          int(readings.hi[0]), E)
    if not np.isfinite(E).all():
        return np.empty((0, 6)), np.empty(0)
    H = np.empty((2, 6))
    for j in range(3):
        H[:, j] = (E[2 * j] - E[2 * j + 1]) / (2.0 * _STEP_T)
        H[:, 3 + j] = (E[6 + 2 * j] - E[6 + 2 * j + 1]) / (2.0 * _STEP_R)
    return H, E[12]
