"""6-DoF pose of the profiler from the corners of one profile (paper §II-C).

Two estimators, both returning ``T_G_F`` (the profiler frame F in the gauge frame G):

``cf``
    The closed form of eq. (9)–(14) (:mod:`~posekit.profiler.closed_form`). Needs
    n >= 5: with 4 corners eq. (10) has 8 equations for 9 unknowns.
``mle``
    The maximum-likelihood refinement of eq. (15), started from the closed form (for
    n = 4 from a closed form that picks, on the one-dimensional solution line of
    ``A x = b``, the point whose r1, r3 are closest to orthonormal; or from a given
    previous pose of a stream).

Residual of the refinement — geometric, not the paper's algebraic one. The paper
minimises ``||A x(k, t) - b||²``, whose rows measure the offset of each transformed
corner from its ridge inside a plane y = const of G: a distance in G, scaled by the
ridge's tilt, that treats all corners alike. posekit minimises instead the
reprojection error where the noise is: for each ridge, the point where it pierces the
laser plane (its predicted corner) is compared with the measured corner in F's x–z
plane, weighted by the inverse of that corner's covariance from the line fits. This is
the maximum-likelihood estimate under the Gaussian corner model (the PnP analogue of
minimising image reprojection error), its Gauss–Newton normal matrix is the Fisher
information, and its inverse is the pose covariance that is returned. Iterations
(:mod:`~posekit.profiler.refine`): Gauss–Newton with Levenberg damping on a left
perturbation of ``T_F_G``, with the analytic Jacobian (cross-checked against finite
differences and against ``scipy.optimize.least_squares`` in the tests).

With mounting 'auto', both corner orders get a closed-form start and the cheaper one is
refined: a sensor mounted the other way round sees the ridges in reverse scan order.
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import EstimationError
from ..geometry import point_line_distance, quaternion_from_matrix
from .closed_form import cf4_start, cf_kernel, closed_form
from .corners import Corners
from .refine import (
    normal_equations,
    pose_covariance_and_reprojection,
    refine_kernel,
    spd_inverse,
)

__all__ = ["PoseEstimate", "solve_pose", "solve_pose_unchecked", "solve_pose_warm", "warm_start_buffers",
           "status_message", "reprojection_residuals",
           "closed_form", "METHODS", "MOUNTINGS"]

METHODS = ("cf", "mle")
MOUNTINGS = ("auto", "normal", "reversed")

OK = 0
CF_UNDERDETERMINED = 1
DEGENERATE = 2
RIDGE_IN_PLANE = 3


@dataclass(frozen=True)
class PoseEstimate:
    """Result of :func:`solve_pose`.

    Attributes
    ----------
    T_G_F : ndarray, shape (4, 4)
        Pose of the profiler frame F in the gauge frame G, mm.
    cov : ndarray, shape (6, 6)
        Covariance of the pose error ``[δt (mm), δθ (rad)]`` with both parts in G
        (``t_true = t + δt``, ``R_true = Exp(δθ) R``), propagated from the corners.
        NaN for the closed form, which has no error model (its error is far larger).
    reprojection_um : float
        Mean distance of the estimated 3D corners from their ridges, µm.
    cost : float
        Weighted squared reprojection error ``Σ rᵀ Σ⁻¹ r`` (χ² with 2n - 6 dof).
    reversed : bool
        True when the corners matched the ridges in reverse order (sensor mounted the
        other way round).
    method : str
    """

    T_G_F: np.ndarray
    cov: np.ndarray
    reprojection_um: float
    cost: float
    reversed: bool
    method: str

    @property
    def t_mm(self) -> np.ndarray:
        """Translation of F in G, mm, shape (3,)."""
        return self.T_G_F[:3, 3]

    @property
    def q_wxyz(self) -> np.ndarray:
        """Rotation of F in G as a unit quaternion [w, x, y, z], shape (4,)."""
        return quaternion_from_matrix(self.T_G_F[:3, :3])

    @property
    def std_t_um(self) -> np.ndarray:
        """Predicted standard deviation of the translation along x, y, z of G, µm."""
        return np.sqrt(np.diag(self.cov)[:3]) * 1e3

    @property
    def std_rot_deg(self) -> np.ndarray:
        """Predicted standard deviation of the rotation about x, y, z of G, degrees."""
        return np.degrees(np.sqrt(np.diag(self.cov)[3:]))


# --------------------------------------------------------------------------- kernels


@njit(cache=True, nogil=True)
def _start(corners, q, s, method, has_init, R_init, t_init):
    """Start pose T_G_F: the given one, else the closed form (n >= 5)."""
    if has_init:
        return OK, R_init.copy(), t_init.copy()
    if corners.shape[0] < 5:
        return (CF_UNDERDETERMINED if method == 0 else DEGENERATE), np.eye(3), np.zeros(3)
    ok, R, t = cf_kernel(corners, q, s)
    return (OK if ok else DEGENERATE), R, t


@njit(cache=True, nogil=True)
def _solve_kernel(corners, cov, q, s, method, mounting, max_iter, has_init, R_init, t_init):
    """Returns status, reversed, R_G_F, t_G_F, H (information of the twist of T_F_G), cost.

    ``has_init`` (2,), ``R_init`` (2, 3, 3), ``t_init`` (2, 3): an optional start pose
    T_G_F for the normal and the reversed corner order.

    With mounting 'auto' (0) both corner orders get a start pose and the one with the
    lower reprojection cost is kept (a wrong order costs orders of magnitude more);
    only that one is refined.
    """
    n = corners.shape[0]
    ok, W = spd_inverse(cov)
    if not ok:
        return DEGENERATE, False, np.eye(3), np.zeros(3), np.zeros((6, 6)), np.inf
    # The reversed order permutes the corners' 2×2 blocks of W.
    perm = np.empty(2 * n, dtype=np.int64)
    for i in range(n):
        perm[2 * i] = 2 * (n - 1 - i)
        perm[2 * i + 1] = 2 * (n - 1 - i) + 1
    W_rev = np.empty_like(W)
    if mounting != 1:
        for a in range(2 * n):
            for b in range(2 * n):
                W_rev[a, b] = W[perm[a], perm[b]]
    H = np.zeros((6, 6))
    g = np.empty(6)
    status = DEGENERATE
    rev = False
    R_FG = np.eye(3)
    t_FG = np.zeros(3)
    cost = np.inf
    for r in range(2):
        if (mounting == 1 and r == 1) or (mounting == 2 and r == 0):
            continue
        cr = corners[::-1].copy() if r == 1 else corners
        Wr = W_rev if r == 1 else W
        st, R_GF, t_GF = _start(cr, q, s, method, has_init[r], R_init[r], t_init[r])
        if st != OK:
            if status != OK:
                status = st
            continue
        R_c = R_GF.T.copy()
        t_c = -(R_c @ t_GF)
        ok, c = normal_equations(R_c, t_c, cr, Wr, q, s, H, g)
        if not ok:
            if status != OK:
                status = RIDGE_IN_PLANE
            continue
        if status != OK or c < cost:
            status, rev, R_FG, t_FG, cost = OK, r == 1, R_c, t_c, c
    if status != OK:
        return status, rev, np.eye(3), np.zeros(3), H, np.inf
    cr = corners[::-1].copy() if rev else corners
    Wr = W_rev if rev else W
    if method == 0:
        ok, cost = normal_equations(R_FG, t_FG, cr, Wr, q, s, H, g)
    else:
        ok, R_FG, t_FG, H, cost, _ = refine_kernel(R_FG, t_FG, cr, Wr, q, s, max_iter)
    if not ok:
        return RIDGE_IN_PLANE, rev, np.eye(3), np.zeros(3), H, np.inf
    return OK, rev, R_FG.T.copy(), -(R_FG.T @ t_FG), H, cost


# --------------------------------------------------------------------------- API


def reprojection_residuals(T_G_F, corners_F, gauge):
    """Distance of each corner, mapped into G by ``T_G_F``, from its ridge, mm, shape (n,).

    Parameters
    ----------
    T_G_F : ndarray, shape (4, 4)
    corners_F : ndarray, shape (n, 2)
        Corners (x, z) in F, mm, in ridge order.
    gauge : Gauge
    """
    c = np.asarray(corners_F, dtype=np.float64)
    p_F = np.stack([c[:, 0], np.zeros(len(c)), c[:, 1]], axis=1)
    p_G = p_F @ T_G_F[:3, :3].T + T_G_F[:3, 3]
    return point_line_distance(p_G, gauge.ridge_q, gauge.ridge_s)


_EYE3 = np.eye(3)
_ZERO3 = np.zeros(3)

_MESSAGES = {
    CF_UNDERDETERMINED: "the closed form needs at least 5 corners (with {n}, eq. (10) has {e} equations "
                        "for 9 unknowns); use method 'mle'",
    DEGENERATE: "degenerate corner geometry: the linear system of eq. (10) is singular "
                "(corners collinear or coincident?)",
    RIDGE_IN_PLANE: "a ridge lies in the laser plane at this pose; its corner is undefined",
}


_NO_INIT = (np.zeros(2, dtype=np.bool_), np.tile(np.eye(3), (2, 1, 1)), np.zeros((2, 3)))


def solve_pose_unchecked(corners, cov, gauge, method_code, mounting_code, max_iter=20, T_init=None):
    """Raw kernel call; returns ``(status, reversed, R_G_F, t_G_F, H, cost)``.

    ``corners`` (n, 2) and ``cov`` (2n, 2n) float64 C-contiguous; codes index
    :data:`METHODS` and :data:`MOUNTINGS`. For the real-time path; no validation.
    """
    if T_init is not None and method_code == 1:
        T = np.asarray(T_init, dtype=np.float64)
        init = (np.ones(2, dtype=np.bool_), np.stack([T[:3, :3]] * 2), np.stack([T[:3, 3]] * 2))
    elif corners.shape[0] == 4 and method_code == 1:
        init = (np.zeros(2, dtype=np.bool_), np.tile(np.eye(3), (2, 1, 1)), np.zeros((2, 3)))
        for r, c in enumerate((corners, corners[::-1])):
            if (mounting_code == 1 and r == 1) or (mounting_code == 2 and r == 0):
                continue                 # this order is ruled out by the mounting
            ok, R, t = cf4_start(np.ascontiguousarray(c), gauge.ridge_q, gauge.ridge_s)
            init[0][r], init[1][r], init[2][r] = ok, R, t
        if not init[0].any():
            return DEGENERATE, False, np.eye(3), np.zeros(3), np.zeros((6, 6)), np.inf
    else:
        init = _NO_INIT
    return _solve_kernel(corners, cov, gauge.ridge_q, gauge.ridge_s, method_code, mounting_code,
                         max_iter, init[0], init[1], init[2])


def warm_start_buffers():
    """Reusable start arrays for :func:`solve_pose_warm`: ``(has_init (2,), R (2, 3, 3), t (2, 3))``."""
    return np.ones(2, dtype=np.bool_), np.empty((2, 3, 3)), np.empty((2, 3))


def solve_pose_warm(corners, cov, gauge, T_init, mounting_code, buffers, max_iter=20):
    """ML refinement from a given start pose (a stream's previous pose), no allocation.

    As :func:`solve_pose_unchecked` with ``method='mle'`` and ``T_init``, but the start is
    written into ``buffers`` (from :func:`warm_start_buffers`) instead of new arrays: the
    real-time path saves the NumPy overhead per frame.
    """
    has, R0, t0 = buffers
    has[:] = True
    R0[:] = T_init[:3, :3]
    t0[:] = T_init[:3, 3]
    return _solve_kernel(corners, cov, gauge.ridge_q, gauge.ridge_s, 1, mounting_code, max_iter, has, R0, t0)


def status_message(status: int, n_corners: int) -> str:
    """The user-facing reason of a failed solver status."""
    return _MESSAGES[status].format(n=n_corners, e=2 * n_corners)


def solve_pose(corners: Corners, gauge, method: str = "mle", mounting: str = "auto", T_init=None,
               max_iter: int = 20) -> PoseEstimate:
    """Pose of the profiler in the gauge frame from the corners of one profile.

    Parameters
    ----------
    corners : Corners
        From :func:`~posekit.profiler.corners.detect_corners`: corner points (n, 2) in F,
        mm, in scan order, with their joint covariance (2n, 2n), mm².
    gauge : Gauge
        The gauge, with n ridges.
    method : {'mle', 'cf'}
        ``cf``: closed form, eq. (9)–(14) (n >= 5). ``mle``: refined (any n >= 4).
    mounting : {'auto', 'normal', 'reversed'}
        Whether the scan order of the corners follows the ridge order ('normal'), runs
        against it (sensor mounted the other way round), or should be decided by the
        lower reprojection cost ('auto').
    T_init : ndarray, shape (4, 4), optional
        Start pose ``T_G_F`` (e.g. the previous pose of a stream) instead of the closed form.
    max_iter : int

    Returns
    -------
    PoseEstimate

    Raises
    ------
    EstimationError
        If the corner count does not match the gauge, the closed form is asked for with
        4 corners, or the geometry is degenerate.
    """
    if method not in METHODS:
        raise EstimationError(f"unknown method '{method}'; expected one of {', '.join(METHODS)}")
    if mounting not in MOUNTINGS:
        raise EstimationError(f"unknown mounting '{mounting}'; expected one of {', '.join(MOUNTINGS)}")
    pts = np.ascontiguousarray(corners.points, dtype=np.float64)
    n = gauge.n_corners
    if pts.shape != (n, 2):
        raise EstimationError(f"expected {n} corners for gauge '{gauge.name}', got {pts.shape[0]}")
    status, rev, R, t, H, cost = solve_pose_unchecked(
        pts, np.ascontiguousarray(corners.cov, dtype=np.float64), gauge, METHODS.index(method),
        MOUNTINGS.index(mounting), max_iter, T_init)
    if status != OK:
        raise EstimationError(status_message(status, n))
    cov, reproj_mm = pose_covariance_and_reprojection(R, t, H, pts, rev, gauge.ridge_q, gauge.ridge_s)
    if method == "cf":
        # The information matrix describes the ML estimate, not the closed form's error.
        cov = np.full((6, 6), np.nan)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return PoseEstimate(T_G_F=T, cov=cov, reprojection_um=float(reproj_mm * 1e3), cost=float(cost),
                        reversed=bool(rev), method=method)
