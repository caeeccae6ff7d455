"""How far an as-built gauge lies from its drawing, and the frame that compares them.

Points spread over each face's footprint (:func:`face_samples`; :func:`observed_samples` puts
the outer faces' weight on their one ridge, the only place a profile sees them), the RMS
distance of one gauge's faces from another's (:func:`face_deviation_um`, µm) and the rigid
motion that best fits a measured gauge onto the drawing (:func:`datum_transform`). Frame G, mm.
"""

import numpy as np

from ...geometry import matrix_from_rotation_vector
from .model import Gauge

__all__ = ["face_samples", "observed_samples", "face_deviation_um", "datum_transform", "GRID"]


#: Footprint grid per face (points along x and y) for the datum and the face statistics.
GRID = 8


def face_samples(gauge: Gauge, grid: int = GRID):
    """Points spread uniformly over each face's footprint, on the face, and their weights.

    Returns
    -------
    points : ndarray, shape (n + 1, grid², 3)
        Points in G, mm (midpoint grid in y over the block, in x between the face's ridges).
    weights : ndarray, shape (n + 1, grid²)
        Footprint area of each point, mm².
    """
    y0, y1 = gauge.y_range
    ys = y0 + (np.arange(grid) + 0.5) * (y1 - y0) / grid
    rx = gauge.ridge_x(ys)                                            # (grid, n)
    lo = np.concatenate([np.full((grid, 1), gauge.x_range[0]), rx], axis=1)
    hi = np.concatenate([rx, np.full((grid, 1), gauge.x_range[1])], axis=1)
    frac = (np.arange(grid) + 0.5) / grid
    xs = lo.T[:, :, None] + (hi - lo).T[:, :, None] * frac            # (F, grid_y, grid_x)
    Y = np.broadcast_to(ys[None, :, None], xs.shape)
    n = gauge.normals
    Z = (gauge.offsets[:, None, None] - n[:, 0, None, None] * xs - n[:, 1, None, None] * Y) / n[:, 2, None, None]
    pts = np.stack([xs, Y, Z], axis=-1).reshape(len(n), grid * grid, 3)
    w = np.repeat(((hi - lo).T * (y1 - y0) / grid**2)[:, :, None], grid, axis=2).reshape(len(n), -1)
    return pts, w


def observed_samples(gauge: Gauge, grid: int = GRID):
    """:func:`face_samples`, with each outer face's points moved onto its ridge.

    The profiles see an outer face only where it meets its one ridge (see
    :func:`hinge_constraints`); its weight, the face's footprint area, is spread along the
    ridge. Same shapes and units as :func:`face_samples`.
    """
    pts, w = face_samples(gauge, grid)
    y0, y1 = gauge.y_range
    m = pts.shape[1]
    ys = y0 + (np.arange(m) + 0.5) * (y1 - y0) / m
    for face, ridge in ((0, 0), (len(w) - 1, gauge.n_corners - 1)):
        pts[face] = gauge.ridge_q[ridge] + ys[:, None] * gauge.ridge_s[ridge]
        w[face] = w[face].sum() / m
    return pts, w


def face_deviation_um(gauge: Gauge, reference: Gauge, grid: int = GRID, observed: bool = False) -> np.ndarray:
    """RMS over each face's footprint of ``gauge``'s face from ``reference``'s, µm, shape (n + 1,).

    At points p on the reference face: the distance ``n · p - d`` from ``gauge``'s face.
    ``observed``: the outer faces along their ridge only (:func:`observed_samples`).
    """
    pts, w = (observed_samples if observed else face_samples)(reference, grid)
    e = np.einsum("fmi,fi->fm", pts, gauge.normals) - gauge.offsets[:, None]
    return np.sqrt(np.sum(w * e**2, axis=1) / np.sum(w, axis=1)) * 1e3


def datum_transform(gauge: Gauge, nominal: Gauge, grid: int = GRID, iters: int = 5) -> np.ndarray:
    """The rigid motion ``T`` (4, 4) that best fits ``gauge``'s faces onto the drawing.

    Minimises ``Σ w (n'_f · p - d'_f)²`` over the nominal :func:`observed_samples` p, for the faces
    ``(n', d')`` of ``gauge`` moved by T (Gauss–Newton, small motions). Moving a gauge by T
    (``p → R p + t``) puts it in the frame :func:`calibrate_gauge` uses; a pose ``T_G_F``
    on it becomes ``T @ T_G_F``.
    """
    pts, w = observed_samples(nominal, grid)
    T = np.eye(4)
    for _ in range(iters):
        n = gauge.normals @ T[:3, :3].T
        d = gauge.offsets + n @ T[:3, 3]
        e = np.einsum("fmi,fi->fm", pts, n) - d[:, None]
        # motion ξ = [ρ, φ]: n' = n + φ × n, d' = d + n·ρ  ⇒  δe = -n·ρ + φ·(n × p)
        J = np.concatenate([-np.broadcast_to(n[:, None, :], pts.shape), np.cross(n[:, None, :], pts)], axis=-1)
        H = np.einsum("fm,fma,fmb->ab", w, J, J)
        g = np.einsum("fm,fma,fm->a", w, J, e)
        xi = -np.linalg.solve(H, g)
        dT = np.eye(4)
        dT[:3, :3] = matrix_from_rotation_vector(xi[3:])
        dT[:3, 3] = xi[:3]
        T = dT @ T
        if np.linalg.norm(xi) < 1e-13:
            break
    return T
