"""Coarse frame alignment of two point sets without correspondences, never mirrored.

The principal axes of each (outlier-trimmed) set give ``R = V_dst D V_src^T``. The sign matrix ``D``
is chosen among the sign patterns with ``det R = +1`` only, so a reflection is never even a
candidate; axes whose spreads are nearly equal (a round path) are also tried rotated by 90 degrees
about the remaining axis. Each candidate is refined by a short CPD run and scored by the
negative log-likelihood of the mixture; orientations break ties between candidates that fit the
positions equally well (a symmetric path), and the best one is kept.
"""

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

from posekit.geometry import rotation_angle_between
from posekit.localcal.registration.alignment import body_rotation_spread, robust_principal_axes, thin_indices
from posekit.localcal.registration.cpd import box_volume, rigid_cpd

__all__ = ["TIE_NATS", "CoarseAlignment", "coarse_align", "orientation_spread", "pca_candidates"]

#: Two principal spreads closer than this ratio are treated as ambiguous (axes may swap).
_NEAR_EQUAL = 0.8
#: Candidates whose scores (mean negative log-likelihood per point) are within this of the best
#: are tied: the positions cannot tell them apart.
TIE_NATS = 0.25
#: Short CPD run per candidate.
_CANDIDATE_ITERS = 30


class CoarseAlignment(NamedTuple):
    """Best coarse transform ``x_dst ≈ s R x_src + t`` and how the candidates scored."""

    R: np.ndarray            #: (3, 3), det +1
    t: np.ndarray            #: (3,), mm
    s: float
    sigma2: float            #: mixture variance reached by the best candidate's CPD run, mm^2
    scores: np.ndarray       #: (K,) mean negative log-likelihood of each candidate (lower is better)
    best: int
    #: Largest angle between ``R`` and a tied candidate's rotation when no orientations broke the
    #: tie, rad (0 when nothing tied or orientations chose): > 0 means positions alone cannot
    #: tell these rotations apart (a symmetric path).
    unresolved_rad: float = 0.0


def _swap(i, j):
    """Rotation by +90 deg in the plane of axes i and j (a proper rotation)."""
    Q = np.eye(3)
    Q[i, i] = Q[j, j] = 0.0
    Q[i, j], Q[j, i] = -1.0, 1.0
    return Q


def pca_candidates(p_src, p_dst, *, with_scale: bool = False):
    """Proper-rotation candidates from the principal axes of two point sets.

    Parameters
    ----------
    p_src : ndarray, shape (M, 3)
        Source points, mm.
    p_dst : ndarray, shape (N, 3)
        Destination points, mm.
    with_scale : bool
        Also give the scale from the ratio of the spreads.

    Returns
    -------
    Rs : ndarray, shape (K, 3, 3)
        Candidate rotations ``R_dst_src``, every one with det +1.
    ts : ndarray, shape (K, 3)
        Matching translations (centroid to centroid), mm.
    s : float
        Scale (1.0 without ``with_scale``).
    """
    mu_s, Vs, sd_s, _ = robust_principal_axes(p_src)
    mu_d, Vd, sd_d, _ = robust_principal_axes(p_dst)
    s = float(np.sqrt((sd_d ** 2).sum() / (sd_s ** 2).sum())) if with_scale else 1.0
    base = []
    for d1 in (1.0, -1.0):
        for d2 in (1.0, -1.0):
            d3 = d1 * d2 * np.sign(np.linalg.det(Vd) * np.linalg.det(Vs))
            base.append(np.diag([d1, d2, d3]))
    extra = [np.eye(3)]
    spread = np.maximum(sd_s, sd_d)
    low = np.minimum(sd_s, sd_d)
    if low[1] > _NEAR_EQUAL * spread[0] or sd_s[1] > _NEAR_EQUAL * sd_s[0] or sd_d[1] > _NEAR_EQUAL * sd_d[0]:
        extra.append(_swap(0, 1))
    if sd_s[2] > _NEAR_EQUAL * sd_s[1] or sd_d[2] > _NEAR_EQUAL * sd_d[1]:
        extra.append(_swap(1, 2))
    Rs = np.array([Vd @ D @ Q @ Vs.T for D in base for Q in extra])
    ts = mu_d - s * Rs @ mu_s
    return Rs, ts, s


