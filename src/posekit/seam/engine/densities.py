"""The densities of the particle filter (paper §II-C), vectorised over particles.

Transition (eq. 3)
    ``x+ = T+ x exp(ξ)``, ``T+ = Fk(q̄+) Fk(q̄)^-1``, ``ξ ~ N(0, diag(σt², σr²))`` in the tool
    frame with ``σt = sigma_t_mm + k_force_t ‖f‖``, ``σr = sigma_r + k_force_r ‖f‖``.
Robot measurement (eq. 5, 7, 8)
    mean ``μ = Fk(q + Cj(τ))`` (``τ = J_vᵀ f``, Cj a compliance hook), error in twist
    coordinates of the base frame ``Δ = [p - p_μ, log(R R_μᵀ)]`` (the geometric Jacobian's
    convention), covariance ``J Σq Jᵀ`` (+ a floor). The time-correlated errors (kinematic
    model, deflection) are the uniform plateau of eq. 8 with radius ``d(f) = d0 + kd ‖f‖``;
    translation (mm) and rotation (rad) are two 3-D blocks, each with its own radius,
    because a single radius over mixed units has no meaning.
Laser (eq. 9, Fig. 4)
    ``m̂ = x T_T_S [m_x, 0, m_z, 1]ᵀ`` (the seam point the particle believes the sensor saw),
    ``pi`` the intersection of the particle's laser plane with the seam polyline,
    ``e = m̂ - pi`` Gaussian with ``σ = laser_sigma_mm`` in the laser plane.
Angle
    The workpiece rotation about the laser-plane normal: ``atan2(ν·x_S, ν·z_S)`` for the
    seam surface normal ``ν``; Gaussian error.
"""

import math
from collections.abc import Callable

import numpy as np

from posekit.geometry import invert_transform
from posekit.robots import KinematicChain
from posekit.seam.engine import _kernels as _k
from posekit.seam.engine.seamline import SeamLine

__all__ = [
    "RobotMeasurement",
    "angle_loglik",
    "ball_volume",
    "bending_stretch",
    "joint_compliance",
    "laser_loglik",
    "plateau_logpdf",
    "plateau_pdf_1d",
    "robot_consistency",
    "robot_loglik",
    "robot_measurement",
    "transition",
]


_TWO_PI_1P5 = (2.0 * math.pi) ** 1.5
_EYE3 = np.eye(3)


def ball_volume(d: float, k: int) -> float:
    """Volume ``V(d, k)`` of a k-dimensional ball of radius ``d``."""
    if d <= 0.0:
        return 0.0
    return math.exp(0.5 * k * math.log(math.pi) - math.lgamma(0.5 * k + 1.0) + k * math.log(d))


def plateau_logpdf(delta: np.ndarray, d: float, Sigma: np.ndarray) -> np.ndarray:
    """Log of the Gaussian + uniform plateau density of eq. (8).

    ``p = D`` inside the ball ``‖Δ‖ <= d``, ``D exp(-½ δᵀ Σ⁻¹ δ)`` outside, with
    ``δ = (1 - d/‖Δ‖) Δ`` and ``D = 1 / ((2π)^(k/2) √det Σ + V(d, k))``. In one dimension this
    is eq. (7) and integrates to 1; with ``d = 0`` it is the Gaussian ``N(0, Σ)``.

    Parameters
    ----------
    delta : ndarray, shape (N, k)
        Errors ``Δ = x - μ`` (any unit, the same as ``d`` and ``√Σ``).
    d : float
        Plateau radius, >= 0.
    Sigma : ndarray, shape (k, k)
        Covariance of the Gaussian tails, positive definite.

    Returns
    -------
    logp : ndarray, shape (N,)
    """
    r = np.sqrt((delta * delta).sum(axis=1))
    shrink = np.where(r > d, 1.0 - d / np.where(r > 0, r, 1.0), 0.0)
    dd = delta * shrink[:, None]
    Sinv = np.linalg.inv(Sigma)
    maha = ((dd @ Sinv) * dd).sum(axis=1)
    return _plateau_log_norm(d, Sigma) - 0.5 * maha


def _plateau_log_norm(d: float, Sigma: np.ndarray) -> float:
    """``log D`` of eq. (8) for a k×k covariance."""
    k = Sigma.shape[0]
    return -math.log((2.0 * math.pi) ** (0.5 * k) * math.sqrt(np.linalg.det(Sigma)) + ball_volume(d, k))


