"""Correspondence-free matching with positions and orientations (hybrid-mixture style).

The paper's fine matching ([31], Min et al., ICRA 2018) uses the full 6-DoF poses: each Gaussian
of the position mixture is multiplied by an orientation factor. Here: the coarse alignment of
:mod:`.coarse`, then rigid CPD with the matrix-Fisher orientation term of :func:`.cpd.rigid_cpd`
(``exp(-κ (3 - tr(R_dst_n^T R R_src_m X)))`` with an unknown constant body-to-body rotation
``X``), then a polish on every pose: each src pose is paired with the dst pose nearest in the
joint space ``|Δp|²/σ² + 2κ (3 - tr(...))`` and ``R`` is re-fitted from positions and
orientations together (``argmax tr(Rᵀ (A/σ² + κ Σ R_dst X^T R_src^T))``), until the pairing
settles.

When the orientations are constant along the path the orientation term is the same for every
pair and the result equals the positional CPD's.
"""

import numpy as np
from scipy.spatial import cKDTree

from posekit.geometry import nearest_rotation
from posekit.localcal.registration.alignment import robust_inliers, thin_indices
from posekit.localcal.registration.cpd import KAPPA_MAX, rigid_cpd

__all__ = ["hybrid_refine"]

#: Joint-space polish iterations at most.
_POLISH_ITERS = 20


def _joint_fit(ps, Rs, pd, Rd, X, sigma2, kappa, w, with_scale):
    """Weighted joint M-step on fixed pairs: (R, t, s)."""
    wsum = w.sum()
    mu_s, mu_d = w @ ps / wsum, w @ pd / wsum
    a, b = ps - mu_s, pd - mu_d
    A = (b * w[:, None]).T @ a
    B = A / sigma2 + kappa * np.einsum("n,nij,kj,nlk->il", w, Rd, X, Rs)   # Σ Rd X^T Rs^T
    R = nearest_rotation(B)
    s = float(np.trace(A.T @ R) / (w @ (a ** 2).sum(1))) if with_scale else 1.0
    return R, mu_d - s * R @ mu_s, s


def hybrid_refine(p_src, R_src, p_dst, R_dst, coarse, *, w: float = 0.05, with_scale: bool = False,
                  max_points: int = 400):
    """Fine correspondence-free registration using positions and orientations.

    Parameters
    ----------
    p_src : ndarray, shape (M, 3)
        Source positions (src world frame), mm.
    R_src : ndarray, shape (M, 3, 3)
        Source orientations ``R_srcworld_body``.
    p_dst : ndarray, shape (N, 3)
        Destination positions (dst world frame), mm.
    R_dst : ndarray, shape (N, 3, 3)
        Destination orientations ``R_dstworld_body``.
    coarse : CoarseAlignment
        Start (``R``, ``t``, ``s``, ``sigma2``).
    w : float
        Outlier weight of the CPD.
    with_scale : bool
        Similarity instead of rigid.
    max_points : int
        Each set is thinned evenly to at most this many points for the CPD.

    Returns
    -------
    R : ndarray, shape (3, 3)
        ``R_dst_src``.
    t : ndarray, shape (3,)
        ``t_dst_src``, mm.
    s : float
        Scale.
    inliers : ndarray, shape (M,), bool
        src poses within ``INLIER_SIGMAS`` robust sigmas of their partner.
    j : ndarray, shape (M,), int
        Each src pose's dst partner.
    """
    ks, kd = thin_indices(len(p_src), max_points), thin_indices(len(p_dst), max_points)
    fine = rigid_cpd(p_dst[kd], p_src[ks], R0=coarse.R, t0=coarse.t, s0=coarse.s, w=w, with_scale=with_scale,
                     sigma2=coarse.sigma2, Rx=R_dst[kd], Ry=R_src[ks])
    R, t, s, X = fine.R, fine.t, fine.s, fine.X_body
    sigma2 = max(fine.sigma2, 1e-6)
    kappa = fine.kappa
    Rd_flat = R_dst.reshape(len(R_dst), 9)
    for _ in range(_POLISH_ITERS):
        # joint nearest neighbour: |Δp|² / σ² + κ |R_dst - R R_src X|_F² (= 2κ (3 - tr))
        c = np.sqrt(kappa * sigma2)
        tree = cKDTree(np.hstack([p_dst, c * Rd_flat]))
        q = np.hstack([s * p_src @ R.T + t, c * (R @ R_src @ X).reshape(len(p_src), 9)])
        _, j = tree.query(q)
        d = np.linalg.norm(p_dst[j] - (s * p_src @ R.T + t), axis=1)
        inl = robust_inliers(d)
        if inl.sum() < 3:
            break
        wts = inl.astype(float)
        R_new, t_new, s = _joint_fit(p_src, R_src, p_dst[j], R_dst[j], X, sigma2, kappa, wts, with_scale)
        X = nearest_rotation(np.einsum("nji,kj,nkl->il", R_src[inl], R_new, R_dst[j][inl]))
        e = p_dst[j][inl] - (s * p_src[inl] @ R_new.T + t_new)
        sigma2 = max(float((e ** 2).sum(1).mean() / 3.0), 1e-6)
        gap = 3.0 - np.einsum("nij,nij->n", R_dst[j][inl], R_new @ R_src[inl] @ X)
        kappa = min(1.5 / max(float(gap.mean()), 1e-12), KAPPA_MAX)
        step = np.linalg.norm(R_new - R) * 1e3 + np.linalg.norm(t_new - t)
        R, t = R_new, t_new
        if step < 1e-4:
            break
    d = np.linalg.norm(p_dst[j] - (s * p_src @ R.T + t), axis=1)
    inl = robust_inliers(d)
    return R, t, s, inl, j
