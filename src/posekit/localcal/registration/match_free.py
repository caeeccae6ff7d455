"""Trajectory matching without timestamps: coarse alignment, rigid CPD, a nearest-neighbour polish
and a point-to-line refinement (the correspondence-free half of :mod:`.match`)."""

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from posekit.errors import TrajectoryError
from posekit.geometry import nearest_rotation, rotation_angle_between
from posekit.localcal.registration.alignment import body_rotation_spread, robust_inliers, thin_indices, umeyama
from posekit.localcal.registration.coarse import coarse_align
from posekit.localcal.registration.cpd import rigid_cpd
from posekit.localcal.registration.hybrid import hybrid_refine
from posekit.localcal.registration.uncertainty import path_tangents

__all__ = ["CPD_MAX_POINTS", "LINE_ITERS", "ORIENTATION_STILL_DEG", "POLISH_ITERS", "SYMMETRY_DEG", "match_free"]

#: Each set is thinned evenly to at most this many points for the fine CPD.
CPD_MAX_POINTS = 400
#: Orientations that all stay within this angle of their mean carry no information on R
#: (the orientation term would be the same for every pair); the CPD then runs on positions only.
ORIENTATION_STILL_DEG = 2.0
#: Nearest-neighbour re-fits after the CPD, at most.
POLISH_ITERS = 30
#: Coarse candidates that tie on the positions but rotate further apart than this make a match
#: without timestamps ambiguous, deg (tied candidates on asymmetric paths: < 0.03 deg; on a circle
#: or an ellipse: 180 deg).
SYMMETRY_DEG = 2.0
#: Point-to-line Gauss-Newton steps after the polish, at most.
LINE_ITERS = 10


def _turns(R) -> bool:
    """True if the orientations along a path vary by more than ORIENTATION_STILL_DEG."""
    angles = rotation_angle_between(R, nearest_rotation(R.sum(0)), check=False)
    return bool(np.rad2deg(angles.max()) > ORIENTATION_STILL_DEG)


def _polish(ps, tree, pd, R, t, s, with_scale, max_iter=POLISH_ITERS):
    """Trimmed nearest-neighbour refinement of the CPD result against every dst pose.

    The CPD runs on thinned sets (``CPD_MAX_POINTS``), and the sample spacing on a fast path
    biases it (seen up to 0.6 deg on random smooth paths); this polish pairs every src pose with
    its nearest dst pose and re-fits (Umeyama) on the pairs within ``INLIER_SIGMAS`` robust sigmas
    until the pairing settles. A second CPD level on 1000 points was as accurate but 5x slower.
    """
    for _ in range(max_iter):
        dist, j = tree.query(s * ps @ R.T + t)
        inl = robust_inliers(dist)
        if inl.sum() < 3:
            break
        R_new, t_new, s_new = umeyama(ps[inl], pd[j[inl]], with_scale=with_scale)
        step = np.linalg.norm(R_new - R) * 1e3 + np.linalg.norm(t_new - t)
        R, t, s = R_new, t_new, s_new
        if step < 1e-4:
            break
    dist, j = tree.query(s * ps @ R.T + t)
    inl = robust_inliers(dist)
    return R, t, s, inl, j


def _line_refine(ps, tree, pd, tangents, R, t, s, inl, j, max_iter=LINE_ITERS):
    """Point-to-line Gauss-Newton refinement of a nearest-neighbour match.

    A nearest-neighbour pair measures the distance to a dst *sample*, not to the path: with dst
    samples a few mm apart that pulls the fit along the path by up to a sample spacing (seen as
    0.2-0.4 deg on the thin planar paths of the verdict tests). Here each pair's residual and
    Jacobian are projected across the local dst path direction (point-to-line), and ``R``, ``t``
    take Gauss-Newton steps on the inlier pairs until the step is below 1e-6 rad / 1e-4 mm.
    """
    for _ in range(max_iter):
        if inl.sum() < 6:
            break
        q = s * ps[inl] @ R.T
        e = pd[j[inl]] - q - t
        tg = tangents[j[inl]]
        J = np.zeros((len(q), 3, 6))
        J[:, 0, 1], J[:, 0, 2] = q[:, 2], -q[:, 1]          # d(exp([δ]x) q)/dδ = -[q]x
        J[:, 1, 0], J[:, 1, 2] = -q[:, 2], q[:, 0]
        J[:, 2, 0], J[:, 2, 1] = q[:, 1], -q[:, 0]
        J[:, :, 3:] = np.eye(3)
        J = J - tg[:, :, None] * np.einsum("ni,nij->nj", tg, J)[:, None, :]
        e = e - tg * np.einsum("ni,ni->n", tg, e)[:, None]
        H = np.einsum("nij,nik->jk", J, J)
        try:
            x = np.linalg.solve(H, np.einsum("nij,ni->j", J, e))
        except np.linalg.LinAlgError:
            break
        R = Rotation.from_rotvec(x[:3]).as_matrix() @ R
        t = t + x[3:]
        dist, j = tree.query(s * ps @ R.T + t)
        inl = robust_inliers(dist)
        if np.linalg.norm(x[:3]) < 1e-6 and np.linalg.norm(x[3:]) < 1e-4:
            break
    return R, t, inl, j


def match_free(src, dst, with_scale, outlier_fraction, use_orientations, names, matcher="cpd"):
    """Correspondence-free match of ``src`` to ``dst``: ``(R, t, s, inliers, j, spread_deg)`` with
    ``j`` the nearest dst pose of every src pose (see :func:`.match.match_trajectories`)."""
    ps, pd = src.positions, dst.positions
    turns = use_orientations and (_turns(src.rotations) or _turns(dst.rotations))
    Rsrc = src.rotations if turns else None
    Rdst = dst.rotations if turns else None
    w = max(outlier_fraction, 1e-3)
    coarse = coarse_align(ps, pd, w=w, with_scale=with_scale, R_src=Rsrc, R_dst=Rdst)
    if use_orientations and np.rad2deg(coarse.unresolved_rad) > SYMMETRY_DEG:
        raise TrajectoryError(
            f"{names[0]} and {names[1]}: the path is symmetric: rotations {np.rad2deg(coarse.unresolved_rad):.0f} deg "
            f"apart fit the positions equally well, and the orientations (constant along the path) cannot tell them "
            f"apart; match with timestamps, or record a path without symmetry (e.g. the asymmetric planar path "
            f"of eq. 17-19)")
    if matcher == "hybrid" and turns:
        R, t, s, inl, j = hybrid_refine(ps, src.rotations, pd, dst.rotations, coarse, w=w, with_scale=with_scale,
                                        max_points=CPD_MAX_POINTS)
    else:                     # (with constant orientations the hybrid mixture is the positional one)
        ks, kd = thin_indices(len(ps), CPD_MAX_POINTS), thin_indices(len(pd), CPD_MAX_POINTS)
        fine = rigid_cpd(pd[kd], ps[ks], R0=coarse.R, t0=coarse.t, s0=coarse.s, w=w, with_scale=with_scale,
                         sigma2=coarse.sigma2)
        tree = cKDTree(pd)
        R, t, s, inl, j = _polish(ps, tree, pd, fine.R, fine.t, fine.s, with_scale)
        tg, smooth = path_tangents(pd, smoothed=True)
        R, t, inl, j = _line_refine(ps, tree, smooth, tg, R, t, s, inl, j)
    spread = np.rad2deg(body_rotation_spread(src.rotations[inl], dst.rotations[j][inl], R))
    return R, t, s, inl, j, spread
