"""Orthogonal (total least squares) line fitting in the plane, plain and outlier-robust."""

import numpy as np

from posekit._jit import njit

from ..errors import GeometryError

__all__ = ["fit_line_tls", "fit_line_robust", "robust_line_kernel"]


@njit(cache=True, nogil=True)
def _line_from_moments(sw, sx, sy, sxx, sxy, syy, rx, ry):
    """TLS line from raw moments of points taken relative to (rx, ry)."""
    mx = sx / sw
    my = sy / sw
    cxx = max(sxx - sx * mx, 0.0)
    cxy = sxy - sx * my
    cyy = max(syy - sy * my, 0.0)
    theta = 0.5 * np.arctan2(2.0 * cxy, cxx - cyy)
    dx = np.cos(theta)
    dy = np.sin(theta)
    nx = -dy
    ny = dx
    half = 0.5 * (cxx + cyy)
    root = np.sqrt(0.25 * (cxx - cyy) ** 2 + cxy * cxy)
    s_tt = half + root               # spread along the line
    s_nn = max(half - root, 0.0)     # sum of squared perpendicular residuals
    mx += rx
    my += ry
    return nx, ny, nx * mx + ny * my, mx, my, s_tt, s_nn


#: IEEE-relaxing flags that let LLVM vectorise the reductions; no 'nnan'/'ninf':
#: NaN and infinity still behave (the kernels see only finite data anyway).
FASTMATH = {"reassoc", "contract", "arcp", "nsz"}


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def robust_line_kernel(xs, ys, start, stop, passes, k_sigma, floor):
    """TLS fit of ``xs[start:stop], ys[start:stop]`` rejecting residuals beyond ``k_sigma`` RMS.

    Each pass is one sweep over the points: residuals from the current line decide the
    inliers (``|r| <= max(k_sigma * rms, floor)``) and their moments give the next line,
    whose residual RMS is the smallest eigenvalue of the scatter matrix. Unchecked.

    Returns ``(nx, ny, c, mx, my, n_inliers, s_tt, rms)``: unit normal, offset
    (``nx*x + ny*y = c``), inlier centroid, inlier count, spread of the inliers along the
    line (sum of squares about the centroid) and inlier residual RMS.
    """
    rx = xs[start]
    ry = ys[start]
    sw = 0.0
    sx = 0.0
    sy = 0.0
    sxx = 0.0
    sxy = 0.0
    syy = 0.0
    for i in range(start, stop):
        x = xs[i] - rx
        y = ys[i] - ry
        sw += 1.0
        sx += x
        sy += y
        sxx += x * x
        sxy += x * y
        syy += y * y
    if sw < 2.0:
        return 0.0, 0.0, 0.0, 0.0, 0.0, sw, 0.0, 0.0
    nx, ny, c, mx, my, s_tt, s_nn = _line_from_moments(sw, sx, sy, sxx, sxy, syy, rx, ry)
    n_in = sw
    for _ in range(passes):
        thr = max(k_sigma * np.sqrt(s_nn / n_in), floor)
        cw = 0.0
        sx = 0.0
        sy = 0.0
        sxx = 0.0
        sxy = 0.0
        syy = 0.0
        for i in range(start, stop):       # branch-free, so LLVM can vectorise it
            x = xs[i] - rx
            y = ys[i] - ry
            w = 1.0 if abs(nx * xs[i] + ny * ys[i] - c) <= thr else 0.0
            wx = w * x
            wy = w * y
            cw += w
            sx += wx
            sy += wy
            sxx += wx * x
            sxy += wx * y
            syy += wy * y
        if cw < 2.0:
            break
        same = cw == n_in
        n_in = cw
        nx, ny, c, mx, my, s_tt, s_nn = _line_from_moments(cw, sx, sy, sxx, sxy, syy, rx, ry)
        if same:
            break
    return nx, ny, c, mx, my, n_in, s_tt, np.sqrt(s_nn / n_in)


