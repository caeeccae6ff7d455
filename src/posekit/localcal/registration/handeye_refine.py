"""Joint least-squares refinement of the hand-eye ``X = T_tool_camera``, the world frame
``Z = T_base_world`` and the clock offset, with a robust loss, and their covariance.

Residual of pair k (camera time ``t_k``, kinematic pose ``A(t_k + offset)`` interpolated):
``C1 = A X`` and ``C2 = Z B_k`` are the camera pose in the base frame via the tool and via the VO
world; the position residual ``p(C1) - p(C2)`` (base frame, mm) is divided by ``sigma_mm`` and the
rotation residual ``log(R(C2)^T R(C1))`` (camera frame, rad) by ``sigma_rad``.

Parameters are increments: ``R_X = exp(w_X) R_X0`` (``w_X`` about the tool axes),
``t_X = t_X0 + d_X`` (tool frame, mm), ``R_Z = exp(w_Z) R_Z0`` (base axes), ``t_Z = t_Z0 + d_Z``
(base frame, mm), and the offset increment, s.
"""

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from .handeye_time import PoseInterpolator

__all__ = ["CHI3_MEDIAN", "INLIER_GATE", "JointFit", "pose_residuals", "refine_joint"]

#: Median of the chi distribution with 3 degrees of freedom (|e| / sigma of a 3D Gaussian).
CHI3_MEDIAN = 1.5382
#: Inlier gate on |residual| / sigma of a pair, each of position and rotation (chi-3 99.9 %: 4.03).
INLIER_GATE = 4.0
#: Robust-loss scale, in sigmas.
_F_SCALE = 3.0
#: A weak prior on every increment (1 sigma: rad, mm, rad, mm, s) keeps the directions the data
#: leave undetermined (rotations about one axis only) at the closed-form start instead of drifting
#: to 1e8 mm; against hundreds of pairs it moves a determined estimate by < 1e-6 of its std.
_PRIOR_SCALE = [1.0] * 3 + [1e4] * 3 + [1.0] * 3 + [1e5] * 3 + [10.0]
#: Most iterations of each solver stage (good data converge in < 10).
_MAX_ITER = 30
#: Most time blocks of the sandwich covariance, and the fewest pairs per block.
_BLOCKS = 8
_BLOCK_PAIRS = 10
#: Smallest noise scales used for weighting (a noise-free simulation), mm and rad.
_SIGMA_FLOOR = (1e-6, 1e-9)


@dataclass(frozen=True)
class JointFit:
    """The refined hand-eye problem.

    Attributes
    ----------
    X, Z : ndarray, shape (4, 4)
        ``T_tool_camera`` and ``T_base_world``, mm.
    offset_s : float
        Clock offset ``t_kinematic - t_camera``, s.
    inliers : ndarray of bool, shape (K,)
        Pairs inside the inlier gate.
    res_mm, res_rad : ndarray, shape (K,)
        Per-pair position (mm) and rotation (rad) residual norms.
    sigma_mm, sigma_rad : float
        Noise scales estimated from the inlier residuals (per component), mm and rad.
    cov : ndarray, shape (P, P)
        Covariance of ``[w_X (rad), d_X (mm), w_Z (rad), d_Z (mm), offset (s)]`` (the offset only
        when estimated): the normal-matrix covariance ``s^2 (J^T J)^-1``, each variance raised to
        the time-block sandwich estimate's when that is larger (VO drift, unequal noise per axis).
    inflation : float
        The largest such variance factor (about 1 for white, isotropic residuals).
    converged : bool
        The last least-squares stage met its tolerance within its iteration limit.
    """

    X: np.ndarray
    Z: np.ndarray
    offset_s: float
    inliers: np.ndarray
    res_mm: np.ndarray
    res_rad: np.ndarray
    sigma_mm: float
    sigma_rad: float
    cov: np.ndarray
    inflation: float
    converged: bool = True


def _compose(p, X0, Z0):
    X, Z = np.eye(4), np.eye(4)
    X[:3, :3] = Rotation.from_rotvec(p[0:3]).as_matrix() @ X0[:3, :3]
    X[:3, 3] = X0[:3, 3] + p[3:6]
    Z[:3, :3] = Rotation.from_rotvec(p[6:9]).as_matrix() @ Z0[:3, :3]
    Z[:3, 3] = Z0[:3, 3] + p[9:12]
    return X, Z


