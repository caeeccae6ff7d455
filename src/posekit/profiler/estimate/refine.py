"""Maximum-likelihood refinement of the pose (the paper's eq. (15), geometric residual).

For each ridge i the predicted corner P_i is where the ridge pierces F's laser plane
y = 0; the residual ``r = c - P`` (x and z in F, mm) is weighted by the inverse joint
covariance of the measured corners, so the minimum is the ML estimate under the Gaussian
corner model and the Gauss–Newton normal matrix H at the minimum is the Fisher
information. The pose is ``T_F_G`` perturbed on the left by a twist ``[ρ, φ]``; the
Jacobian is analytic: ``dP = B (dρ - [P]× dφ)`` with ``B v = v - s_F v_y / s_Fy``.

Compiled with numba, allocation- and BLAS-free in the inner loops.
"""

import numpy as np

from posekit._jit import njit

from ...geometry import cholesky_solve

__all__ = ["normal_equations", "spd_inverse", "refine_kernel", "pose_covariance_and_reprojection"]


@njit(cache=True, nogil=True)
def normal_equations(R, t, corners, W, q, s, H, g):
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
def spd_inverse(C):
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
def refine_kernel(R, t, corners, W, q, s, max_iter):
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
    ok, cost = normal_equations(R, t, corners, W, q, s, H, g)
    if not ok:
        return False, R, t, H, cost, 0
    lam = 0.0                      # pure Gauss-Newton until a step fails to descend
    it = 0
    for it in range(1, max_iter + 1):
        accepted = False
        cost2 = cost
        for _ in range(12):
            if cholesky_solve(H, g, d, L, lam):
                _exp_left(R, t, d, R2, t2)
                ok2, cost2 = normal_equations(R2, t2, corners, W, q, s, H2, g2)
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
def pose_covariance_and_reprojection(R_GF, t_GF, H, corners, rev, q, s):
    """Pose covariance in G (6, 6) and the mean corner-to-ridge distance (mm).

    H is the information of the left twist ξ = [ρ, φ] of T_F_G; T_G_F = T_F_G⁻¹ gets the
    right twist -ξ, i.e. δt_G = -R_G_F ρ and δθ_G = -R_G_F φ, so the covariance is
    B H⁻¹ Bᵀ with B = diag(R_G_F, R_G_F).
    """
    ok, S = spd_inverse(H)
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


