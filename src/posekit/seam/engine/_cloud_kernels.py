"""Compiled kernels of the seam particle cloud's statistics (numba, cached on disk): the weighted mean pose on
SE(3) and the spread about it, the regularised resampling move, and the weighted moments of the lasers' innovations.

The densities' kernels are in :mod:`posekit.seam.engine._kernels`. Particles are ``T (N, 4, 4)`` rigid transforms
(mm, rad); each kernel is cross-checked in the tests against an independent NumPy/geometry computation.
"""

import math

import numpy as np

from posekit._jit import njit
from posekit.geometry import rotvec_from_entries
from posekit.seam.engine._kernels import inv_det3, so3_exp_coefficients

__all__ = [
    "cloud_kernel",
    "kernel_move",
    "mean_spread_kernel",
    "weighted_moments_kernel",
]


@njit(cache=True, boundscheck=False)
def _chordal_mean(T, w):
    """``T_mean (4, 4)``: ``p̄ = Σ w p``, ``R̄`` = the polar factor of ``Σ w R``."""
    n = T.shape[0]
    S = np.zeros((4, 4))
    for i in range(n):
        wi = w[i]
        for a in range(3):
            for b in range(4):
                S[a, b] += wi * T[i, a, b]
    # nearest rotation to Σ w R: the polar factor, by Newton's iteration X <- (X + X⁻ᵀ) / 2
    # (quadratic convergence; no LAPACK, which would cost seconds of compilation)
    R = S[:3, :3].copy()
    for _ in range(30):
        Xi, _det = inv_det3(R)
        change = 0.0
        for a in range(3):
            for b in range(3):
                v = 0.5 * (R[a, b] + Xi[b, a])
                change = max(change, abs(v - R[a, b]))
                R[a, b] = v
        if change < 1e-15:
            break
    Tm = np.eye(4)
    for a in range(3):
        for b in range(3):
            Tm[a, b] = R[a, b]
        Tm[a, 3] = S[a, 3]
    return Tm


@njit(cache=True, boundscheck=False)
def _offset(T, i, Tm, q, out):
    """Offset of particle ``i`` from the mean ``Tm`` in its frame: ``out (6,)`` =
    ``[R̄ᵀ (p_i - p̄), log(R̄ᵀ R_i)]`` (mm, rad); ``q (9,)`` is work space."""
    dx = T[i, 0, 3] - Tm[0, 3]
    dy = T[i, 1, 3] - Tm[1, 3]
    dz = T[i, 2, 3] - Tm[2, 3]
    for a in range(3):
        out[a] = Tm[0, a] * dx + Tm[1, a] * dy + Tm[2, a] * dz
        for b in range(3):
            q[3 * a + b] = Tm[0, a] * T[i, 0, b] + Tm[1, a] * T[i, 1, b] + Tm[2, a] * T[i, 2, b]
    out[3], out[4], out[5] = rotvec_from_entries(q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7], q[8])


@njit(cache=True, boundscheck=False)
def mean_spread_kernel(T, w):
    """Chordal weighted mean ``(T_mean (4, 4), spread (6,))`` of particles ``T (N, 4, 4)``.

    ``p̄ = Σ w p``, ``R̄`` = the rotation nearest ``Σ w R`` (its polar factor; the cloud must be
    narrower than 90°); the spread is the weighted
    standard deviation of ``[R̄ᵀ (p_i - p̄), log(R̄ᵀ R_i)]`` (mm, rad).
    """
    n = T.shape[0]
    Tm = _chordal_mean(T, w)
    m1 = np.zeros(6)
    m2 = np.zeros(6)
    q = np.empty(9)
    d = np.empty(6)
    for i in range(n):
        _offset(T, i, Tm, q, d)
        wi = w[i]
        for j in range(6):
            m1[j] += wi * d[j]
            m2[j] += wi * d[j] * d[j]
    spread = np.empty(6)
    for j in range(6):
        spread[j] = math.sqrt(max(m2[j] - m1[j] * m1[j], 0.0))
    return Tm, spread



