"""Resolved-rate (Cartesian velocity) control with a quaternion orientation error.

Eq. (4)–(5) of the long-reach manipulator paper: the desired joint velocity is

``q̇_d = J⁺(q) [ṗ_d + K_p (p_d - p);  ω_d + K_θ · 2 δr]``

and is integrated over one control period, ``q_d = q + q̇_d dt``. ``J⁺`` is a **damped
least-squares** inverse, ``J⁺ = Jᵀ (J Jᵀ + λ² I)⁻¹``, instead of the paper's ``J⁻¹``: it is
defined for redundant, deficient and singular configurations and equals the pseudo-inverse
for ``λ = 0``. ``δr`` is the vector part of the error quaternion ``r_d ⊗ r⁻¹`` (base frame,
sign chosen so that its scalar part is ≥ 0); it is scaled by 2 so that ``2 δr ≈ θ·axis`` for
small errors and ``K_θ`` is a decay rate in 1/s like ``K_p``. The joint servo of eq. (6),
``u = K_v (q_d - q)``, is the caller's: :func:`resolved_rate_step` returns ``q_d``, clamped
to the joint limits.

:func:`resolved_rate_update` is the compiled step itself (numba): the validated
:func:`resolved_rate_step` calls it, and so do loops that run it thousands of times (the
long-reach arm simulator, the seam program's inverse kinematics) — one implementation.
"""

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from posekit._jit import njit
from posekit.errors import ConfigError
from posekit.geometry import (
    cholesky_solve,
    quaternion_from_entries,
    quaternion_from_matrix,
)

from ._kernels import fk_jacobian_into
from .chain import KinematicChain

__all__ = ["RateGains", "RateStep", "pose_error", "resolved_rate_step", "resolved_rate_update"]


@njit(cache=True, nogil=True)
def resolved_rate_update(q, M, A, q_min, q_max, p_d, R_d, twist_ff, gains, dt, damping, q_out, err_out):
    """One compiled resolved-rate step (eq. 4–5), damped least squares, clamped.

    ``q_out = clamp(q + Jᵀ (J Jᵀ + λ² I)⁻¹ (ff + K e) dt)`` with the pose error
    ``e = [p_d - p; 2 δr]`` at ``q`` written to ``err_out`` (see :func:`pose_error`).

    Parameters
    ----------
    q : ndarray, shape (n,)
        Joints, rad / mm.
    M, A : ndarray, shapes (n + 1, 4, 4), (n, 4)
        The chain's kinematic pack with its tool (``chain.kinematic_pack``).
    q_min, q_max : ndarray, shape (n,)
        Joint limits.
    p_d : ndarray, shape (3,)
        Target position, base frame, mm.
    R_d : ndarray, shape (3, 3)
        Target orientation ``R_base_target``.
    twist_ff : ndarray, shape (6,)
        Feed-forward ``[ṗ_d (mm/s); ω_d (rad/s)]``, base frame.
    gains : ndarray, shape (6,)
        ``K_p`` (3) then ``K_θ`` (3), 1/s.
    dt, damping : float
        Control period (s) and DLS damping ``λ``.
    q_out : ndarray, shape (n,)
        Output joints (may alias ``q``).
    err_out : ndarray, shape (6,)
        Output pose error at the input ``q``, ``[mm; rad]``.
    """
    n = q.shape[0]
    T = np.empty((4, 4))
    J = np.empty((6, n))
    W = np.empty((n, 6))
    fk_jacobian_into(q, M, A, T, J, W)
    # E = R_d Rᵀ and its quaternion (w >= 0)
    e = np.empty((3, 3))
    for r in range(3):
        for c in range(3):
            e[r, c] = R_d[r, 0] * T[c, 0] + R_d[r, 1] * T[c, 1] + R_d[r, 2] * T[c, 2]
    _, qx, qy, qz = quaternion_from_entries(e[0, 0], e[0, 1], e[0, 2], e[1, 0], e[1, 1], e[1, 2],
                                            e[2, 0], e[2, 1], e[2, 2])
    for m in range(3):
        err_out[m] = p_d[m] - T[m, 3]
    err_out[3], err_out[4], err_out[5] = 2.0 * qx, 2.0 * qy, 2.0 * qz
    tw = np.empty(6)
    for m in range(6):
        tw[m] = twist_ff[m] + gains[m] * err_out[m]
    JJ = np.empty((6, 6))
    for r in range(6):
        for c in range(6):
            acc = 0.0
            for i in range(n):
                acc += J[r, i] * J[c, i]
            JJ[r, c] = acc
        JJ[r, r] += damping * damping
    x6 = np.empty(6)
    L = np.empty((6, 6))
    cholesky_solve(JJ, tw, x6, L)
    for i in range(n):
        acc = 0.0
        for m in range(6):
            acc += J[m, i] * x6[m]
        q_out[i] = min(max(q[i] + acc * dt, q_min[i]), q_max[i])


