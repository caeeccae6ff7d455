"""Closed-form and robust alignment of corresponding point sets (Umeyama), and path checks.

``umeyama`` is the weighted least-squares similarity/rigid transform of Umeyama (1991, PAMI 13(4))
with the reflection guard, so ``det R = +1`` always. ``robust_umeyama`` wraps it in a trimmed
re-fit that rejects gross outliers by a median-based threshold.
"""

import numpy as np

from posekit.errors import GeometryError, TrajectoryError
from posekit.geometry import nearest_rotation, rotation_angle_between

__all__ = [
    "INLIER_SIGMAS",
    "MIN_POSES",
    "body_rotation_spread",
    "check_path_shape",
    "robust_inliers",
    "robust_principal_axes",
    "robust_umeyama",
    "thin_indices",
    "umeyama",
]

#: Fewest poses (or pose pairs) a trajectory match accepts.
MIN_POSES = 6
#: Inlier gate, in robust standard deviations of the 3D residual. Meant for gross outliers only:
#: real SLAM residuals are heavy-tailed (TUM fr1/xyz RGB-D SLAM: median 11 mm, max 36 mm), and a
#: 4-sigma gate (chi-3 99.9 %) would drop 2 % of good pairs there and turn R by 0.22 deg.
INLIER_SIGMAS = 6.0
#: Median of the chi distribution with 3 degrees of freedom: median |e| = 1.538 sigma.
_CHI3_MEDIAN = 1.5382
#: A path whose second principal extent is below this fraction of the first is a straight line.
LINE_RATIO = 0.01
#: Largest number of points :func:`robust_principal_axes` fits its axes to (evenly subsampled).
_AXES_MAX_POINTS = 50_000
#: A path whose first principal extent (std) is below this, mm, does not move.
STILL_MM = 1e-3


def robust_inliers(dist):
    """Residuals within ``INLIER_SIGMAS`` robust sigmas (median / chi-3 median) of zero.

    Parameters
    ----------
    dist : ndarray, shape (N,)
        3D residual lengths, mm.

    Returns
    -------
    ndarray, shape (N,), bool
        True where ``dist <= INLIER_SIGMAS * max(median(dist) / 1.5382, 1e-9)``.
    """
    return dist <= INLIER_SIGMAS * max(np.median(dist) / _CHI3_MEDIAN, 1e-9)


def umeyama(src, dst, *, weights=None, with_scale: bool = False):
    """Least-squares rigid (or similarity) transform with ``dst ≈ s R src + t``.

    Parameters
    ----------
    src, dst : array_like, shape (N, 3)
        Corresponding points, src frame and dst frame, mm; N >= 3.
    weights : array_like, shape (N,), optional
        Non-negative weights (default all 1).
    with_scale : bool
        Also estimate the scale ``s`` (Sim(3)); otherwise ``s = 1``.

    Returns
    -------
    R : ndarray, shape (3, 3)
        Rotation ``R_dst_src`` with ``det R = +1`` (never a reflection).
    t : ndarray, shape (3,)
        Translation ``t_dst_src``, mm.
    s : float
        Scale (1.0 unless ``with_scale``).

    Raises
    ------
    GeometryError
        ``src`` and ``dst`` not of one shape (N, 3) with N >= 3, a value not finite, or weights
        that are not N finite values >= 0 with a positive sum.
    """
    src = np.ascontiguousarray(src, dtype=np.float64)     # a strided view (T[:, :3, 3]) is 10x slower
    dst = np.ascontiguousarray(dst, dtype=np.float64)
    if src.ndim != 2 or src.shape[1] != 3 or dst.shape != src.shape or len(src) < 3:
        raise GeometryError(f"umeyama: expected src and dst of one shape (N, 3) with N >= 3, "
                            f"got {src.shape} and {dst.shape}")
    if not (np.isfinite(src).all() and np.isfinite(dst).all()):
        raise GeometryError("umeyama: expected finite points, found NaN or infinity")
    w = np.ones(len(src)) if weights is None else np.asarray(weights, dtype=np.float64)
    if w.shape != (len(src),) or not np.isfinite(w).all() or (w < 0).any() or not w.sum() > 0:
        raise GeometryError(f"umeyama: expected {len(src)} finite weights >= 0 with a positive sum")
    w = w / w.sum()
    mu_s = w @ src
    mu_d = w @ dst
    a = src - mu_s
    b = dst - mu_d
    cov = (b * w[:, None]).T @ a                       # sum w (dst - mu_d)(src - mu_s)^T
    U, S, Vt = np.linalg.svd(cov)
    d = np.ones(3)
    d[2] = np.sign(np.linalg.det(U) * np.linalg.det(Vt)) or 1.0
    R = (U * d) @ Vt
    s = 1.0
    if with_scale:
        var_s = w @ np.einsum("ij,ij->i", a, a)
        s = float((S * d).sum() / var_s)
    t = mu_d - s * R @ mu_s
    return R, t, s


