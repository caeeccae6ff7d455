"""The fits of one face in the model-based corner detector, and the corners' covariance from them.

Compiled building blocks of :func:`~posekit.profiler.estimate.faces.model_kernel`: a total
least-squares line of the returns inside a gate (:func:`gated_fit`), a consensus line of a face
that clutter contaminates (:func:`consensus_line`), the test of whether the returns past a
ridge band still lean to one side of the line (:func:`edge_leans`), and the corners' joint
covariance from the fits plus the declared face tilt and sensor scale (:func:`corner_covariance`).
Lines are ``(nx, nz, c)`` with ``nx x + nz z = c`` in the profiler frame F, mm.
"""

import numpy as np

from posekit._jit import njit

from ...geometry._fit import FASTMATH

__all__ = ["gated_fit", "consensus_line", "edge_leans", "corner_jacobian_rows", "corner_covariance"]


_RUN = 10          # returns per test of the band's edge


_CHUNKS = 8        # stretches of a contaminated face voting for its line


_RUN_Z = 4.0       # a run whose mean residual is this many standard errors off leans


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def gated_fit(xs, zs, a, b, nx, nz, c, dx, dz, t_lo, t_hi, gate):
    """TLS line of points a <= i < b with ``t_lo <= t <= t_hi`` along (dx, dz) and ``|r| <= gate``.

    Returns ``(n, mx, mz, cxx, cxz, czz, n_range)``: count, centroid and central moments,
    and the number of points in the t range whatever their residual.
    """
    rx = xs[a]
    rz = zs[a]
    n_range = 0.0
    sw = 0.0
    sx = 0.0
    sz = 0.0
    sxx = 0.0
    sxz = 0.0
    szz = 0.0
    for i in range(a, b):
        x = xs[i]
        z = zs[i]
        t = dx * x + dz * z
        r = nx * x + nz * z - c
        in_range = 1.0 if (t >= t_lo and t <= t_hi) else 0.0
        w = in_range if abs(r) <= gate else 0.0
        n_range += in_range
        x -= rx
        z -= rz
        sw += w
        sx += w * x
        sz += w * z
        sxx += w * x * x
        sxz += w * x * z
        szz += w * z * z
    if sw < 2.0:
        return sw, 0.0, 0.0, 0.0, 0.0, 0.0, n_range
    mx = sx / sw
    mz = sz / sw
    return sw, mx + rx, mz + rz, max(sxx - sx * mx, 0.0), sxz - sx * mz, max(szz - sz * mz, 0.0), n_range


@njit(cache=True, nogil=True)
def consensus_line(xs, zs, a, b, dx, dz, t_lo, t_hi, gate, lean):
    """A line that most returns of a contaminated face agree with.

    The returns with ``t_lo <= t <= t_hi`` fall into _CHUNKS equal stretches of t; the line
    through the centroids of each pair of stretches is scored by the returns within
    ``gate`` of it; the best (ties: the pair farthest apart) wins. ``lean`` (-1, 0, +1)
    weights the returns from 0.5 at one end to 1.5 at the other: +1 trusts the end at
    ``t_hi`` more (multipath sits beside valleys, so the end away from a valley is the
    cleaner one). Returns ``(ok, nx, nz, c)``.
    """
    Q = _CHUNKS
    cnt = np.zeros(Q)
    sx = np.zeros(Q)
    sz = np.zeros(Q)
    span = max(t_hi - t_lo, 1e-9)
    for i in range(a, b):
        t = dx * xs[i] + dz * zs[i]
        if t >= t_lo and t <= t_hi:
            q = min(int((t - t_lo) / span * Q), Q - 1)
            cnt[q] += 1.0
            sx[q] += xs[i]
            sz[q] += zs[i]
    best = -1.0
    best_sep = -1
    bnx = 0.0
    bnz = 0.0
    bc = 0.0
    for q1 in range(Q):
        if cnt[q1] < 2.0:
            continue
        for q2 in range(q1 + 1, Q):
            if cnt[q2] < 2.0:
                continue
            x1 = sx[q1] / cnt[q1]
            z1 = sz[q1] / cnt[q1]
            ux = sx[q2] / cnt[q2] - x1
            uz = sz[q2] / cnt[q2] - z1
            ln = np.sqrt(ux * ux + uz * uz)
            if ln <= 0.0:
                continue
            nx = -uz / ln
            nz = ux / ln
            c = nx * x1 + nz * z1
            score = 0.0
            for i in range(a, b):
                t = dx * xs[i] + dz * zs[i]
                if t >= t_lo and t <= t_hi and abs(nx * xs[i] + nz * zs[i] - c) <= gate:
                    score += 1.0 + lean * ((t - t_lo) / span - 0.5)
            if score > best or (score == best and q2 - q1 > best_sep):
                best = score
                best_sep = q2 - q1
                bnx = nx
                bnz = nz
                bc = c
    if best < 2.0:
        return False, 0.0, 0.0, 0.0
    if bnx * (-dz) + bnz * dx < 0.0:
        bnx = -bnx
        bnz = -bnz
        bc = -bc
    return True, bnx, bnz, bc


