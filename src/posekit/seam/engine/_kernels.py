"""Compiled per-particle kernels of the seam particle filter's densities (numba, cached on disk).

NumPy needs ~7 ms per filter step at N = 1,000 on a loaded 2-core machine: the per-particle
4×4 products, Rodrigues' formula, rotation logarithms and the laser-plane search are dozens of
small array operations each. One compiled pass per density brings the step under 1 ms. Each
kernel is cross-checked in the tests against an independent NumPy/geometry computation. The particle cloud's
statistics (mean, spread, resampling move, innovation moments) are in :mod:`posekit.seam.engine._cloud_kernels`.

Particles are ``T (N, 4, 4)`` rigid transforms (mm, rad); every kernel writes into ``out``.
"""

import math

import numpy as np

from posekit._jit import njit
from posekit.geometry import rotvec_from_entries

__all__ = [
    "inv_det3",
    "laser_error_kernel",
    "laser_loglik_kernel",
    "local_level_nll",
    "propagate",
    "relative_offset_kernel",
    "robot_consistency_kernel",
    "robot_loglik_kernel",
    "so3_exp_coefficients",
    "window_kernel",
]


@njit(cache=True, inline="always")
def so3_exp_coefficients(th2):
    """Rodrigues' coefficients ``(sin θ / θ, (1 - cos θ) / θ²)`` of a rotation vector with ``θ² = th2`` (rad²):
    ``exp([w]x) = I + a [w]x + b [w]x²`` (a series to θ⁴ below 0.01 rad: truncation < 1e-16)."""
    if th2 < 1e-4:
        return 1.0 - th2 / 6.0 * (1.0 - th2 / 20.0), 0.5 - th2 / 24.0 * (1.0 - th2 / 30.0)
    th = math.sqrt(th2)
    return math.sin(th) / th, (1.0 - math.cos(th)) / th2


@njit(cache=True, boundscheck=False)
def propagate(T, A, z_, sig, out):
    """``out_i = A @ T_i @ exp(xi_i)``, ``xi_i = sig * z_i`` per axis (standard normal ``z_``,
    ``sig (6,)`` the widths x, y, z (mm), rx, ry, rz (rad)); exp by Rodrigues, translation part
    ``rho`` (small noise).

    T (N, 4, 4), A (4, 4), z_ (N, 6) (float32 or float64), sig (6,), out (N, 4, 4).
    """
    n = T.shape[0]
    M = np.empty((3, 3))
    E = np.empty((3, 3))
    for i in range(n):
        # M = A @ T_i (rotation and translation)
        for r in range(3):
            for c in range(3):
                M[r, c] = A[r, 0] * T[i, 0, c] + A[r, 1] * T[i, 1, c] + A[r, 2] * T[i, 2, c]
        t0 = A[0, 0] * T[i, 0, 3] + A[0, 1] * T[i, 1, 3] + A[0, 2] * T[i, 2, 3] + A[0, 3]
        t1 = A[1, 0] * T[i, 0, 3] + A[1, 1] * T[i, 1, 3] + A[1, 2] * T[i, 2, 3] + A[1, 3]
        t2 = A[2, 0] * T[i, 0, 3] + A[2, 1] * T[i, 1, 3] + A[2, 2] * T[i, 2, 3] + A[2, 3]
        # E = exp(hat(phi))
        x, y, z = sig[3] * z_[i, 3], sig[4] * z_[i, 4], sig[5] * z_[i, 5]
        a, b = so3_exp_coefficients(x * x + y * y + z * z)
        E[0, 0] = 1.0 - b * (y * y + z * z)
        E[1, 1] = 1.0 - b * (x * x + z * z)
        E[2, 2] = 1.0 - b * (x * x + y * y)
        E[0, 1] = b * x * y - a * z
        E[1, 0] = b * x * y + a * z
        E[0, 2] = b * x * z + a * y
        E[2, 0] = b * x * z - a * y
        E[1, 2] = b * y * z - a * x
        E[2, 1] = b * y * z + a * x
        rx, ry, rz = sig[0] * z_[i, 0], sig[1] * z_[i, 1], sig[2] * z_[i, 2]
        for r in range(3):
            for c in range(3):
                out[i, r, c] = M[r, 0] * E[0, c] + M[r, 1] * E[1, c] + M[r, 2] * E[2, c]
        out[i, 0, 3] = t0 + M[0, 0] * rx + M[0, 1] * ry + M[0, 2] * rz
        out[i, 1, 3] = t1 + M[1, 0] * rx + M[1, 1] * ry + M[1, 2] * rz
        out[i, 2, 3] = t2 + M[2, 0] * rx + M[2, 1] * ry + M[2, 2] * rz
        out[i, 3, 0] = 0.0
        out[i, 3, 1] = 0.0
        out[i, 3, 2] = 0.0
        out[i, 3, 3] = 1.0


