"""Compiled kernels of the linearised filter on the tool pose (numba, cached on disk).

One linear-Gaussian step in the tangent space of a pose estimate ``T`` (tool frame ``[x, y, z, rx, ry, rz]``,
mm and rad), shared by the particle filter's spread bound (:mod:`posekit.seam.engine.spread_bound`) and the
likelihood the tuner maximises (:mod:`posekit.seam.engine.ekf`):

* :func:`plateau_cov` — the robot density's covariance (uniform plateau + Gaussian tails, eq. 8) in the frame of
  ``T``;
* :func:`predict_capped` — ``P ← P + diag(q²) + Q_pf``, each axis capped at the plateau (rows and columns scaled:
  the robot cannot leave its plateau, whatever the walk);
* :func:`laser_rows` — the lasers' in-plane errors ``e(T)`` and their Jacobian ``H`` by central differences
  (right perturbation ``T exp(±h e_j)``), the laser density's own error function (eq. 9);
* :func:`kalman_update` — ``P ← P - P Hᵀ S⁻¹ H P``, the correction ``δ = -P Hᵀ S⁻¹ e`` and the innovation's
  negative log-likelihood ``½ (eᵀ S⁻¹ e + log det S + m log 2π)``.
"""

import math

import numpy as np

from posekit._jit import njit
from posekit.seam.engine._kernels import _plane_error, window_kernel

__all__ = ["ekf_pass", "exp_right", "kalman_update", "laser_rows", "plateau_cov", "predict_capped"]

_LOG_2PI = math.log(2.0 * math.pi)


@njit(cache=True, boundscheck=False)
def plateau_cov(T, Sigma_t, Sigma_r, A_inv, d_t, d_r, C):
    """Write ``C (6, 6)``: the robot density's covariance in the frame of ``T (4, 4)``, block diagonal —
    a uniform ball of radius ``d_t`` (mm; ``d²/5`` per axis) plus ``Sigma_t`` (mm², base frame), and the
    rotation ellipsoid ``‖A Δr‖ <= d_r`` (``A_inv`` its inverse shape) plus ``Sigma_r`` (rad²)."""
    R = np.ascontiguousarray(T[:3, :3])
    Rt = np.ascontiguousarray(R.T)
    Ct = (d_t * d_t / 5.0) * np.eye(3) + Sigma_t
    Cr = (d_r * d_r / 5.0) * (A_inv @ np.ascontiguousarray(A_inv.T)) + Sigma_r
    C[:, :] = 0.0
    C[:3, :3] = Rt @ Ct @ R
    C[3:, 3:] = Rt @ Cr @ R


@njit(cache=True, boundscheck=False)
def predict_capped(P, C, first, q2, Q_pf):
    """In place on ``P (6, 6)``: ``C`` when ``first``, else ``P + diag(q2) + Q_pf`` with every axis capped at
    ``diag(C)`` by scaling its row and column (the correlations kept)."""
    if first:
        P[:, :] = C
        return
    s = np.empty(6)
    for a in range(6):
        for b in range(6):
            P[a, b] += Q_pf[a, b]
    for j in range(6):
        P[j, j] += q2[j]
        s[j] = math.sqrt(C[j, j] / P[j, j]) if P[j, j] > C[j, j] else 1.0
    for a in range(6):
        for b in range(6):
            P[a, b] *= s[a] * s[b]


@njit(cache=True, boundscheck=False)
def exp_right(T, d, out):
    """``out = T exp(d)``: ``d (6,)`` a tangent offset ``[ρ (mm), φ (rad)]`` in the frame of ``T``
    (translation ``R ρ``, rotation by Rodrigues)."""
    x, y, z = d[3], d[4], d[5]
    th2 = x * x + y * y + z * z
    if th2 < 1e-8:
        a = 1.0 - th2 / 6.0
        b = 0.5 - th2 / 24.0
    else:
        th = math.sqrt(th2)
        a = math.sin(th) / th
        b = (1.0 - math.cos(th)) / th2
    E = np.empty((3, 3))
    E[0, 0] = 1.0 - b * (y * y + z * z)
    E[1, 1] = 1.0 - b * (x * x + z * z)
    E[2, 2] = 1.0 - b * (x * x + y * y)
    E[0, 1], E[1, 0] = b * x * y - a * z, b * x * y + a * z
    E[0, 2], E[2, 0] = b * x * z + a * y, b * x * z - a * y
    E[1, 2], E[2, 1] = b * y * z - a * x, b * y * z + a * x
    for r in range(3):
        for c in range(3):
            out[r, c] = T[r, 0] * E[0, c] + T[r, 1] * E[1, c] + T[r, 2] * E[2, c]
        out[r, 3] = T[r, 3] + T[r, 0] * d[0] + T[r, 1] * d[1] + T[r, 2] * d[2]
    out[3, 0] = 0.0
    out[3, 1] = 0.0
    out[3, 2] = 0.0
    out[3, 3] = 1.0


