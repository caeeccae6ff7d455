"""6-DoF pose of the profiler from the corners of one profile (paper §II-C).

Two estimators, both returning ``T_G_F`` (the profiler frame F in the gauge frame G):

``cf``
    The closed form of eq. (9)–(14) (:mod:`~posekit.profiler.estimate.closed_form`). Needs
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
(:mod:`~posekit.profiler.estimate.refine`): Gauss–Newton with Levenberg damping on a left
perturbation of ``T_F_G``, with the analytic Jacobian (cross-checked against finite
differences and against ``scipy.optimize.least_squares`` in the tests).

With mounting 'auto', both corner orders are solved and the better one is kept (a pose
that could have produced the corners first, then the lower χ²): a sensor mounted the
other way round sees the ridges in reverse scan order.

Verdict (DESIGN.md "Trust"). Every estimate carries ``status`` 'ok' or 'suspect' with a
``reason``, from a χ² test at significance α (default :data:`DEFAULT_SIGNIFICANCE`, the
rate at which good data are called suspect; split equally over the tests made):

* **fit**: ``χ² = rᵀ C⁻¹ r`` of the corner residuals at the estimate, with ``C`` the
  corners' covariance under the assumed noise plus the gauge's ``tolerance_um`` (each
  face's position uncertain by that 1σ, mapped to the corners at the estimated pose),
  against χ²(2n - 6). The refinement itself is weighted by the line fits' own covariance
  (plus the tolerance), as the real-time server weights it, so the offline and streamed
  poses agree; on data that match the model the two weightings differ by sampling only. For the closed form, r and its covariance come from the closed
  form's own linearisation (its pseudo-inverse, rank 2n - 6). It catches a wrong gauge
  file, a face machined off its drawing beyond the tolerance, a rounded or chamfered
  ridge that moves a corner, a wrong basin (a local minimum fits badly).
* **noise** (only with an assumed ``noise`` model): the scatter of the profile's points
  about the fitted faces, ``Σ RSS_j / σ_j²`` against χ²(Σ (N_j - 2)) with σ_j the assumed
  noise across face j. Noise above the sensor model's makes the covariance a lie.
* **ambiguity** (mounting 'auto'): the other corner order fits too (passes the fit test at
  a possible pose); **possibility**: the best fit would see a face from behind.

The assumed noise is explicit: ``noise=NoiseModel(...)`` (the estimator entry points in
:mod:`~posekit.profiler.estimate.pipeline` default to the LJ-X8400's 10/5 µm). With ``noise=None``
the corner covariance comes from the line fits' own residuals (the noise is estimated,
so the test sees the geometry but not the noise level) — the behaviour of the studies.
"""

import functools
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.stats import chi2 as _chi2

from ...errors import EstimationError
from ...geometry import (
    matrix_from_rotation_vector,
    quaternion_from_matrix,
    rotation_vector_from_matrix,
)
from .closed_form import cf4_start, cf_kernel, closed_form
from .corners import Corners
from .gauge import _piercing_points, pose_is_possible
from .refine import (
    normal_equations,
    pose_covariance_and_reprojection,
    refine_kernel,
    spd_inverse,
)

__all__ = ["PoseEstimate", "solve_pose", "solve_pose_unchecked",
           "status_message", "corner_covariance", "face_tolerance_covariance",
           "closed_form", "METHODS", "MOUNTINGS", "DEFAULT_SIGNIFICANCE", "estimate_from_corners", "chi2_critical"]