def plateau_pdf_1d(x, mu: float, d: float, sigma: float) -> np.ndarray:
    """Eq. (7): ``C`` for ``|x - μ| <= d``, ``C exp(-(|x - μ| - d)² / 2σ²)`` outside,
    ``C = 1 / (√(2π) σ + 2d)``. ``x`` any shape; returns the same shape."""
    x = np.asarray(x, dtype=np.float64)
    flat = (x.reshape(-1, 1) - mu)
    return np.exp(plateau_logpdf(flat, d, np.array([[sigma * sigma]]))).reshape(x.shape)


def transition(Ts: np.ndarray, T_increment: np.ndarray, sigma_t_mm, sigma_r_rad,
               rng: np.random.Generator, *, noise_buffer: np.ndarray | None = None) -> np.ndarray:
    """Sample the state transition of eq. (3) for all particles: ``x+ = T+ x exp(ξ)``.

    Parameters
    ----------
    Ts : ndarray, shape (N, 4, 4)
        Particle poses ``T_base_tool`` (mm).
    T_increment : ndarray, shape (4, 4)
        ``T+ = Fk(q̄+) Fk(q̄)^-1`` in the base frame.
    sigma_t_mm, sigma_r_rad : float or array_like, shape (3,)
        Noise widths (translation mm, rotation rad) in the tool frame, already scaled with
        the force; one per axis (x, y, z) or one for all three.
    rng : numpy.random.Generator
    noise_buffer : ndarray of float32, shape (N, 6), optional
        Reused for the standard-normal draws (float32: half the cost of float64 draws).

    Returns
    -------
    Ts_new : ndarray, shape (N, 4, 4)
    """
    n = Ts.shape[0]
    z = np.empty((n, 6), np.float32) if noise_buffer is None else noise_buffer
    rng.standard_normal(out=z, dtype=np.float32)
    sig = np.empty(6)
    sig[:3] = sigma_t_mm
    sig[3:] = sigma_r_rad
    out = np.empty_like(Ts)
    _k.propagate(Ts, np.asarray(T_increment, dtype=np.float64), z, sig, out)
    return out


def joint_compliance(c_rad_per_nm: float) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    """A diagonal joint compliance model ``Cj(q, τ) = c τ`` with ``c`` in rad/(N·m).

    The returned callable takes ``q (n,)`` (rad) and ``τ (n,)`` in N·mm (the unit of
    ``J_vᵀ f`` with J in mm/rad) and returns ``Δq (n,)`` in rad."""

    def cj(q: np.ndarray, tau_nmm: np.ndarray) -> np.ndarray:
        return (c_rad_per_nm * 1e-3) * tau_nmm

    return cj


class RobotMeasurement:
    """The robot measurement density for one time step (eq. 5, 7, 8).

    Attributes
    ----------
    T_mean : ndarray, shape (4, 4)
        ``μ = Fk(q + Cj(τ))`` in the base frame (the kinematics-only tool pose), mm.
    Sigma_t : ndarray, shape (3, 3)
        Translation covariance (mm²), ``[J Σq Jᵀ]_tt + floor²``.
    Sigma_r : ndarray, shape (3, 3)
        Rotation covariance (rad²), ``[J Σq Jᵀ]_rr + floor²``.
    d_t_mm, d_r_rad : float
        Plateau radii ``d(f)``; the rotation plateau is the ellipsoid ``‖A_r Δr‖ <= d_r_rad``.
    A_r : ndarray, shape (3, 3) or None
        Shape of the rotation plateau (None: a ball of radius ``d_r_rad``).
    T_deflection : ndarray, shape (4, 4) or None
        The modelled deflection as a base-frame transform, ``Fk(q + Cj(τ)) Fk(q)⁻¹`` (mm); None
        without a compliance model.
    """

    __slots__ = ("A_r", "Sigma_r", "Sigma_t", "T_deflection", "T_mean", "d_r_rad", "d_t_mm")

    def __init__(self, T_mean, Sigma_t, Sigma_r, d_t_mm, d_r_rad, A_r=None, T_deflection=None):
        self.T_deflection = T_deflection
        self.T_mean = T_mean
        self.Sigma_t = Sigma_t
        self.Sigma_r = Sigma_r
        self.d_t_mm = d_t_mm
        self.d_r_rad = d_r_rad
        self.A_r = A_r


def bending_stretch(d_r, d0_rad):
    """The bending plateau's stretch along the force: ``A_r = I + s u uᵀ`` (``u`` the force direction)
    with ``s = d_r / d0 - 1``, so that ``‖A_r Δr‖ <= d_r`` allows ``d_r`` across the force and ``d0``
    along it (``d0`` floored at ``1e-3 d_r``: no infinite stretch for ``d0 = 0``). Scalars or arrays, rad."""
    return d_r / np.maximum(d0_rad, 1e-3 * d_r) - 1.0