@njit(cache=True, inline="always")
def _plateau_maha(x, y, z, d, Sinv):
    """``δᵀ Sinv δ`` with ``δ = (1 - d/‖Δ‖)₊ Δ`` for ``Δ = (x, y, z)``: 0 inside the plateau of radius d."""
    r = math.sqrt(x * x + y * y + z * z)
    if not r > d:
        return 0.0
    k = 1.0 - d / r
    x *= k
    y *= k
    z *= k
    return (x * (Sinv[0, 0] * x + Sinv[0, 1] * y + Sinv[0, 2] * z)
            + y * (Sinv[1, 0] * x + Sinv[1, 1] * y + Sinv[1, 2] * z)
            + z * (Sinv[2, 0] * x + Sinv[2, 1] * y + Sinv[2, 2] * z))


@njit(cache=True, boundscheck=False)
def robot_loglik_kernel(T, mu, Sinv_t, Sinv_r, A_r, d_t, d_r, logD, out):
    """Eq. (8) in two 3-D blocks: ``Δt = p_i - p_μ``, ``Δr = log(R_i R_μᵀ)`` (base frame).

    ``out_i += logD - ½ (δtᵀ Sinv_t δt + δrᵀ Sinv_r δr)`` with ``δ = (1 - d/‖Δ‖)₊ Δ``; the
    rotation error enters as ``A_r Δr`` (an ellipsoidal plateau; ``Sinv_r`` is for ``A_r Δr``).
    """
    n = T.shape[0]
    q = np.empty(9)
    for i in range(n):
        mt = _plateau_maha(T[i, 0, 3] - mu[0, 3], T[i, 1, 3] - mu[1, 3], T[i, 2, 3] - mu[2, 3], d_t, Sinv_t)
        # R_i R_mu^T
        for a in range(3):
            for b in range(3):
                q[3 * a + b] = T[i, a, 0] * mu[b, 0] + T[i, a, 1] * mu[b, 1] + T[i, a, 2] * mu[b, 2]
        ex, ey, ez = rotvec_from_entries(q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7], q[8])
        ax = A_r[0, 0] * ex + A_r[0, 1] * ey + A_r[0, 2] * ez
        ay = A_r[1, 0] * ex + A_r[1, 1] * ey + A_r[1, 2] * ez
        az = A_r[2, 0] * ex + A_r[2, 1] * ey + A_r[2, 2] * ez
        out[i] += logD - 0.5 * (mt + _plateau_maha(ax, ay, az, d_r, Sinv_r))


