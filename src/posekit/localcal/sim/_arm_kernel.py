"""Compiled inner loop of the long-reach arm simulator (numba).

One time step does, in this order (see :mod:`posekit.localcal.sim.arm` for the model):

1. resolved-rate control on the **nominal** chain (eq. 4–5): the commanded joint vector
   ``q_d`` is integrated with ``q̇_d = J⁺(q_d) [ṗ_d + K_p (p_d - p); ω_d + K_θ 2δr]``,
   ``J⁺ = Jᵀ (J Jᵀ + λ² I)⁻¹``, then clamped to the joint limits — the core's compiled
   :func:`posekit.robots.resolved_rate_update`, called inside this loop (a move has hundreds
   of steps);
2. joint P servo (eq. 6) ``u = K_v (q_d - q_meas)`` on the encoder readings;
3. PT-1 hydraulic joint (eq. 25): the joint velocity follows ``u`` with a first-order lag
   ``τ v̇ + v = u`` (exact zero-order-hold discretisation), saturated at ``v_max``;
   ``q ← q + v dt``;
4. backlash: the link angle follows the actuator through a dead band of full width ``b``
   (play operator), ``q_link ← clip(q_link, q - b/2, q + b/2)``;
5. encoder reading ``q_meas = q + noise``.
"""

import numpy as np

from posekit._jit import njit
from posekit.robots import resolved_rate_update

__all__ = ["simulate_moves"]


@njit(cache=True)
def simulate_moves(M, A, q_min, q_max, p_path, R_path, twist_path, gains, damping, dt,
                   kv, lag, v_max, half_play, encoder_noise,
                   q_cmd, q_act, v, q_link, q_meas):
    """Run K time steps of control + joint dynamics (one compiled function: cheap to compile).

    Parameters
    ----------
    M, A : (n + 1, 4, 4), (n, 4)
        The nominal chain's kinematic pack with its tool (``chain.kinematic_pack``);
        q_min, q_max : (n,) joint limits.
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
    n = q_cmd.shape[0]
    q_meas_log = np.empty((K, n))
    q_link_log = np.empty((K, n))
    q_cmd_log = np.empty((K, n))
    err = np.empty(6)
    for k in range(K):
        # 1. resolved-rate step on the nominal chain at q_cmd (the core's compiled step)
        resolved_rate_update(q_cmd, M, A, q_min, q_max, p_path[k], R_path[k], twist_path[k],
                             gains, dt, damping, q_cmd, err)
        # 2.-5.: P servo, PT-1 joint, backlash, encoder
        for i in range(n):
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