def robot_measurement(chain: KinematicChain, q_meas: np.ndarray, force_n: np.ndarray, *, joint_sigma_rad: float,
                      floor_t_mm: float, floor_r_rad: float, d0_mm: float, kd_mm_per_n: float,
                      d0_rad: float, kd_rad_per_n: float, bending: bool = False,
                      compliance: Callable | None = None) -> RobotMeasurement:
    """Build the robot measurement density from joint readings and the measured force.

    Parameters
    ----------
    chain : KinematicChain
        Nominal robot model with its tool (DH or URDF).
    q_meas : ndarray, shape (n,)
        Measured joints (rad).
    force_n : ndarray, shape (3,)
        Measured process force on the tool in the base frame, N.
    joint_sigma_rad : float
        Joint measurement noise (Σq = σ² I), rad.
    floor_t_mm, floor_r_rad : float
        Standard deviations added to the Gaussian tails (keep Σ well conditioned).
    d0_mm, kd_mm_per_n, d0_rad, kd_rad_per_n : float
        Plateau radii ``d(f) = d0 + kd ‖f‖`` for translation and rotation.
    bending : bool
        The force-dependent part of the rotation plateau lies perpendicular to the force: an
        ellipsoid with semi-axis ``d0_rad`` along ``f`` and ``d0_rad + kd_rad_per_n ‖f‖``
        across it. A force at the tool centre point has no moment about its own line of
        action, so the tool bends about axes across the force, not about the force. False:
        a ball of radius ``d0_rad + kd_rad_per_n ‖f‖`` (eq. 8 as printed).
    compliance : callable ``Cj(q (n,), τ (n,) in N·mm) -> Δq (n,)``, optional
        The compliance model hook of eq. (5); None: no deflection model.

    Returns
    -------
    RobotMeasurement
    """
    T, J = chain.forward_kinematics_and_jacobian(q_meas, check=False)
    T_defl = None
    if compliance is not None:
        tau = J[:3].T @ force_n  # N·mm: J_v is mm/rad
        T_rigid = T
        T, J = chain.forward_kinematics_and_jacobian(q_meas + compliance(q_meas, tau), check=False)
        T_defl = T @ invert_transform(T_rigid, check=False)
    S = (joint_sigma_rad ** 2) * (J @ J.T)
    fn = float(np.linalg.norm(force_n))
    d_r = d0_rad + kd_rad_per_n * fn
    A_r = None
    if bending and fn > 0.0 and d_r > 0.0:
        # ‖A Δ‖ <= d_r: Δ across f within d_r, along f within d0 (ratio capped for d0 = 0)
        u = np.asarray(force_n, dtype=np.float64) / fn
        A_r = np.eye(3) + float(bending_stretch(d_r, d0_rad)) * np.outer(u, u)
    return RobotMeasurement(
        T,
        S[:3, :3] + floor_t_mm ** 2 * np.eye(3),
        S[3:, 3:] + floor_r_rad ** 2 * np.eye(3),
        d0_mm + kd_mm_per_n * fn,
        d_r,
        A_r,
        T_defl,
    )


def robot_loglik(Ts: np.ndarray, meas: RobotMeasurement) -> np.ndarray:
    """Log-likelihood ``log p(q, f | x)`` of each particle (eq. 8, two 3-D blocks).

    Parameters
    ----------
    Ts : ndarray, shape (N, 4, 4)
        Particle poses in the base frame, mm.
    meas : RobotMeasurement

    Returns
    -------
    loglik : ndarray, shape (N,)
    """
    out = np.zeros(Ts.shape[0])
    A = meas.A_r
    Sinv_t, det_t = _k.inv_det3(meas.Sigma_t)
    if A is None:
        A, log_det_A = _EYE3, 0.0
        Sinv_r, det_r = _k.inv_det3(meas.Sigma_r)
    else:  # the covariance of A Δr; eq. 8's normaliser in those coordinates, times |det A|
        Sinv_r, det_r = _k.inv_det3(A @ meas.Sigma_r @ A.T)
        log_det_A = math.log(abs(_k.inv_det3(A)[1]))
    logD = -math.log(_TWO_PI_1P5 * math.sqrt(det_t) + ball_volume(meas.d_t_mm, 3)) - math.log(
        _TWO_PI_1P5 * math.sqrt(det_r) + ball_volume(meas.d_r_rad, 3)) + log_det_A
    _k.robot_loglik_kernel(Ts, meas.T_mean, Sinv_t, Sinv_r, A, meas.d_t_mm, meas.d_r_rad, logD, out)
    return out