@njit(cache=True, inline="always")
def _plane_error(T, i, mx, mz, M, P, lo, hi):
    """In-plane error ``(found, ex_S, ez_S)`` of particle ``i`` for one laser reading ``(mx, mz)``.

    THE SENSOR POSE ENTERS HERE (and only here): ``M (4, 4)`` is ``T_tool_sensor`` (mm), the
    laser plane being the sensor's x–z plane. The sensor frame of particle ``i`` is
    ``T_i M``: ``R_S = R_i M_R``, origin ``p_i + R_i M_t``; ``m̂ = origin + R_S [mx, 0, mz]``;
    the plane's normal is ``R_S[:, 1]``; ``pi`` its crossing with the polyline ``P[lo..hi]``
    (bisection when the range's ends lie on opposite sides, else the crossing nearest ``m̂``
    by a scan); the error ``m̂ - pi`` is returned in the sensor's x and z axes. No crossing:
    ``found`` False.
    """
    # sensor axes x_S, y_S (normal), z_S and the seam point m-hat the particle believes it saw
    sx0 = T[i, 0, 0] * M[0, 0] + T[i, 0, 1] * M[1, 0] + T[i, 0, 2] * M[2, 0]
    sx1 = T[i, 1, 0] * M[0, 0] + T[i, 1, 1] * M[1, 0] + T[i, 1, 2] * M[2, 0]
    sx2 = T[i, 2, 0] * M[0, 0] + T[i, 2, 1] * M[1, 0] + T[i, 2, 2] * M[2, 0]
    nx = T[i, 0, 0] * M[0, 1] + T[i, 0, 1] * M[1, 1] + T[i, 0, 2] * M[2, 1]
    ny = T[i, 1, 0] * M[0, 1] + T[i, 1, 1] * M[1, 1] + T[i, 1, 2] * M[2, 1]
    nz = T[i, 2, 0] * M[0, 1] + T[i, 2, 1] * M[1, 1] + T[i, 2, 2] * M[2, 1]
    sz0 = T[i, 0, 0] * M[0, 2] + T[i, 0, 1] * M[1, 2] + T[i, 0, 2] * M[2, 2]
    sz1 = T[i, 1, 0] * M[0, 2] + T[i, 1, 1] * M[1, 2] + T[i, 1, 2] * M[2, 2]
    sz2 = T[i, 2, 0] * M[0, 2] + T[i, 2, 1] * M[1, 2] + T[i, 2, 2] * M[2, 2]
    ox = T[i, 0, 3] + T[i, 0, 0] * M[0, 3] + T[i, 0, 1] * M[1, 3] + T[i, 0, 2] * M[2, 3] + sx0 * mx + sz0 * mz
    oy = T[i, 1, 3] + T[i, 1, 0] * M[0, 3] + T[i, 1, 1] * M[1, 3] + T[i, 1, 2] * M[2, 3] + sx1 * mx + sz1 * mz
    oz = T[i, 2, 3] + T[i, 2, 0] * M[0, 3] + T[i, 2, 1] * M[1, 3] + T[i, 2, 2] * M[2, 3] + sx2 * mx + sz2 * mz
    best = math.inf
    bx = 0.0
    bz = 0.0
    s_lo = nx * (P[lo, 0] - ox) + ny * (P[lo, 1] - oy) + nz * (P[lo, 2] - oz)
    s_hi = nx * (P[hi, 0] - ox) + ny * (P[hi, 1] - oy) + nz * (P[hi, 2] - oz)
    if s_lo < 0.0 < s_hi or s_hi < 0.0 < s_lo:
        # one sign change between the ends: bisect to a crossing segment (the seam
        # advances through the plane; a fold-back within the window is not searched)
        a, b, sa = lo, hi, s_lo
        while b - a > 1:
            m = (a + b) // 2
            sm = nx * (P[m, 0] - ox) + ny * (P[m, 1] - oy) + nz * (P[m, 2] - oz)
            if (sm < 0.0) == (sa < 0.0):
                a, sa = m, sm
            else:
                b = m
        k0, k1 = a, b
        sb = nx * (P[k1, 0] - ox) + ny * (P[k1, 1] - oy) + nz * (P[k1, 2] - oz)
        g = sa / (sa - sb)
        ex = ox - (P[k0, 0] + g * (P[k1, 0] - P[k0, 0]))
        ey = oy - (P[k0, 1] + g * (P[k1, 1] - P[k0, 1]))
        ez = oz - (P[k0, 2] + g * (P[k1, 2] - P[k0, 2]))
        best = 0.0
        bx = ex * sx0 + ey * sx1 + ez * sx2
        bz = ex * sz0 + ey * sz1 + ez * sz2
    else:
        # no or several crossings: scan every segment, keep the crossing nearest m-hat
        s_prev = s_lo
        for k in range(lo + 1, hi + 1):
            s = nx * (P[k, 0] - ox) + ny * (P[k, 1] - oy) + nz * (P[k, 2] - oz)
            if s_prev * s <= 0.0 and s != s_prev:
                g = s_prev / (s_prev - s)
                ex = ox - (P[k - 1, 0] + g * (P[k, 0] - P[k - 1, 0]))
                ey = oy - (P[k - 1, 1] + g * (P[k, 1] - P[k - 1, 1]))
                ez = oz - (P[k - 1, 2] + g * (P[k, 2] - P[k - 1, 2]))
                d2 = ex * ex + ey * ey + ez * ez
                if d2 < best:
                    best = d2
                    bx = ex * sx0 + ey * sx1 + ez * sx2
                    bz = ex * sz0 + ey * sz1 + ez * sz2
            s_prev = s
    return best < math.inf, bx, bz


