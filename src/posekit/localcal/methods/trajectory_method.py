"""Trajectory-matching range adjustment (Sec. 3.2.2, eq. 17–22).

The TCP runs an asymmetric planar point-to-point path (eq. 17–19) in the plane of its unit
vectors ``n`` and ``s``, holding its orientation. A VO/SLAM system tracks the camera poses in
its world frame W meanwhile, and the encoders give the TCP poses through the kinematic model.
Matching the two trajectories (:func:`posekit.localcal.registration.match.match_trajectories`:
coarse frame alignment, then robust fine registration) gives the rotation ``R_B_W`` (the
paper's ``R_fm R_cfa``). Any camera-frame error between the tool marker and the OOI is then
expressed in the base frame and added to the TCP position (eq. 20–22), as often as needed.
"""

from pathlib import Path

import numpy as np

from posekit.errors import ConfigError, TrajectoryError
from posekit.geometry import check_rotation_matrix, check_transform, matrix_from_rotation_vector

__all__ = [
    "PATH_LENGTHS_MM",
    "PATH_XI_RAD",
    "STANDOFF_MM",
    "asymmetric_path",
    "calibrate_trajectories",
    "trajectory_reference",
]

#: Segment lengths L_i of the default calibration path, mm (signed: a negative length walks
#: back along the segment's direction). Chosen asymmetric, within ~0.5 m of the start.
PATH_LENGTHS_MM = (300.0, 200.0, -250.0, -300.0, 150.0, 150.0)
#: The angle ξ alternates between these values along the path (Sec. 3.2.2), rad.
PATH_XI_RAD = (0.0, np.pi / 4)
#: Depth offset b of eq. (21) that keeps the tool off the OOI (Sec. 5.2.2: 10 cm), mm.
STANDOFF_MM = 100.0

_MIN_SPREAD_MM = 1.0


