"""Can a gauge's profiles tell the normal from the reversed corner reading? (the load-time check)

A gauge whose profiles cannot tell two sensor poses apart is refused at load
(:func:`~posekit.profiler.gauge.model.load_gauge`) unless the mounting is given: the corners
read in reverse order match the ridges at another physically possible pose (the sensor above
the gauge, every face seen from its outside) within :data:`AMBIGUITY_MIN_MISS_UM` (or
:data:`AMBIGUITY_TOLERANCE_FACTOR` × ``tolerance_um`` if larger). The check probes a few
poses above the gauge (:func:`gauge_ambiguity`) and fits the reversed reading with the
estimator's compiled kernels (closed form and refinement: a design rule measured with the
solver that will read the gauge). :func:`pose_is_possible` and :func:`piercing_points` are
the gauge geometry the estimator's verdict uses too.
"""

import numpy as np

from ...geometry import matrix_from_rotation_vector
from ..estimate.closed_form import cf4_start, cf_kernel
from ..estimate.refine import refine_kernel
from .raycast import seen_from_behind

__all__ = ["gauge_ambiguity", "reversed_miss_um", "ambiguity_text", "pose_is_possible", "piercing_points",
           "SEEN_FROM_BEHIND_COS", "AMBIGUITY_MIN_MISS_UM", "AMBIGUITY_TOLERANCE_FACTOR"]

#: The reversed reading of a usable gauge misses its ridges by at least this (RMS, µm) at
#: every probe pose, or by 5 × ``tolerance_um`` if that is larger. The bundled gauges miss
#: by 180 µm or more; a corner's noise at the LJ-X8400's 10/5 µm is about 1-3 µm.
AMBIGUITY_MIN_MISS_UM = 10.0
AMBIGUITY_TOLERANCE_FACTOR = 5.0
#: Depth of the probe poses below the sensor, mm (any depth gives the same answer).
_PROBE_STANDOFF_MM = 440.0


def _probe_poses(gauge) -> list:
    """Sensor poses ``T_G_F`` above the gauge: level and tilted by 3-5°, at three places along y."""
    R0 = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    y_lo, y_hi = gauge.y_range
    yc = 0.5 * (y_lo + y_hi)
    tilts = np.radians([[0, 0, 0], [3, 0, 0], [-3, 0, 0], [0, 3, 0], [0, -3, 0], [0, 0, 5], [0, 0, -5]])
    poses = []
    for y in (yc, yc - 0.25 * (y_hi - y_lo), yc + 0.25 * (y_hi - y_lo)):
        ridge = gauge.ridge_q + y * gauge.ridge_s
        pivot = np.array([0.5 * (ridge[0, 0] + ridge[-1, 0]), y, float(np.mean(ridge[:, 2]))])
        for rv in tilts:
            T = np.eye(4)
            T[:3, :3] = R0 @ matrix_from_rotation_vector(rv)
            T[:3, 3] = pivot - T[:3, :3] @ np.array([0.0, 0.0, _PROBE_STANDOFF_MM])
            poses.append(T)
    return poses


def piercing_points(gauge, R_G_F, t_G_F):
    """Where each ridge crosses F's plane y = 0: (n, 2) corners (x, z) in F, ridge order, mm."""
    R_F_G = R_G_F.T
    q = gauge.ridge_q @ R_F_G.T - R_F_G @ t_G_F
    s = gauge.ridge_s @ R_F_G.T
    if np.any(np.abs(s[:, 1]) < 1e-9):
        return None
    p = q - (q[:, 1] / s[:, 1])[:, None] * s
    return np.ascontiguousarray(p[:, [0, 2]])


#: A face counts as seen from behind when the line of sight to its corner makes
#: ``normal · direction`` above this (about 14° behind the face's plane): far beyond the
#: fan's spread, so a real pose never fails it.
SEEN_FROM_BEHIND_COS = 0.25