@njit(cache=True, boundscheck=False)
def laser_loglik_kernel(T, mx, mz, dist, P, lo, hi, sigma, miss, out):
    """Eq. (9) for one sensor: ``out_i += log N(e; 0, σ² I₂)``, ``e = m̂ - pi`` in the laser plane.

    The sensor sits ``dist`` ahead of the TCP along tool y, axes parallel to the tool's
    (``T_tool_sensor`` = translation ``[0, dist, 0]``; any mount: :func:`laser_error_kernel`).
    ``m̂ = p_i + R_i [mx, dist, mz]``; the plane has normal ``R_i[:, 1]``; ``pi`` is its
    crossing with the polyline ``P[lo..hi]`` (knots, mm), see :func:`_plane_error`.
    No crossing: error ``miss`` (mm).
    """
    n = T.shape[0]
    inv = 0.5 / (sigma * sigma)
    const = -math.log(2.0 * math.pi * sigma * sigma)
    M = np.eye(4)
    M[1, 3] = dist
    for i in range(n):
        found, bx, bz = _plane_error(T, i, mx, mz, M, P, lo, hi)
        if found:
            out[i] += const - inv * (bx * bx + bz * bz)
        else:
            out[i] += const - inv * miss * miss


@njit(cache=True, boundscheck=False)
def laser_error_kernel(T, mx, mz, M, P, lo, hi, err):
    """In-plane errors ``e = m̂ - pi`` of every particle for one laser reading (eq. 9, Fig. 4).

    T (N, 4, 4) particles ``T_base_tool``; ``(mx, mz)`` the reading in the sensor frame (mm);
    M (4, 4) the sensor mount ``T_tool_sensor`` (mm); P (K, 3) the seam knots, searched in
    ``P[lo..hi]``. Writes ``err (N, 2)`` (mm, sensor x and z); NaN where the particle's laser
    plane meets no segment. Returns the number of particles with a crossing.
    """
    n = T.shape[0]
    found_n = 0
    for i in range(n):
        found, bx, bz = _plane_error(T, i, mx, mz, M, P, lo, hi)
        if found:
            err[i, 0] = bx
            err[i, 1] = bz
            found_n += 1
        else:
            err[i, 0] = math.nan
            err[i, 1] = math.nan
    return found_n


@njit(cache=True, boundscheck=False)
def interp_columns(x, xp, fp, out):
    """``out[j] = numpy.interp(x, xp, fp[:, j])`` for every column of ``fp (n, J)``, with NumPy's own arithmetic
    (the same result to the bit): ``x`` finite, ``xp (n,)`` non-decreasing, ``n >= 2``. Returns False, leaving
    ``out`` unset, where ``xp`` decreases somewhere (the caller then asks NumPy)."""
    n = xp.shape[0]
    for k in range(1, n):
        if xp[k] < xp[k - 1]:
            return False
    J = fp.shape[1]
    if x > xp[n - 1]:
        j = n - 1                      # NumPy's right value: fp[-1]
    elif x < xp[0]:
        j = 0                          # its left value: fp[0]
    else:
        lo, hi = 0, n - 1              # the j with xp[j] <= x < xp[j + 1] (n - 1 where x == xp[-1])
        if x >= xp[n - 1]:
            lo = n - 1
        while hi - lo > 1:
            mid = (lo + hi) // 2
            if xp[mid] <= x:
                lo = mid
            else:
                hi = mid
        j = lo
        if j < n - 1 and xp[j] != x:
            for c in range(J):
                slope = (fp[j + 1, c] - fp[j, c]) / (xp[j + 1] - xp[j])
                r = slope * (x - xp[j]) + fp[j, c]
                if math.isnan(r):
                    r = slope * (x - xp[j + 1]) + fp[j + 1, c]
                    if math.isnan(r) and fp[j, c] == fp[j + 1, c]:
                        r = fp[j, c]
                out[c] = r
            return True
    for c in range(J):
        out[c] = fp[j, c]
    return True


