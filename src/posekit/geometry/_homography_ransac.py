"""Homography robust to mismatched points: RANSAC on minimal 4-point samples."""

import itertools
import math

import numpy as np

from ..errors import CalibrationError
from ._homography import (
    COLLINEAR_TOL,
    _dlt_normalized,
    _hartley,
    _unnormalize,
    check_correspondences,
)

__all__ = ["homography_ransac"]


def _sample_errors(Hs, ps, pd):
    """Squared transfer errors (B, N) of normalized points under normalized homographies (B, 3, 3)."""
    P = np.c_[ps, np.ones(len(ps))]
    q = P @ np.swapaxes(Hs, 1, 2)                                    # (B, N, 3)
    w = q[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        e2 = ((q[..., :2] / w[..., None] - pd) ** 2).sum(axis=-1)
    return np.where(np.isfinite(e2), e2, np.inf)


def _good_samples(p4):
    """(B,) True where no 3 of the 4 points (B, 4, 2) are on a line (height/side >= COLLINEAR_TOL)."""
    ok = np.ones(len(p4), dtype=bool)
    for tri in ((0, 1, 2), (0, 1, 3), (0, 2, 3), (1, 2, 3)):
        a, b, c = (p4[:, k] for k in tri)
        ab, ac, bc = b - a, c - a, c - b
        cross = np.abs(ab[:, 0] * ac[:, 1] - ab[:, 1] * ac[:, 0])
        side2 = np.maximum(np.maximum((ab**2).sum(1), (ac**2).sum(1)), (bc**2).sum(1))
        ok &= cross >= COLLINEAR_TOL * side2
    return ok


def _dlt4_batch(ps4, pd4):
    """Homographies (B, 3, 3) from minimal samples (B, 4, 2) of normalized points."""
    b = len(ps4)
    A = np.zeros((b, 9, 9))                              # 8 equations + a zero row
    x, y, u, v = ps4[..., 0], ps4[..., 1], pd4[..., 0], pd4[..., 1]
    one = np.ones_like(x)
    A[:, 0:8:2, 0:3] = -np.stack([x, y, one], axis=-1)
    A[:, 1:8:2, 3:6] = -np.stack([x, y, one], axis=-1)
    A[:, 0:8:2, 6:9] = u[..., None] * np.stack([x, y, one], axis=-1)
    A[:, 1:8:2, 6:9] = v[..., None] * np.stack([x, y, one], axis=-1)
    return np.linalg.svd(A)[2][:, -1].reshape(b, 3, 3)


def homography_ransac(src, dst, threshold, *, rng=None, max_trials=5000, confidence=0.999, check=True):
    """Homography robust to mismatched points: RANSAC on minimal 4-point samples.

    Samples with 3 collinear points (in either plane) are skipped. Each hypothesis is scored
    by its inlier count (transfer error in dst ``<= threshold``), ties broken by the MSAC cost;
    the number of random trials adapts to the inlier ratio (``confidence``). When all
    ``C(N, 4)`` samples fit in ``max_trials`` (N <= 20 by default) every one is tried, and the
    result does not depend on ``rng``. The winner is refitted
    by :func:`~posekit.geometry.homography_dlt` on its inliers until the inlier set settles.

    Parameters
    ----------
    src, dst : array_like, shape (N, 2)
        Correspondences, N >= 4 (e.g. world mm, image px).
    threshold : float
        Largest transfer error ``‖H(src) - dst‖`` of an inlier, in dst units (px).
    rng : numpy.random.Generator or int or None, optional
        Source of the random samples.
    max_trials : int, optional
        Most samples tried.
    confidence : float, optional
        Probability that at least one all-inlier sample was drawn, in (0, 1).
    check : bool, optional
        Validate the correspondences first (default).

    Returns
    -------
    H_dst_src : ndarray, shape (3, 3)
        DLT fit on the inliers, ``H[2, 2] = 1``; not refined (see
        :func:`~posekit.geometry.refine_homography`).
    inliers : ndarray of bool, shape (N,)

    Raises
    ------
    CalibrationError
        Degenerate correspondences, a bad threshold, or no sample in general position.
    """
    if not (np.isfinite(threshold) and threshold > 0):
        raise CalibrationError(f"homography_ransac: threshold must be a finite number > 0 (dst units), got {threshold}")
    if not 0 < confidence < 1:
        raise CalibrationError(f"homography_ransac: confidence must be in (0, 1), got {confidence}")
    if check:
        src, dst = check_correspondences(src, dst)
    else:
        src, dst = np.asarray(src, dtype=np.float64), np.asarray(dst, dtype=np.float64)
    rng = np.random.default_rng(rng)
    n = len(src)
    Ts, ps = _hartley(src)
    Td, pd = _hartley(dst)
    thr2 = (threshold * Td[0, 0]) ** 2
    exhaustive = math.comb(n, 4) <= max_trials
    pool = np.array(list(itertools.combinations(range(n), 4))) if exhaustive else None
    limit = len(pool) if exhaustive else int(max_trials)
    best = (-1, np.inf, None)                                # (count, MSAC cost, H)
    trials, drawn_good, needed = 0, 0, float(limit)
    while trials < min(limit, needed):
        b = min(512, limit - trials)
        idx = pool[trials:trials + b] if exhaustive else np.argsort(rng.random((b, n)), axis=1)[:, :4]
        trials += b
        good = _good_samples(ps[idx]) & _good_samples(pd[idx])
        if not good.any():
            continue
        drawn_good += int(good.sum())
        Hs = _dlt4_batch(ps[idx[good]], pd[idx[good]])
        e2 = _sample_errors(Hs, ps, pd)
        counts = (e2 <= thr2).sum(axis=1)
        costs = np.minimum(e2, thr2).sum(axis=1)
        k = np.lexsort((costs, -counts))[0]
        if (counts[k], -costs[k]) > (best[0], -best[1]):
            best = (int(counts[k]), float(costs[k]), Hs[k])
            w = best[0] / n
            if not exhaustive:
                needed = 0.0 if w >= 1 else math.log1p(-confidence) / math.log1p(-(w**4))
    if drawn_good == 0:
        raise CalibrationError(f"homography_ransac: all {trials} 4-point samples had 3 points on a line; "
                               "expected points in general position")
    inliers = _sample_errors(best[2][None], ps, pd)[0] <= thr2
    Hn = best[2]
    for _ in range(10):                                      # local optimisation on the inliers
        if inliers.sum() < 4:
            break
        Hn_new, _ = _dlt_normalized(ps[inliers], pd[inliers])
        new = _sample_errors(Hn_new[None], ps, pd)[0] <= thr2
        if new.sum() < inliers.sum():
            break
        Hn, changed, inliers = Hn_new, np.any(new != inliers), new
        if not changed:
            break
    return _unnormalize(Td, Hn, Ts), inliers