@njit(cache=True, boundscheck=False)
def laser_rows(T, mxs, mzs, Ms, los, his, pts, r2s, h_t, h_r, H, e0, r2):
    """The lasers' in-plane errors at ``T (4, 4)`` and their Jacobian with respect to its tangent offset.

    Readings ``mxs, mzs (S,)`` (mm, NaN: none) with effective mounts ``Ms (S, 4, 4)`` and knot windows
    ``los, his (S,)`` (``lo < 0``: skipped) on the seam knots ``pts (K, 3)``; ``r2s (S, 2)`` each reading's
    variance along the sensor's x and z (mm²). Writes the used rows into ``H (2 S, 6)`` (mm per mm, mm per
    rad), ``e0 (2 S,)`` (mm) and ``r2 (2 S,)``; a reading whose plane misses the seam at ``T`` or at a
    perturbed pose is dropped. Returns the number of rows.
    """
    R = np.ascontiguousarray(T[:3, :3])
    Tp = np.empty((13, 4, 4))
    for k in range(13):
        Tp[k] = T
    for j in range(3):
        for sgn in range(2):
            sign = 1.0 if sgn == 0 else -1.0
            k = 2 * j + sgn
            for r in range(3):
                Tp[k, r, 3] = T[r, 3] + sign * h_t * R[r, j]
            a = sign * h_r
            cs, sn = math.cos(a), math.sin(a)
            G = np.eye(3)
            k1, k2 = (j + 1) % 3, (j + 2) % 3
            G[k1, k1] = cs
            G[k2, k2] = cs
            G[k2, k1] = sn
            G[k1, k2] = -sn
            Tp[6 + k, :3, :3] = R @ G
    E = np.empty((13, 2))
    m = 0
    for i in range(mxs.shape[0]):
        if los[i] < 0 or not (math.isfinite(mxs[i]) and math.isfinite(mzs[i])):
            continue
        ok = True
        for k in range(13):
            found, bx, bz = _plane_error(Tp, k, mxs[i], mzs[i], Ms[i], pts, los[i], his[i])
            if not found:
                ok = False
                break
            E[k, 0] = bx
            E[k, 1] = bz
        if not ok:
            continue
        for row in range(2):
            for j in range(3):
                H[m, j] = (E[2 * j, row] - E[2 * j + 1, row]) / (2.0 * h_t)
                H[m, 3 + j] = (E[6 + 2 * j, row] - E[6 + 2 * j + 1, row]) / (2.0 * h_r)
            e0[m] = E[12, row]
            r2[m] = r2s[i, row]
            m += 1
    return m


@njit(cache=True, boundscheck=False)
def kalman_update(P, H, e0, r2, m, dx):
    """Condition ``P (6, 6)`` on ``m`` laser rows (in place) and write the correction ``dx (6,)``.

    The rows say ``0 = e0 + H δ + v`` with ``v ~ N(0, diag(r2))``: ``S = H P Hᵀ + diag(r2)``,
    ``dx = -P Hᵀ S⁻¹ e0``, ``P ← P - P Hᵀ S⁻¹ H P`` (symmetrised). Returns the innovation's negative
    log-likelihood ``½ (e0ᵀ S⁻¹ e0 + log det S + m log 2π)`` (0 without rows; inf if ``S`` is singular).
    """
    for j in range(6):
        dx[j] = 0.0
    if m == 0:
        return 0.0
    Hm = np.ascontiguousarray(H[:m])
    PH = P @ np.ascontiguousarray(Hm.T)
    S = Hm @ PH
    for a in range(m):
        S[a, a] += r2[a]
    L = np.linalg.cholesky(S)
    logdet = 0.0
    for a in range(m):
        logdet += 2.0 * math.log(L[a, a])
    K = np.linalg.solve(S, np.ascontiguousarray(PH.T))  # (m, 6) = S⁻¹ H P
    y = np.linalg.solve(S, np.ascontiguousarray(e0[:m]))
    quad = 0.0
    for a in range(m):
        quad += e0[a] * y[a]
    for j in range(6):
        v = 0.0
        for a in range(m):
            v -= PH[j, a] * y[a]
        dx[j] = v
    P -= PH @ K
    for a in range(6):
        for b in range(a + 1, 6):
            v = 0.5 * (P[a, b] + P[b, a])
            P[a, b] = v
            P[b, a] = v
    return 0.5 * (quad + logdet + m * _LOG_2PI)