def robust_umeyama(src, dst, *, with_scale: bool = False, outlier_fraction: float = 0.05,
                   max_iter: int = 30):
    """Umeyama with gross-outlier rejection (trimmed start, then a median-based gate).

    The first fit uses every pair; the worst ``2 * outlier_fraction`` of the pairs are dropped
    for the second; then pairs whose residual exceeds ``INLIER_SIGMAS`` robust standard deviations
    (``sigma = median |e| / 1.538`` over the current inliers, the chi-3 median) are rejected, until
    the inlier set no longer changes.

    Parameters
    ----------
    src, dst : array_like, shape (N, 3)
        Corresponding points in the src and dst frames, mm.
    with_scale : bool
        Estimate a scale too.
    outlier_fraction : float
        Expected fraction of gross outliers, for the trimmed start.
    max_iter : int
        Cap on the re-fits.

    Returns
    -------
    R : ndarray, shape (3, 3)
        Rotation ``R_dst_src`` (det +1), fitted on the inliers.
    t : ndarray, shape (3,)
        Translation ``t_dst_src``, mm.
    s : float
        Scale (1.0 unless ``with_scale``).
    inliers : ndarray, shape (N,), bool
        Pairs kept by the gate.
    residuals : ndarray, shape (N,)
        ``|dst - (s R src + t)|`` of every pair, mm.
    """
    src = np.ascontiguousarray(src, dtype=np.float64)
    dst = np.ascontiguousarray(dst, dtype=np.float64)
    n = len(src)
    R, t, s = umeyama(src, dst, with_scale=with_scale)
    res = np.linalg.norm(dst - (s * src @ R.T + t), axis=1)
    keep = max(3, int(np.ceil(n * (1.0 - 2.0 * outlier_fraction))))
    inl = np.zeros(n, dtype=bool)
    inl[np.argsort(res)[:keep]] = True
    for _ in range(max_iter):
        R, t, s = umeyama(src[inl], dst[inl], with_scale=with_scale)
        res = np.linalg.norm(dst - (s * src @ R.T + t), axis=1)
        sigma = np.median(res[inl]) / _CHI3_MEDIAN
        new = res <= INLIER_SIGMAS * sigma + 1e-9
        if new.sum() < 3:
            break
        if np.array_equal(new, inl):
            break
        inl = new
    return R, t, s, inl, res