def pose_residuals(A, X, Z, B):
    """Position (mm, base frame) and rotation (rad, camera frame) residuals of ``A_k X = Z B_k``.

    Parameters
    ----------
    A : ndarray, shape (K, 4, 4)
        ``T_base_tool``, mm.
    X : ndarray, shape (4, 4)
        ``T_tool_camera``, mm.
    Z : ndarray, shape (4, 4)
        ``T_base_world``, mm.
    B : ndarray, shape (K, 4, 4)
        ``T_world_camera``, mm.

    Returns
    -------
    r_mm : ndarray, shape (K, 3)
    r_rad : ndarray, shape (K, 3)
    """
    R1 = A[:, :3, :3] @ X[:3, :3]
    p1 = A[:, :3, :3] @ X[:3, 3] + A[:, :3, 3]
    R2 = Z[:3, :3] @ B[:, :3, :3]
    p2 = B[:, :3, 3] @ Z[:3, :3].T + Z[:3, 3]
    return p1 - p2, _log(np.swapaxes(R2, 1, 2) @ R1)


def _log(R) -> np.ndarray:
    """Rotation vectors of rotation matrices (..., 3, 3) -> (..., 3), rad; exact away from 180 deg
    (where only the direction degrades, the angle stays right), fast for small residuals."""
    c = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(c)
    w = 0.5 * np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    s = np.sin(th)
    k = np.where(s > 1e-9, th / np.where(s > 1e-9, s, 1.0), 1.0 + th ** 2 / 6.0)
    return w * k[..., None]