def _score(X, Y, res, w):
    """Mean negative log-likelihood of the data X under the converged mixture (lower is better).

    The outlier component is uniform over the bounding box of X (a proper density), so scores of
    different candidates compare even though their variances differ.
    """
    TY = res.s * Y @ res.R.T + res.t
    d2 = ((X[None, :, :] - TY[:, None, :]) ** 2).sum(-1)
    volume = box_volume(X)
    logg = -d2 / (2 * res.sigma2) - 1.5 * np.log(2 * np.pi * res.sigma2)
    m = logg.max(0)
    inl = np.log(np.exp(logg - m).mean(0)) + m + np.log(1.0 - w)
    lik = np.logaddexp(inl, -np.log(volume) + np.log(w))
    return float(-lik.mean())


def orientation_spread(R, t, s, p_src, R_src, p_dst, R_dst) -> float:
    """How far the orientations disagree with a transform, rad (median).

    Each src pose is paired with its nearest dst pose after ``s R p + t``; see
    :func:`.alignment.body_rotation_spread`.

    Parameters
    ----------
    R : ndarray, shape (3, 3)
        Candidate rotation ``R_dst_src``.
    t : ndarray, shape (3,)
        Candidate translation ``t_dst_src``, mm.
    s : float
        Candidate scale.
    p_src : ndarray, shape (M, 3)
        Source positions (src world frame), mm.
    R_src : ndarray, shape (M, 3, 3)
        Source orientations ``R_srcworld_body``.
    p_dst : ndarray, shape (N, 3)
        Destination positions (dst world frame), mm.
    R_dst : ndarray, shape (N, 3, 3)
        Destination orientations ``R_dstworld_body``.

    Returns
    -------
    float
        Median angle of the paired body-to-body rotations from their mean, rad.
    """
    _, j = cKDTree(p_dst).query(s * p_src @ R.T + t)
    return body_rotation_spread(R_src, R_dst[j], R)


def coarse_align(p_src, p_dst, *, w: float = 0.05, with_scale: bool = False, R_src=None, R_dst=None,
                 max_points: int = 150) -> CoarseAlignment:
    """Coarse transform from src to dst without correspondences (det +1 by construction).

    Every proper-rotation candidate of :func:`pca_candidates` is refined by a short positional CPD
    run and scored by the mixture's negative log-likelihood. When the best scores tie within
    ``TIE_NATS`` (a path whose shape is symmetric, so positions cannot tell the candidates apart)
    and orientations are given, the tied candidate whose orientations agree best
    (:func:`orientation_spread`) wins.

    Parameters
    ----------
    p_src : ndarray, shape (M, 3)
        Source positions, mm.
    p_dst : ndarray, shape (N, 3)
        Destination positions, mm.
    w : float
        Outlier weight of the CPD runs.
    with_scale : bool
        Similarity instead of rigid.
    R_src : ndarray, shape (M, 3, 3), optional
        Source orientations, for breaking ties.
    R_dst : ndarray, shape (N, 3, 3), optional
        Destination orientations.
    max_points : int
        Each set is thinned evenly (in its order) to at most this many points.

    Returns
    -------
    CoarseAlignment
        With ``unresolved_rad`` > 0 when candidates tie on the positions, rotate apart, and no
        orientations were given to choose.
    """
    ks = thin_indices(len(p_src), max_points)
    kd = thin_indices(len(p_dst), max_points)
    Y, X = p_src[ks], p_dst[kd]
    Rs, ts, s = pca_candidates(p_src, p_dst, with_scale=with_scale)
    scores, fits = [], []
    for R0, t0 in zip(Rs, ts):
        res = rigid_cpd(X, Y, R0=R0, t0=t0, s0=s, w=w, with_scale=with_scale,
                        max_iter=_CANDIDATE_ITERS, tol=1e-6)
        fits.append(res)
        scores.append(_score(X, Y, res, w))
    scores = np.array(scores)
    best = int(np.argmin(scores))
    tied = np.flatnonzero(scores <= scores[best] + TIE_NATS)
    unresolved = 0.0
    if R_src is not None and R_dst is not None and tied.size > 1:
        spread = [orientation_spread(fits[k].R, fits[k].t, fits[k].s, Y, R_src[ks], X, R_dst[kd])
                  for k in tied]
        best = int(tied[int(np.argmin(spread))])
    elif tied.size > 1:
        unresolved = float(rotation_angle_between(fits[best].R, np.array([fits[k].R for k in tied]),
                                                  check=False).max())
    return CoarseAlignment(fits[best].R, fits[best].t, fits[best].s, fits[best].sigma2, scores, best,
                           unresolved)
