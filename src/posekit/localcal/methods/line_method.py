"""Line-equation range adjustment (Sec. 3.2.1, eq. 10–16).

The TCP runs a circular path in the plane spanned by the unit vectors ``n`` and ``s`` of its
current pose (eq. 9–12; the first and last points are the circle's centre) while holding its
orientation. Along the path the camera measures the planar distance between the tool marker
and the OOI in the camera frame (eq. 13). The TCP position at the smallest distance,
``p_ε``, and the centre ``p_init`` give the direction to the OOI (eq. 15) and the reference
position ``p_init + p_u (r + d_ε,min)`` (eq. 16).

The method presumes what the paper presumes: the plane of motion is parallel to the camera's
image plane (the camera and TCP frames are 'uniform') and the OOI lies outside the circle.
"""

from typing import NamedTuple

import numpy as np

from posekit.errors import ConfigError, EstimationError
from posekit.geometry import check_transform

__all__ = [
    "CIRCLE_POINTS",
    "CIRCLE_RADIUS_MM",
    "LineAdjustment",
    "circle_path",
    "line_range_adjustment",
    "line_reference",
    "planar_distance_error",
]

#: Radius of the circular path of the paper's experiments (Sec. 5.2.1), mm.
CIRCLE_RADIUS_MM = 200.0
#: Points of the circular path, the first and last at the centre (Sec. 5.2.1).
CIRCLE_POINTS = 18

_MIN_STEP_MM = 1e-6


def circle_path(T_B_F, *, radius_mm: float = CIRCLE_RADIUS_MM, n_points: int = CIRCLE_POINTS) -> np.ndarray:
    """Waypoints of the circular calibration path, eq. (10)–(12).

    Parameters
    ----------
    T_B_F : array_like, shape (4, 4)
        TCP pose at the circle's centre in the base frame B, mm; its columns ``n`` (x) and
        ``s`` (y) span the plane of the circle.
    radius_mm : float
        Circle radius ``r``, mm (> 0).
    n_points : int
        Number of waypoints (>= 5): the centre, ``n_points - 2`` points at
        ``φ = 0 … 2π`` (both ends included, so the circle closes), the centre again.

    Returns
    -------
    T_B_path : ndarray, shape (n_points, 4, 4)
        Waypoint TCP poses in B, all with the orientation of ``T_B_F``, mm.

    Raises
    ------
    ConfigError
        ``radius_mm <= 0`` or ``n_points < 5``.
    GeometryError
        ``T_B_F`` is not a rigid transform.
    """
    T_B_F = check_transform(T_B_F, name="T_B_F")
    if not (np.isfinite(radius_mm) and radius_mm > 0):
        raise ConfigError(f"circle radius must be a finite number > 0 mm, got {radius_mm!r}")
    if int(n_points) != n_points or n_points < 5:
        raise ConfigError(f"circular path: expected at least 5 points (centre, 3 on the circle, centre), "
                          f"got {n_points!r}")
    phi = np.linspace(0.0, 2.0 * np.pi, int(n_points) - 2)
    n, s, p = T_B_F[:3, 0], T_B_F[:3, 1], T_B_F[:3, 3]
    ring = p + radius_mm * (np.cos(phi)[:, None] * n + np.sin(phi)[:, None] * s)
    path = np.broadcast_to(T_B_F, (int(n_points), 4, 4)).copy()
    path[1:-1, :3, 3] = ring
    return path


def planar_distance_error(p_C_O, p_C_M) -> np.ndarray:
    """Image-based planar distance between the tool marker and the OOI, eq. (13).

    Parameters
    ----------
    p_C_O, p_C_M : array_like, shape (..., 3)
        Measured positions of the OOI and the tool marker in the camera frame C, mm
        (NaN where not seen).

    Returns
    -------
    d_eps_mm : ndarray, shape (...)
        ``sqrt((O_x - T_x)² + (O_y - T_y)²)``, mm (NaN where either is missing).
    """
    d = np.asarray(p_C_O, dtype=np.float64)[..., :2] - np.asarray(p_C_M, dtype=np.float64)[..., :2]
    return np.hypot(d[..., 0], d[..., 1])


