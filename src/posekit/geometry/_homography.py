"""Planar homographies: normalized DLT, reprojection refinement, degeneracy checks.

A homography ``H`` maps points ``p_src`` of one plane to ``p_dst`` of another:
``[u, v, w]ᵀ = H @ [x, y, 1]ᵀ``, ``p_dst = (u / w, v / w)``. It is defined up to scale; this
module returns it scaled so that ``H[2, 2] == 1`` (or, when ``|H[2, 2]|`` vanishes, to unit
Frobenius norm). Image coordinates follow OpenCV: the centre of the top-left pixel is (0, 0).
"""

import math

import numpy as np

from ..errors import CalibrationError, GeometryError

__all__ = [
    "homography_dlt",
    "apply_homography",
    "refine_homography",
    "check_correspondences",
    "normalize_homography",
]

# --- tolerances, in one place --------------------------------------------------------------
#: Points whose spread across their best-fit line is below this fraction of the spread along
#: it count as lying on one line (also: a triangle with height < this fraction of its
#: longest side is degenerate).
COLLINEAR_TOL = 1e-3
#: Two points closer than this (in Hartley-normalized units, mean distance √2) coincide.
DUPLICATE_TOL = 1e-9
#: A point maps to infinity when ``|w| <= INFINITY_TOL * (|h20 x| + |h21 y| + |h22|)``.
INFINITY_TOL = 1e-12
#: The normalized DLT system must have rank 8: its 8th singular value above this fraction
#: of the largest.
RANK_TOL = 1e-9
#: An estimated homography whose condition number exceeds this is singular.
MAX_COND = 1e12


def normalize_homography(H):
    """Scale a homography so that ``H[..., 2, 2] == 1``.

    Parameters
    ----------
    H : array_like, shape (..., 3, 3)

    Returns
    -------
    H : ndarray, shape (..., 3, 3)
        ``H / H[2, 2]``; where ``|H[2, 2]| <= 1e-12 ‖H‖_F`` (the origin of the source plane
        maps to infinity) ``H / ‖H‖_F`` instead, with the sign of ``H[2, 2]`` kept.
    """
    H = np.asarray(H, dtype=np.float64)
    if H.ndim == 2:                                      # the common single-matrix case, fast
        h22, fro = H[2, 2], math.sqrt(float((H * H).sum()))
        return H / h22 if abs(h22) > 1e-12 * fro else H / math.copysign(fro, h22)
    h22 = H[..., 2, 2]
    fro = np.linalg.norm(H, axis=(-2, -1))
    small = np.abs(h22) <= 1e-12 * fro
    scale = np.where(small, fro * np.where(h22 < 0, -1.0, 1.0), h22)
    return H / scale[..., None, None]


def _hartley(pts):
    """Similarity ``T`` (3, 3) moving the centroid to 0 and the mean distance to √2."""
    c = pts.mean(axis=0)
    q = pts - c
    d = np.sqrt(q[:, 0] ** 2 + q[:, 1] ** 2).mean()
    s = math.sqrt(2.0) / d if d > 0 else 1.0
    T = np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])
    return T, q * s


def _unnormalize(Td, Hn, Ts):
    """``Td⁻¹ @ Hn @ Ts`` for Hartley similarities, scaled to ``H[2, 2] = 1``."""
    s = Td[0, 0]
    Td_inv = np.array([[1.0 / s, 0.0, -Td[0, 2] / s], [0.0, 1.0 / s, -Td[1, 2] / s], [0.0, 0.0, 1.0]])
    return normalize_homography(Td_inv @ Hn @ Ts)


