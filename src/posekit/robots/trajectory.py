"""Quintic point-to-point joint trajectories with zero boundary velocity and acceleration.

``q(t) = q_0 + (q_1 - q_0) s(τ)``, ``τ = (t - t_0) / T``, with the minimum-jerk blend
``s(τ) = 10τ³ - 15τ⁴ + 6τ⁵`` (``s(0)=0, s(1)=1``, ``s' = s'' = 0`` at both ends); outside
``[t_0, t_0 + T]`` the trajectory holds its end points. The long-reach manipulator paper
uses such quintic paths between reference poses (Sec. 4.2, its ref. [33]).
"""

from typing import NamedTuple

import numpy as np

from posekit.errors import ConfigError

__all__ = ["JointSamples", "quintic_trajectory"]


class JointSamples(NamedTuple):
    """Joint trajectory samples; each array has shape (n,) for a scalar time, else (K, n).

    q : positions (rad / mm); qd : velocities (rad/s / mm/s); qdd : accelerations (rad/s² / mm/s²).
    """

    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray


def _vector(x, name: str) -> np.ndarray:
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: expected numbers, got {type(x).__name__}") from None
    if a.ndim != 1:
        raise ConfigError(f"{name}: expected shape (n,), got shape {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ConfigError(f"{name}: expected finite values, found NaN or inf")
    return a


def quintic_trajectory(
    q_start, q_end, duration: float, t, *, t_start: float = 0.0
) -> JointSamples:
    """Sample a quintic point-to-point joint trajectory, vectorised over times.

    Parameters
    ----------
    q_start, q_end : array_like, shape (n,)
        Start and end joint vectors (rad for revolute, mm for prismatic joints).
    duration : float
        Motion time ``T`` in s, > 0.
    t : float or array_like, shape (K,)
        Sample times in s (absolute; the motion starts at ``t_start``).
    t_start : float
        Start time in s.

    Returns
    -------
    JointSamples
        ``(q, qd, qdd)``, each of shape (n,) for a scalar ``t`` or (K, n).

    Raises
    ------
    ConfigError
        Start/end of different lengths, non-finite values, ``duration <= 0``.

    Examples
    --------
    >>> s = quintic_trajectory([0.0, 0.0], [1.0, -2.0], 2.0, [0.0, 1.0, 2.0])
    >>> s.q.tolist()
    [[0.0, 0.0], [0.5, -1.0], [1.0, -2.0]]
    """
    q0 = _vector(q_start, "q_start")
    q1 = _vector(q_end, "q_end")
    if q0.shape != q1.shape:
        raise ConfigError(
            f"q_end: expected shape {q0.shape} like q_start, got shape {q1.shape}"
        )
    if not (np.ndim(duration) == 0 and np.isfinite(duration) and duration > 0):
        raise ConfigError(f"duration must be a finite number > 0 s, got {duration!r}")
    t_arr = np.asarray(t, dtype=np.float64)
    if t_arr.ndim > 1 or not np.all(np.isfinite(t_arr)) or not np.isfinite(t_start):
        raise ConfigError(
            f"t must be a finite scalar or shape (K,), got shape {t_arr.shape}"
        )
    T = float(duration)
    tau = np.clip((t_arr - t_start) / T, 0.0, 1.0)[..., None]
    inside = ((t_arr - t_start >= 0) & (t_arr - t_start <= T))[..., None]
    s = tau**3 * (10.0 + tau * (-15.0 + 6.0 * tau))
    ds = 30.0 * tau**2 * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    dq = q1 - q0
    q = q0 * (1.0 - s) + q1 * s  # exact end points at s = 0 and s = 1
    qd = np.where(inside, dq * ds / T, 0.0)
    qdd = np.where(inside, dq * dds / T**2, 0.0)
    return JointSamples(q, qd, qdd)