METHODS = ("cf", "mle")
MOUNTINGS = ("auto", "normal", "reversed")
#: Default significance α of the consistency test: the rate at which data that match the
#: model are called suspect. Measured on simulated good data of the bundled gauges
#: (tests/profiler/test_verdict_rates.py): well under 1 % suspect.
DEFAULT_SIGNIFICANCE = 1e-3

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
        (``t_true = t + δt``, ``R_true = Exp(δθ) R``), propagated from the corners (and
        the gauge's tolerance): for 'mle' the inverse Fisher information, for 'cf' the
        closed form's own linearisation ``J C Jᵀ`` (its error is far larger).
    reprojection_um : float
        Mean distance of the estimated 3D corners from their ridges, µm.
    cost : float
        The refinement's objective at the estimate: ``rᵀ C⁻¹ r`` with ``C`` the line fits'
        corner covariance (plus the gauge's tolerance).
    reversed : bool
        True when the corners matched the ridges in reverse order (sensor mounted the
        other way round).
    method : str
    chi2 : float
        Consistency statistic of the fit, ``rᵀ C⁻¹ r`` with ``C`` under the assumed noise
        (equal to ``cost`` for 'mle' without one; the closed form's own linearisation for
        'cf'): χ²(dof) on data that match the model.
    dof : int
        ``2n - 6``.
    status : {'ok', 'suspect'}
    reason : str or None
        Why the estimate is suspect (None when 'ok').
    """

    T_G_F: np.ndarray
    cov: np.ndarray
    reprojection_um: float
    cost: float
    reversed: bool
    method: str
    chi2: float = float("nan")
    dof: int = 0
    status: str = "ok"
    reason: str | None = None

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
        init = (np.ones(2, dtype=np.bool_), np.empty((2, 3, 3)), np.empty((2, 3)))
        init[1][:] = T[:3, :3]
        init[2][:] = T[:3, 3]
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


def status_message(status: int, n_corners: int) -> str:
    """The user-facing reason of a failed solver status."""
    return _MESSAGES[status].format(n=n_corners, e=2 * n_corners)


# --------------------------------------------------------------------------- covariances


def corner_covariance(corners: Corners, noise=None) -> np.ndarray:
    """Joint covariance of the corners under an assumed noise model, mm², (2n, 2n).

    The line fits of :func:`~posekit.profiler.estimate.corners.detect_corners` give each corner's
    covariance from the residual RMS σ̂_j of its two faces. Under a known noise model the
    scatter of face j across its line is ``σ_j² = nx² σx² + nz² σz²`` ((nx, nz) its unit
    normal in F); each face's share of the covariance is rescaled by ``(σ_j / σ̂_j)²``.
    The shares separate exactly: with ``N_k`` the 2×2 matrix of the normals of faces k,
    k+1, ``N_k δp_k`` holds the two faces' offsets at corner k, one face per entry, so the
    rescaled covariance is ``T C Tᵀ`` with ``T_k = N_k⁻¹ diag(σ_k/σ̂_k, σ_k+1/σ̂_k+1) N_k``.

    Parameters
    ----------
    corners : Corners
        Corners in scan order with their fits (``lines``, ``sigma``, ``cov``).
    noise : NoiseModel or None
        Assumed noise (``sigma_x_um``, ``sigma_z_um``: 1σ per point along x and z of F,
        µm). None: the fits' own residuals (``corners.cov`` unchanged).

    Returns
    -------
    ndarray, shape (2n, 2n)
    """
    if noise is None:
        return np.ascontiguousarray(corners.cov, dtype=np.float64)
    f = _face_sigma_mm(corners, noise) / corners.sigma
    return _rescale_corner_cov(np.ascontiguousarray(corners.lines, dtype=np.float64), f,
                               np.ascontiguousarray(corners.cov, dtype=np.float64))


@njit(cache=True, nogil=True)
def _rescale_corner_cov(lines, f, cov):
    """``T C Tᵀ`` (symmetrised) with block-diagonal ``T_k = N_k⁻¹ diag(f_k, f_k+1) N_k``
    (:func:`corner_covariance`)."""
    m = cov.shape[0]
    n = m // 2
    T = np.zeros((m, m))
    for k in range(n):
        a, b = lines[k, 0], lines[k, 1]
        c, d = lines[k + 1, 0], lines[k + 1, 1]
        det = a * d - b * c
        fa, fc = f[k], f[k + 1]
        # N⁻¹ = [[d, -b], [-c, a]] / det;  M = diag(fa, fc) N = [[fa a, fa b], [fc c, fc d]]
        T[2 * k, 2 * k] = (d * fa * a - b * fc * c) / det
        T[2 * k, 2 * k + 1] = (d * fa * b - b * fc * d) / det
        T[2 * k + 1, 2 * k] = (-c * fa * a + a * fc * c) / det
        T[2 * k + 1, 2 * k + 1] = (-c * fa * b + a * fc * d) / det
    out = np.zeros((m, m))
    for i in range(m):
        for j in range(m):
            acc = 0.0
            for p in range(2 * (i // 2), 2 * (i // 2) + 2):
                for q in range(2 * (j // 2), 2 * (j // 2) + 2):
                    acc += T[i, p] * cov[p, q] * T[j, q]
            out[i, j] = acc
    for i in range(m):
        for j in range(i + 1, m):
            v = 0.5 * (out[i, j] + out[j, i])
            out[i, j] = v
            out[j, i] = v
    return out


def _face_sigma_mm(corners: Corners, noise) -> np.ndarray:
    """Assumed scatter of each face's points across its fitted line, mm, (n + 1,)."""
    sx = noise.sigma_x_um * 1e-3
    sz = noise.sigma_z_um * 1e-3
    nrm = corners.lines[:, :2]
    return np.maximum(np.hypot(nrm[:, 0] * sx, nrm[:, 1] * sz), 1e-9)


def face_tolerance_covariance(gauge, T_G_F, reversed_order: bool = False) -> np.ndarray:
    """Covariance of the corners from the gauge's face tolerance, mm², (2n, 2n).

    Face k lies at ``normal_k · p = offset_k + δ_k`` with independent ``δ_k ~ N(0, tol²)``
    (``tol = gauge.tolerance_um``). In the laser plane of a pose ``T_G_F`` face k is the
    line ``m_k · (x, z) = offset_k - normal_k · t`` with ``m_k`` the x, z part of
    ``R_G_Fᵀ normal_k``; corner k (faces k, k+1) moves by ``N_k⁻¹ [δ_k, δ_k+1]``.

    Parameters
    ----------
    gauge : Gauge
    T_G_F : ndarray, shape (4, 4)
        Pose of the profiler in G, mm.
    reversed_order : bool
        Corners in reverse scan order (the covariance is returned in scan order).

    Returns
    -------
    ndarray, shape (2n, 2n)
    """
    n = gauge.n_corners
    tol = gauge.tolerance_um * 1e-3
    if tol == 0:
        return np.zeros((2 * n, 2 * n))
    m = (gauge.normals @ np.asarray(T_G_F)[:3, :3])[:, [0, 2]]       # rows: (R^T normal_k)_x, _z
    J = np.zeros((2 * n, n + 1))
    for k in range(n):
        J[2 * k:2 * k + 2, k:k + 2] = np.linalg.inv(m[k:k + 2])
    cov = tol**2 * (J @ J.T)
    if reversed_order:
        idx = _reverse_index(n)
        cov = cov[np.ix_(idx, idx)]
    return cov


def _reverse_index(n: int) -> np.ndarray:
    """Index of the stacked ``[x0, z0, x1, z1, ...]`` with the corners in reverse order."""
    return (2 * (n - 1 - np.arange(n))[:, None] + np.arange(2)).ravel()


# --------------------------------------------------------------------------- verdict


class _Candidate:
    """One corner order's solution; what only the verdict may need is computed on demand."""

    __slots__ = ("rev", "T", "cov", "reprojection_mm", "cost", "chi2", "_c", "_gauge", "_resid", "_possible")

    def __init__(self, rev, T, cov, reprojection_mm, cost, chi2, c, gauge):
        self.rev, self.T, self.cov, self.reprojection_mm, self.cost, self.chi2 = rev, T, cov, reprojection_mm, cost, chi2
        self._c = c                   # corners in ridge order
        self._gauge = gauge
        self._resid = None
        self._possible = None

    @property
    def resid_mm(self) -> np.ndarray:
        """|corner - predicted| per ridge, mm."""
        if self._resid is None:
            P = _piercing_points(self._gauge, self.T[:3, :3], self.T[:3, 3])
            self._resid = (np.full(len(self._c), np.nan) if P is None
                           else np.sqrt(np.sum((self._c - P) ** 2, axis=1)))
        return self._resid

    @property
    def possible(self) -> bool:
        """Whether the pose could have produced the corners (no face seen from behind)."""
        if self._possible is None:
            self._possible = bool(pose_is_possible(self._gauge, self.T, self._c, extent=False))
        return self._possible


def _as_T(R, t) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T


def _cf_linearisation(c, C, gauge, T_cf):
    """The closed form's own error model (ridge order): pose covariance (6, 6) and χ².

    ``J = ∂pose/∂corners`` by central differences of eq. (9)-(14) (pose error as in
    :attr:`PoseEstimate.cov`); the residual ``r = c - P(pose(c))`` then has covariance
    ``M C Mᵀ`` with ``M = I - J_P J`` (a projection of rank 2n - 6), and
    ``χ² = rᵀ (M C Mᵀ)⁺ r``.
    """
    n = c.shape[0]
    m = 2 * n
    dof = m - 6
    h = 1e-5
    flat = c.ravel()
    J = np.empty((6, m))
    for i in range(m):
        poses = []
        for sign in (1.0, -1.0):
            cp = flat.copy()
            cp[i] += sign * h
            ok, R, t = cf_kernel(cp.reshape(n, 2), gauge.ridge_q, gauge.ridge_s)
            if not ok:
                return np.full((6, 6), np.nan), np.nan
            poses.append((R, t))
        (Rp, tp), (Rm, tm) = poses
        J[:3, i] = (tp - tm) / (2 * h)
        J[3:, i] = rotation_vector_from_matrix(Rp @ Rm.T, check=False) / (2 * h)
    cov = J @ C @ J.T
    P0 = _piercing_points(gauge, T_cf[:3, :3], T_cf[:3, 3])
    JP = np.empty((m, 6))
    for k in range(6):
        pts = []
        for sign in (1.0, -1.0):
            d = np.zeros(6)
            d[k] = sign * h
            R = matrix_from_rotation_vector(d[3:]) @ T_cf[:3, :3]
            P = _piercing_points(gauge, R, T_cf[:3, 3] + d[:3])
            if P is None or P0 is None:
                return 0.5 * (cov + cov.T), np.nan
            pts.append(P.ravel())
        JP[:, k] = (pts[0] - pts[1]) / (2 * h)
    r = flat - P0.ravel()
    M = np.eye(m) - JP @ J
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        return 0.5 * (cov + cov.T), np.nan
    Mw = np.linalg.solve(L, M @ L)
    rw = np.linalg.solve(L, r)
    lam, U = np.linalg.eigh(Mw @ Mw.T)
    lam, U = lam[-dof:], U[:, -dof:]
    chi2 = float(np.sum((U.T @ rw) ** 2 / lam)) if dof > 0 else 0.0
    return 0.5 * (cov + cov.T), chi2


def _solve_order(pts, C_fit, C_model, gauge, method, rev, T_init, max_iter, gate=None):
    """Solve one corner order; ``(candidate, cold_restart)`` with a :class:`_Candidate` or a
    failed kernel status (int).

    The fit is weighted by ``C_fit`` (the line fits' covariance); χ² and the pose covariance
    use ``C_model`` (the assumed noise), both plus the gauge's tolerance at the solution.
    ``gate``: with a start pose ``T_init`` and method 'mle', a start that fails or ends with a
    cost above the gate (a wrong minimum) is solved again from the closed form, and the lower
    cost is kept (``cold_restart`` True).
    """
    code = 2 if rev else 1
    method_code = METHODS.index(method)
    status, _, R, t, H, cost = solve_pose_unchecked(pts, C_fit, gauge, method_code, code, max_iter, T_init)
    cold = False
    if gate is not None and T_init is not None and method_code == 1 and not (status == OK and cost <= gate):
        cold = True
        res = solve_pose_unchecked(pts, C_fit, gauge, 1, code, max_iter, None)
        if not (status == OK and (res[0] != OK or cost < res[5])):
            status, _, R, t, H, cost = res
    if status != OK:
        return status, cold
    C_tol = None
    if gauge.tolerance_um > 0:
        # The tolerance maps to the corners through the pose: add it at the solution, solve again from there.
        C_tol = face_tolerance_covariance(gauge, _as_T(R, t), rev)
        status, _, R2, t2, H, cost = solve_pose_unchecked(pts, np.ascontiguousarray(C_fit + C_tol), gauge,
                                                          method_code, code, max_iter,
                                                          _as_T(R, t) if method == "mle" else None)
        if status != OK:
            return status, cold
        if method == "mle":
            R, t = R2, t2
    C_tot = C_model if C_tol is None else C_model + C_tol
    c = np.ascontiguousarray(pts[::-1]) if rev else pts
    if rev:
        idx = _reverse_index(len(c))
        C_ridge = C_tot[np.ix_(idx, idx)]
    else:
        C_ridge = C_tot
    chi2 = float(cost)
    if C_model is not C_fit:
        # χ² and the information under the assumed noise, at the fitted pose
        ok, W = spd_inverse(np.ascontiguousarray(C_ridge))
        if not ok:
            return DEGENERATE, cold
        R_FG = np.ascontiguousarray(R.T)
        H = np.empty((6, 6))
        ok, chi2 = normal_equations(R_FG, -(R_FG @ t), c, W, gauge.ridge_q, gauge.ridge_s, H, np.empty(6))
        if not ok:
            return RIDGE_IN_PLANE, cold
        chi2 = float(chi2)
    cov, reproj_mm = pose_covariance_and_reprojection(R, t, H, pts, rev, gauge.ridge_q, gauge.ridge_s)
    T = _as_T(R, t)
    if method == "cf":
        cov, chi2 = _cf_linearisation(c, C_ridge, gauge, T)
    return _Candidate(bool(rev), T, cov, float(reproj_mm), float(cost), chi2, c, gauge), cold


@functools.lru_cache(maxsize=4096)
def chi2_critical(alpha: float, dof: int) -> float:
    """Critical value of the χ² test: ``chi2.isf(alpha, dof)`` (0 for ``dof <= 0``), cached.

    The real-time path evaluates it per frame; SciPy's ``isf`` costs ~30 µs a call.
    """
    return float(_chi2.isf(alpha, dof)) if dof > 0 else 0.0


def _noise_verdict(corners: Corners, noise, alpha: float) -> str | None:
    """The reason why the profile is noisier than ``noise`` allows, or None."""
    sig = _face_sigma_mm(corners, noise)
    n_fit = corners.n_points.astype(np.float64)
    stat = float(np.sum((n_fit - 2.0) * corners.sigma**2 / sig**2))
    dof = int(np.sum(n_fit - 2))
    crit = chi2_critical(alpha, dof)
    if not stat > crit:
        return None
    ratio = corners.sigma / sig
    j = int(np.argmax(ratio))
    return (f"the profile scatters {np.sqrt(stat / dof):.2f}x the assumed noise about its faces (chi2 = {stat:.0f} "
            f"> {crit:.0f}, {dof} dof, worst face {j}: {corners.sigma[j] * 1e3:.1f} µm RMS, expected "
            f"{sig[j] * 1e3:.1f} µm): noisier than the sensor model (x {noise.sigma_x_um:g} µm, "
            f"z {noise.sigma_z_um:g} µm) or a face that is not flat")


def _check_noise(noise) -> None:
    if noise is None:
        return
    sx = getattr(noise, "sigma_x_um", None)
    sz = getattr(noise, "sigma_z_um", None)
    if sx is None or sz is None:
        raise EstimationError(f"noise: expected a NoiseModel (sigma_x_um, sigma_z_um), got {type(noise).__name__}")
    if not (np.isfinite(sx) and np.isfinite(sz) and sx >= 0 and sz >= 0 and sx + sz > 0):
        raise EstimationError(f"noise: the assumed noise must be finite, >= 0 and not zero in both x and z, "
                              f"got x {sx:g} µm, z {sz:g} µm")


def solve_pose(corners: Corners, gauge, method: str = "mle", mounting: str = "auto", T_init=None,
               max_iter: int = 20, *, noise=None, significance: float = DEFAULT_SIGNIFICANCE) -> PoseEstimate:
    """Pose of the profiler in the gauge frame from the corners of one profile, with its verdict.

    Parameters
    ----------
    corners : Corners
        From :func:`~posekit.profiler.estimate.corners.detect_corners`: corner points (n, 2) in F,
        mm, in scan order, with their joint covariance (2n, 2n), mm².
    gauge : Gauge
        The gauge, with n ridges (its ``tolerance_um`` enters the covariance and the test).
    method : {'mle', 'cf'}
        ``cf``: closed form, eq. (9)–(14) (n >= 5). ``mle``: refined (any n >= 4).
    mounting : {'auto', 'normal', 'reversed'}
        Whether the scan order of the corners follows the ridge order ('normal'), runs
        against it (sensor mounted the other way round), or should be decided per profile
        ('auto': both are solved; a possible pose first, then the lower χ²). An ambiguous
        gauge (:attr:`Gauge.ambiguity`) needs a given mounting.
    T_init : ndarray, shape (4, 4), optional
        Start pose ``T_G_F`` (e.g. the previous pose of a stream) instead of the closed form.
    max_iter : int
    noise : NoiseModel, optional
        The noise the estimator assumes (per point, x and z of F, µm): the corner
        covariance and the noise test follow it. None: the line fits' own residuals (no
        noise test).
    significance : float
        α of the consistency test, in (0, 1) (module docstring).

    Returns
    -------
    PoseEstimate
        With ``status`` 'ok' or 'suspect' and the ``reason``.

    Raises
    ------
    EstimationError
        If the corner count does not match the gauge, the closed form is asked for with
        4 corners, the geometry is degenerate, or an ambiguous gauge is used with
        mounting 'auto'.
    """
    if method not in METHODS:
        raise EstimationError(f"unknown method '{method}'; expected one of {', '.join(METHODS)}")
    if mounting not in MOUNTINGS:
        raise EstimationError(f"unknown mounting '{mounting}'; expected one of {', '.join(MOUNTINGS)}")
    if not (isinstance(significance, (float, int)) and 0 < significance < 1):
        raise EstimationError(f"significance must be a number in (0, 1), got {significance!r}")
    _check_noise(noise)
    n = gauge.n_corners
    if np.shape(corners.points) != (n, 2):
        raise EstimationError(f"expected {n} corners for gauge '{gauge.name}', got {np.shape(corners.points)[0]}")
    if mounting == "auto" and getattr(gauge, "ambiguity", None):
        raise EstimationError(f"gauge '{gauge.name}' is ambiguous ({gauge.ambiguity}); give the mounting "
                              "('normal' or 'reversed')")
    orders = {"auto": (False, True), "normal": (False,), "reversed": (True,)}[mounting]
    res, _ = estimate_from_corners(corners, gauge, method, orders, (T_init, T_init), max_iter, noise,
                                   significance)
    if not isinstance(res, PoseEstimate):
        raise EstimationError(status_message(res, n))
    return res


def estimate_from_corners(corners: Corners, gauge, method: str, orders, T_inits, max_iter: int, noise,
                          significance: float, gate: float | None = None):
    """Pose and verdict of :func:`solve_pose` without its checks: the one path both the
    checked estimator and the real-time one (:mod:`~posekit.profiler.estimate.fast`) take.

    Parameters
    ----------
    corners : Corners
        Corner count matching the gauge (not checked).
    gauge, method, max_iter, noise, significance
        As :func:`solve_pose` (valid values, not checked).
    orders : tuple of bool
        Corner orders to solve (False: normal, True: reversed): ``(False, True)`` is 'auto'.
    T_inits : (T or None, T or None)
        Start pose of the normal and of the reversed order (None: the closed form).
    gate : float, optional
        Cost above which a start from ``T_inits`` is retried from the closed form.

    Returns
    -------
    (PoseEstimate or int, bool)
        The estimate, or the failed kernel status of the first order tried (for
        :func:`status_message`); and whether a start pose was retried from the closed form.
    """
    pts = np.ascontiguousarray(corners.points, dtype=np.float64)
    C_fit = np.ascontiguousarray(corners.cov, dtype=np.float64)
    C_model = C_fit if noise is None else corner_covariance(corners, noise)
    cands, failure, cold = [], None, False
    for rev in orders:
        res, c = _solve_order(pts, C_fit, C_model, gauge, method, rev, T_inits[int(rev)], max_iter, gate)
        cold |= c
        if isinstance(res, _Candidate):
            cands.append(res)
        elif failure is None:
            failure = res
    if not cands:
        return failure, cold
    return _verdict(cands, corners, gauge, method, noise, significance), cold


def _verdict(cands, corners: Corners, gauge, method: str, noise, significance: float) -> PoseEstimate:
    """The best candidate (a possible pose first, then the lower χ²) with its verdict (module docstring)."""
    n = corners.points.shape[0]
    # A possible pose first, then the lower χ²: the other candidate's possibility is only
    # looked at when it matters (the lower χ² is impossible, or the other one fits too).
    cands.sort(key=lambda c: c.chi2 if np.isfinite(c.chi2) else np.inf)
    if len(cands) == 2 and not cands[0].possible and cands[1].possible:
        cands.reverse()
    best = cands[0]

    dof = 2 * n - 6
    alpha = significance / (2 if noise is not None else 1)
    crit = chi2_critical(alpha, dof)
    reasons = []
    if not best.chi2 <= crit:
        k = int(np.nanargmax(best.resid_mm)) if np.any(np.isfinite(best.resid_mm)) else 0
        what = (f"the assumed noise (x {noise.sigma_x_um:g} µm, z {noise.sigma_z_um:g} µm)" if noise is not None
                else "the line fits' noise")
        reasons.append(f"chi2 = {best.chi2:.1f} > {crit:.1f} ({dof} dof, significance {alpha:g}): the corners do "
                       f"not fit gauge '{gauge.name}' within {what} and its tolerance ({gauge.tolerance_um:g} µm), "
                       f"largest miss at corner {k} ({best.resid_mm[k] * 1e3:.1f} µm): wrong gauge file, a face off "
                       "its drawing, a rounded or chamfered ridge, or a wrong basin")
    if noise is not None:
        why = _noise_verdict(corners, noise, alpha)
        if why is not None:
            reasons.append(why)
    if not best.possible:
        reasons.append("at the fitted pose the sensor would see a face from behind (through the gauge): no real "
                       "pose gives these corners")
    if len(cands) == 2 and cands[1].chi2 <= crit and cands[1].possible:
        reasons.append(f"the {'normal' if best.rev else 'reversed'} corner order fits too (chi2 = "
                       f"{cands[1].chi2:.1f} <= {crit:.1f}): the mounting cannot be told from this profile, "
                       "give it (--mounting normal|reversed)")
    # reasons hold no "; " of their own: the record joins them with it
    return PoseEstimate(T_G_F=best.T, cov=best.cov, reprojection_um=best.reprojection_mm * 1e3, cost=best.cost,
                        reversed=best.rev, method=method, chi2=float(best.chi2), dof=dof,
                        status="suspect" if reasons else "ok", reason="; ".join(reasons) or None)
