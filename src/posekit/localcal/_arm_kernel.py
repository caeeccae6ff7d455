"""Compiled inner loop of the long-reach arm simulator (numba).

One time step does, in this order (see :mod:`posekit.localcal.arm` for the model):

1. resolved-rate control on the **nominal** DH chain (eq. 4–5): the commanded joint vector
   ``q_d`` is integrated with ``q̇_d = J⁺(q_d) [ṗ_d + K_p (p_d - p); ω_d + K_θ 2δr]``,
   ``J⁺ = Jᵀ (J Jᵀ + λ² I)⁻¹``, then clamped to the joint limits — the same maths as
   :func:`posekit.robots.resolved_rate_step` (checked against it in the tests), compiled
   because that function costs ~1 ms per call in NumPy and a move has hundreds of steps;
2. joint P servo (eq. 6) ``u = K_v (q_d - q_meas)`` on the encoder readings;
3. PT-1 hydraulic joint (eq. 25): the joint velocity follows ``u`` with a first-order lag
   ``τ v̇ + v = u`` (exact zero-order-hold discretisation), saturated at ``v_max``;
   ``q ← q + v dt``;
4. backlash: the link angle follows the actuator through a dead band of full width ``b``
   (play operator), ``q_link ← clip(q_link, q - b/2, q + b/2)``;
5. encoder reading ``q_meas = q + noise``.
"""

import numpy as np
from numba import njit

__all__ = ["simulate_moves"]


@njit(cache=True)
def _mul44(X, Y, out):
    """``out = X @ Y`` for (4, 4) arrays (explicit loops: cheap to compile)."""
    for r in range(4):
        for c in range(4):
            acc = 0.0
            for k in range(4):
                acc += X[r, k] * Y[k, c]
            out[r, c] = acc


@njit(cache=True)
def _fk(a, alpha, d, theta0, revolute, q, T_tool):
    """Link frames (n+1, 4, 4) and tool pose (4, 4) of a standard-DH chain."""
    n = a.shape[0]
    frames = np.zeros((n + 1, 4, 4))
    for r in range(4):
        frames[0, r, r] = 1.0
    A = np.zeros((4, 4))
    for i in range(n):
        th = theta0[i] + (q[i] if revolute[i] else 0.0)
        di = d[i] + (0.0 if revolute[i] else q[i])
        ct, st = np.cos(th), np.sin(th)
        ca, sa = np.cos(alpha[i]), np.sin(alpha[i])
        A[0, 0] = ct
        A[0, 1] = -st * ca
        A[0, 2] = st * sa
        A[0, 3] = a[i] * ct
        A[1, 0] = st
        A[1, 1] = ct * ca
        A[1, 2] = -ct * sa
        A[1, 3] = a[i] * st
        A[2, 0] = 0.0
        A[2, 1] = sa
        A[2, 2] = ca
        A[2, 3] = di
        A[3, 0] = 0.0
        A[3, 1] = 0.0
        A[3, 2] = 0.0
        A[3, 3] = 1.0
        _mul44(frames[i], A, frames[i + 1])
    T = np.empty((4, 4))
    _mul44(frames[n], T_tool, T)
    return frames, T