@dataclass(frozen=True)
class RateGains:
    """Feedback gains of eq. (4).

    Parameters
    ----------
    k_p : float or array_like, shape (3,)
        Position gain ``K_p`` (diagonal), in 1/s.
    k_theta : float or array_like, shape (3,)
        Orientation gain ``K_θ`` (diagonal), in 1/s.
    """

    k_p: float | np.ndarray = 1.0
    k_theta: float | np.ndarray = 1.0


class RateStep(NamedTuple):
    """Result of one resolved-rate step.

    q : ndarray, shape (n,)
        New joint vector ``q_d`` (rad / mm), clamped to the joint limits.
    error : ndarray, shape (6,)
        Pose error at the input ``q``: ``p_d - p`` in mm (base frame), then ``2 δr`` in rad
        (≈ rotation vector of ``R_d R^T``, base frame).
    """

    q: np.ndarray
    error: np.ndarray


def pose_error(T_base_tool, T_base_target) -> np.ndarray:
    """Pose error of eq. (4): position difference and quaternion orientation error.

    Parameters
    ----------
    T_base_tool : array_like, shape (..., 4, 4)
        Current tool pose in the base frame, mm.
    T_base_target : array_like, shape (..., 4, 4)
        Target tool pose in the base frame, mm.

    Returns
    -------
    error : ndarray, shape (..., 6)
        ``[p_d - p (mm); 2 δr (rad)]`` in the base frame, where ``δr`` is the vector part of
        the error quaternion ``r_d ⊗ r⁻¹`` with a non-negative scalar part
        (``|2 δr| = 2 sin(θ/2)`` for a rotation error θ).
    """
    T = np.asarray(T_base_tool, dtype=np.float64)
    Td = np.asarray(T_base_target, dtype=np.float64)
    e_p = Td[..., :3, 3] - T[..., :3, 3]
    R_err = Td[..., :3, :3] @ np.swapaxes(T[..., :3, :3], -1, -2)
    r = quaternion_from_matrix(R_err, check=False)
    sign = np.where(r[..., :1] < 0.0, -1.0, 1.0)
    return np.concatenate([e_p, 2.0 * sign * r[..., 1:]], axis=-1)


def _gain(value, name: str) -> np.ndarray:
    try:
        g = np.broadcast_to(np.asarray(value, dtype=np.float64), (3,))
    except (TypeError, ValueError):
        raise ConfigError(
            f"gains.{name}: expected a number or 3 numbers, got {value!r}"
        ) from None
    if not np.all(np.isfinite(g)) or np.any(g < 0):
        raise ConfigError(
            f"gains.{name}: expected finite non-negative values, got {g.tolist()}"
        )
    return g