@njit(cache=True, boundscheck=False)
def sensor_axes_levers(M, axes, lever):
    """For mounts ``M (S, 4, 4)``: ``axes[s] = [x axis, z axis]`` of sensor ``s`` (tool frame) and ``lever[s, k] =
    p_s × axes[s, k]`` with ``p_s`` its origin (mm), in ``numpy.cross``'s order of operations (the same bits)."""
    for s in range(M.shape[0]):
        p0, p1, p2 = M[s, 0, 3], M[s, 1, 3], M[s, 2, 3]
        for k in range(2):
            c = 2 * k
            b0, b1, b2 = M[s, 0, c], M[s, 1, c], M[s, 2, c]
            axes[s, k, 0], axes[s, k, 1], axes[s, k, 2] = b0, b1, b2
            lever[s, k, 0] = p1 * b2 - p2 * b1
            lever[s, k, 1] = p2 * b0 - p0 * b2
            lever[s, k, 2] = p0 * b1 - p1 * b0


@njit(cache=True, boundscheck=False)
def window_kernel(P, px, py, pz, nx, ny, nz, window, reach):
    """Knot range ``(lo, hi)`` of the polyline ``P (K, 3)`` around a plane through ``p`` with
    normal ``n``: the first and last segment reaching within ``window`` of the plane and
    within ``reach`` of ``p`` (the segment's nearest point, not its ends: a long straight segment
    passing close counts); ``(-1, -1)`` when none does."""
    lo = -1
    hi = -1
    k_n = P.shape[0]
    s_prev = nx * (P[0, 0] - px) + ny * (P[0, 1] - py) + nz * (P[0, 2] - pz)
    for k in range(1, k_n):
        s = nx * (P[k, 0] - px) + ny * (P[k, 1] - py) + nz * (P[k, 2] - pz)
        if min(s, s_prev) <= window and max(s, s_prev) >= -window:
            # distance of p from the segment P[k-1] .. P[k]
            vx, vy, vz = P[k, 0] - P[k - 1, 0], P[k, 1] - P[k - 1, 1], P[k, 2] - P[k - 1, 2]
            wx, wy, wz = px - P[k - 1, 0], py - P[k - 1, 1], pz - P[k - 1, 2]
            vv = vx * vx + vy * vy + vz * vz
            g = (wx * vx + wy * vy + wz * vz) / vv if vv > 0.0 else 0.0
            g = min(max(g, 0.0), 1.0)
            dx, dy, dz = wx - g * vx, wy - g * vy, wz - g * vz
            if math.sqrt(dx * dx + dy * dy + dz * dz) <= reach:
                if lo < 0:
                    lo = k - 1
                hi = k
        s_prev = s
    return lo, hi


@njit(cache=True)
def inv_det3(S):
    """Inverse and determinant of a 3×3 matrix by cofactors: ``(S⁻¹ (3, 3), det S)``."""
    a, b, c = S[0, 0], S[0, 1], S[0, 2]
    d, e, f = S[1, 0], S[1, 1], S[1, 2]
    g, h, i = S[2, 0], S[2, 1], S[2, 2]
    A, B, C = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * A + b * B + c * C
    inv = np.empty((3, 3))
    inv[0, 0], inv[1, 0], inv[2, 0] = A / det, B / det, C / det
    inv[0, 1], inv[1, 1], inv[2, 1] = (c * h - b * i) / det, (a * i - c * g) / det, (b * g - a * h) / det
    inv[0, 2], inv[1, 2], inv[2, 2] = (b * f - c * e) / det, (c * d - a * f) / det, (a * e - b * d) / det
    return inv, det


@njit(cache=True, boundscheck=False)
def _shrunk_maha_cov(x, y, z, d, S):
    """``δᵀ S⁻¹ δ`` for ``δ = (1 - d/‖Δ‖)₊ Δ``, ``Δ = (x, y, z)``; ``S (3, 3)`` SPD (inf if singular)."""
    r = math.sqrt(x * x + y * y + z * z)
    if not r > d:
        return 0.0
    Sinv, det = inv_det3(S)
    if not det > 0.0:
        return math.inf
    return _plateau_maha(x, y, z, d, Sinv)


