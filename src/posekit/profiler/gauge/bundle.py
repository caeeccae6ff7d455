"""Bundle adjustment of a gauge's face planes and the profiler's poses (the solver of
:func:`~posekit.profiler.gauge.calibration.calibrate_gauge`).

Model. Face f is the plane ``{p : n_f · p = d_f}`` in G, parametrized about the drawing's
``(n0_f, d0_f)`` by ``θ_f = [α_f (2), δ_f]``: ``n_f = normalize(n0_f + B_f α_f)`` with
``B_f`` an orthonormal basis of the plane ⊥ ``n0_f`` (α: tilts, rad) and
``d_f = d0_f + δ_f`` (mm). Corner i of a profile, a point ``(x, 0, z)`` of the laser frame
F, lies on ridge i (faces i and i + 1); its predicted position ``P_i`` is where that ridge
pierces F's laser plane y = 0 (the two face equations of ``T_G_F (P_x, 0, P_z)``, a 2×2
solve). The residual is ``c_i - P_i`` (x, z in F, mm), whitened by the joint covariance of
the profile's corners, so the minimum is the maximum-likelihood estimate and the
Gauss–Newton matrix its information. The Jacobian is analytic: with ``h_f = n_f · p - d_f``
at ``p = T_G_F (P_x, 0, P_z)``, ``d(c - P) = A⁻¹ dh`` where ``A = [n_i; n_i+1] [r1 r3]``;
a pose moves as ``T_G_F ← (Exp(φ) R, t + ρ)``.

Solver. Levenberg–Marquardt on the block structure of bundle adjustment: each pose's 6×6
block is eliminated (Schur complement), the reduced ``3(n + 1)`` face system is solved
under linear equality constraints ``C θ = 0`` (a bordered, KKT system), and the poses are
back-substituted. Every step is batched over the profiles: 100 profiles of a 5-ridge gauge
take about 5 ms per iteration. The tests check the analytic Jacobian against finite
differences and the solution against ``scipy.optimize.least_squares`` (MINPACK's LM on the
block-sparse Jacobian, parametrized on the constrained subspace).
"""

import numpy as np

from ...errors import CalibrationError
from ...geometry import matrix_from_rotation_vector
from .model import Gauge

__all__ = ["tangent_bases", "plane_params", "bundle_residuals", "adjust", "normal_blocks", "reduced_system"]