def _block_meat(J, r, t_s) -> np.ndarray:
    """``sum_b g_b g_b^T`` with ``g_b = J_b^T r_b`` over ``_BLOCKS`` consecutive blocks of pairs in
    time (6 rows per pair), scaled by ``n_b / (n_b - 1)``."""
    k = t_s.size
    n_b = int(np.clip(k // _BLOCK_PAIRS, 2, _BLOCKS))
    order = np.argsort(t_s, kind="stable")
    rows = (order[:, None] * 6 + np.arange(6)).ravel()
    G = np.stack([Jb.T @ rb for Jb, rb in zip(np.array_split(J[rows], n_b), np.array_split(r[rows], n_b))])
    return G.T @ G * n_b / (n_b - 1)


def refine_joint(t_cam, B, kin: PoseInterpolator, X0, Z0, offset0_s: float, *, fit_offset: bool = True,
                 sigma0=None) -> JointFit:
    """Refine ``X``, ``Z`` (and the clock offset) jointly with a robust loss, then by plain least
    squares on the inliers, and return their covariance.

    Parameters
    ----------
    t_cam : ndarray, shape (K,)
        Camera times of the pairs, s.
    B : ndarray, shape (K, 4, 4)
        ``T_world_camera`` at those times, mm.
    kin : PoseInterpolator
        The kinematic trajectory ``T_base_tool``, mm.
    X0, Z0 : ndarray, shape (4, 4)
        Starting ``T_tool_camera`` and ``T_base_world``, mm.
    offset0_s : float
        Starting clock offset, s (kept fixed unless ``fit_offset``).
    fit_offset : bool
        Estimate the offset with the transforms.
    sigma0 : (float, float), optional
        Starting noise scales (mm, rad); from the starting residuals by default.

    Returns
    -------
    JointFit
    """
    n_par = 13 if fit_offset else 12

    def unpack(p):
        X, Z = _compose(p, X0, Z0)
        return X, Z, offset0_s + (p[12] if fit_offset else 0.0)

    def raw(p, sel):
        X, Z, off = unpack(p)
        A = kin(t_cam[sel] + off)
        return pose_residuals(A, X, Z, B[sel])

    every = np.ones(t_cam.size, dtype=bool)
    p0 = np.zeros(n_par)
    r_mm, r_rad = raw(p0, every)
    if sigma0 is None:
        s_mm = np.median(np.linalg.norm(r_mm, axis=1)) / CHI3_MEDIAN
        s_rad = np.median(np.linalg.norm(r_rad, axis=1)) / CHI3_MEDIAN
    else:
        s_mm, s_rad = sigma0
    s_mm, s_rad = max(s_mm, _SIGMA_FLOOR[0]), max(s_rad, _SIGMA_FLOOR[1])

    prior = np.r_[_PRIOR_SCALE][:n_par]

    def fun(p, sel, s_mm, s_rad):
        a, b = raw(p, sel)
        return np.concatenate([np.concatenate([a / s_mm, b / s_rad], axis=1).ravel(), p / prior])

    x_scale = np.r_[[1e-3] * 3, [1.0] * 3, [1e-3] * 3, [1.0] * 3, [1e-3] * (n_par - 12)]
    sol = least_squares(fun, p0, args=(every, s_mm, s_rad), loss="soft_l1", f_scale=_F_SCALE,
                        x_scale=x_scale, method="trf", tr_solver="lsmr", max_nfev=_MAX_ITER)
    inl = every
    p = sol.x
    for _ in range(2):
        r_mm, r_rad = raw(p, every)
        e_mm, e_rad = np.linalg.norm(r_mm, axis=1), np.linalg.norm(r_rad, axis=1)
        s_mm = max(np.median(e_mm[inl]) / CHI3_MEDIAN, _SIGMA_FLOOR[0])
        s_rad = max(np.median(e_rad[inl]) / CHI3_MEDIAN, _SIGMA_FLOOR[1])
        inl = (e_mm <= INLIER_GATE * s_mm) & (e_rad <= INLIER_GATE * s_rad)
        if inl.sum() < 3:
            inl = every
        sol = least_squares(fun, p, args=(inl, s_mm, s_rad), method="lm", x_scale=x_scale,
                            max_nfev=_MAX_ITER * (n_par + 1))
        p = sol.x
    converged = sol.status > 0
    r_mm, r_rad = raw(p, every)
    e_mm, e_rad = np.linalg.norm(r_mm, axis=1), np.linalg.norm(r_rad, axis=1)
    # noise scales per component from the inliers (rms), the covariance from the normal matrix
    s_mm = max(float(np.sqrt(np.mean(r_mm[inl] ** 2))), _SIGMA_FLOOR[0])
    s_rad = max(float(np.sqrt(np.mean(r_rad[inl] ** 2))), _SIGMA_FLOOR[1])
    r = fun(p, inl, s_mm, s_rad)
    J = _jacobian(lambda q: fun(q, inl, s_mm, s_rad), p, x_scale)
    r = r[:-n_par]                                   # the data residuals; the prior rows stay in J
    m = r.size
    s2 = float(r @ r) / max(m - n_par, 1)
    H = J.T @ J
    try:
        Hinv = np.linalg.inv(H)
    except np.linalg.LinAlgError:
        Hinv = np.full((n_par, n_par), np.inf)
    cov_normal = Hinv * s2
    # block sandwich: residuals correlated in time (VO drift) and unequal per axis (stereo depth)
    cov_block = Hinv @ _block_meat(J[:m], r, t_cam[inl]) @ Hinv if np.isfinite(Hinv).all() else cov_normal
    d_n, d_b = np.diag(cov_normal), np.diag(cov_block)
    inflation = float(np.nanmax(np.where(d_n > 0, d_b / np.where(d_n > 0, d_n, 1.0), 1.0)).clip(min=1.0))
    scale = np.sqrt(np.maximum(d_b, d_n) / np.where(d_n > 0, d_n, 1.0))
    cov = cov_normal * np.outer(scale, scale)
    X, Z, off = unpack(p)
    return JointFit(X=X, Z=Z, offset_s=float(off), inliers=inl, res_mm=e_mm, res_rad=e_rad,
                    sigma_mm=s_mm, sigma_rad=s_rad, cov=cov, inflation=inflation, converged=converged)


def _jacobian(f, p, scale) -> np.ndarray:
    """Central-difference Jacobian of ``f`` at ``p`` with steps proportional to ``scale``."""
    cols = []
    for i in range(p.size):
        h = 1e-4 * scale[i]
        e = np.zeros_like(p)
        e[i] = h
        cols.append((f(p + e) - f(p - e)) / (2 * h))
    return np.stack(cols, axis=1)
