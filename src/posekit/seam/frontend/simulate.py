"""The simulated world of a seam-tracking episode: the true robot, the process and the sensors.

One episode's world (:func:`simulate_data`):

1. the nominal program along the seam (:func:`~posekit.seam.frontend.trajectories.nominal_trajectory`);
2. the true robot (``simulation``): the nominal model with kinematic errors (drawn per episode); the
   motors track the joint stream ``q̄`` exactly, the process force (tool frame, slow drift +
   noise) deflects the joints (``Δq = c J_vᵀ f``) and the tool (an unmodelled Cartesian part),
   ``T_true = Fk_true(q̄ + Δq) exp(ξ_cart)``;
3. measurements: joints ``q̄ + noise + offset`` (motor side, blind to deflection), a force sensor
   (noise and bias), laser seam trackers on the true seam at the time they read it, ``laser_latency_s``
   before the sample (the true robot between samples interpolated linearly; missing without an
   intersection, beyond the range or by dropout) and optionally angles.

The particle filter runs over it in :func:`posekit.seam.frontend.episode.run_episode`.
"""

import math
from dataclasses import dataclass

import numpy as np

from posekit.geometry import matrix_from_rotation_vector, transform_from
from posekit.robots import KinematicChain
from posekit.seam.engine.seamline import SeamLine
from posekit.seam.frontend.config import SeamConfig
from posekit.seam.frontend.trajectories import NominalTrajectory, nominal_trajectory

__all__ = ["SimulatedData", "simulate_data", "start_offset"]


@dataclass
class SimulatedData:
    """The simulated world of one episode (before filtering).

    Attributes
    ----------
    nominal : NominalTrajectory
    truth : ndarray, shape (T, 4, 4)
        True tool poses ``T_base_tool``, mm.
    q_meas : ndarray, shape (T, 6)
        Measured joints, rad.
    force_n : ndarray, shape (T, 3)
        True process force on the tool in the base frame, N.
    force_meas_n : ndarray, shape (T, 3)
        Force-sensor reading, base frame, N.
    laser_mm : ndarray, shape (T, S, 2)
        Laser measurements (across, along the tool axis) in mm; NaN where missing; each taken
        ``latency_s`` before its sample's time.
    angle_rad : ndarray, shape (T, S)
        Angle measurements (rad); NaN where missing or not measured.
    true_chain : KinematicChain
        The robot with kinematic errors.
    latency_s : ndarray, shape (S,)
        The true latency of each sensor (s).
    """

    nominal: NominalTrajectory
    truth: np.ndarray
    q_meas: np.ndarray
    force_n: np.ndarray
    force_meas_n: np.ndarray
    laser_mm: np.ndarray
    angle_rad: np.ndarray
    true_chain: KinematicChain
    latency_s: np.ndarray

