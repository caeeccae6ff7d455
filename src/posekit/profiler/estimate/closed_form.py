"""Closed-form pose from the corners of one profile: the paper's eq. (9)–(14).

Stack eq. (9) for the n corners into ``A x = b`` (eq. 10) with ``x = [m1; m2; m3]`` the
rows of ``M = [r1 r3 t]``, solve it by least squares (Householder QR with column scaling),
rebuild ``R̂ = [r1, r3 × r1, r3]``, take its nearest rotation (eq. 13, the orthogonal polar
factor) and rescale ``t`` by the ratio of Frobenius norms (eq. 14). With n = 4 the system
has 8 equations for 9 unknowns; :func:`cf4_start` then picks, on its one-dimensional
solution line, the point whose r1 and r3 are closest to orthonormal.

The kernels avoid LAPACK and allocation in loops: at this size a library call costs more
than the arithmetic.
"""

import numpy as np

from posekit._jit import njit

from ...errors import EstimationError

__all__ = ["closed_form", "cf_kernel", "cf4_start", "CF_NEEDS"]

#: Corners the closed form needs (eq. 10 has 2n equations for 9 unknowns).
CF_NEEDS = 5


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
def cf_kernel(corners, q, s):
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


def cf4_start(corners, q, s):
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





def closed_form(corners_F, gauge):
    """The closed-form pose of eq. (9)–(14) alone, ``T_G_F`` of shape (4, 4).

    Parameters
    ----------
    corners_F : array_like, shape (n, 2)
        Corners (x, z) in F, mm, in ridge order; n >= 5.
    gauge : Gauge

    Raises
    ------
    EstimationError
        With fewer than 5 corners, or a singular system (degenerate corners).
    """
    c = np.ascontiguousarray(corners_F, dtype=np.float64)
    n = c.shape[0]
    if n < CF_NEEDS:
        raise EstimationError(f"the closed form needs at least 5 corners (with {n}, eq. (10) has {2 * n} "
                              "equations for 9 unknowns); use method 'mle'")
    ok, R, t = cf_kernel(c, gauge.ridge_q, gauge.ridge_s)
    if not ok:
        raise EstimationError("degenerate corner geometry: the linear system of eq. (10) is singular "
                              "(corners collinear or coincident?)")
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = t
    return T