def _check_points(points, name):
    pts = np.asarray(points, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise GeometryError(f"{name}: expected points of shape (N, 2), got {pts.shape}")
    if pts.shape[0] < 2:
        raise GeometryError(f"{name}: a line needs at least 2 points, got {pts.shape[0]}")
    if not np.all(np.isfinite(pts)):
        raise GeometryError(f"{name}: points must be finite (drop NaN before fitting)")
    return pts


def _line_result(nx, ny, c, mx, my, sw, name):
    if sw <= 0.0:
        raise GeometryError(f"{name}: no points left to fit a line")
    normal = np.array([nx, ny]) + 0.0
    # Canonical sign: offset c >= 0, and for c == 0 a normal in the upper half plane.
    if c < 0 or (c == 0 and (ny < 0 or (ny == 0 and nx < 0))):
        normal, c = -normal, -c
    return normal, float(c), np.array([mx, my])


def fit_line_tls(points):
    """Orthogonal (total least squares) line fit.

    Minimises the sum of squared perpendicular distances, unlike ordinary regression
    of y on x, so a steep or vertical line is fitted as well as a flat one.

    Parameters
    ----------
    points : array_like, shape (N, 2)
        Points in the plane (mm in posekit), N >= 2, finite.

    Returns
    -------
    normal : ndarray, shape (2,)
        Unit normal of the line; sign chosen so that ``offset >= 0``.
    offset : float
        The line is ``{p : normal @ p == offset}``, in the unit of ``points``.
    centroid : ndarray, shape (2,)
        Mean of the points, a point on the line.

    Raises
    ------
    GeometryError
        On a wrong shape, fewer than 2 points or non-finite values.

    Examples
    --------
    >>> n, c, m = fit_line_tls([[0, 1], [1, 1], [2, 1]])
    >>> n.round(6).tolist(), round(c, 6)
    ([0.0, 1.0], 1.0)
    """
    pts = _check_points(points, "fit_line_tls")
    nx, ny, c, mx, my, n_in, _, _ = robust_line_kernel(
        np.ascontiguousarray(pts[:, 0]), np.ascontiguousarray(pts[:, 1]), 0, pts.shape[0], 0, 0.0, 0.0
    )
    return _line_result(nx, ny, c, mx, my, n_in, "fit_line_tls")


def fit_line_robust(points, *, k_sigma=4.0, passes=4, floor=1e-6):
    """Orthogonal line fit that rejects outliers (spikes) by iterated residual trimming.

    Fits by TLS, then repeatedly keeps only the points within ``max(k_sigma * rms, floor)``
    of the line and refits on them (at most ``passes`` times, until the inliers settle).

    Parameters
    ----------
    points : array_like, shape (N, 2)
        Points in the plane (mm in posekit), N >= 2, finite.
    k_sigma : float, optional
        Rejection threshold in residual RMS units.
    passes : int, optional
        Maximum number of reject-and-refit passes.
    floor : float, optional
        Smallest rejection threshold, in the unit of ``points``.

    Returns
    -------
    normal : ndarray, shape (2,)
    offset : float
    centroid : ndarray, shape (2,)
        As :func:`fit_line_tls`, for the inliers.
    inliers : ndarray of bool, shape (N,)
    rms : float
        Residual RMS of the inliers, in the unit of ``points``.
    """
    pts = _check_points(points, "fit_line_robust")
    xs = np.ascontiguousarray(pts[:, 0])
    ys = np.ascontiguousarray(pts[:, 1])
    nx, ny, c, mx, my, n_in, _, rms = robust_line_kernel(xs, ys, 0, pts.shape[0], int(passes),
                                                         float(k_sigma), float(floor))
    normal, offset, centroid = _line_result(nx, ny, c, mx, my, n_in, "fit_line_robust")
    thr = max(k_sigma * rms, floor)
    inliers = np.abs(pts @ np.array([nx, ny]) - c) <= thr * (1 + 1e-9)
    return normal, offset, centroid, inliers, float(rms)