def laser_loglik(Ts: np.ndarray, m_mm: np.ndarray, distance_mm: float, seam: SeamLine,
                 knot_range: tuple[int, int], sigma_mm: float, miss_mm: float) -> np.ndarray:
    """Log-likelihood ``log p(m | x)`` of one laser measurement for each particle (eq. 9).

    Parameters
    ----------
    Ts : ndarray, shape (N, 4, 4)
        Particle tool poses ``T_base_tool``, mm.
    m_mm : ndarray, shape (2,)
        Measured seam position in the laser plane (across = x_S, along the tool axis = z_S), mm.
    distance_mm : float
        Sensor distance ahead of the TCP along +y of the tool (sensor frame = tool frame
        shifted by ``[0, distance, 0]``; the laser plane is its x–z plane).
    seam : SeamLine
        Seam polyline in the base frame (the trend-filter knots).
    knot_range : (int, int)
        First and last knot of the searched stretch (:meth:`SeamLine.window`); ``(-1, -1)``
        for none.
    sigma_mm : float
        Laser measurement standard deviation, mm.
    miss_mm : float
        Error charged to a particle whose laser plane meets no candidate segment.

    Returns
    -------
    loglik : ndarray, shape (N,)

    Notes
    -----
    Of several crossings within the knot range the one nearest ``m̂`` counts (compiled
    kernel; :meth:`SeamLine.intersect` is the NumPy equivalent).
    """
    out = np.zeros(Ts.shape[0])
    lo, hi = knot_range
    if lo < 0:
        out -= 0.5 * (miss_mm / sigma_mm) ** 2 + math.log(2.0 * math.pi * sigma_mm * sigma_mm)
        return out
    _k.laser_loglik_kernel(Ts, float(m_mm[0]), float(m_mm[1]), float(distance_mm), seam.points, lo, hi,
                           float(sigma_mm), float(miss_mm), out)
    return out


def angle_loglik(Ts: np.ndarray, angle_rad: float, surface_normal: np.ndarray, sigma_rad: float) -> np.ndarray:
    """Log-likelihood of an angle measurement for each particle.

    The predicted angle is the workpiece rotation about the laser-plane normal (y of the
    tool/sensor): ``atan2(ν·x, ν·z)`` for the surface normal ``ν`` (base frame, unit).

    Parameters
    ----------
    Ts : ndarray, shape (N, 4, 4)
        Particle tool poses ``T_base_tool``, mm (only the rotations are used).
    angle_rad : float
        Measured angle about the laser-plane normal, rad.
    surface_normal : ndarray, shape (3,)
        Unit normal ``ν`` of the workpiece surface in the base frame.
    sigma_rad : float
        Standard deviation of the angle measurement, rad (> 0).

    Returns
    -------
    loglik : ndarray, shape (N,)
        Gaussian log-density of the wrapped error ``angle_rad - pred`` in (-π, π].
    """
    R = Ts[:, :3, :3]
    pred = np.arctan2(R[:, :, 0] @ surface_normal, R[:, :, 2] @ surface_normal)
    e = (angle_rad - pred + np.pi) % (2.0 * np.pi) - np.pi
    return -0.5 * (e / sigma_rad) ** 2 - math.log(math.sqrt(2.0 * math.pi) * sigma_rad)


def robot_consistency(T_est: np.ndarray, spread: np.ndarray, meas) -> tuple[float, float]:
    """Mahalanobis distances of the estimate from the robot measurement, outside its plateau.

    Parameters
    ----------
    T_est : ndarray, shape (4, 4)
        Estimated tool pose ``T_base_tool``, mm.
    spread : ndarray, shape (6,)
        The estimate's standard deviations in its own frame: x, y, z (mm), rx, ry, rz (rad).
    meas : RobotMeasurement
        The step's robot density (:func:`~posekit.seam.engine.densities.robot_measurement`):
        mean ``T_mean``, tails ``Sigma_t`` (mm²), ``Sigma_r`` (rad²), radii ``d_t_mm``,
        ``d_r_rad``, rotation-plateau shape ``A_r``.

    Returns
    -------
    m_t, m_r : float
        Translation and rotation Mahalanobis distances (each χ² with 3 dof under the model;
        0 inside the plateau). The estimate's spread (rotated into the base frame) is added to
        the tails' covariance.
    """
    A = _EYE3 if meas.A_r is None else np.ascontiguousarray(meas.A_r, dtype=np.float64)
    m_t, m_r = _k.robot_consistency_kernel(np.ascontiguousarray(T_est, dtype=np.float64),
                                           np.ascontiguousarray(spread, dtype=np.float64),
                                           np.ascontiguousarray(meas.T_mean, dtype=np.float64),
                                           np.ascontiguousarray(meas.Sigma_t, dtype=np.float64),
                                           np.ascontiguousarray(meas.Sigma_r, dtype=np.float64), A,
                                           float(meas.d_t_mm), float(meas.d_r_rad))
    return m_t, m_r
