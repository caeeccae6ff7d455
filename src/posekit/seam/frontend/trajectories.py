"""Seams and nominal robot programs along them (paper §II-D and §III-B, Fig. 9).

A seam is a curve given in the tool frame ``T0`` at the start of the weld (y along the travel,
z along the tool axis, x across), parametrised by its length parameter ``u`` in mm:

``xy``    ``(A tri(u), u, 0)``: 200 mm along y, a smooth triangle wave of amplitude 20 mm in x
``yz``    ``(0, u, A sin(2π u / P))``: 200 mm along y, a sine of amplitude 100 mm in z
``line``  ``(0, u, 0)``
``bend``  straight along y up to ``u_b``, then at ``bend_deg`` about the tool z axis (a corner)

The robot program (what a robot simulator would export) is the Cartesian path of the TCP
along the seam with the tool orientation of ``T0`` held constant (``tool_orientation:
fixed``, the paper's Fig. 9) or turning with the seam tangent (``tangent``, the authors'
simulator: :func:`program_rotations_T0`); it is turned into a joint
stream by resolved-rate inverse kinematics (:func:`posekit.robots.resolved_rate_step` with
``k dt = 1``, i.e. a damped Gauss–Newton step, unchecked on the core's compiled kinematics;
one step per sample, more after a long step) on the configured robot (the PUMA 560 by
default, or a URDF arm) with a tool of ``tool_length_mm`` along the flange z axis, and the
nominal trajectory is the forward kinematics of that stream.
The seam polyline extends ``seam_extension_mm`` beyond the program's end, so sensors
ahead of the tool keep seeing it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING

import numpy as np

from posekit.errors import ConfigError, TrajectoryError
from posekit.robots import (
    KinematicChain,
    RateGains,
    load_urdf,
    resolved_rate_step,
    robot_model,
)

if TYPE_CHECKING:  # annotations only: the configuration validates programs with this module (no import circle)
    from posekit.seam.frontend.config import TrajectoryConfig
    from posekit.seam.frontend.config_cell import RobotConfig

__all__ = [
    "IK_SEED_DEG",
    "NominalTrajectory",
    "nominal_trajectory",
    "program_rotations_T0",
    "seam_headings_T0",
    "seam_points_T0",
    "ik_seed",
    "start_pose",
    "tool_chain",
]

#: Joint guess (deg) from which the first program pose is solved on the PUMA 560: elbow up,
#: wrist down.
IK_SEED_DEG = (0.0, 45.0, -160.0, 0.0, -60.0, 0.0)
#: The same for the other bundled robots (tool axis down in front of the robot).
_BUNDLED_SEEDS_DEG = {
    "puma560": IK_SEED_DEG,
    "abb_irb6640": (0.0, 10.0, 10.0, 0.0, 70.0, 0.0),
    "ur10": (0.0, -90.0, 90.0, -90.0, -90.0, 0.0),
}
#: Gauss–Newton gains of the program's inverse kinematics: k dt = 1 with dt = 1.
_IK_GAINS = RateGains(1.0, 1.0)
#: Spacing (mm of the parameter u) of the dense seam polyline.
SEAM_SPACING_MM = 0.5


@dataclass(frozen=True, eq=False)
class NominalTrajectory:
    """The nominal robot program and the seam it follows.

    Attributes
    ----------
    t_s : ndarray, shape (T,)
        Sample times in s.
    u_mm : ndarray, shape (T,)
        Seam parameter of each sample, mm.
    q : ndarray, shape (T, 6)
        Joint stream (rad) from the inverse kinematics: the reference ``q̄``.
    T_program : ndarray, shape (T, 4, 4)
        Programmed TCP poses ``T_base_tool`` (mm).
    T_nominal : ndarray, shape (T, 4, 4)
        ``Fk(q̄)``: the nominal trajectory the filter propagates along (mm).
    seam : ndarray, shape (K, 3)
        Dense seam polyline in the base frame (mm), beyond the program's end.
    seam_normal : ndarray, shape (3,)
        Workpiece surface normal in the base frame (the programmed tool z axis), unit.
    T_base_T0 : ndarray, shape (4, 4)
        The start frame T0 in which the seam is defined.
    chain : KinematicChain
        The nominal robot model with its tool.
    ik_max_error_mm : float
        Largest TCP position error of the joint stream against the program, mm.
    """

    t_s: np.ndarray
    u_mm: np.ndarray
    q: np.ndarray
    T_program: np.ndarray
    T_nominal: np.ndarray
    seam: np.ndarray
    seam_normal: np.ndarray
    T_base_T0: np.ndarray
    chain: KinematicChain
    ik_max_error_mm: float


def _smooth_triangle(u: np.ndarray, period: float, blend: float) -> np.ndarray:
    """Triangle wave of unit amplitude (peak at ``u = period / 4``), its corners rounded by a
    moving average of width ``blend * period`` and rescaled to peak 1: exactly linear between
    the corners, parabolic at them."""
    def tri(v):
        return (2.0 / np.pi) * np.arcsin(np.clip(np.sin(2.0 * np.pi * v / period), -1.0, 1.0))

    if blend <= 0.0:
        return tri(u)
    nodes = (np.arange(64) + 0.5) / 64 - 0.5  # midpoint rule over [-1/2, 1/2]
    # the average lowers the peaks by `blend` (slope 4/period over a quarter of the width)
    return tri(u[..., None] + blend * period * nodes).mean(axis=-1) / (1.0 - blend)


def seam_points_T0(cfg: TrajectoryConfig, u) -> np.ndarray:
    """Seam points in the start tool frame T0 at parameters ``u``.

    Parameters
    ----------
    cfg : TrajectoryConfig
    u : array_like, shape (M,)
        Seam parameter in mm (0 at the start; along y, or along the path for ``bend``).

    Returns
    -------
    p_T0 : ndarray, shape (M, 3)
        ``(x across, y along, z tool axis)`` in mm.
    """
    u = np.asarray(u, dtype=np.float64)
    p = np.zeros(u.shape + (3,))
    A, P = cfg.resolved_amplitude_mm(), cfg.resolved_period_mm()
    if cfg.kind == "bend":
        ub = cfg.bend_at * cfg.length_mm
        b = np.deg2rad(cfg.bend_deg)
        after = np.maximum(u - ub, 0.0)
        p[..., 0] = np.sin(b) * after
        p[..., 1] = np.minimum(u, ub) + np.cos(b) * after
        return p
    p[..., 1] = u
    if cfg.kind == "xy":
        p[..., 0] = A * _smooth_triangle(u, P, cfg.corner_smoothing)
    elif cfg.kind == "yz":
        p[..., 2] = A * np.sin(2.0 * np.pi * u / P)
    return p


def start_pose(cfg: TrajectoryConfig) -> np.ndarray:
    """``T_base_T0`` (4, 4): the tool at the seam start, tool axis down (-z of the base),
    travel along +y of the base, translation ``start_mm`` (mm)."""
    T = np.eye(4)
    T[:3, :3] = np.column_stack([[-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0]])
    T[:3, 3] = cfg.start_mm
    return T


def seam_headings_T0(cfg: TrajectoryConfig, u) -> np.ndarray:
    """Travel direction of a tool that follows the seam, in the start frame T0.

    The seam tangent projected on the workpiece plane (x-y of T0), averaged over
    ``cfg.turn_mm`` of the seam parameter centred on ``u`` (a sharp corner becomes a turn over
    that length), unit length.

    Parameters
    ----------
    cfg : TrajectoryConfig
    u : array_like, shape (M,)
        Seam parameter, mm.

    Returns
    -------
    ndarray, shape (M, 3)
        Unit heading ``(hx, hy, 0)`` in T0.
    """
    u = np.asarray(u, dtype=np.float64)
    nodes = ((np.arange(32) + 0.5) / 32 - 0.5) * cfg.turn_mm if cfg.turn_mm > 0 else np.zeros(1)
    uu = u[:, None] + nodes[None]
    t = seam_points_T0(cfg, uu + 1e-3) - seam_points_T0(cfg, uu - 1e-3)
    t[..., 2] = 0.0
    t /= np.maximum(np.linalg.norm(t, axis=-1, keepdims=True), 1e-12)
    h = t.mean(axis=1)
    return h / np.maximum(np.linalg.norm(h, axis=-1, keepdims=True), 1e-12)


def program_rotations_T0(cfg: TrajectoryConfig, u) -> np.ndarray:
    """Tool orientations ``R_T0_tool`` along the program, shape (M, 3, 3).

    ``fixed``: the identity (the tool keeps the start orientation). ``tangent``: the tool's y
    axis along :func:`seam_headings_T0`, z the workpiece normal (z of T0), x = y × z.
    """
    u = np.asarray(u, dtype=np.float64)
    R = np.repeat(np.eye(3)[None], u.shape[0], axis=0)
    if cfg.tool_orientation == "tangent":
        h = seam_headings_T0(cfg, u)
        R[:, 0, 0], R[:, 1, 0] = h[:, 1], -h[:, 0]
        R[:, 0, 1], R[:, 1, 1] = h[:, 0], h[:, 1]
    return R


@lru_cache(maxsize=16)
def tool_chain(robot: RobotConfig) -> KinematicChain:
    """The nominal robot model (bundled or URDF) with its tool ``T_flange_tool``
    (:meth:`RobotConfig.tool_matrix`: ``robot.tool``, or ``tool_length_mm`` along the flange z
    axis), cached per configuration; chains are immutable."""
    T_flange_tool = robot.tool_matrix()
    if robot.urdf is not None:
        chain = load_urdf(robot.urdf, robot.base_link, robot.tip_link)
    else:
        chain = robot_model(robot.model)
    return chain.with_tool(T_flange_tool)


def ik_seed(robot: RobotConfig, chain: KinematicChain) -> np.ndarray:
    """The joint guess (rad) for the program's first pose: ``robot.ik_seed_deg``, the bundled
    model's seed, or the middle of the joint ranges clipped to ±90°."""
    if robot.ik_seed_deg is not None:
        if len(robot.ik_seed_deg) != chain.n_joints:
            raise ConfigError(f"cell.robot.ik_seed_deg: expected {chain.n_joints} values for {robot.label}, "
                              f"got {len(robot.ik_seed_deg)}")
        return np.deg2rad(robot.ik_seed_deg)
    if robot.urdf is None and robot.model in _BUNDLED_SEEDS_DEG:
        return np.deg2rad(_BUNDLED_SEEDS_DEG[robot.model])
    mid = 0.5 * (np.clip(chain.q_min, -np.pi / 2, np.pi / 2) + np.clip(chain.q_max, -np.pi / 2, np.pi / 2))
    return np.where(chain.is_revolute, mid, 0.5 * (np.clip(chain.q_min, -1e3, 1e3) + np.clip(chain.q_max, -1e3, 1e3)))