def pose_is_possible(gauge, T_G_F, corners_F, margin_mm: float = 1.0, extent: bool = True) -> bool:
    """Whether a pose could have produced these corners.

    Parameters
    ----------
    gauge : Gauge
    T_G_F : ndarray, shape (4, 4)
        Pose of the profiler in G, mm.
    corners_F : ndarray, shape (n, 2)
        Corners (x, z) in F, mm, in ridge order.
    margin_mm : float
        How far beyond the block's y-extent a corner may lie, mm.
    extent : bool
        Check the y-extent (False: only which side the faces are seen from; a gauge file
        without ``extent`` has a guessed one).

    Returns
    -------
    bool
        False when a face would be seen from behind (through the material, e.g. from
        below the gauge: ``normal · line of sight`` > :data:`SEEN_FROM_BEHIND_COS`) or a
        corner lies beyond the block's ends in y.
    """
    c = np.asarray(corners_F, dtype=np.float64)
    T = np.asarray(T_G_F, dtype=np.float64)
    p_F = np.stack([c[:, 0], np.zeros(len(c)), c[:, 1]], axis=1)
    y = p_F @ T[1, :3] + T[1, 3]
    if extent and np.any((y < gauge.y_range[0] - margin_mm) | (y > gauge.y_range[1] + margin_mm)):
        return False
    return not seen_from_behind(gauge.normals, T, c, SEEN_FROM_BEHIND_COS)


def _reversed_miss_mm(gauge, T_G_F) -> float:
    """Smallest RMS miss (mm) of the reversed reading at a physically possible pose."""
    c = piercing_points(gauge, T_G_F[:3, :3], T_G_F[:3, 3])
    if c is None:
        return np.inf
    n = len(c)
    rev = np.ascontiguousarray(c[::-1])
    starts = []
    ok, R, t = (cf_kernel if n >= 5 else cf4_start)(rev, gauge.ridge_q, gauge.ridge_s)
    if ok:
        starts.append((R, t))
    # a 180° turn about the vertical through the middle of the ridges: exact for a symmetric gauge
    cx = 0.5 * (gauge.ridge_q[0, 0] + gauge.ridge_q[-1, 0])
    S = np.diag([-1.0, -1.0, 1.0])
    starts.append((S @ T_G_F[:3, :3], S @ T_G_F[:3, 3] + np.array([2.0 * cx, 0.0, 0.0])))
    W = np.eye(2 * n)
    best = np.inf
    for R_GF, t_GF in starts:
        R_FG = np.ascontiguousarray(R_GF.T)
        ok, R2, t2, _, cost, _ = refine_kernel(R_FG, -(R_FG @ t_GF), rev, W, gauge.ridge_q, gauge.ridge_s, 50)
        if not ok or not np.isfinite(cost):
            continue
        T = np.eye(4)
        T[:3, :3] = R2.T
        T[:3, 3] = -(R2.T @ t2)
        if pose_is_possible(gauge, T, rev):
            best = min(best, float(np.sqrt(cost / (2 * n))))
    return best


def gauge_ambiguity(gauge) -> str | None:
    """Why the gauge's profiles cannot tell the normal from the reversed reading, or None.

    At each of 21 probe poses above the gauge (level and tilted by 3-5°, at three places
    along the ridges) the noise-free corners are read in reverse order and fitted to the
    ridges (closed-form start and a 180° turn about the vertical, refined); fits that put
    the sensor where it could not have seen the corners (below the gauge, beyond its ends)
    do not count. The gauge is ambiguous when the best such fit misses by less than
    :data:`AMBIGUITY_MIN_MISS_UM` RMS (or :data:`AMBIGUITY_TOLERANCE_FACTOR` × its
    ``tolerance_um``).

    Parameters
    ----------
    gauge : Gauge

    Returns
    -------
    str or None
        A one-line description naming the ambiguity.
    """
    return ambiguity_text(gauge, reversed_miss_um(gauge))


def reversed_miss_um(gauge) -> float:
    """The best fit of the reversed reading over the probe poses of :func:`gauge_ambiguity`, µm RMS."""
    return float(1e3 * min(_reversed_miss_mm(gauge, T) for T in _probe_poses(gauge)))


def ambiguity_text(gauge, miss_um: float) -> str | None:
    """:func:`gauge_ambiguity` from the gauge's :func:`reversed_miss_um`."""
    limit_um = max(AMBIGUITY_MIN_MISS_UM, AMBIGUITY_TOLERANCE_FACTOR * gauge.tolerance_um)
    if miss_um >= limit_um:
        return None
    if miss_um < 0.01:
        return ("its cross-section is symmetric under a 180° turn about the vertical: read in reverse order, "
                "the corners fit the ridges exactly at another pose")
    return (f"read in reverse order, the corners fit the ridges at another pose within {miss_um:.2f} µm RMS "
            f"(a usable gauge misses by >= {limit_um:g} µm): too close to symmetric under a 180° turn")

