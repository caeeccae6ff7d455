"""Laser-plane / seam-polyline intersection (paper eq. 9 and Fig. 4), batched over planes.

The seam is a polyline ``P (K, 3)`` (the trend-filter knots for the filter, the dense true seam
for the simulated sensors). For a plane through ``m̂`` with unit normal ``n``, a segment
``p1 -> p2`` crosses it where the signed distances ``s = nᵀ(p - m̂)`` of its ends change
sign; the intersection is ``pi = p1 + γ v`` with ``γ = nᵀ(m̂ - p1) / nᵀv``, ``v = p2 - p1``.
Of several crossings, the one nearest ``m̂`` is taken. :meth:`SeamLine.candidates` restricts
the search to the few segments near an expected intersection (§II-E: the point of the
piecewise-affine approximation is to search tens of segments, not the whole trajectory).
"""

from typing import NamedTuple

import numpy as np

from posekit.errors import GeometryError
from posekit.seam.engine._kernels import window_kernel as _window_kernel

__all__ = ["Intersection", "SeamLine"]


class Intersection(NamedTuple):
    """Result of :meth:`SeamLine.intersect`.

    point : ndarray, shape (N, 3)
        Intersection points ``pi`` (mm, frame of the polyline); NaN where none was found.
    found : ndarray of bool, shape (N,)
        True where the plane crosses a candidate segment.
    segment : ndarray of int, shape (N,)
        Index of the crossed segment (-1 where none).
    """

    point: np.ndarray
    found: np.ndarray
    segment: np.ndarray


class SeamLine:
    """A seam polyline with a batched plane-intersection search.

    Parameters
    ----------
    points : array_like, shape (K, 3)
        Polyline vertices in order along the seam, mm (e.g. robot base frame). K >= 2.

    Raises
    ------
    GeometryError
        Wrong shape, fewer than 2 points or non-finite values.
    """

    def __init__(self, points):
        P = np.asarray(points, dtype=np.float64)
        if P.ndim != 2 or P.shape[1] != 3 or P.shape[0] < 2:
            raise GeometryError(f"seam polyline: expected shape (K >= 2, 3), got {P.shape}")
        if not np.all(np.isfinite(P)):
            raise GeometryError("seam polyline: non-finite vertices")
        self.points = P
        self.starts = P[:-1]
        self.vectors = P[1:] - P[:-1]
        self.all_segments = np.arange(P.shape[0] - 1)

    @property
    def n_segments(self) -> int:
        """Number of segments ``K - 1``."""
        return self.vectors.shape[0]

    def candidates(self, point, normal, window_mm: float, reach_mm: float | None = None) -> np.ndarray:
        """Segments that may cross planes near a given plane.

        Parameters
        ----------
        point : array_like, shape (3,)
            A point of the expected plane (e.g. the nominal sensor origin), mm.
        normal : array_like, shape (3,)
            Unit normal of the expected plane.
        window_mm : float
            Keep segments reaching within ``window_mm`` of the plane.
        reach_mm : float, optional
            Also drop segments farther than this from ``point`` (their nearest point; default
            ``10 window_mm + 50``).

        Returns
        -------
        segments : ndarray of int, shape (M,)
            Segment indices (possibly empty).
        """
        point = np.asarray(point, dtype=np.float64)
        normal = np.asarray(normal, dtype=np.float64)
        s = (self.points - point) @ normal
        s1, s2 = s[:-1], s[1:]
        near = (np.minimum(s1, s2) <= window_mm) & (np.maximum(s1, s2) >= -window_mm)
        reach = 10.0 * window_mm + 50.0 if reach_mm is None else reach_mm
        # the distance of the point from each segment (its nearest point: a long straight segment passing close counts)
        w = point - self.starts
        vv = (self.vectors * self.vectors).sum(axis=1)
        with np.errstate(invalid="ignore", divide="ignore"):
            g = np.clip(np.where(vv > 0.0, (w * self.vectors).sum(axis=1) / vv, 0.0), 0.0, 1.0)
        near &= np.linalg.norm(w - g[:, None] * self.vectors, axis=1) <= reach
        return np.flatnonzero(near)

    def window(self, point, normal, window_mm: float, reach_mm: float | None = None) -> tuple[int, int]:
        """Knot range ``(lo, hi)`` spanning :meth:`candidates` (compiled; hot path).

        Parameters
        ----------
        point : array_like, shape (3,)
            A point of the expected plane, mm, in the polyline's frame.
        normal : array_like, shape (3,)
            Unit normal of the expected plane.
        window_mm, reach_mm : float
            As in :meth:`candidates`.

        Returns
        -------
        (int, int)
            First and last knot index of the near segments; ``(-1, -1)`` when none is near.
        """
        reach = 10.0 * window_mm + 50.0 if reach_mm is None else reach_mm
        return _window_kernel(self.points, float(point[0]), float(point[1]), float(point[2]),
                              float(normal[0]), float(normal[1]), float(normal[2]), float(window_mm),
                              float(reach))

    def intersect(self, origins, normals, segments=None) -> Intersection:
        """Intersections of N planes with the polyline (no validation; hot path).

        Parameters
        ----------
        origins : ndarray, shape (N, 3)
            A point ``m̂`` on each plane (mm); the crossing nearest it is kept.
        normals : ndarray, shape (N, 3)
            Unit normal of each plane.
        segments : ndarray of int, shape (M,), optional
            Candidate segments (all by default).

        Returns
        -------
        Intersection
        """
        seg = self.all_segments if segments is None else np.asarray(segments)
        n = origins.shape[0]
        if seg.shape[0] == 0:
            return Intersection(np.full((n, 3), np.nan), np.zeros(n, bool), np.full(n, -1))
        a = self.starts[seg]  # (M, 3)
        v = self.vectors[seg]  # (M, 3)
        rowdot = (normals * origins).sum(axis=1)  # (N,)
        sa = normals @ a.T - rowdot[:, None]  # (N, M) signed distance of the segment starts
        nv = normals @ v.T  # (N, M)
        sb = sa + nv
        cross = (sa * sb <= 0.0) & (nv != 0.0)
        gamma = -sa / np.where(nv == 0.0, 1.0, nv)
        pts = a[None] + gamma[..., None] * v[None]  # (N, M, 3)
        diff = pts - origins[:, None, :]
        d2 = np.where(cross, (diff * diff).sum(axis=2), np.inf)
        j = np.argmin(d2, axis=1)
        rows = np.arange(n)
        found = np.isfinite(d2[rows, j])
        point = np.where(found[:, None], pts[rows, j], np.nan)
        return Intersection(point, found, np.where(found, seg[j], -1))