def _readonly(*arrays):
    for a in arrays:
        a.setflags(write=False)


@lru_cache(maxsize=16)
def _nominal_cached(traj: TrajectoryConfig, robot: RobotConfig, extra_mm: float) -> NominalTrajectory:
    chain = tool_chain(robot)
    T0 = start_pose(traj)
    n = traj.steps
    t_s = np.arange(n) * traj.dt_s
    u = np.linspace(0.0, traj.length_mm, n)
    p_T0 = seam_points_T0(traj, u)
    T_program = np.repeat(T0[None], n, axis=0)
    T_program[:, :3, 3] = p_T0 @ T0[:3, :3].T + T0[:3, 3]
    if traj.tool_orientation != "fixed":
        T_program[:, :3, :3] = np.matmul(T0[:3, :3], program_rotations_T0(traj, u))

    q = ik_seed(robot, chain)
    for _ in range(200):  # converge on the first pose
        q, err = resolved_rate_step(chain, q, T_program[0], _IK_GAINS, 1.0, 1e-2, check=False)
        if np.abs(err).max() < 1e-9:
            break
    qs = np.empty((n, chain.n_joints))
    for k in range(n):
        for _ in range(6):  # one step usually; long steps leave a second-order residual
            q, err = resolved_rate_step(chain, q, T_program[k], _IK_GAINS, 1.0, 1e-3, check=False)
            if np.abs(err).max() < 1e-3:  # the step just taken was small: residual ~1e-9 mm
                break
        qs[k] = q
    T_nominal = chain.forward_kinematics(qs)
    ik_err = float(np.linalg.norm(T_nominal[:, :3, 3] - T_program[:, :3, 3], axis=1).max())
    if ik_err > 1e-3:
        raise TrajectoryError(
            f"trajectory '{traj.kind}' from start_mm {list(traj.start_mm)}: the inverse kinematics "
            f"misses the program by {ik_err:.3g} mm (expected < 0.001 mm); the path leaves the "
            f"{robot.label} workspace or passes a singularity (set trajectory.start_mm or cell.robot.ik_seed_deg)"
        )
    n_seam = int(np.ceil((traj.length_mm + extra_mm) / SEAM_SPACING_MM)) + 1
    u_seam = np.linspace(0.0, traj.length_mm + extra_mm, n_seam)
    if traj.kind == "bend":  # keep the corner exactly as a vertex
        u_seam = np.unique(np.append(u_seam, traj.bend_at * traj.length_mm))
    seam = seam_points_T0(traj, u_seam) @ T0[:3, :3].T + T0[:3, 3]
    normal = T0[:3, 2].copy()
    _readonly(t_s, u, qs, T_program, T_nominal, seam, normal, T0)
    return NominalTrajectory(t_s, u, qs, T_program, T_nominal, seam, normal, T0, chain, ik_err)


def nominal_trajectory(traj: TrajectoryConfig, robot: RobotConfig, extra_mm: float | None = None) -> NominalTrajectory:
    """The nominal trajectory of a robot program along the configured seam.

    Cached per (trajectory, robot) configuration: the arrays are read-only.

    Parameters
    ----------
    traj : TrajectoryConfig
    robot : RobotConfig
    extra_mm : float, optional
        Seam length beyond the program's end (default ``traj.seam_extension_mm``).

    Returns
    -------
    NominalTrajectory

    Raises
    ------
    TrajectoryError
        The inverse kinematics cannot follow the program (workspace, singularity).
    """
    extra = traj.seam_extension_mm if extra_mm is None else float(extra_mm)
    return _nominal_cached(traj, robot, extra)