def robust_principal_axes(p, n_iter: int = 3):
    """Centroid and principal axes of a point set, ignoring gross outliers.

    Points beyond a Mahalanobis distance of 4 (chi-square 3-dof 99.9 % is 16.3) from the current
    mean and covariance are dropped, three times. Sets larger than ``_AXES_MAX_POINTS`` are
    evenly subsampled for the axes (``keep`` still covers every point).

    Parameters
    ----------
    p : ndarray, shape (N, 3)
        Points, mm.

    Returns
    -------
    mean : ndarray, shape (3,)
        mm.
    axes : ndarray, shape (3, 3)
        Columns are the principal directions, largest variance first.
    std : ndarray, shape (3,)
        Standard deviations along ``axes``, mm, descending.
    keep : ndarray, shape (N,), bool
        The points used.
    """
    p = full = np.ascontiguousarray(p, dtype=np.float64)
    if len(p) > _AXES_MAX_POINTS:              # a long trajectory: the axes of an even subsample
        p = p[thin_indices(len(p), _AXES_MAX_POINTS)]
    keep = np.ones(len(p), dtype=bool)
    cov_r = np.eye(3)
    for _ in range(n_iter):
        mean = p[keep].mean(axis=0)
        cov = np.cov(p[keep].T, bias=True)
        cov_r = cov + np.eye(3) * (1e-9 * np.trace(cov) + 1e-12)
        d = p - mean
        m2 = np.einsum("ij,ij->i", d @ np.linalg.inv(cov_r), d)
        new = m2 <= 16.3
        if new.sum() < 3 or np.array_equal(new, keep):
            break
        keep = new
    mean = p[keep].mean(axis=0)
    cov = np.cov(p[keep].T, bias=True)
    lam, V = np.linalg.eigh(cov)
    order = np.argsort(lam)[::-1]
    if full is not p:
        d = full - mean
        cov_r = cov + np.eye(3) * (1e-9 * np.trace(cov) + 1e-12)
        keep = np.einsum("ij,ij->i", d @ np.linalg.inv(cov_r), d) <= 16.3
    return mean, V[:, order], np.sqrt(np.clip(lam[order], 0.0, None)), keep


def body_rotation_spread(R_src, R_dst, R) -> float:
    """Median angle between paired body-to-body rotations and their mean, rad.

    For pairs of orientations ``R_src_i`` (src world) and ``R_dst_i`` (dst world) of two rigidly
    attached bodies, ``X_i = R_src_i^T R^T R_dst_i`` is one constant rotation when ``R`` is the
    right ``R_dst_src``, whatever the mount between the bodies is.

    Parameters
    ----------
    R_src, R_dst : ndarray, shape (K, 3, 3)
        Paired orientations.
    R : ndarray, shape (3, 3)
        Candidate ``R_dst_src``.

    Returns
    -------
    float
        Median angle of the ``X_i`` from their chordal mean, rad (NaN for K = 0).
    """
    if len(R_src) == 0:
        return float("nan")
    if len(R_src) > _AXES_MAX_POINTS:          # a median: an even subsample of a long trajectory
        k = thin_indices(len(R_src), _AXES_MAX_POINTS)
        R_src, R_dst = R_src[k], R_dst[k]
    Xs = np.swapaxes(R_src, 1, 2) @ R.T @ R_dst
    return float(np.median(rotation_angle_between(Xs, nearest_rotation(Xs.sum(0)), check=False)))


def thin_indices(n: int, k: int) -> np.ndarray:
    """At most ``k`` evenly spaced indices of ``range(n)`` (all of them if ``n <= k``).

    Parameters
    ----------
    n : int
        Length of the sequence.
    k : int
        Largest number of indices to keep.

    Returns
    -------
    idx : ndarray of int, shape (min(n, k),)
        Increasing indices, the first and last of the sequence included.
    """
    if n <= k:
        return np.arange(n)
    return np.linspace(0, n - 1, k).round().astype(int)


def check_path_shape(p, name: str) -> None:
    """Raise TrajectoryError if a path is too short, does not move, or is a straight line.

    Parameters
    ----------
    p : ndarray, shape (N, 3)
        Positions, mm.
    name : str
        What the path is, for the message (a file name).
    """
    if len(p) < MIN_POSES:
        raise TrajectoryError(f"{name}: {len(p)} poses, at least {MIN_POSES} are needed for "
                              f"trajectory matching")
    _, _, std, _ = robust_principal_axes(p)
    if std[0] < STILL_MM:
        raise TrajectoryError(f"{name}: all positions are equal (the body does not move); "
                              f"trajectory matching needs a planar or 3D path")
    if std[1] < LINE_RATIO * std[0]:
        raise TrajectoryError(
            f"{name}: the path is a straight line (spread {std[1]:.1f} mm across vs {std[0]:.1f} mm "
            f"along it), so the rotation about it is undetermined; trajectory matching needs a planar "
            f"or 3D path")