@njit(cache=True, nogil=True)
def edge_leans(xs, zs, a, b, step, nx, nz, c, dx, dz, t_edge, sigma, t_far):
    """Whether the first _RUN returns past ``t_edge`` (walking from index a towards b by
    ``step``, away from the ridge) lean to one side of the line; and the t of the last one.

    Returns ``(leans, t_last)``. Only returns with t between t_edge and t_far count;
    residuals are clipped at 8σ so a single spike cannot make a run lean.
    """
    acc = 0.0
    cnt = 0
    t_last = t_edge
    i = a
    while i != b and cnt < _RUN:
        x = xs[i]
        z = zs[i]
        t = dx * x + dz * z
        if step < 0:
            inside = t <= t_edge and t >= t_far
        else:
            inside = t >= t_edge and t <= t_far
        if inside:
            r = nx * x + nz * z - c
            r = min(max(r, -8.0 * sigma), 8.0 * sigma)
            acc += r
            cnt += 1
            t_last = t
        i += step
    if cnt < _RUN:
        return False, t_last
    return abs(acc / cnt) > _RUN_Z * sigma / np.sqrt(cnt), t_last


@njit(cache=True, nogil=True, inline="always")
def corner_jacobian_rows(G, k, px, pz, cent, ax, az, bx, bz, det):
    """Rows 2k, 2k+1 of the corner Jacobian ``G``: how corner k = (px, pz), the crossing of
    lines k (normal (ax, az)) and k+1 (normal (bx, bz), ``det`` their determinant), moves with
    each line's offset and its turn about its centroid ``cent[j, :2]``."""
    ta = (px - cent[k, 0]) * az - (pz - cent[k, 1]) * ax          # direction of a line = (nz, -nx)
    tb = (px - cent[k + 1, 0]) * bz - (pz - cent[k + 1, 1]) * bx
    i00 = bz / det                                                 # N_k⁻¹
    i01 = -az / det
    i10 = -bx / det
    i11 = ax / det
    G[2 * k, 2 * k] = i00
    G[2 * k, 2 * k + 1] = i00 * ta
    G[2 * k, 2 * k + 2] = i01
    G[2 * k, 2 * k + 3] = i01 * tb
    G[2 * k + 1, 2 * k] = i10
    G[2 * k + 1, 2 * k + 1] = i10 * ta
    G[2 * k + 1, 2 * k + 2] = i11
    G[2 * k + 1, 2 * k + 3] = i11 * tb


@njit(cache=True, nogil=True)
def corner_covariance(lines, cent, sig, npts, corners, var_tilt, var_scale, z_center):
    """Joint covariance (2n, 2n) of corners that intersect consecutive fitted lines.

    Line j's error is an offset δc_j (variance σ_j²/N_j) and a turn δθ_j about its
    centroid (σ_j²/S_tt + var_tilt: the face's own tilt); at a point τ along the line it
    moves the line by
    δc_j + τ δθ_j; corner k solves N_k δp = [δ_k, δ_k+1]. A sensor scale error s moves
    corner (x, z) by s (x, z - z_center) in each axis (variance var_scale each).
    Returns ``(ok, cov, k_bad)``.
    """
    n = corners.shape[0]
    cov = np.zeros((2 * n, 2 * n))
    G = np.zeros((2 * n, 2 * (n + 1)))
    for k in range(n):
        ax = lines[k, 0]
        az = lines[k, 1]
        bx = lines[k + 1, 0]
        bz = lines[k + 1, 1]
        det = ax * bz - az * bx
        if abs(det) < 1e-9:
            return False, cov, k
        px = corners[k, 0]
        pz = corners[k, 1]
        corner_jacobian_rows(G, k, px, pz, cent, ax, az, bx, bz, det)
    var = np.empty(2 * (n + 1))
    for j in range(n + 1):
        var[2 * j] = sig[j] ** 2 / npts[j]
        var[2 * j + 1] = sig[j] ** 2 / max(cent[j, 2], 1e-300) + var_tilt
    for a in range(2 * n):
        for b in range(a, 2 * n):
            acc = 0.0
            for cc in range(2 * (a // 2), 2 * (a // 2) + 4):
                acc += G[a, cc] * var[cc] * G[b, cc]
            if var_scale > 0.0:
                if a % 2 == 0 and b % 2 == 0:
                    acc += var_scale * corners[a // 2, 0] * corners[b // 2, 0]
                elif a % 2 == 1 and b % 2 == 1:
                    acc += var_scale * (corners[a // 2, 1] - z_center) * (corners[b // 2, 1] - z_center)
            cov[a, b] = acc
            cov[b, a] = acc
    return True, cov, -1