def asymmetric_path(T_B_F, lengths_mm=PATH_LENGTHS_MM, *, xi=PATH_XI_RAD, tilt_rad: float = 0.0) -> np.ndarray:
    """Waypoints of the planar calibration path, eq. (17)–(19).

    ``p_{i+1} = p_i + L_i (cos ξ_i n + sin ξ_i s)`` from ``p_1`` = the TCP position, with
    ``ξ_i`` cycling through ``xi`` (0 and π/4 in the paper). The paper holds the orientation;
    with ``tilt_rad > 0`` the inner waypoints are tilted by that angle about the TCP's ``n``,
    ``s``, ``-n``, ``-s`` axes in turn (the last waypoint returns to the start orientation), so
    that a hand-eye calibration can see the camera's lever arm.

    Parameters
    ----------
    T_B_F : array_like, shape (4, 4)
        Current TCP pose in the base frame B, mm; columns ``n`` (x) and ``s`` (y) span the plane.
    lengths_mm : sequence of float, length K >= 2
        Segment lengths ``L_i``, mm (signed).
    xi : sequence of float
        Segment angles in rad, used cyclically.
    tilt_rad : float
        Tilt of the inner waypoints, rad (0: the paper's orientation-holding path).

    Returns
    -------
    T_B_path : ndarray, shape (K + 1, 4, 4)
        Waypoint TCP poses in B (the start first), with the orientation of ``T_B_F`` (tilted at the
        inner waypoints when ``tilt_rad > 0``), mm.

    Raises
    ------
    TrajectoryError
        Fewer than 2 segments, or a degenerate path (all waypoints on one straight line).
    ConfigError
        Non-finite lengths or angles.
    GeometryError
        ``T_B_F`` is not a rigid transform.
    """
    T_B_F = check_transform(T_B_F, name="T_B_F")
    L = np.asarray(lengths_mm, dtype=np.float64).reshape(-1)
    angles = np.asarray(xi, dtype=np.float64).reshape(-1)
    if not (np.ndim(tilt_rad) == 0 and np.isfinite(tilt_rad) and 0.0 <= tilt_rad <= np.pi / 4):
        raise ConfigError(f"calibration path: tilt must be between 0 and pi/4 rad, got {tilt_rad!r}")
    if not np.all(np.isfinite(L)) or angles.size == 0 or not np.all(np.isfinite(angles)):
        raise ConfigError("calibration path: expected finite segment lengths (mm) and angles xi (rad)")
    if L.size < 2:
        raise TrajectoryError(f"calibration path: too few segments: expected at least 2, got {L.size}")
    xi_i = angles[np.arange(L.size) % angles.size]
    n, s = T_B_F[:3, 0], T_B_F[:3, 1]
    steps = L[:, None] * (np.cos(xi_i)[:, None] * n + np.sin(xi_i)[:, None] * s)
    points = T_B_F[:3, 3] + np.concatenate([np.zeros((1, 3)), np.cumsum(steps, axis=0)])
    centred = points - points.mean(axis=0)
    spread = np.linalg.svd(centred, compute_uv=False)
    if spread[1] / np.sqrt(len(points)) < _MIN_SPREAD_MM:
        raise TrajectoryError("calibration path is degenerate: all waypoints lie on one straight line "
                              "(expected a planar path that spans two directions, e.g. xi alternating 0 and pi/4)")
    path = np.broadcast_to(T_B_F, (len(points), 4, 4)).copy()
    path[:, :3, 3] = points
    if tilt_rad > 0:
        axes = np.array([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
        k = np.arange(1, len(points) - 1)
        path[k, :3, :3] = T_B_F[:3, :3] @ matrix_from_rotation_vector(tilt_rad * axes[(k - 1) % 4])
    return path


def trajectory_reference(T_B_F, R_B_W, R_W_C, delta_C, *, b_mm: float = STANDOFF_MM) -> np.ndarray:
    """Reference TCP pose of the trajectory-matching method, eq. (20)–(22).

    Parameters
    ----------
    T_B_F : array_like, shape (4, 4)
        Current TCP pose in the base frame B (kinematic model), mm; its orientation is held.
    R_B_W : array_like, shape (3, 3)
        Rotation of the VO world frame W in B from trajectory matching (``R_fm R_cfa``).
    R_W_C : array_like, shape (3, 3)
        Current camera orientation in W (from VO); identity while the orientation is the one
        VO started with.
    delta_C : array_like, shape (3,)
        Measured position of the OOI minus that of the tool marker, camera frame C, mm
        (``^O p - ^T p``).
    b_mm : float
        Depth offset ``b`` subtracted along the camera's z axis (eq. 21), mm.

    Returns
    -------
    T_B_ref : ndarray, shape (4, 4)
        ``[R_B_F, p_lc + p_B_F]`` with ``p_lc = R_B_W R_W_C (delta_C - [0, 0, b])``, mm.

    Raises
    ------
    GeometryError
        A rotation or transform is malformed.
    ConfigError
        ``delta_C`` not 3 finite numbers, or ``b_mm`` not finite.

    Examples
    --------
    >>> trajectory_reference(np.eye(4), np.eye(3), np.eye(3), [10.0, -5.0, 600.0])[:3, 3]
    array([ 10.,  -5., 500.])
    """
    T_B_F = check_transform(T_B_F, name="T_B_F")
    R_B_W = check_rotation_matrix(R_B_W, name="R_B_W")
    R_W_C = check_rotation_matrix(R_W_C, name="R_W_C")
    d = np.asarray(delta_C, dtype=np.float64)
    if d.shape != (3,) or not np.all(np.isfinite(d)):
        raise ConfigError(f"delta_C: expected 3 finite numbers (mm), got {np.asarray(delta_C).tolist()}")
    if not np.isfinite(b_mm):
        raise ConfigError(f"b_mm: expected a finite offset in mm, got {b_mm!r}")
    p_lc = R_B_W @ R_W_C @ (d - np.array([0.0, 0.0, float(b_mm)]))
    T_ref = T_B_F.copy()
    T_ref[:3, 3] = T_B_F[:3, 3] + p_lc
    return T_ref


def calibrate_trajectories(camera, kinematic, **match_options):
    """Local calibration: match a camera (VO) trajectory to the kinematic TCP trajectory.

    Parameters
    ----------
    camera : Trajectory or path
        Camera poses ``T_W_C`` in the VO world frame W (mm), or a TUM file of them.
    kinematic : Trajectory or path
        TCP poses ``T_B_F`` from the encoders and the kinematic model (mm), or a TUM file.
    **match_options
        Passed to :func:`posekit.localcal.registration.match.match_trajectories`
        (``use_timestamps``, ``max_dt_s``, ``with_scale``, ...).

    Returns
    -------
    Registration
        ``R`` is ``R_B_W`` (the paper's ``R_fm R_cfa``); the errors are Table 3's.

    Raises
    ------
    TrajectoryError, InputFileError
        Too few poses, a degenerate (straight-line) path, an unreadable TUM file.
    """
    from posekit.localcal.model.trajectory import Trajectory
    from posekit.localcal.registration.formats.tum import read_tum
    from posekit.localcal.registration.match import match_trajectories

    def load(x, name):
        if isinstance(x, Trajectory):
            return x
        if isinstance(x, (str, Path)):
            return read_tum(x)
        raise TrajectoryError(f"{name}: expected a Trajectory or a TUM file path, got {type(x).__name__}")

    return match_trajectories(load(camera, "camera"), load(kinematic, "kinematic"), **match_options)