def _line_spread(sxx, sxy, syy):
    """sqrt(λmin / λmax) of the 2x2 scatter matrices (batched): 0 for points on a line."""
    half = 0.5 * (sxx + syy)
    root = np.sqrt(0.25 * (sxx - syy) ** 2 + sxy**2)
    lmax = half + root
    lmin = np.maximum(half - root, 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(lmax > 0, np.sqrt(lmin / lmax), 0.0)


def _collinearity_message(pn, name):
    """None, or why the normalized points ``pn`` (N, 2) cannot carry a homography."""
    n = len(pn)
    x, y = pn[:, 0], pn[:, 1]
    sx, sy = x.sum(), y.sum()
    sxx, sxy, syy = (x * x).sum(), (x * y).sum(), (y * y).sum()
    if _line_spread(sxx - sx * sx / n, sxy - sx * sy / n, syy - sy * sy / n) < COLLINEAR_TOL:
        return (f"all {n} {name} points lie on one line (or within 0.1 % of one); expected points "
                "spread over the plane, at least 4 of them with no 3 on a line")
    # Leave-one-out scatter of the other n - 1 points, all at once.
    m = n - 1
    lx, ly = sx - x, sy - y
    ratio = _line_spread(sxx - x * x - lx * lx / m, sxy - x * y - lx * ly / m, syy - y * y - ly * ly / m)
    i = int(np.argmin(ratio))
    if ratio[i] < COLLINEAR_TOL:
        return (f"{m} of the {n} {name} points lie on one line (all but point {i}); expected at "
                "least 4 points with no 3 on a line")
    return None


def check_correspondences(src, dst, *, names=("src", "dst")):
    """Validate point correspondences for a homography; raise the reason they cannot carry one.

    Parameters
    ----------
    src, dst : array_like, shape (N, 2)
        Corresponding points of the two planes (any unit, e.g. mm and px).
    names : tuple of str, optional
        What to call the two sets in messages (``("world", "image")`` → "world points").

    Returns
    -------
    src, dst : ndarray, shape (N, 2), float64

    Raises
    ------
    CalibrationError
        Wrong shape, fewer than 4 points, a non-finite value, two coinciding points, or all
        (or all but one) points of a set on one line (within ``COLLINEAR_TOL``). Points are
        numbered from 0 in the messages.
    """
    out = []
    for pts, name in zip((src, dst), names):
        try:
            arr = np.asarray(pts, dtype=np.float64)
        except (TypeError, ValueError):
            raise CalibrationError(f"homography: {name} points must be numbers in an (N, 2) array") from None
        if arr.ndim != 2 or arr.shape[1] != 2:
            raise CalibrationError(f"homography: expected {name} points of shape (N, 2), got {arr.shape}")
        out.append(arr)
    src, dst = out
    if len(src) != len(dst):
        raise CalibrationError(f"homography: {len(src)} {names[0]} points but {len(dst)} {names[1]} "
                               "points; expected one per correspondence")
    n = len(src)
    if n < 4:
        raise CalibrationError(f"homography: need at least 4 point correspondences, got {n}")
    for arr, name in zip((src, dst), names):
        bad = np.flatnonzero(~np.isfinite(arr).all(axis=1))
        if bad.size:
            i = int(bad[0])
            raise CalibrationError(f"homography: {name} point {i} is not finite ({arr[i, 0]:g}, {arr[i, 1]:g}); "
                                   "expected finite coordinates")
        _, pn = _hartley(arr)
        if n <= 256:
            d2 = ((pn[:, None, :] - pn[None, :, :]) ** 2).sum(axis=-1)
            pairs = np.argwhere(np.triu(d2 <= DUPLICATE_TOL**2, k=1))
        else:
            from scipy.spatial import cKDTree
            pairs = cKDTree(pn).query_pairs(DUPLICATE_TOL, output_type="ndarray")
        if len(pairs):
            i, j = min(tuple(sorted(p)) for p in pairs.tolist())
            raise CalibrationError(f"homography: {name} points {i} and {j} coincide at "
                                   f"({arr[i, 0]:g}, {arr[i, 1]:g}); expected distinct points")
        msg = _collinearity_message(pn, name)
        if msg:
            raise CalibrationError(f"homography: {msg}")
    return src, dst


def _dlt_normalized(ps, pd):
    """DLT of normalized points (N, 2) → (H (3, 3), 8th/1st singular value ratio)."""
    n = len(ps)
    A = np.zeros((max(n, 5), 2, 9))                     # (n, 2, 9) rows; a zero row pads n = 4
    P = A[:n, 0, 0:3]
    P[:, 0:2] = ps
    P[:, 2] = 1.0
    A[:n, 1, 3:6] = P
    A[:n, 0, 6:9] = pd[:, 0:1] * P
    A[:n, 1, 6:9] = pd[:, 1:2] * P
    A[:n, 0, 0:3] *= -1.0
    A[:n, 1, 3:6] *= -1.0
    _, s, Vt = np.linalg.svd(A.reshape(-1, 9), full_matrices=False)
    return Vt[-1].reshape(3, 3), s[7] / s[0]


def homography_dlt(src, dst, *, normalize=True, check=True):
    """Homography from 4 or more point correspondences by the normalized DLT (Hartley).

    Each point set is translated to its centroid and scaled to a mean distance √2 from it;
    the 2N×9 system is solved by SVD; the result is denormalized and scaled to ``H[2,2] = 1``.
    Minimises the algebraic error; :func:`refine_homography` then minimises the geometric one;
    :func:`~posekit.geometry.homography_ransac` rejects mismatched points.

    Parameters
    ----------
    src : array_like, shape (N, 2)
        Points of the source plane, e.g. world (X, Y) on the ceiling, mm.
    dst : array_like, shape (N, 2)
        The corresponding points of the destination plane, e.g. image (u, v), px.
    normalize : bool, optional
        Hartley normalization (default). Without it the result depends on the coordinates'
        origin and scale; only for comparisons.
    check : bool, optional
        Validate the input with :func:`check_correspondences` (default). ``False`` skips
        the checks, for callers that validated already.

    Returns
    -------
    H_dst_src : ndarray, shape (3, 3)
        Maps src to dst: ``dst ~ H @ [x, y, 1]``.

    Raises
    ------
    CalibrationError
        Degenerate input (see :func:`check_correspondences`), or correspondences that do not
        determine a homography (rank-deficient system, singular result).

    Examples
    --------
    >>> src = [[0, 0], [1, 0], [1, 1], [0, 1]]
    >>> homography_dlt(src, [[0, 0], [2, 0], [2, 2], [0, 2]]).round(12) + 0.0
    array([[2., 0., 0.],
           [0., 2., 0.],
           [0., 0., 1.]])
    >>> homography_dlt(src[:3], src[:3])
    Traceback (most recent call last):
    ...
    posekit.errors.CalibrationError: homography: need at least 4 point correspondences, got 3
    """
    if check:
        src, dst = check_correspondences(src, dst)
    else:
        src, dst = np.asarray(src, dtype=np.float64), np.asarray(dst, dtype=np.float64)
    if normalize:
        Ts, ps = _hartley(src)
        Td, pd = _hartley(dst)
    else:
        Ts = Td = np.eye(3)
        ps, pd = src, dst
    Hn, rank_ratio = _dlt_normalized(ps, pd)
    if check and not rank_ratio > RANK_TOL:
        raise CalibrationError("homography: the correspondences do not determine a homography (the DLT "
                               "system has rank < 8); expected at least 4 points with no 3 on a line")
    if check and np.linalg.cond(Hn) > MAX_COND:
        raise CalibrationError("homography: the least-squares homography is singular; the correspondences "
                               "are inconsistent (swapped or mistyped points?)")
    return _unnormalize(Td, Hn, Ts)


def apply_homography(H, pts, *, invalid="raise"):
    """Map points through a homography.

    Parameters
    ----------
    H : array_like, shape (3, 3)
        ``H_dst_src``, e.g. ``H_image_world`` (mm → px).
    pts : array_like, shape (..., 2)
        Points of the source plane.
    invalid : {"raise", "nan"}, optional
        What to do with a point that maps to infinity (it lies on the line H sends to the
        line at infinity, e.g. the horizon of the ceiling in the image): raise (default) or
        return NaN for it.

    Returns
    -------
    out : ndarray, shape (..., 2)
        The mapped points, in the unit of the destination plane.

    Raises
    ------
    GeometryError
        If ``H`` is not 3x3 or ``pts`` not (..., 2); with ``invalid="raise"``, if a point
        maps to infinity.
    """
    H = np.asarray(H, dtype=np.float64)
    pts = np.asarray(pts, dtype=np.float64)
    if H.shape != (3, 3):
        raise GeometryError(f"apply_homography: expected a 3x3 homography, got shape {H.shape}")
    if pts.ndim == 0 or pts.shape[-1] != 2:
        raise GeometryError(f"apply_homography: expected points of shape (..., 2), got {pts.shape}")
    x, y = pts[..., 0], pts[..., 1]
    w = H[2, 0] * x + H[2, 1] * y + H[2, 2]
    at_inf = np.abs(w) <= INFINITY_TOL * (np.abs(H[2, 0] * x) + np.abs(H[2, 1] * y) + abs(H[2, 2]))
    if np.any(at_inf):
        if invalid == "raise":
            k = int(np.flatnonzero(at_inf.ravel())[0])
            px, py = x.ravel()[k], y.ravel()[k]
            raise GeometryError(f"apply_homography: point {k} ({px:g}, {py:g}) maps to infinity (it lies on "
                                "the line the homography sends to infinity); expected points away from it")
        w = np.where(at_inf, np.nan, w)
    out = np.empty(pts.shape)
    out[..., 0] = (H[0, 0] * x + H[0, 1] * y + H[0, 2]) / w
    out[..., 1] = (H[1, 0] * x + H[1, 1] * y + H[1, 2]) / w
    return out


def _project_and_jacobian(theta, ps):
    """Projection of normalized points and its Jacobian w.r.t. the 8 free entries (h22 = 1)."""
    h = np.append(theta, 1.0)
    n = len(ps)
    P = np.c_[ps, np.ones(n)]
    num_u, num_v, w = P @ h[0:3], P @ h[3:6], P @ h[6:9]
    u, v = num_u / w, num_v / w
    J = np.zeros((n, 2, 8))
    J[:, 0, 0:3] = P / w[:, None]
    J[:, 1, 3:6] = P / w[:, None]
    J[:, 0, 6:8] = -(u / w)[:, None] * ps
    J[:, 1, 6:8] = -(v / w)[:, None] * ps
    return np.c_[u, v], J


def refine_homography(H, src, dst, *, check=True):
    """Refine a homography by minimising the reprojection error in the destination plane.

    Minimises ``Σ ‖apply_homography(H, src_i) - dst_i‖²`` over the 8 free parameters of H
    (Levenberg–Marquardt, ``scipy.optimize.least_squares(method="lm")`` with an analytic
    Jacobian) in Hartley-normalized coordinates. The result is never worse than ``H``.

    Parameters
    ----------
    H : array_like, shape (3, 3)
        Initial ``H_dst_src``, e.g. from :func:`homography_dlt`.
    src, dst : array_like, shape (N, 2)
        Correspondences, N >= 4 (as for :func:`homography_dlt`).
    check : bool, optional
        Validate the correspondences first (default).

    Returns
    -------
    H_dst_src : ndarray, shape (3, 3)
        Scaled to ``H[2, 2] = 1``.

    Raises
    ------
    CalibrationError
        Degenerate correspondences, or an ``H`` that maps the centroid of ``src`` to infinity.
    """
    from scipy.optimize import least_squares

    if check:
        src, dst = check_correspondences(src, dst)
    else:
        src, dst = np.asarray(src, dtype=np.float64), np.asarray(dst, dtype=np.float64)
    H = np.asarray(H, dtype=np.float64)
    Ts, ps = _hartley(src)
    Td, pd = _hartley(dst)
    Hn = Td @ H @ np.linalg.inv(Ts)
    if not abs(Hn[2, 2]) > 1e-12 * np.linalg.norm(Hn):
        raise CalibrationError("refine_homography: the initial homography maps the centroid of the source "
                               "points to infinity; expected an estimate such as homography_dlt's")
    theta0 = (Hn / Hn[2, 2]).ravel()[:8]
    scale = 1.0 / Td[0, 0]                   # normalized dst units -> dst units

    def fun(theta):
        proj, _ = _project_and_jacobian(theta, ps)
        return ((proj - pd) * scale).ravel()

    def jac(theta):
        return _project_and_jacobian(theta, ps)[1].reshape(-1, 8) * scale

    r0 = fun(theta0)
    cost0 = float(r0 @ r0) if np.all(np.isfinite(r0)) else np.inf
    res = least_squares(fun, theta0, jac=jac, method="lm", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    theta = res.x if np.all(np.isfinite(res.fun)) and 2.0 * res.cost <= cost0 else theta0
    Hn = np.append(theta, 1.0).reshape(3, 3)
    return _unnormalize(Td, Hn, Ts)
