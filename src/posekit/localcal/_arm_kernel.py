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

import math

import numpy as np
from numba import njit

from posekit.geometry import cholesky_solve

__all__ = ["simulate_moves"]


@njit(cache=True)
def simulate_moves(a, alpha, d, theta0, revolute, q_min, q_max, T_tool,
                   p_path, R_path, twist_path, gains, damping, dt,
                   kv, lag, v_max, half_play, encoder_noise,
                   q_cmd, q_act, v, q_link, q_meas):
    """Run K time steps of control + joint dynamics (one compiled function: cheap to compile).

    Parameters
    ----------
    a, alpha, d, theta0 : (n,)
        Nominal DH rows (mm, rad); revolute : (n,) bool; q_min, q_max : (n,) joint limits;
        T_tool : (4, 4) tool transform of the chain.
    p_path, R_path, twist_path : (K, 3), (K, 3, 3), (K, 6)
        Cartesian reference at the end of each step (base frame, mm, rad, mm/s, rad/s).
    gains : (6,)
        K_p (3) then K_θ (3), 1/s.
    damping, dt : float
        DLS damping λ and the controller period, s.
    kv, lag, v_max, half_play : (n,)
        Servo gain 1/s, PT-1 factor exp(-dt/τ), velocity limit rad/s, half dead band rad.
    encoder_noise : (K, n)
        Encoder noise added at each step, rad.
    q_cmd, q_act, v, q_link, q_meas : (n,)
        State at the start (commanded, actuator, velocity, link after backlash, encoder);
        updated in place.

    Returns
    -------
    q_meas_log, q_link_log, q_cmd_log : (K, n) each
        Encoder readings, link-side angles and commanded joints after each step.
    """
    K = p_path.shape[0]
    n = a.shape[0]
    q_meas_log = np.empty((K, n))
    q_link_log = np.empty((K, n))
    q_cmd_log = np.empty((K, n))
    F = np.empty((n + 1, 4, 4))
    A = np.empty((4, 4))
    T = np.empty((4, 4))
    J = np.empty((6, n))
    E = np.empty((3, 3))
    M = np.empty((6, 6))
    L = np.empty((6, 6))
    tw = np.empty(6)
    x6 = np.empty(6)
    ca = np.cos(alpha)
    sa = np.sin(alpha)
    for k in range(K):
        # 1. resolved-rate step on the nominal chain at q_cmd: forward kinematics ...
        for r in range(4):
            for c in range(4):
                F[0, r, c] = 1.0 if r == c else 0.0
        for i in range(n):
            th = theta0[i] + (q_cmd[i] if revolute[i] else 0.0)
            di = d[i] + (0.0 if revolute[i] else q_cmd[i])
            ct = math.cos(th)
            st = math.sin(th)
            A[0, 0] = ct; A[0, 1] = -st * ca[i]; A[0, 2] = st * sa[i]; A[0, 3] = a[i] * ct
            A[1, 0] = st; A[1, 1] = ct * ca[i]; A[1, 2] = -ct * sa[i]; A[1, 3] = a[i] * st
            A[2, 0] = 0.0; A[2, 1] = sa[i]; A[2, 2] = ca[i]; A[2, 3] = di
            A[3, 0] = 0.0; A[3, 1] = 0.0; A[3, 2] = 0.0; A[3, 3] = 1.0
            for r in range(4):
                for c in range(4):
                    acc = 0.0
                    for m in range(4):
                        acc += F[i, r, m] * A[m, c]
                    F[i + 1, r, c] = acc
        for r in range(4):
            for c in range(4):
                acc = 0.0
                for m in range(4):
                    acc += F[n, r, m] * T_tool[m, c]
                T[r, c] = acc
        # ... geometric Jacobian (base frame) ...
        for i in range(n):
            z0 = F[i, 0, 2]; z1 = F[i, 1, 2]; z2 = F[i, 2, 2]
            if revolute[i]:
                r0 = T[0, 3] - F[i, 0, 3]; r1 = T[1, 3] - F[i, 1, 3]; r2 = T[2, 3] - F[i, 2, 3]
                J[0, i] = z1 * r2 - z2 * r1
                J[1, i] = z2 * r0 - z0 * r2
                J[2, i] = z0 * r1 - z1 * r0
                J[3, i] = z0; J[4, i] = z1; J[5, i] = z2
            else:
                J[0, i] = z0; J[1, i] = z1; J[2, i] = z2
                J[3, i] = 0.0; J[4, i] = 0.0; J[5, i] = 0.0
        # ... quaternion orientation error of R_d R^T (scalar part >= 0) ...
        for r in range(3):
            for c in range(3):
                acc = 0.0
                for m in range(3):
                    acc += R_path[k, r, m] * T[c, m]
                E[r, c] = acc
        tr = E[0, 0] + E[1, 1] + E[2, 2]
        if tr > 0.0:
            s = 2.0 * math.sqrt(tr + 1.0)
            w = 0.25 * s; qx = (E[2, 1] - E[1, 2]) / s; qy = (E[0, 2] - E[2, 0]) / s; qz = (E[1, 0] - E[0, 1]) / s
        elif E[0, 0] > E[1, 1] and E[0, 0] > E[2, 2]:
            s = 2.0 * math.sqrt(1.0 + E[0, 0] - E[1, 1] - E[2, 2])
            w = (E[2, 1] - E[1, 2]) / s; qx = 0.25 * s; qy = (E[0, 1] + E[1, 0]) / s; qz = (E[0, 2] + E[2, 0]) / s
        elif E[1, 1] > E[2, 2]:
            s = 2.0 * math.sqrt(1.0 + E[1, 1] - E[0, 0] - E[2, 2])
            w = (E[0, 2] - E[2, 0]) / s; qx = (E[0, 1] + E[1, 0]) / s; qy = 0.25 * s; qz = (E[1, 2] + E[2, 1]) / s
        else:
            s = 2.0 * math.sqrt(1.0 + E[2, 2] - E[0, 0] - E[1, 1])
            w = (E[1, 0] - E[0, 1]) / s; qx = (E[0, 2] + E[2, 0]) / s; qy = (E[1, 2] + E[2, 1]) / s; qz = 0.25 * s
        sg = -2.0 if w < 0.0 else 2.0
        for m in range(3):
            tw[m] = twist_path[k, m] + gains[m] * (p_path[k, m] - T[m, 3])
        tw[3] = twist_path[k, 3] + gains[3] * sg * qx
        tw[4] = twist_path[k, 4] + gains[4] * sg * qy
        tw[5] = twist_path[k, 5] + gains[5] * sg * qz
        # ... damped least squares q̇ = Jᵀ (J Jᵀ + λ² I)⁻¹ twist (Cholesky) ...
        for r in range(6):
            for c in range(6):
                acc = 0.0
                for i in range(n):
                    acc += J[r, i] * J[c, i]
                M[r, c] = acc
            M[r, r] += damping * damping
        cholesky_solve(M, tw, x6, L)
        # ... then 2.-5.: clamp, P servo, PT-1 joint, backlash, encoder
        for i in range(n):
            acc = 0.0
            for m in range(6):
                acc += J[m, i] * x6[m]
            qc = q_cmd[i] + acc * dt
            q_cmd[i] = min(max(qc, q_min[i]), q_max[i])
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