@njit(cache=True, boundscheck=False)
def ekf_pass(U, T0, K, Sigma_t, Sigma_r, A_inv, d_t, d_r, laser, Ms, r2, q2, ds, pts, lever, h_t, h_r,
             out_T, out_P):
    """The linearised filter over one episode; returns the lasers' negative log-likelihood (sum over steps).

    Per step ``k``: the mean moves with ``U[k]`` (the modelled motion, identity at ``k = 0`` where it starts at
    ``T0``), ``P`` gets ``diag(q2 ds[k])`` (``ds`` the program's travel of the step, mm) capped at the robot plateau of the step (:func:`plateau_cov` of
    ``Sigma_t, Sigma_r, A_inv (T, 3, 3)``, ``d_t, d_r (T,)``; ``P`` starts there), the readings ``laser (T, S, 2)``
    (NaN: none) with effective mounts ``Ms (T, S, 4, 4)`` and variances ``r2 (S, 2)`` are searched on the knots
    ``pts (K, 3)`` about the kinematic pose ``K[k]`` as far as the plateau reaches (plus ``d_r`` times the
    sensor's ``lever (S,)``), and the mean is corrected by :func:`kalman_update`. Writes ``out_T (T, 4, 4)`` and
    the diagonal ``out_P (T, 6)``.
    """
    n = U.shape[0]
    S = laser.shape[1]
    P = np.zeros((6, 6))
    C = np.empty((6, 6))
    Z = np.zeros((6, 6))
    T = T0.copy()
    Tn = np.empty((4, 4))
    H = np.empty((2 * S, 6))
    e0 = np.empty(2 * S)
    rr = np.empty(2 * S)
    dx = np.empty(6)
    mx = np.empty(S)
    mz = np.empty(S)
    lo = np.empty(S, dtype=np.int64)
    hi = np.empty(S, dtype=np.int64)
    q2k = np.empty(6)
    nll = 0.0
    for k in range(n):
        if k > 0:
            Tn[:, :] = U[k] @ T
            T[:, :] = Tn
        plateau_cov(T, Sigma_t[k], Sigma_r[k], A_inv[k], d_t[k], d_r[k], C)
        for j in range(6):
            q2k[j] = q2[j] * ds[k]
        predict_capped(P, C, k == 0, q2k, Z)
        tr = Sigma_t[k, 0, 0] + Sigma_t[k, 1, 1] + Sigma_t[k, 2, 2]
        reach = d_t[k] + 3.0 * math.sqrt(max(tr, 0.0))
        for i in range(S):
            mx[i] = laser[k, i, 0]
            mz[i] = laser[k, i, 1]
            lo[i] = -1
            hi[i] = -1
            if not (math.isfinite(mx[i]) and math.isfinite(mz[i])):
                continue
            Sp = K[k] @ Ms[k, i]
            cx = Sp[0, 3] + Sp[0, 0] * mx[i] + Sp[0, 2] * mz[i]
            cy = Sp[1, 3] + Sp[1, 0] * mx[i] + Sp[1, 2] * mz[i]
            cz = Sp[2, 3] + Sp[2, 0] * mx[i] + Sp[2, 2] * mz[i]
            rad = reach + d_r[k] * lever[i]
            a, b = window_kernel(pts, cx, cy, cz, Sp[0, 1], Sp[1, 1], Sp[2, 1], rad, 10.0 * rad + 50.0)
            lo[i] = a
            hi[i] = b
        m = laser_rows(T, mx, mz, Ms[k], lo, hi, pts, r2, h_t, h_r, H, e0, rr)
        nll += kalman_update(P, H, e0, rr, m, dx)
        exp_right(T, dx, Tn)
        T[:, :] = Tn
        out_T[k] = T
        for j in range(6):
            out_P[k, j] = P[j, j]
    return nll
