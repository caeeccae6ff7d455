"""Lines and planes: intersections and distances, batched."""

import numpy as np

from ..errors import GeometryError

__all__ = [
    "plane_intersection",
    "intersect_lines_2d",
    "point_line_distance",
    "line_plane_intersection",
]


def plane_intersection(n_a, d_a, n_b, d_b, *, min_sin=1e-9):
    """Line of intersection of planes ``{p : n_a·p = d_a}`` and ``{p : n_b·p = d_b}``.

    Parameters
    ----------
    n_a, n_b : array_like, shape (..., 3)
        Plane normals (any length, not zero).
    d_a, d_b : array_like, shape (...)
        Plane offsets, in the unit of the points (mm).
    min_sin : float, optional
        Planes whose unit normals make an angle with ``|sin| < min_sin`` count as parallel.

    Returns
    -------
    point : ndarray, shape (..., 3)
        The point of the line closest to the origin.
    direction : ndarray, shape (..., 3)
        Unit direction ``n_a × n_b / |n_a × n_b|``.

    Raises
    ------
    GeometryError
        If a normal is zero or the planes are parallel.
    """
    n_a = np.asarray(n_a, dtype=np.float64)
    n_b = np.asarray(n_b, dtype=np.float64)
    d_a = np.asarray(d_a, dtype=np.float64)
    d_b = np.asarray(d_b, dtype=np.float64)
    la = np.linalg.norm(n_a, axis=-1)
    lb = np.linalg.norm(n_b, axis=-1)
    if np.any(la == 0) or np.any(lb == 0):
        raise GeometryError("plane_intersection: a plane normal is zero; expected a non-zero normal")
    ua, ub = n_a / la[..., None], n_b / lb[..., None]
    da, db = d_a / la, d_b / lb
    cross = np.cross(ua, ub)
    s = np.linalg.norm(cross, axis=-1)
    if np.any(s < min_sin):
        raise GeometryError("plane_intersection: planes are parallel; they have no line in common")
    direction = cross / s[..., None]
    # Closest point to the origin: p = (da (ub×c) + db (c×ua)) / |c|², c = ua×ub.
    point = (da[..., None] * np.cross(ub, cross) + db[..., None] * np.cross(cross, ua)) / (s**2)[..., None]
    return point, direction


def intersect_lines_2d(n_a, c_a, n_b, c_b, *, min_sin=1e-12):
    """Intersection of 2D lines ``{p : n_a·p = c_a}`` and ``{p : n_b·p = c_b}``.

    Parameters
    ----------
    n_a, n_b : array_like, shape (..., 2)
        Line normals (unit or not).
    c_a, c_b : array_like, shape (...)
        Line offsets.

    Returns
    -------
    point : ndarray, shape (..., 2)

    Raises
    ------
    GeometryError
        If the lines are parallel (``|n_a × n_b| < min_sin |n_a||n_b|``).
    """
    n_a = np.asarray(n_a, dtype=np.float64)
    n_b = np.asarray(n_b, dtype=np.float64)
    c_a = np.asarray(c_a, dtype=np.float64)
    c_b = np.asarray(c_b, dtype=np.float64)
    det = n_a[..., 0] * n_b[..., 1] - n_a[..., 1] * n_b[..., 0]
    scale = np.linalg.norm(n_a, axis=-1) * np.linalg.norm(n_b, axis=-1)
    if np.any(np.abs(det) <= min_sin * scale):
        raise GeometryError("intersect_lines_2d: lines are parallel; expected lines that cross")
    x = (c_a * n_b[..., 1] - c_b * n_a[..., 1]) / det
    y = (n_a[..., 0] * c_b - n_b[..., 0] * c_a) / det
    return np.stack([x, y], axis=-1)


def point_line_distance(p, q, s):
    """Perpendicular distance of points from 3D lines ``q + λ s``.

    Parameters
    ----------
    p : array_like, shape (..., 3)
        Points.
    q : array_like, shape (..., 3)
        A point of each line.
    s : array_like, shape (..., 3)
        Direction of each line (any non-zero length).

    Returns
    -------
    distance : ndarray, shape (...)
        In the unit of the points.
    """
    p = np.asarray(p, dtype=np.float64)
    q = np.asarray(q, dtype=np.float64)
    s = np.asarray(s, dtype=np.float64)
    s_hat = s / np.linalg.norm(s, axis=-1, keepdims=True)
    return np.linalg.norm(np.cross(p - q, s_hat), axis=-1)


def line_plane_intersection(q, s, normal, offset, *, min_cos=1e-12):
    """Intersection of lines ``q + λ s`` with planes ``{p : normal·p = offset}``.

    Parameters
    ----------
    q, s : array_like, shape (..., 3)
        Point and direction of each line.
    normal : array_like, shape (..., 3)
    offset : array_like, shape (...)

    Returns
    -------
    point : ndarray, shape (..., 3)
    lam : ndarray, shape (...)
        Line parameter of the intersection.

    Raises
    ------
    GeometryError
        If a line is parallel to its plane.
    """
    q = np.asarray(q, dtype=np.float64)
    s = np.asarray(s, dtype=np.float64)
    normal = np.asarray(normal, dtype=np.float64)
    denom = np.sum(normal * s, axis=-1)
    scale = np.linalg.norm(normal, axis=-1) * np.linalg.norm(s, axis=-1)
    if np.any(np.abs(denom) <= min_cos * scale):
        raise GeometryError("line_plane_intersection: line is parallel to the plane")
    lam = (np.asarray(offset, dtype=np.float64) - np.sum(normal * q, axis=-1)) / denom
    return q + lam[..., None] * s, lam