@njit(cache=True)
def _solve_spd(M, b):
    """Solve ``M x = b`` for a symmetric positive definite (6, 6) ``M`` (Cholesky)."""
    m = b.shape[0]
    L = np.zeros((m, m))
    for j in range(m):
        acc = M[j, j]
        for k in range(j):
            acc -= L[j, k] * L[j, k]
        L[j, j] = np.sqrt(acc)
        for i in range(j + 1, m):
            acc = M[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            L[i, j] = acc / L[j, j]
    y = np.empty(m)
    for i in range(m):
        acc = b[i]
        for k in range(i):
            acc -= L[i, k] * y[k]
        y[i] = acc / L[i, i]
    x = np.empty(m)
    for i in range(m - 1, -1, -1):
        acc = y[i]
        for k in range(i + 1, m):
            acc -= L[k, i] * x[k]
        x[i] = acc / L[i, i]
    return x


@njit(cache=True)
def _rate_step(a, alpha, d, theta0, revolute, q_min, q_max, T_tool,
               q, p_d, R_d, twist_ff, gains, damping, dt):
    """One resolved-rate step; returns the new commanded joint vector (n,)."""
    n = a.shape[0]
    frames, T = _fk(a, alpha, d, theta0, revolute, q, T_tool)
    p = T[:3, 3]
    J = np.zeros((6, n))
    for i in range(n):
        z = frames[i, :3, 2]
        o = frames[i, :3, 3]
        if revolute[i]:
            r = p - o
            J[0, i] = z[1] * r[2] - z[2] * r[1]
            J[1, i] = z[2] * r[0] - z[0] * r[2]
            J[2, i] = z[0] * r[1] - z[1] * r[0]
            J[3, i] = z[0]
            J[4, i] = z[1]
            J[5, i] = z[2]
        else:
            J[0, i] = z[0]
            J[1, i] = z[1]
            J[2, i] = z[2]
    # Orientation error: vector part of the quaternion of R_d R^T, scalar part >= 0, times 2.
    E = np.zeros((3, 3))  # R_d @ R.T
    for r in range(3):
        for c in range(3):
            for k in range(3):
                E[r, c] += R_d[r, k] * T[c, k]
    tr = E[0, 0] + E[1, 1] + E[2, 2]
    if tr > 0.0:
        s = 2.0 * np.sqrt(tr + 1.0)
        w = 0.25 * s
        x = (E[2, 1] - E[1, 2]) / s
        y = (E[0, 2] - E[2, 0]) / s
        zq = (E[1, 0] - E[0, 1]) / s
    elif E[0, 0] > E[1, 1] and E[0, 0] > E[2, 2]:
        s = 2.0 * np.sqrt(1.0 + E[0, 0] - E[1, 1] - E[2, 2])
        w = (E[2, 1] - E[1, 2]) / s
        x = 0.25 * s
        y = (E[0, 1] + E[1, 0]) / s
        zq = (E[0, 2] + E[2, 0]) / s
    elif E[1, 1] > E[2, 2]:
        s = 2.0 * np.sqrt(1.0 + E[1, 1] - E[0, 0] - E[2, 2])
        w = (E[0, 2] - E[2, 0]) / s
        x = (E[0, 1] + E[1, 0]) / s
        y = 0.25 * s
        zq = (E[1, 2] + E[2, 1]) / s
    else:
        s = 2.0 * np.sqrt(1.0 + E[2, 2] - E[0, 0] - E[1, 1])
        w = (E[1, 0] - E[0, 1]) / s
        x = (E[0, 2] + E[2, 0]) / s
        y = (E[1, 2] + E[2, 1]) / s
        zq = 0.25 * s
    sign = -1.0 if w < 0.0 else 1.0
    twist = np.empty(6)
    for k in range(3):
        twist[k] = twist_ff[k] + gains[k] * (p_d[k] - p[k])
    twist[3] = twist_ff[3] + gains[3] * 2.0 * sign * x
    twist[4] = twist_ff[4] + gains[4] * 2.0 * sign * y
    twist[5] = twist_ff[5] + gains[5] * 2.0 * sign * zq
    M = np.zeros((6, 6))
    for r in range(6):
        for c in range(6):
            acc = 0.0
            for i in range(n):
                acc += J[r, i] * J[c, i]
            M[r, c] = acc
        M[r, r] += damping * damping
    y = _solve_spd(M, twist)
    qdot = np.zeros(n)
    for i in range(n):
        for k in range(6):
            qdot[i] += J[k, i] * y[k]
    out = np.empty(n)
    for i in range(n):
        out[i] = min(max(q[i] + qdot[i] * dt, q_min[i]), q_max[i])
    return out


@njit(cache=True)
def simulate_moves(a, alpha, d, theta0, revolute, q_min, q_max, T_tool,
                   p_path, R_path, twist_path, gains, damping, dt,
                   kv, lag, v_max, half_play, encoder_noise,
                   q_cmd, q_act, v, q_link, q_meas):
    """Run K time steps of control + joint dynamics.

    Parameters
    ----------
    p_path, R_path, twist_path : (K, 3), (K, 3, 3), (K, 6)
        Cartesian reference at the end of each step (base frame, mm, rad, mm/s, rad/s).
    gains : (6,)  K_p (3) then K_θ (3), 1/s.
    kv, lag, v_max, half_play : (n,)
        Servo gain 1/s, PT-1 factor exp(-dt/τ), velocity limit rad/s, half dead band rad.
    encoder_noise : (K, n)
        Encoder noise added at each step, rad.
    q_cmd, q_act, v, q_link, q_meas : (n,)
        State at the start, updated in place.

    Returns
    -------
    q_meas_log, q_link_log, q_cmd_log : (K, n) each.
    """
    K = p_path.shape[0]
    n = a.shape[0]
    q_meas_log = np.empty((K, n))
    q_link_log = np.empty((K, n))
    q_cmd_log = np.empty((K, n))
    for k in range(K):
        new_cmd = _rate_step(a, alpha, d, theta0, revolute, q_min, q_max, T_tool,
                             q_cmd, p_path[k], R_path[k], twist_path[k], gains,
                             damping, dt)
        for i in range(n):
            q_cmd[i] = new_cmd[i]
            u = kv[i] * (q_cmd[i] - q_meas[i])
            vi = lag[i] * v[i] + (1.0 - lag[i]) * u
            v[i] = min(max(vi, -v_max[i]), v_max[i])
            q_act[i] += v[i] * dt
            q_link[i] = min(max(q_link[i], q_act[i] - half_play[i]), q_act[i] + half_play[i])
            q_meas[i] = q_act[i] + encoder_noise[k, i]
            q_meas_log[k, i] = q_meas[i]
            q_link_log[k, i] = q_link[i]
            q_cmd_log[k, i] = q_cmd[i]
    return q_meas_log, q_link_log, q_cmd_log