def resolved_rate_step(
    chain: KinematicChain,
    q,
    T_target,
    gains: RateGains | tuple = RateGains(),
    dt: float = 0.01,
    damping: float = 1e-3,
    *,
    twist_target=None,
    check: bool = True,
) -> RateStep:
    """One resolved-rate control step (eq. 4–5) with a damped least-squares inverse.

    Parameters
    ----------
    chain : KinematicChain
        The manipulator (a DH chain or a URDF chain).
    q : array_like, shape (n,)
        Current joint vector (rad / mm).
    T_target : array_like, shape (4, 4)
        Desired tool pose ``T_base_target`` in the base frame, mm.
    gains : RateGains or (k_p, k_theta)
        Feedback gains in 1/s. ``k · dt = 1`` is a full Gauss–Newton step; smaller values
        give a first-order decay of the error.
    dt : float
        Control period in s, > 0.
    damping : float
        DLS damping ``λ`` ≥ 0 of ``Jᵀ (J Jᵀ + λ² I)⁻¹`` (same units as ``J``'s entries; the
        linear rows are in mm/rad, so a small λ mostly damps the orientation near singularities).
    twist_target : array_like, shape (6,), optional
        Feed-forward ``[ṗ_d (mm/s); ω_d (rad/s)]`` in the base frame; zero by default.
    check : bool
        Validate every input; ``False`` is the unchecked hot path (``q`` a float64 (n,)
        array, ``T_target`` a rigid (4, 4) array, ``gains`` a :class:`RateGains`).

    Returns
    -------
    RateStep
        ``(q, error)``: new joint vector clamped to ``[q_min, q_max]``, shape (n,), and the
        pose error ``[p_d - p (mm); 2 δr (rad)]`` at the input ``q``, shape (6,).

    Raises
    ------
    ConfigError
        Wrong ``q`` length, NaN/inf in ``q`` or ``T_target``, ``dt <= 0``, ``damping < 0``,
        negative gains.
    """
    if not check:
        M, A = chain.kinematic_pack
        q = np.asarray(q, dtype=np.float64)
        Td = np.asarray(T_target, dtype=np.float64)
        k = np.empty(6)
        k[:3], k[3:] = gains.k_p, gains.k_theta
        ff = np.zeros(6) if twist_target is None else np.asarray(twist_target, dtype=np.float64)
        q_out, error = np.empty_like(q), np.empty(6)
        resolved_rate_update(q, M, A, chain.q_min, chain.q_max, np.ascontiguousarray(Td[:3, 3]),
                             np.ascontiguousarray(Td[:3, :3]), ff, k, float(dt), float(damping), q_out, error)
        return RateStep(q_out, error)
    q = chain.check_q(q)
    if q.ndim != 1:
        raise ConfigError(
            f"{chain.name}: q must have shape ({chain.n_joints},), got shape {q.shape}"
        )
    if not (
        isinstance(dt, (int, float, np.floating, np.integer))
        and np.isfinite(dt)
        and dt > 0
    ):
        raise ConfigError(f"dt must be a finite number > 0 s, got {dt!r}")
    if not (
        isinstance(damping, (int, float, np.floating, np.integer))
        and np.isfinite(damping)
        and damping >= 0
    ):
        raise ConfigError(f"damping must be a finite number >= 0, got {damping!r}")
    Td = np.asarray(T_target, dtype=np.float64)
    if Td.shape != (4, 4) or not np.all(np.isfinite(Td)):
        raise ConfigError(
            f"T_target must be a finite (4, 4) transform, got shape {Td.shape}"
        )
    R = Td[:3, :3]
    if np.max(np.abs(R.T @ R - np.eye(3))) > 1e-6 or np.linalg.det(R) <= 0:
        raise ConfigError("T_target: rotation block is not a rotation matrix")
    if not isinstance(gains, RateGains):
        try:
            k_p, k_theta = gains
        except (TypeError, ValueError):
            raise ConfigError(
                f"gains: expected RateGains or (k_p, k_theta), got {gains!r}"
            ) from None
        gains = RateGains(k_p, k_theta)
    k_p, k_theta = _gain(gains.k_p, "k_p"), _gain(gains.k_theta, "k_theta")
    ff = (
        np.zeros(6)
        if twist_target is None
        else np.asarray(twist_target, dtype=np.float64)
    )
    if ff.shape != (6,) or not np.all(np.isfinite(ff)):
        raise ConfigError(
            f"twist_target must be 6 finite numbers, got shape {ff.shape}"
        )

    return resolved_rate_step(chain, q, Td, RateGains(k_p, k_theta), float(dt), float(damping),
                              twist_target=ff, check=False)