@njit(cache=True, boundscheck=False)
def cloud_kernel(T, w, xi, L):
    """:func:`mean_spread_kernel` plus the offsets and the factor of their covariance.

    Returns ``(T_mean (4, 4), spread (6,), mu (6,))`` for particles ``T (N, 4, 4)`` and weights
    ``w (N,)``: the chordal mean, the weighted standard deviations and the weighted mean of the
    offsets; writes ``xi (N, 6)``, the offsets ``[R̄ᵀ (p_i - p̄), log(R̄ᵀ R_i)]`` (mm, rad; the
    inverse of :func:`kernel_move`), and ``L (6, 6)`` lower triangular with ``L Lᵀ`` = their
    weighted covariance (Cholesky, ridge 1e-9 of each variance).
    """
    n = T.shape[0]
    Tm = _chordal_mean(T, w)
    q = np.empty(9)
    mu = np.zeros(6)
    for i in range(n):
        _offset(T, i, Tm, q, xi[i])
        for j in range(6):
            mu[j] += w[i] * xi[i, j]
    C = np.zeros((6, 6))
    for i in range(n):
        for j in range(6):
            dj = w[i] * (xi[i, j] - mu[j])
            for k in range(j + 1):
                C[j, k] += dj * (xi[i, k] - mu[k])
    spread = np.empty(6)
    for j in range(6):
        spread[j] = math.sqrt(max(C[j, j], 0.0))
        C[j, j] = C[j, j] * (1.0 + 1e-9) + 1e-30
    for j in range(6):  # Cholesky, lower triangle of C
        for k in range(j + 1):
            v = C[j, k]
            for m in range(k):
                v -= L[j, m] * L[k, m]
            if j == k:
                L[j, j] = math.sqrt(max(v, 1e-30))
            else:
                L[j, k] = v / L[k, k]
        for k in range(j + 1, 6):
            L[j, k] = 0.0
    return Tm, spread, mu


@njit(cache=True, boundscheck=False)
def kernel_move(Tm, xi, idx, mu, a, B, z_, out):
    """Regularised resampling in the tangent space at ``Tm (4, 4)``:
    ``out_i = Tm exp(ξ'_i)`` with ``ξ'_i = a xi[idx_i] + (1 - a) mu + B z_i`` (translation part
    ``Tm`` rotation times ``ξ'[:3]``, the convention of :func:`cloud_kernel`).

    xi (N, 6), idx (N,) ancestors, mu (6,), B (6, 6), z_ (N, 6) standard normal, out (N, 4, 4).
    """
    n = out.shape[0]
    v = np.empty(6)
    for i in range(n):
        r = idx[i]
        for j in range(6):
            s = a * xi[r, j] + (1.0 - a) * mu[j]
            for k in range(6):
                s += B[j, k] * z_[i, k]
            v[j] = s
        x, y, z = v[3], v[4], v[5]
        c1, c2 = so3_exp_coefficients(x * x + y * y + z * z)
        e00 = 1.0 - c2 * (y * y + z * z)
        e11 = 1.0 - c2 * (x * x + z * z)
        e22 = 1.0 - c2 * (x * x + y * y)
        e01, e10 = c2 * x * y - c1 * z, c2 * x * y + c1 * z
        e02, e20 = c2 * x * z + c1 * y, c2 * x * z - c1 * y
        e12, e21 = c2 * y * z - c1 * x, c2 * y * z + c1 * x
        for rr in range(3):
            out[i, rr, 0] = Tm[rr, 0] * e00 + Tm[rr, 1] * e10 + Tm[rr, 2] * e20
            out[i, rr, 1] = Tm[rr, 0] * e01 + Tm[rr, 1] * e11 + Tm[rr, 2] * e21
            out[i, rr, 2] = Tm[rr, 0] * e02 + Tm[rr, 1] * e12 + Tm[rr, 2] * e22
            out[i, rr, 3] = Tm[rr, 3] + Tm[rr, 0] * v[0] + Tm[rr, 1] * v[1] + Tm[rr, 2] * v[2]
        out[i, 3, 0] = 0.0
        out[i, 3, 1] = 0.0
        out[i, 3, 2] = 0.0
        out[i, 3, 3] = 1.0


@njit(cache=True, inline="always")
def _row_finite(E, i):
    """Whether every entry of row ``i`` of ``E`` is finite."""
    for j in range(E.shape[1]):
        if not math.isfinite(E[i, j]):
            return False
    return True


@njit(cache=True, boundscheck=False)
def weighted_moments_kernel(E, w, mean, C):
    """Weighted mean and covariance of the rows of ``E (N, k)`` whose entries are all finite.

    ``w (N,)`` weights (renormalised over those rows); writes ``mean (k,)`` and ``C (k, k)``
    (``Σ w (e - ē)(e - ē)ᵀ``). Returns the total weight of the finite rows (0: none).
    """
    n, k = E.shape
    total = 0.0
    for j in range(k):
        mean[j] = 0.0
        for m in range(k):
            C[j, m] = 0.0
    for i in range(n):
        if _row_finite(E, i):
            total += w[i]
            for j in range(k):
                mean[j] += w[i] * E[i, j]
    if total <= 0.0:
        return 0.0
    for j in range(k):
        mean[j] /= total
    for i in range(n):
        if _row_finite(E, i):
            wi = w[i] / total
            for j in range(k):
                dj = wi * (E[i, j] - mean[j])
                for m in range(j + 1):
                    C[j, m] += dj * (E[i, m] - mean[m])
    for j in range(k):
        for m in range(j + 1, k):
            C[j, m] = C[m, j]
    return total
