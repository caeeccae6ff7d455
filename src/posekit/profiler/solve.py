"""6-DoF pose of the profiler from the corners of one profile (paper §II-C).

Two estimators, both returning ``T_G_F`` (the profiler frame F in the gauge frame G):

``cf``
    The closed form of eq. (9)–(14): stack eq. (9) for the n corners into ``A x = b``,
    solve by least squares (SVD), rebuild ``R̂ = [r1, r3 × r1, r3]``, project it on
    SO(3) (eq. 13) and rescale ``t`` by the ratio of Frobenius norms (eq. 14). Needs
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
information, and its inverse is the pose covariance that is returned. Iterations:
Gauss–Newton with Levenberg damping on a left perturbation of ``T_F_G``, with the
analytic Jacobian (cross-checked against finite differences and against
``scipy.optimize.least_squares`` in the tests).
"""

from dataclasses import dataclass

import numpy as np
from numba import njit

from ..errors import EstimationError
from ..geometry import point_line_distance, quaternion_from_matrix, transform_from
from .corners import Corners

__all__ = ["PoseEstimate", "solve_pose", "solve_pose_unchecked", "reprojection_residuals",
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
def _inv3(M, out):
    """out = M⁻¹ for a 3×3 matrix; returns det."""
    a, b, c = M[0, 0], M[0, 1], M[0, 2]
    d, e, f = M[1, 0], M[1, 1], M[1, 2]
    g, h, k = M[2, 0], M[2, 1], M[2, 2]
    A = e * k - f * h
    B = f * g - d * k
    C = d * h - e * g
    det = a * A + b * B + c * C
    if det == 0.0:
        return 0.0
    out[0, 0] = A / det
    out[1, 0] = B / det
    out[2, 0] = C / det
    out[0, 1] = (c * h - b * k) / det
    out[1, 1] = (a * k - c * g) / det
    out[2, 1] = (b * g - a * h) / det
    out[0, 2] = (b * f - c * e) / det
    out[1, 2] = (c * d - a * f) / det
    out[2, 2] = (a * e - b * d) / det
    return det


@njit(cache=True, nogil=True)
def _polar_rotation(M):
    """Orthogonal polar factor of M (det M > 0): the nearest rotation, eq. (13).

    Scaled Newton iteration X ← (γX + (γX)⁻ᵀ)/2 (Higham), quadratically convergent;
    equal to U Vᵀ of the SVD M = U Σ Vᵀ without calling LAPACK.
    """
    X = M.copy()
    Y = np.empty((3, 3))
    for _ in range(30):
        det = _inv3(X, Y)
        if det <= 0.0:
            return False, X
        nx = 0.0
        ny = 0.0
        for i in range(3):
            for j in range(3):
                nx += X[i, j] * X[i, j]
                ny += Y[i, j] * Y[i, j]
        nx = np.sqrt(nx)
        ny = np.sqrt(ny)
        gam = np.sqrt(ny / nx)
        delta = 0.0
        for i in range(3):
            for j in range(3):
                v = 0.5 * (gam * X[i, j] + Y[j, i] / gam)
                delta = max(delta, abs(v - X[i, j]))
                X[i, j] = v
        if delta < 1e-15:
            break
    return True, X


@njit(cache=True, nogil=True)
def _system(corners, q, s, A, b):
    """Fill A (2n×9) and b (2n) of eq. (10), unknowns x = [m1; m2; m3] (rows of M = [r1 r3 t])."""
    n = corners.shape[0]
    A[:, :] = 0.0
    for i in range(n):
        p0 = corners[i, 0]
        p1 = corners[i, 1]
        u = s[i, 0]
        w = s[i, 2]
        A[2 * i, 0] = p0
        A[2 * i, 1] = p1
        A[2 * i, 2] = 1.0
        A[2 * i, 3] = -u * p0
        A[2 * i, 4] = -u * p1
        A[2 * i, 5] = -u
        A[2 * i + 1, 3] = -w * p0
        A[2 * i + 1, 4] = -w * p1
        A[2 * i + 1, 5] = -w
        A[2 * i + 1, 6] = p0
        A[2 * i + 1, 7] = p1
        A[2 * i + 1, 8] = 1.0
        b[2 * i] = q[i, 0]
        b[2 * i + 1] = q[i, 2]


@njit(cache=True, nogil=True)
def _lstsq_qr(A, b):
    """Least squares min |A x - b| by Householder QR with column scaling; A, b overwritten.

    Returns ok (full column rank) and x.
    """
    m, nc = A.shape
    scale = np.empty(nc)
    for j in range(nc):
        acc = 0.0
        for i in range(m):
            acc += A[i, j] * A[i, j]
        scale[j] = np.sqrt(acc) if acc > 0.0 else 1.0
        for i in range(m):
            A[i, j] /= scale[j]
    diag = np.empty(nc)
    for j in range(nc):
        norm = 0.0
        for i in range(j, m):
            norm += A[i, j] * A[i, j]
        norm = np.sqrt(norm)
        if norm < 1e-12:
            return False, diag
        alpha = -norm if A[j, j] > 0.0 else norm
        A[j, j] -= alpha
        vnorm2 = 0.0
        for i in range(j, m):
            vnorm2 += A[i, j] * A[i, j]
        for k in range(j + 1, nc):
            dot = 0.0
            for i in range(j, m):
                dot += A[i, j] * A[i, k]
            f = 2.0 * dot / vnorm2
            for i in range(j, m):
                A[i, k] -= f * A[i, j]
        dot = 0.0
        for i in range(j, m):
            dot += A[i, j] * b[i]
        f = 2.0 * dot / vnorm2
        for i in range(j, m):
            b[i] -= f * A[i, j]
        diag[j] = alpha
    x = np.empty(nc)
    for j in range(nc - 1, -1, -1):
        acc = b[j]
        for k in range(j + 1, nc):
            acc -= A[j, k] * x[k]
        x[j] = acc / diag[j]
    for j in range(nc):
        x[j] /= scale[j]
    return True, x


@njit(cache=True, nogil=True)
def _from_x(x):
    """R̂ = [r1, r3 × r1, r3] and t̂ from x = [m1; m2; m3], M = [r1 r3 t]."""
    R = np.empty((3, 3))
    for i in range(3):
        R[i, 0] = x[3 * i]
        R[i, 2] = x[3 * i + 1]
    R[0, 1] = R[1, 2] * R[2, 0] - R[2, 2] * R[1, 0]
    R[1, 1] = R[2, 2] * R[0, 0] - R[0, 2] * R[2, 0]
    R[2, 1] = R[0, 2] * R[1, 0] - R[1, 2] * R[0, 0]
    t = np.array([x[2], x[5], x[8]])
    return R, t


@njit(cache=True, nogil=True)
def _cf_kernel(corners, q, s):
    """Closed form eq. (9)-(14); needs n >= 5. Returns ok, R_G_F, t_G_F."""
    n = corners.shape[0]
    A = np.empty((2 * n, 9))
    b = np.empty(2 * n)
    _system(corners, q, s, A, b)
    ok, x = _lstsq_qr(A, b)
    if not ok:
        return False, np.eye(3), np.zeros(3)
    R_hat, t_hat = _from_x(x)
    nrm = np.sqrt(np.sum(R_hat * R_hat))
    ok, R_bar = _polar_rotation(R_hat)
    if not ok or not np.isfinite(nrm):
        return False, np.eye(3), np.zeros(3)
    return True, R_bar, (np.sqrt(3.0) / nrm) * t_hat          # eq. (14): ||R̄||_F = √3


@njit(cache=True, nogil=True)
def _normal_equations(R, t, corners, W, q, s, H, g):
    """Fill H = Jᵀ W J and g = Jᵀ W r for r = c - P(T_F_G) under a left twist [ρ, φ] of
    T_F_G = (R, t); returns ok and the cost rᵀ W r. W is the (2n, 2n) inverse of the
    joint corner covariance, r and J stack the corners as [x0, z0, x1, z1, ...].

    P is where ridge i (q + λ s, in G) pierces F's plane y = 0:
    dP = B (dρ - [P]× dφ), with B v = v - s_F v_y / s_Fy; rows x and z of F.
    """
    n = corners.shape[0]
    m = 2 * n
    J = np.empty((m, 6))
    r = np.empty(m)
    for i in range(n):
        qx = R[0, 0] * q[i, 0] + R[0, 1] * q[i, 1] + R[0, 2] * q[i, 2] + t[0]
        qy = R[1, 0] * q[i, 0] + R[1, 1] * q[i, 1] + R[1, 2] * q[i, 2] + t[1]
        qz = R[2, 0] * q[i, 0] + R[2, 1] * q[i, 1] + R[2, 2] * q[i, 2] + t[2]
        sx = R[0, 0] * s[i, 0] + R[0, 1] * s[i, 1] + R[0, 2] * s[i, 2]
        sy = R[1, 0] * s[i, 0] + R[1, 1] * s[i, 1] + R[1, 2] * s[i, 2]
        sz = R[2, 0] * s[i, 0] + R[2, 1] * s[i, 1] + R[2, 2] * s[i, 2]
        if abs(sy) < 1e-9 * np.sqrt(sx * sx + sy * sy + sz * sz):
            return False, np.inf
        lam = -qy / sy
        px = qx + lam * sx
        pz = qz + lam * sz
        r[2 * i] = corners[i, 0] - px
        r[2 * i + 1] = corners[i, 1] - pz
        bx = sx / sy
        bz = sz / sy
        # rows of [I | -[P]x] with P = (px, 0, pz):  x: [1,0,0, 0, pz, 0]
        # y: [0,1,0, -pz, 0, px]   z: [0,0,1, 0, -px, 0];   dP_x = row x - bx row y, ...
        J[2 * i, 0] = 1.0
        J[2 * i, 1] = -bx
        J[2 * i, 2] = 0.0
        J[2 * i, 3] = bx * pz
        J[2 * i, 4] = pz
        J[2 * i, 5] = -bx * px
        J[2 * i + 1, 0] = 0.0
        J[2 * i + 1, 1] = -bz
        J[2 * i + 1, 2] = 1.0
        J[2 * i + 1, 3] = bz * pz
        J[2 * i + 1, 4] = -px
        J[2 * i + 1, 5] = -bz * px
    # W J and W r by loops: tiny matrices, where a BLAS call costs more than the work.
    WJ = np.zeros((m, 6))
    Wr = np.zeros(m)
    for a in range(m):
        for k in range(m):
            w = W[a, k]
            Wr[a] += w * r[k]
            for c in range(6):
                WJ[a, c] += w * J[k, c]
    cost = 0.0
    for a in range(m):
        cost += r[a] * Wr[a]
    for a in range(6):
        acc = 0.0
        for k in range(m):
            acc += J[k, a] * Wr[k]
        g[a] = acc
        for c in range(a, 6):
            acc = 0.0
            for k in range(m):
                acc += J[k, a] * WJ[k, c]
            H[a, c] = acc
            H[c, a] = acc
    return True, cost


@njit(cache=True, nogil=True)
def _spd_inverse(C):
    """Inverse of a symmetric positive definite matrix by Cholesky; ok=False if not SPD."""
    m = C.shape[0]
    L = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            acc = C[i, j]
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            if i == j:
                if not (acc > 0.0):
                    return False, L
                L[i, i] = np.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
    Linv = np.zeros((m, m))
    for j in range(m):
        for i in range(j, m):
            acc = 1.0 if i == j else 0.0
            for k in range(j, i):
                acc -= L[i, k] * Linv[k, j]
            Linv[i, j] = acc / L[i, i]
    W = np.zeros((m, m))
    for i in range(m):
        for j in range(i + 1):
            acc = 0.0
            for k in range(i, m):
                acc += Linv[k, i] * Linv[k, j]
            W[i, j] = acc
            W[j, i] = acc
    return True, W


@njit(cache=True, nogil=True)
def _cholesky_solve(H, lam, g, x, L):
    """Solve (H + lam·diag(H)) x = g by Cholesky; returns False if not positive definite."""
    for i in range(6):
        for j in range(i + 1):
            acc = H[i, j] + (lam * max(H[i, i], 1e-30) if i == j else 0.0)
            for k in range(j):
                acc -= L[i, k] * L[j, k]
            if i == j:
                if acc <= 0.0:
                    return False
                L[i, i] = np.sqrt(acc)
            else:
                L[i, j] = acc / L[j, j]
    for i in range(6):
        acc = g[i]
        for k in range(i):
            acc -= L[i, k] * x[k]
        x[i] = acc / L[i, i]
    for i in range(5, -1, -1):
        acc = x[i]
        for k in range(i + 1, 6):
            acc -= L[k, i] * x[k]
        x[i] = acc / L[i, i]
    return True


@njit(cache=True, nogil=True)
def _exp_left(R, t, d, R_out, t_out):
    """(R_out, t_out) = exp(d^) (R, t) for a twist d = [ρ, φ] (Rodrigues, no allocation)."""
    p0 = d[3]
    p1 = d[4]
    p2 = d[5]
    th2 = p0 * p0 + p1 * p1 + p2 * p2
    if th2 < 1e-12:
        A = 1.0 - th2 / 6.0
        B = 0.5 - th2 / 24.0
        C = 1.0 / 6.0 - th2 / 120.0
    else:
        th = np.sqrt(th2)
        A = np.sin(th) / th
        B = (1.0 - np.cos(th)) / th2
        C = (th - np.sin(th)) / (th2 * th)
    # K = [φ]x ; K² = φφᵀ - θ² I
    k01 = -p2
    k02 = p1
    k10 = p2
    k12 = -p0
    k20 = -p1
    k21 = p0
    dR00 = 1.0 + B * (p0 * p0 - th2)
    dR11 = 1.0 + B * (p1 * p1 - th2)
    dR22 = 1.0 + B * (p2 * p2 - th2)
    dR01 = A * k01 + B * p0 * p1
    dR02 = A * k02 + B * p0 * p2
    dR10 = A * k10 + B * p1 * p0
    dR12 = A * k12 + B * p1 * p2
    dR20 = A * k20 + B * p2 * p0
    dR21 = A * k21 + B * p2 * p1
    V00 = 1.0 + C * (p0 * p0 - th2)
    V11 = 1.0 + C * (p1 * p1 - th2)
    V22 = 1.0 + C * (p2 * p2 - th2)
    V01 = B * k01 + C * p0 * p1
    V02 = B * k02 + C * p0 * p2
    V10 = B * k10 + C * p1 * p0
    V12 = B * k12 + C * p1 * p2
    V20 = B * k20 + C * p2 * p0
    V21 = B * k21 + C * p2 * p1
    for j in range(3):
        r0 = R[0, j]
        r1 = R[1, j]
        r2 = R[2, j]
        R_out[0, j] = dR00 * r0 + dR01 * r1 + dR02 * r2
        R_out[1, j] = dR10 * r0 + dR11 * r1 + dR12 * r2
        R_out[2, j] = dR20 * r0 + dR21 * r1 + dR22 * r2
    t0 = t[0]
    t1 = t[1]
    t2 = t[2]
    t_out[0] = dR00 * t0 + dR01 * t1 + dR02 * t2 + V00 * d[0] + V01 * d[1] + V02 * d[2]
    t_out[1] = dR10 * t0 + dR11 * t1 + dR12 * t2 + V10 * d[0] + V11 * d[1] + V12 * d[2]
    t_out[2] = dR20 * t0 + dR21 * t1 + dR22 * t2 + V20 * d[0] + V21 * d[1] + V22 * d[2]


@njit(cache=True, nogil=True)
def _refine_kernel(R, t, corners, W, q, s, max_iter):
    """Levenberg-damped Gauss-Newton on T_F_G = (R, t); returns ok, R, t, H, cost, iters."""
    H = np.empty((6, 6))
    g = np.empty(6)
    H2 = np.empty((6, 6))
    g2 = np.empty(6)
    L = np.zeros((6, 6))
    d = np.empty(6)
    R = R.copy()
    t = t.copy()
    R2 = np.empty((3, 3))
    t2 = np.empty(3)
    ok, cost = _normal_equations(R, t, corners, W, q, s, H, g)
    if not ok:
        return False, R, t, H, cost, 0
    lam = 0.0                      # pure Gauss-Newton until a step fails to descend
    it = 0
    for it in range(1, max_iter + 1):
        accepted = False
        cost2 = cost
        for _ in range(12):
            if _cholesky_solve(H, lam, g, d, L):
                _exp_left(R, t, d, R2, t2)
                ok2, cost2 = _normal_equations(R2, t2, corners, W, q, s, H2, g2)
                if ok2 and cost2 <= cost * (1.0 + 1e-12):
                    accepted = True
                    break
            lam = 1e-6 if lam == 0.0 else lam * 10.0
        if not accepted:
            break
        decrement = 0.0               # Newton decrement dᵀ H d: the cost still to gain
        for a in range(6):
            decrement += d[a] * g[a]
        R[:, :] = R2
        t[:] = t2
        H[:, :] = H2
        g[:] = g2
        cost = cost2
        lam = 0.0 if lam <= 1e-6 else lam * 0.1
        if decrement < 1e-12 * max(1.0, cost):
            break
    return True, R, t, H, cost, it


@njit(cache=True, nogil=True)
def _start(corners, q, s, method, has_init, R_init, t_init):
    """Start pose T_G_F: the given one, else the closed form (n >= 5)."""
    if has_init:
        return OK, R_init.copy(), t_init.copy()
    if corners.shape[0] < 5:
        return (CF_UNDERDETERMINED if method == 0 else DEGENERATE), np.eye(3), np.zeros(3)
    ok, R, t = _cf_kernel(corners, q, s)
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
    ok, W = _spd_inverse(cov)
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
        ok, c = _normal_equations(R_c, t_c, cr, Wr, q, s, H, g)
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
        ok, cost = _normal_equations(R_FG, t_FG, cr, Wr, q, s, H, g)
    else:
        ok, R_FG, t_FG, H, cost, _ = _refine_kernel(R_FG, t_FG, cr, Wr, q, s, max_iter)
    if not ok:
        return RIDGE_IN_PLANE, rev, np.eye(3), np.zeros(3), H, np.inf
    return OK, rev, R_FG.T.copy(), -(R_FG.T @ t_FG), H, cost


@njit(cache=True, nogil=True)
def _finish_kernel(R_GF, t_GF, H, corners, rev, q, s):
    """Pose covariance in G (6, 6) and the mean corner-to-ridge distance (mm).

    H is the information of the left twist ξ = [ρ, φ] of T_F_G; T_G_F = T_F_G⁻¹ gets the
    right twist -ξ, i.e. δt_G = -R_G_F ρ and δθ_G = -R_G_F φ, so the covariance is
    B H⁻¹ Bᵀ with B = diag(R_G_F, R_G_F).
    """
    ok, S = _spd_inverse(H)
    cov = np.full((6, 6), np.inf)
    if ok:
        B = np.zeros((6, 6))
        B[:3, :3] = R_GF
        B[3:, 3:] = R_GF
        cov = B @ S @ B.T
        cov = 0.5 * (cov + cov.T)
    n = corners.shape[0]
    total = 0.0
    for i in range(n):
        j = n - 1 - i if rev else i
        px = R_GF[0, 0] * corners[j, 0] + R_GF[0, 2] * corners[j, 1] + t_GF[0] - q[i, 0]
        py = R_GF[1, 0] * corners[j, 0] + R_GF[1, 2] * corners[j, 1] + t_GF[1] - q[i, 1]
        pz = R_GF[2, 0] * corners[j, 0] + R_GF[2, 2] * corners[j, 1] + t_GF[2] - q[i, 2]
        ns = np.sqrt(s[i, 0] ** 2 + s[i, 1] ** 2 + s[i, 2] ** 2)
        ux = s[i, 0] / ns
        uy = s[i, 1] / ns
        uz = s[i, 2] / ns
        cx = py * uz - pz * uy
        cy = pz * ux - px * uz
        cz = px * uy - py * ux
        total += np.sqrt(cx * cx + cy * cy + cz * cz)
    return cov, total / n


# --------------------------------------------------------------------------- API


def _cf4_start(corners, q, s):
    """n = 4 start pose ``(ok, R_G_F, t_G_F)``: on the solution line x(μ) = x_p + μ v of
    the 8×9 system of eq. (10), the μ whose r1 and r3 are closest to orthonormal.

    ``g(μ) = (|r1|² - 1)² + (|r3|² - 1)² + 2 (r1·r3)²`` is a quartic in μ; its minimum is
    among the real roots of the cubic g'(μ). Plain NumPy: only 4-corner gauges without a
    previous pose need it, and it keeps the compiled kernels small.
    """
    n = corners.shape[0]
    A = np.empty((2 * n, 9))
    b = np.empty(2 * n)
    _system(corners, q, s, A, b)
    scale = np.linalg.norm(A, axis=0)
    scale[scale == 0] = 1.0
    U, sv, Vt = np.linalg.svd(A / scale, full_matrices=True)
    if sv[7] <= 1e-12 * sv[0]:
        return False, np.eye(3), np.zeros(3)
    xp = (Vt[:8].T @ ((U[:, :8].T @ b) / sv[:8])) / scale
    v = Vt[8] / scale
    a1, b1 = xp[[0, 3, 6]], v[[0, 3, 6]]
    a3, b3 = xp[[1, 4, 7]], v[[1, 4, 7]]
    quads = [np.array([b1 @ b1, 2 * a1 @ b1, a1 @ a1 - 1.0]),
             np.array([b3 @ b3, 2 * a3 @ b3, a3 @ a3 - 1.0]),
             np.array([b1 @ b3, a1 @ b3 + b1 @ a3, a1 @ a3])]
    g = sum(w * np.polymul(f, f) for w, f in zip((1.0, 1.0, 2.0), quads))
    roots = np.roots(np.polyder(g))
    real = roots[np.abs(roots.imag) < 1e-6 * np.maximum(1.0, np.abs(roots.real))].real
    if real.size == 0:
        return False, np.eye(3), np.zeros(3)
    mu = real[np.argmin(np.polyval(g, real))]
    R_hat, t_hat = _from_x(xp + mu * v)
    ok, R = _polar_rotation(R_hat)
    return ok, R, t_hat




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
            ok, R, t = _cf4_start(np.ascontiguousarray(c), gauge.ridge_q, gauge.ridge_s)
            init[0][r], init[1][r], init[2][r] = ok, R, t
        if not init[0].any():
            return DEGENERATE, False, np.eye(3), np.zeros(3), np.zeros((6, 6)), np.inf
    else:
        init = _NO_INIT
    return _solve_kernel(corners, cov, gauge.ridge_q, gauge.ridge_s, method_code, mounting_code,
                         max_iter, init[0], init[1], init[2])


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
        raise EstimationError(_MESSAGES[status].format(n=n, e=2 * n))
    cov, reproj_mm = _finish_kernel(R, t, H, pts, rev, gauge.ridge_q, gauge.ridge_s)
    if method == "cf":
        # The information matrix describes the ML estimate, not the closed form's error.
        cov = np.full((6, 6), np.nan)
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return PoseEstimate(T_G_F=T, cov=cov, reprojection_um=float(reproj_mm * 1e3), cost=float(cost),
                        reversed=bool(rev), method=method)


def closed_form(corners_F, gauge):
    """The closed-form pose of eq. (9)–(14) alone, ``T_G_F`` of shape (4, 4).

    Parameters
    ----------
    corners_F : array_like, shape (n, 2)
        Corners (x, z) in F, mm, in ridge order; n >= 5.
    gauge : Gauge
    """
    c = np.ascontiguousarray(corners_F, dtype=np.float64)
    if c.shape[0] < 5:
        raise EstimationError(_MESSAGES[CF_UNDERDETERMINED].format(n=c.shape[0], e=2 * c.shape[0]))
    ok, R, t = _cf_kernel(c, gauge.ridge_q, gauge.ridge_s)
    if not ok:
        raise EstimationError(_MESSAGES[DEGENERATE])
    return transform_from(R, t)