def tangent_bases(n0):
    """Orthonormal bases ``B`` (F, 3, 2) of the planes ⊥ each unit normal ``n0`` (F, 3)."""
    a = np.where(np.abs(n0[:, :1]) < 0.9, np.array([[1.0, 0.0, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    b1 = a - np.sum(a * n0, axis=1, keepdims=True) * n0
    b1 /= np.linalg.norm(b1, axis=1, keepdims=True)
    b2 = np.cross(n0, b1)
    return np.stack([b1, b2], axis=2)


def plane_params(nominal: Gauge, theta):
    """Face normals and offsets in G from the deviations ``θ`` of the drawing.

    Parameters
    ----------
    nominal : Gauge
    theta : array_like, shape (n + 1, 3)
        Per face ``[α1, α2 (rad), δ (mm)]``: tilt of the normal in the face's tangent basis
        and change of the offset.

    Returns
    -------
    normals : ndarray, shape (n + 1, 3)
        Unit normals.
    offsets : ndarray, shape (n + 1,)
        mm.
    """
    theta = np.asarray(theta, dtype=np.float64).reshape(-1, 3)
    B = tangent_bases(nominal.normals)
    m = nominal.normals + np.einsum("fij,fj->fi", B, theta[:, :2])
    return m / np.linalg.norm(m, axis=1, keepdims=True), nominal.offsets + theta[:, 2]


def bundle_residuals(theta, Ts_G_F, corners_F, nominal: Gauge, Linv=None):
    """Corner residuals of every profile and their Jacobians.

    Parameters
    ----------
    theta : array_like, shape (n + 1, 3)
        Face deviations from the drawing (:func:`plane_params`).
    Ts_G_F : ndarray, shape (K, 4, 4)
        Poses, mm.
    corners_F : ndarray, shape (K, n, 2)
        Corners (x, z) in F, mm, in ridge order.
    nominal : Gauge
    Linv : ndarray, shape (K, 2n, 2n), optional
        Whitening: inverse Cholesky factors of the corners' joint covariances (None: identity).

    Returns
    -------
    r : ndarray, shape (K, 2n)
        ``c - P`` stacked ``[x0, z0, x1, ...]`` (whitened if ``Linv``), mm.
    J_pose : ndarray, shape (K, 2n, 6)
        d r / d[ρ, φ] for ``T_G_F ← (Exp(φ) R, t + ρ)``.
    J_face : ndarray, shape (K, 2n, 3(n + 1))
        d r / d θ.

    Raises
    ------
    CalibrationError
        If a ridge lies in a profile's laser plane (its corner is undefined).
    """
    theta = np.asarray(theta, dtype=np.float64).reshape(-1, 3)
    B = tangent_bases(nominal.normals)
    m = nominal.normals + np.einsum("fij,fj->fi", B, theta[:, :2])
    norm = np.linalg.norm(m, axis=1)
    n = m / norm[:, None]
    d = nominal.offsets + theta[:, 2]
    K, nc = corners_F.shape[:2]
    R = Ts_G_F[:, :3, :3]
    t = Ts_G_F[:, :3, 3]
    nn = np.stack([n[:-1], n[1:]], axis=1)                                      # (nc, 2, 3)
    A = np.einsum("cai,kij->kcaj", nn, R[:, :, [0, 2]])                          # (K, nc, 2, 2)
    rhs = np.stack([d[:-1], d[1:]], axis=1)[None] - np.einsum("cai,ki->kca", nn, t)
    det = A[..., 0, 0] * A[..., 1, 1] - A[..., 0, 1] * A[..., 1, 0]
    if np.any(np.abs(det) < 1e-9):
        k, i = np.argwhere(np.abs(det) < 1e-9)[0]
        raise CalibrationError(f"profile {k}: ridge {i} lies in the laser plane; its corner is undefined")
    Ainv = np.stack([np.stack([A[..., 1, 1], -A[..., 0, 1]], -1), np.stack([-A[..., 1, 0], A[..., 0, 0]], -1)],
                    -2) / det[..., None, None]
    P = np.einsum("kcab,kcb->kca", Ainv, rhs)                                    # (K, nc, 2)
    r = corners_F - P
    u = R[:, None, :, 0] * P[..., 0:1] + R[:, None, :, 2] * P[..., 1:2]          # R (Px, 0, Pz), (K, nc, 3)
    p = u + t[:, None, :]
    # dh/d pose for faces a (i) and b (i + 1): [n, u × n]
    dh_pose = np.concatenate([np.broadcast_to(nn[None], (K, nc, 2, 3)), np.cross(u[:, :, None, :], nn[None])], -1)
    J_pose = np.einsum("kcab,kcbj->kcaj", Ainv, dh_pose).reshape(K, 2 * nc, 6)
    # dh_f/dα_f = pᵀ (I - n nᵀ) B_f / |m_f|, dh_f/dδ_f = -1
    proj = np.eye(3)[None] - n[:, :, None] * n[:, None, :]
    G = np.einsum("fij,fjk->fik", proj, B) / norm[:, None, None]                # (F, 3, 2)
    dh_a = np.concatenate([np.einsum("kci,cij->kcj", p, G[:-1]), -np.ones((K, nc, 1))], -1)   # (K, nc, 3)
    dh_b = np.concatenate([np.einsum("kci,cij->kcj", p, G[1:]), -np.ones((K, nc, 1))], -1)
    J_face = np.zeros((K, nc, 2, len(n), 3))
    ic = np.arange(nc)
    J_face[:, ic, :, ic, :] = np.moveaxis(Ainv[..., :, 0:1] * dh_a[:, :, None, :], 1, 0)
    J_face[:, ic, :, ic + 1, :] = np.moveaxis(Ainv[..., :, 1:2] * dh_b[:, :, None, :], 1, 0)
    J_face = J_face.reshape(K, 2 * nc, 3 * len(n))
    r = r.reshape(K, 2 * nc)
    if Linv is not None:
        r = np.einsum("kab,kb->ka", Linv, r)
        J_pose = Linv @ J_pose
        J_face = Linv @ J_face
    return r, J_pose, J_face


def _apply_pose_step(Ts, step):
    """Poses moved by ``step`` (K, 6) ``[ρ, φ]``: ``(Exp(φ) R, t + ρ)``."""
    out = Ts.copy()
    out[:, :3, :3] = matrix_from_rotation_vector(step[:, 3:]) @ Ts[:, :3, :3]
    out[:, :3, 3] += step[:, :3]
    return out


def normal_blocks(J_pose, J_face, r):
    """Blocks of the Gauss–Newton system from :func:`bundle_residuals`.

    Returns ``U`` (P, P) faces × faces, ``V`` (K, 6, 6) each pose, ``W`` (K, P, 6) faces ×
    pose, and the gradients ``gp`` (P,) and ``gx`` (K, 6); P = 3(n + 1).
    """
    V = np.swapaxes(J_pose, 1, 2) @ J_pose                       # (K, 6, 6)
    W = np.swapaxes(J_face, 1, 2) @ J_pose                       # (K, P, 6)
    U = np.einsum("kai,kaj->ij", J_face, J_face)
    gx = np.einsum("kai,ka->ki", J_pose, r)
    gp = np.einsum("kai,ka->i", J_face, r)
    return U, V, W, gp, gx


def reduced_system(U, V, W, gp, gx, lam):
    """The faces' system with the poses eliminated (Schur complement), Marquardt damping ``lam``.

    Returns ``S`` (P, P), its right-hand side (P,) and the damped ``V⁻¹`` (K, 6, 6); at
    ``lam = 0``, S is the faces' information (singular along the frame's 6 rigid motions).
    """
    Vd = V + lam * (V * np.eye(6))
    Vinv = np.linalg.inv(Vd)
    WVi = W @ Vinv
    S = U + lam * np.diag(np.diag(U)) - np.einsum("kpi,kqi->pq", WVi, W)
    rhs = gp - np.einsum("kpi,ki->p", WVi, gx)
    return S, rhs, Vinv


def _bordered_solve(S, rhs, C, c):
    """Solve ``S x = -rhs`` subject to ``C x = c``."""
    nP, nC = S.shape[0], C.shape[0]
    M = np.zeros((nP + nC, nP + nC))
    M[:nP, :nP] = S
    M[:nP, nP:] = C.T
    M[nP:, :nP] = C
    sol = np.linalg.solve(M, np.concatenate([-rhs, c]))
    return sol[:nP]


def adjust(theta, Ts, corners, Linv, nominal, C, max_iter=50):
    """Levenberg–Marquardt on faces and poses, the faces held to ``C θ = 0``.

    Parameters
    ----------
    theta : ndarray, shape (n + 1, 3)
        Start deviations of the faces from the drawing.
    Ts : ndarray, shape (K, 4, 4)
        Start poses ``T_G_F``, mm.
    corners : ndarray, shape (K, n, 2)
        Corners (x, z) in F, mm, in ridge order.
    Linv : ndarray, shape (K, 2n, 2n)
        Whitening of each profile's corners (inverse Cholesky factor of their covariance).
    nominal : Gauge
    C : ndarray, shape (c, 3(n + 1))
        Linear constraints on θ (the frame and the outer faces' hinge).
    max_iter : int

    Returns
    -------
    theta, Ts, r, J_pose, J_face, cost, iterations
        At the solution (r, J whitened; cost = Σ r²).
    """
    r, Jx, Jp = bundle_residuals(theta, Ts, corners, nominal, Linv)
    cost = float(np.sum(r**2))
    lam = 1e-6
    it = 0
    for it in range(1, max_iter + 1):
        U, V, W, gp, gx = normal_blocks(Jx, Jp, r)
        accepted = False
        while lam < 1e12:
            S, rhs, Vinv = reduced_system(U, V, W, gp, gx, lam)
            dp = _bordered_solve(S, rhs, C, -C @ theta.ravel())
            dx = -np.einsum("kij,kj->ki", Vinv, gx + np.einsum("kpi,p->ki", W, dp))
            theta2 = theta + dp.reshape(theta.shape)
            Ts2 = _apply_pose_step(Ts, dx)
            try:
                r2, Jx2, Jp2 = bundle_residuals(theta2, Ts2, corners, nominal, Linv)
                cost2 = float(np.sum(r2**2))
            except CalibrationError:
                cost2 = np.inf
            if cost2 <= cost:
                accepted = True
                break
            lam *= 10.0
        if not accepted:
            break
        gain = cost - cost2
        theta, Ts, r, Jx, Jp, cost = theta2, Ts2, r2, Jx2, Jp2, cost2
        lam = max(lam / 10.0, 1e-9)
        if gain <= 1e-12 * max(cost, 1.0) and np.max(np.abs(dp)) < 1e-9:
            break
    return theta, Ts, r, Jx, Jp, cost, it