def simulate_data(cfg: SeamConfig, seed: int) -> SimulatedData:
    """Simulate the true tool poses and all measurements of one episode.

    Parameters
    ----------
    cfg : SeamConfig
        ``trajectory``, ``cell`` (robot, sensor mounts) and ``simulation`` (the world) are used.
    seed : int
        Episode seed; the same seed gives the same numbers.

    Returns
    -------
    SimulatedData
    """
    nt = nominal_trajectory(cfg.trajectory, cfg.cell.robot)
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 1]))
    n = nt.q.shape[0]
    chain = nt.chain
    sim = cfg.simulation
    true_chain = chain.perturbed(sim.kinematic_error_mm, math.radians(sim.kinematic_error_deg), rng)
    # process force in the tool frame: mean, slow drift, white noise; then base frame
    phase = rng.uniform(0.0, 2.0 * np.pi)
    drift = 1.0 + sim.force_drift * np.sin(2.0 * np.pi * np.arange(n) / n + phase)
    f_T = np.asarray(sim.force_n)[None, :] * drift[:, None] + sim.force_noise_n * rng.standard_normal((n, 3))
    R_nom = nt.T_nominal[:, :3, :3]
    f_W = np.matmul(R_nom, f_T[..., None])[..., 0]
    # joint deflection through the true robot's Jacobian, Cartesian (unmodelled) deflection
    J = true_chain.geometric_jacobian(nt.q)  # (T, 6, 6)
    tau = np.matmul(np.swapaxes(J[:, :3, :], 1, 2), f_W[..., None])[..., 0]  # N·mm
    q_arm = nt.q + sim.joint_compliance_rad_per_nm * 1e-3 * tau

    def truth_at(q, f_tool):
        xi = np.zeros((q.shape[0], 6))
        xi[:, :3] = sim.cartesian_compliance_mm_per_n * f_tool
        xi[:, 3:] = math.radians(sim.cartesian_compliance_deg_per_n) * np.cross([0.0, 0.0, 1.0], f_tool)
        cartesian = transform_from(matrix_from_rotation_vector(xi[:, 3:]), xi[:, :3], check=False)
        return np.matmul(true_chain.forward_kinematics(q), cartesian)

    truth = truth_at(q_arm, f_T)
    q_meas = nt.q + math.radians(sim.joint_noise_deg) * rng.standard_normal(nt.q.shape)
    offset = np.zeros(nt.q.shape[1])
    k = min(len(sim.encoder_offset_deg), offset.size)
    offset[:k] = np.radians(sim.encoder_offset_deg[:k])
    q_meas = q_meas + offset
    force_meas = f_W + sim.force_sensor_noise_n * rng.standard_normal((n, 3))
    force_meas += np.matmul(R_nom, np.asarray(sim.force_sensor_bias_n, dtype=np.float64))
    # laser sensors on the true seam, each at the time it reads (the true robot interpolated between samples)
    sc = cfg.cell.sensors
    mounts = sc.resolved_mounts()  # T_tool_sensor (S, 4, 4)
    latency = sim.latencies_s(mounts.shape[0]) if mounts.shape[0] else np.zeros(0)
    laser = np.full((n, mounts.shape[0], 2), np.nan)
    angle = np.full((n, mounts.shape[0]), np.nan)
    seam = SeamLine(nt.seam)
    for i, M in enumerate(mounts):  # over the sensors (<= 4): the true sensor frames T_true M
        if latency[i] > 0.0:
            t_read = nt.t_s - latency[i]
            interp = lambda a: np.stack([np.interp(t_read, nt.t_s, a[:, j]) for j in range(a.shape[1])], -1)  # noqa: E731
            T_read = truth_at(interp(q_arm), interp(f_T))
        else:
            T_read = truth
        S = np.matmul(T_read, M)
        origin, R_S = S[:, :3, 3], S[:, :3, :3]
        hit = seam.intersect(origin, R_S[:, :, 1])
        e = hit.point - origin
        m = np.stack([(e * R_S[:, :, 0]).sum(1), (e * R_S[:, :, 2]).sum(1)], axis=1)
        m += sim.laser_noise_mm * rng.standard_normal((n, 2))
        ok = hit.found & (np.abs(m).max(axis=1) <= sim.laser_range_mm)
        ok &= rng.random(n) >= sim.laser_dropout
        laser[ok, i] = m[ok]
        if sc.angle:
            nu = nt.seam_normal
            R_true = T_read[:, :3, :3]
            a = np.arctan2(R_true[:, :, 0] @ nu, R_true[:, :, 2] @ nu)
            a += math.radians(sim.angle_noise_deg) * rng.standard_normal(n)
            angle[ok, i] = a[ok]
    return SimulatedData(nt, truth, q_meas, f_W, force_meas, laser, angle, true_chain, latency)


def start_offset(cfg: SeamConfig) -> np.ndarray:
    """``simulation.start_offset_*`` as a tool-frame transform (4, 4): where the first cloud is drawn about."""
    sim = cfg.simulation
    return transform_from(matrix_from_rotation_vector(np.radians(sim.start_offset_deg)),
                          np.asarray(sim.start_offset_mm, dtype=np.float64), check=False)
