"""Closed-form hand-eye start for ``A_k X = Z B_k``: Park & Martin on relative motions for ``X``,
then ``Z`` by the chordal mean.

Frames: ``A_k = T_base_tool`` (kinematics), ``B_k = T_world_camera`` (VO/SLAM), the unknowns
``X = T_tool_camera`` (the camera mount) and ``Z = T_base_world`` (the VO world frame in the base).
For two poses i, j the relative motions ``A_ij = A_i^-1 A_j`` and ``B_ij = B_i^-1 B_j`` satisfy
``A_ij X = X B_ij`` (Z cancels), so Park & Martin (1994, IEEE T-RA 10(5)) give
``alpha_ij = R_X beta_ij`` for the rotation vectors (an orthogonal Procrustes problem) and
``(R_Aij - I) t_X = R_X t_Bij - t_Aij`` for the translation (linear least squares). Each stage
drops the worst-fitting motions (relocalisation jumps, outliers) and refits once.
"""

import numpy as np

from posekit.errors import CalibrationError
from posekit.geometry import nearest_rotation, rotation_vector_from_matrix

from .alignment import thin_indices

__all__ = ["MIN_MOTION_DEG", "park_martin", "solve_world", "relative_motion_pairs"]

#: Smallest rotation of a relative motion the rotation stage uses, deg (smaller ones carry
#: little axis information); relaxed to a tenth when too few motions rotate that much.
MIN_MOTION_DEG = 5.0
#: Largest rotation of a relative motion used, deg (the rotation vector is ill-defined near 180).
MAX_MOTION_DEG = 170.0
#: Poses (evenly thinned) whose pairs form the relative motions.
_POSES_FOR_PAIRS = 60
#: A motion is kept in the refit when its residual is within this many medians.
_TRIM_MEDIANS = 3.0


def _procrustes(a, b, w=None) -> np.ndarray:
    """``R`` minimising ``sum w |a - R b|^2`` (rows of a, b), det +1."""
    w = np.ones(len(a)) if w is None else w
    H = (a * w[:, None]).T @ b
    U, _, Vt = np.linalg.svd(H)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt)) or 1.0])
    return U @ D @ Vt


def relative_motion_pairs(R_A, n_max: int = _POSES_FOR_PAIRS):
    """Index pairs (i, j) of poses whose relative rotation is usable for the rotation stage.

    Parameters
    ----------
    R_A : ndarray, shape (N, 3, 3)
        Tool orientations ``R_base_tool``.
    n_max : int
        Poses to draw pairs from (evenly thinned).

    Returns
    -------
    i, j : ndarray of int, shape (P,)
        All pairs among the thinned poses with a relative rotation in
        ``[MIN_MOTION_DEG, MAX_MOTION_DEG]`` (``MIN_MOTION_DEG / 10`` when fewer than 3 qualify).
    """
    idx = thin_indices(len(R_A), n_max)
    ii, jj = np.triu_indices(idx.size, k=1)
    i, j = idx[ii], idx[jj]
    rel = np.swapaxes(R_A[i], 1, 2) @ R_A[j]
    ang = np.rad2deg(np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)))
    for lo in (MIN_MOTION_DEG, MIN_MOTION_DEG / 10):
        keep = (ang >= lo) & (ang <= MAX_MOTION_DEG)
        if keep.sum() >= 3:
            break
    return i[keep], j[keep]


def _trimmed(res, keep_min: int):
    med = np.median(res)
    keep = res <= _TRIM_MEDIANS * max(med, 1e-12)
    if keep.sum() < keep_min:
        keep = res <= np.sort(res)[min(keep_min, res.size) - 1]
    return keep


def _ridge(M, b) -> np.ndarray:
    """Least squares ``M t = b`` ignoring directions whose singular value is below 1e-2 of the
    largest: a direction the motions leave undetermined (rotation about one axis) stays at 0
    instead of following the noise; a determined one is solved exactly."""
    return np.linalg.lstsq(M, b, rcond=1e-2)[0]


def park_martin(A, B) -> np.ndarray:
    """Closed-form ``X`` of ``A_ij X = X B_ij`` from paired absolute poses (Park & Martin).

    Parameters
    ----------
    A : ndarray, shape (N, 4, 4)
        ``T_base_tool`` at the pair times, mm.
    B : ndarray, shape (N, 4, 4)
        ``T_world_camera`` at the same times, mm.

    Returns
    -------
    X : ndarray, shape (4, 4)
        ``T_tool_camera``, mm.

    Raises
    ------
    CalibrationError
        If fewer than 3 relative motions rotate by at least ``MIN_MOTION_DEG / 10``.
    """
    i, j = relative_motion_pairs(A[:, :3, :3])
    if i.size < 3:
        raise CalibrationError(f"hand-eye needs relative motions that rotate the tool; found {i.size} pairs "
                               f"rotating by more than {MIN_MOTION_DEG / 10:g} deg (expected >= 3)")
    Aij = np.linalg.inv(A[i]) @ A[j]
    Bij = np.linalg.inv(B[i]) @ B[j]
    alpha = rotation_vector_from_matrix(nearest_rotation(Aij[:, :3, :3]), check=False)
    beta = rotation_vector_from_matrix(nearest_rotation(Bij[:, :3, :3]), check=False)
    R = _procrustes(alpha, beta)
    keep = _trimmed(np.linalg.norm(alpha - beta @ R.T, axis=1), 3)
    R = _procrustes(alpha[keep], beta[keep])
    # translation: (R_Aij - I) t = R t_Bij - t_Aij
    M = Aij[:, :3, :3] - np.eye(3)
    rhs = Bij[:, :3, 3] @ R.T - Aij[:, :3, 3]
    t = _ridge(M[keep].reshape(-1, 3), rhs[keep].reshape(-1))
    res = np.linalg.norm(np.einsum("kab,b->ka", M, t) - rhs, axis=1)
    keep &= _trimmed(np.where(keep, res, np.inf), 3)
    t = _ridge(M[keep].reshape(-1, 3), rhs[keep].reshape(-1))
    X = np.eye(4)
    X[:3, :3], X[:3, 3] = R, t
    return X


def solve_world(A, X, B) -> np.ndarray:
    """``Z = T_base_world`` from ``A_k X = Z B_k`` given ``X``: chordal mean rotation, trimmed mean
    translation.

    Parameters
    ----------
    A : ndarray, shape (N, 4, 4)
        ``T_base_tool``, mm.
    X : ndarray, shape (4, 4)
        ``T_tool_camera``, mm.
    B : ndarray, shape (N, 4, 4)
        ``T_world_camera``, mm.

    Returns
    -------
    Z : ndarray, shape (4, 4)
        ``T_base_world``, mm.
    """
    C = A @ X                                    # T_base_camera via the tool
    Rk = C[:, :3, :3] @ np.swapaxes(B[:, :3, :3], 1, 2)
    R = nearest_rotation(Rk.sum(axis=0))
    tk = C[:, :3, 3] - B[:, :3, 3] @ R.T
    med = np.median(tk, axis=0)
    d = np.linalg.norm(tk - med, axis=1)
    keep = _trimmed(d, max(3, d.size // 2))
    Z = np.eye(4)
    Z[:3, :3], Z[:3, 3] = R, tk[keep].mean(axis=0)
    return Z