def line_reference(T_B_F_init, p_eps, d_eps_min_mm: float, *, radius_mm: float = CIRCLE_RADIUS_MM) -> np.ndarray:
    """Reference TCP pose of the line-equation method, eq. (14)–(16).

    Parameters
    ----------
    T_B_F_init : array_like, shape (4, 4)
        TCP pose at the circle's centre, base frame B, mm (its orientation is held).
    p_eps : array_like, shape (3,)
        TCP position in B where the smallest distance error was measured, mm.
    d_eps_min_mm : float
        That smallest distance error (eq. 13), mm (>= 0).
    radius_mm : float
        Radius ``r`` of the circular path, mm.

    Returns
    -------
    T_B_ref : ndarray, shape (4, 4)
        ``[R_B_F_init, p_init + p_u (r + d_ε,min)]`` with ``p_u`` the unit vector from the
        centre towards ``p_eps`` (eq. 15), mm.

    Raises
    ------
    EstimationError
        ``p_eps`` coincides with the centre: the direction to the OOI is undefined.
    ConfigError
        A negative or non-finite distance or radius, or ``p_eps`` not 3 finite numbers.

    Examples
    --------
    >>> line_reference(np.eye(4), [0.0, 200.0, 0.0], 50.0)[:3, 3]
    array([  0., 250.,   0.])
    """
    T_init = check_transform(T_B_F_init, name="T_B_F_init")
    p_eps = np.asarray(p_eps, dtype=np.float64)
    if p_eps.shape != (3,) or not np.all(np.isfinite(p_eps)):
        raise ConfigError(f"p_eps: expected 3 finite numbers (mm), got {np.asarray(p_eps).tolist()}")
    if not (np.isfinite(d_eps_min_mm) and d_eps_min_mm >= 0):
        raise ConfigError(f"d_eps_min_mm: expected a finite distance >= 0 mm, got {d_eps_min_mm!r}")
    if not (np.isfinite(radius_mm) and radius_mm > 0):
        raise ConfigError(f"circle radius must be a finite number > 0 mm, got {radius_mm!r}")
    step = p_eps - T_init[:3, 3]
    norm = float(np.linalg.norm(step))
    if norm < _MIN_STEP_MM:
        raise EstimationError("line equation: the smallest distance error was measured at the circle's "
                              "centre, so the direction to the OOI is undefined (is the OOI inside the circle?)")
    p_u = step / norm
    T_ref = T_init.copy()
    T_ref[:3, 3] = T_init[:3, 3] + p_u * (radius_mm + float(d_eps_min_mm))
    return T_ref


class LineAdjustment(NamedTuple):
    """Outcome of :func:`line_range_adjustment`.

    T_B_ref : ndarray, shape (4, 4)
        Reference TCP pose (eq. 16) in B, mm.
    index : int
        Sample index of the smallest distance error.
    d_eps_min_mm : float
        The smallest distance error, mm.
    d_eps_mm : ndarray, shape (K,)
        Distance error of every sample, mm (NaN where the OOI or the tool marker was not seen).
    p_u : ndarray, shape (3,)
        Unit vector from the centre towards the OOI in B (eq. 15).
    """

    T_B_ref: np.ndarray
    index: int
    d_eps_min_mm: float
    d_eps_mm: np.ndarray
    p_u: np.ndarray


def line_range_adjustment(T_B_F_init, p_B_F, p_C_O, p_C_M, *,
                          radius_mm: float = CIRCLE_RADIUS_MM) -> LineAdjustment:
    """Find the smallest distance error along the executed circle and apply eq. (16).

    Parameters
    ----------
    T_B_F_init : array_like, shape (4, 4)
        TCP pose at the circle's centre (kinematic model), base frame B, mm.
    p_B_F : array_like, shape (K, 3)
        TCP positions (kinematic model, encoders) at the K camera samples along the path, mm.
    p_C_O, p_C_M : array_like, shape (K, 3)
        Measured OOI and tool-marker positions in the camera frame at those samples, mm;
        NaN rows where the OOI or the tool marker was not detected.
    radius_mm : float
        Radius of the circular path, mm.

    Returns
    -------
    LineAdjustment

    Raises
    ------
    EstimationError
        The OOI or the tool marker was never seen along the path, or the minimum lies at
        the centre.
    ConfigError
        Arrays of mismatched shapes.
    """
    p_B_F = np.asarray(p_B_F, dtype=np.float64)
    p_C_O = np.asarray(p_C_O, dtype=np.float64)
    p_C_M = np.asarray(p_C_M, dtype=np.float64)
    if p_B_F.ndim != 2 or p_B_F.shape[1] != 3 or p_C_O.shape != p_B_F.shape or p_C_M.shape != p_B_F.shape:
        raise ConfigError(f"line range adjustment: expected p_B_F, p_C_O, p_C_M of one shape (K, 3), got "
                          f"{p_B_F.shape}, {p_C_O.shape}, {p_C_M.shape}")
    if len(p_B_F) == 0 or np.all(np.isnan(p_C_O).any(axis=1)):
        raise EstimationError("line equation: the OOI (markers 1, 2, 3) was never seen during the circular path")
    if np.all(np.isnan(p_C_M).any(axis=1)):
        raise EstimationError("line equation: the tool marker (id 0) was never seen during the circular path")
    d = planar_distance_error(p_C_O, p_C_M)
    if np.all(np.isnan(d)):
        raise EstimationError("line equation: the OOI and the tool marker were never seen together during "
                              "the circular path")
    i = int(np.nanargmin(d))
    T_ref = line_reference(T_B_F_init, p_B_F[i], float(d[i]), radius_mm=radius_mm)
    T_init = np.asarray(T_B_F_init, dtype=np.float64)
    p_u = (T_ref[:3, 3] - T_init[:3, 3]) / (radius_mm + float(d[i]))
    return LineAdjustment(T_ref, i, float(d[i]), d, p_u)