@njit(cache=True, boundscheck=False)
def robot_consistency_kernel(T, spread, mu, Sigma_t, Sigma_r, A, d_t, d_r):
    """Mahalanobis distances ``(m_t, m_r)`` of the pose ``T (4, 4)`` from the robot measurement
    mean ``mu (4, 4)`` outside its plateau (eq. 8), with the pose's own spread ``spread (6,)``
    (its frame; rotated into the base frame) added to ``Sigma_t`` / ``Sigma_r`` (3, 3). The
    rotation error ``log(R Rμᵀ)`` enters as ``A Δr`` with covariance ``A (Σr + P) Aᵀ``."""
    P = np.empty((3, 3))
    S = np.empty((3, 3))
    for a in range(3):
        for b in range(3):
            v = 0.0
            for c in range(3):
                v += T[a, c] * T[b, c] * spread[c] * spread[c]
            S[a, b] = Sigma_t[a, b] + v
    m_t = _shrunk_maha_cov(T[0, 3] - mu[0, 3], T[1, 3] - mu[1, 3], T[2, 3] - mu[2, 3], d_t, S)
    q = np.empty(9)
    for a in range(3):
        for b in range(3):
            q[3 * a + b] = T[a, 0] * mu[b, 0] + T[a, 1] * mu[b, 1] + T[a, 2] * mu[b, 2]
    ex, ey, ez = rotvec_from_entries(q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7], q[8])
    for a in range(3):
        for b in range(3):
            v = 0.0
            for c in range(3):
                v += T[a, c] * T[b, c] * spread[3 + c] * spread[3 + c]
            P[a, b] = Sigma_r[a, b] + v
    for a in range(3):  # S = A P Aᵀ
        for b in range(3):
            v = 0.0
            for c in range(3):
                for e in range(3):
                    v += A[a, c] * P[c, e] * A[b, e]
            S[a, b] = v
    ax = A[0, 0] * ex + A[0, 1] * ey + A[0, 2] * ez
    ay = A[1, 0] * ex + A[1, 1] * ey + A[1, 2] * ez
    az = A[2, 0] * ex + A[2, 1] * ey + A[2, 2] * ez
    return m_t, _shrunk_maha_cov(ax, ay, az, d_r, S)


@njit(cache=True, boundscheck=False)
def local_level_nll(y, ds, q2, r2):
    """Negative log-likelihood of a scalar series ``y (T,)`` under the local-level model ``y_k = s_k + v``,
    ``s_k = s_{k-1} + w``, ``v ~ N(0, r2)``, ``w ~ N(0, q2 ds_k)`` (``ds (T,)`` the travel per step, the first
    ignored), by its
    Kalman filter started at the first sample (the first term is left out: a diffuse start)."""
    n = y.shape[0]
    if n < 2:
        return 0.0
    s = y[0]
    P = r2
    out = 0.0
    for k in range(1, n):
        P += q2 * ds[k]
        S = P + r2
        v = y[k] - s
        out += 0.5 * (v * v / S + math.log(2.0 * math.pi * S))
        g = P / S
        s += g * v
        P *= 1.0 - g
    return out


@njit(cache=True, boundscheck=False)
def relative_offset_kernel(T, K, out):
    """``out[i] (6,)``: the pose ``T[i] (4, 4)`` relative to ``K[i] (4, 4)`` in ``K[i]``'s frame, ``R_Kᵀ (p_T -
    p_K)`` and the rotation vector of ``R_Kᵀ R_T`` (the integrity monitor's offset test); ``T, K (m, 4, 4)``,
    ``out (m, 6)``."""
    q = np.empty(9)
    for i in range(T.shape[0]):
        for a in range(3):
            out[i, a] = (K[i, 0, a] * (T[i, 0, 3] - K[i, 0, 3]) + K[i, 1, a] * (T[i, 1, 3] - K[i, 1, 3])
                         + K[i, 2, a] * (T[i, 2, 3] - K[i, 2, 3]))
        for a in range(3):
            for b in range(3):
                q[3 * a + b] = K[i, 0, a] * T[i, 0, b] + K[i, 1, a] * T[i, 1, b] + K[i, 2, a] * T[i, 2, b]
        out[i, 3], out[i, 4], out[i, 5] = rotvec_from_entries(q[0], q[1], q[2], q[3], q[4], q[5], q[6], q[7], q[8])
