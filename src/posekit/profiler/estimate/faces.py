"""Corners of a real profile from the gauge's faces: the compiled model-based detector.

:func:`model_kernel` runs, in one compiled call:

1. the segmentation and face assignment of :mod:`~posekit.profiler.estimate.segments`;
2. for each face, a window of returns from the end of the previous face's segment to the
   start of the next one's (for the outer faces: their own segment), and in it a robust
   orthogonal line fit that keeps only returns
   - within ``max(k_sigma σ, gate_floor_mm)`` of the face's line (ghost clusters, bumps,
     chamfers and the neighbouring faces are out), and
   - farther than a band from each ridge along the line (``band_mm``; the rounded or
     chamfered zone, and the triangulation's edge effects, are out). The band grows
     (up to ``max_band_mm``) while the first ten returns outside it still lean to one
     side of the line — a fillet larger than the band or a shallow multipath cluster;
3. corners as the intersections of neighbouring lines, re-fitted once with the bands
   placed at the new corners;
4. the corners' joint covariance from the fits, as the RDP detector's, plus declared
   systematic uncertainties: the as-built faces' tilt (a turn of each line, shared by its
   two corners) and the sensor's scale (common to all corners). The faces' offset
   tolerance is the gauge's own (``Gauge.tolerance_um``), added by the solver at the pose.
"""

import numpy as np

from posekit._jit import njit

from .face_fit import consensus_line, corner_covariance, edge_leans, gated_fit
from .segments import (
    BX,
    BZ,
    DX,
    DZ,
    EX,
    EZ,
    I0,
    I1,
    LEN,
    NX,
    NZ,
    RMS,
    C,
    _pair_geometry,
    assign_faces,
    clean_points,
    line_candidates,
    noise_sigma,
    segment_table,
    split_segments,
)

__all__ = ["model_kernel", "N_PARAMS"]

OK = 0
NO_POINTS = 1
MISSING = 2
SHORT_SEGMENT = 4
PARALLEL = 5
NO_MATCH = 6
CLUTTER = 7
EXTRA_FACE = 8

# Layout of the parameter vector (see CornerParams in corners.py).
(P_SPIKE, P_KSIG, P_MINPTS, P_SIGFLOOR, P_SEGTOL, P_SEGSIG, P_MINFACE, P_BAND, P_MAXBAND, P_MERGEDEG,
 P_MAXSKIP, P_TURNSIG, P_TURNMAX, P_TURNMIN, P_TOLIN, P_DETSIG, P_DETMAX, P_SKIPCOST, P_GATEFLOOR,
 P_FACETILT, P_SCALE, P_SCALEZ, P_MAXVERT, P_ATTACH, P_EXTRAGAP) = range(25)
N_PARAMS = 25


@njit(cache=True, nogil=True)
def model_kernel(profile, turns, prm):
    """Model-based corner detection; returns what the RDP kernel returns.

    Parameters
    ----------
    profile : ndarray, shape (N, 2)
        Points (x, z) in F, mm, scan order, NaN = no return; float64, C-contiguous.
    turns : ndarray, shape (n,)
        The gauge's turn at each ridge, rad (:func:`~posekit.profiler.estimate.segments.expected_turns`).
    prm : ndarray, shape (N_PARAMS,)
        Parameter vector (built from ``CornerParams`` in :mod:`~posekit.profiler.estimate.corners`).

    Returns
    -------
    ``(status, info, corners (n, 2), cov (2n, 2n), lines (n+1, 3), sigma (n+1,),
    npts (n+1,), cand (n+1, 3))`` as the RDP kernel: corners in scan order, mm; the face
    lines ``nx x + nz z = c``; their residual σ, mm, and point counts. ``info`` (8,):
    line candidates found, valid returns, spikes, a face or corner index for errors,
    reversed (1: the faces came in reverse file order), assignment cost, noise σ (mm),
    segments. ``cand``: per face the x of its segment's first and last return (on
    success); the boundaries found and the returns' x span (MISSING); the extra corner
    x, z and its turn in degrees (EXTRA_FACE, row n).
    """
    n = turns.shape[0]
    corners = np.full((n, 2), np.nan)
    cov = np.full((2 * n, 2 * n), np.nan)
    lines = np.full((n + 1, 3), np.nan)
    sig = np.full(n + 1, np.nan)
    npts = np.zeros(n + 1, dtype=np.int64)
    cand_out = np.full((n + 1, 3), np.nan)
    info = np.zeros(8)
    min_pts = int(prm[P_MINPTS])

    xs, zs, m0, m = clean_points(profile, prm[P_SPIKE])
    info[1] = m0
    info[2] = m0 - m
    if m < (n + 1) * min_pts:
        return NO_POINTS, info, corners, cov, lines, sig, npts, cand_out
    sigma_n = noise_sigma(xs, zs, m)
    info[6] = sigma_n
    tol = max(prm[P_SEGTOL], prm[P_SEGSIG] * sigma_n)
    verts, nv, ok = split_segments(xs, zs, m, tol, int(prm[P_MAXVERT]))
    info[7] = nv - 1
    if not ok:
        return CLUTTER, info, corners, cov, lines, sig, npts, cand_out
    tab = segment_table(xs, zs, verts, nv)
    cand = line_candidates(tab, prm[P_MINFACE], min_pts, prm[P_MERGEDEG], sigma_n)
    nc = cand.shape[0]
    info[0] = nc
    if nc < n + 1:
        # Report where the faces found so far meet, as the RDP detector reports its corners.
        found = max(nc - 1, 0)
        for s in range(found):
            cand_out[s, 0] = 0.5 * (cand[s, EX] + cand[s + 1, BX])
            cand_out[s, 1] = 0.5 * (cand[s, EZ] + cand[s + 1, BZ])
        cand_out[n, 0] = xs[0]
        cand_out[n, 1] = xs[m - 1]
        info[0] = found
        return MISSING, info, corners, cov, lines, sig, npts, cand_out
    scan_sign = 1.0 if xs[m - 1] >= xs[0] else -1.0
    okd, prim, rev, cost = assign_faces(cand, turns, scan_sign, int(prm[P_MAXSKIP]), prm[P_TURNSIG],
                                        prm[P_TURNMAX], prm[P_TURNMIN], prm[P_TOLIN], prm[P_DETSIG],
                                        prm[P_DETMAX], prm[P_SKIPCOST], prm[P_ATTACH])
    info[4] = 1.0 if rev else 0.0
    info[5] = cost
    if not okd:
        return NO_MATCH, info, corners, cov, lines, sig, npts, cand_out
    # The gauge's surface must end with its outer faces: a face-like segment that continues
    # it without a gap (a ridge, perhaps rounded: within extra_face_gap_mm), long, meeting
    # the outer face in a corner, means the gauge has more faces than the file says. A
    # fixture beside the gauge leaves a gap (its shadow or the plate between).
    for end in range(2):
        step = -1 if end == 0 else 1
        outer = cand[prim[0]] if end == 0 else cand[prim[n]]
        prev = outer
        i = prim[0] - 1 if end == 0 else prim[n] + 1
        while 0 <= i < nc:
            nxt = cand[i]
            a = nxt if end == 0 else prev
            b = prev if end == 0 else nxt
            if np.sqrt((b[BX] - a[EX]) ** 2 + (b[BZ] - a[EZ]) ** 2) > prm[P_EXTRAGAP]:
                break                               # a gap: what follows is background
            if nxt[LEN] >= 2.0 * prm[P_MINFACE]:
                a = nxt if end == 0 else outer
                b = outer if end == 0 else nxt
                okg, detour, turn = _pair_geometry(a, b, prm[P_TOLIN])
                if okg and detour <= prm[P_DETSIG] and abs(turn) >= prm[P_TURNMIN]:
                    det = a[NX] * b[NZ] - a[NZ] * b[NX]
                    cand_out[n, 0] = (a[C] * b[NZ] - b[C] * a[NZ]) / det
                    cand_out[n, 1] = (a[NX] * b[C] - b[NX] * a[C]) / det
                    cand_out[n, 2] = np.degrees(abs(turn))
                    return EXTRA_FACE, info, corners, cov, lines, sig, npts, cand_out
                break
            prev = nxt
            i += step
    # The gauge's turn at each corner in scan order (> 0 ridge, < 0 valley).
    turn_scan = np.empty(n)
    for k in range(n):
        turn_scan[k] = turns[n - 1 - k] if rev else turns[k]
    # Windows, starting lines and scales of the faces.
    lo = np.empty(n + 1, dtype=np.int64)
    hi = np.empty(n + 1, dtype=np.int64)
    L = np.empty((n + 1, 5))              # nx, nz, c, dx, dz
    s_face = np.empty(n + 1)
    for k in range(n + 1):
        row = cand[prim[k]]
        lo[k] = int(cand[prim[k - 1], I1]) + 1 if k > 0 else int(row[I0])
        hi[k] = int(cand[prim[k + 1], I0]) if k < n else int(row[I1]) + 1
        L[k, 0] = row[NX]
        L[k, 1] = row[NZ]
        L[k, 2] = row[C]
        L[k, 3] = row[DX]
        L[k, 4] = row[DZ]
        s_face[k] = max(row[RMS], sigma_n, prm[P_SIGFLOOR])
        cand_out[k, 0] = row[BX]
        cand_out[k, 1] = row[EX]
    # Outer limits of the outer faces, along their lines.
    r0 = cand[prim[0]]
    rn = cand[prim[n]]
    band_lo = np.full(n + 1, prm[P_BAND])     # band at the face's start (towards ridge k - 1)
    band_hi = np.full(n + 1, prm[P_BAND])     # band at its end (towards ridge k)
    cent = np.empty((n + 1, 3))
    k_sig = prm[P_KSIG]
    gate_floor = prm[P_GATEFLOOR]
    for it in range(3):
        # Corners of the current lines.
        for k in range(n):
            det = L[k, 0] * L[k + 1, 1] - L[k, 1] * L[k + 1, 0]
            if abs(det) < 1e-9:
                info[3] = k
                return PARALLEL, info, corners, cov, lines, sig, npts, cand_out
            corners[k, 0] = (L[k, 2] * L[k + 1, 1] - L[k + 1, 2] * L[k, 1]) / det
            corners[k, 1] = (L[k, 0] * L[k + 1, 2] - L[k + 1, 0] * L[k, 2]) / det
        for k in range(n + 1):
            dx = L[k, 3]
            dz = L[k, 4]
            # The face runs from corner k - 1 (or its segment's start) to corner k (or its end).
            if k > 0:
                sx0 = corners[k - 1, 0]
                sz0 = corners[k - 1, 1]
            else:
                sx0 = r0[BX]
                sz0 = r0[BZ]
            if k < n:
                ex0 = corners[k, 0]
                ez0 = corners[k, 1]
            else:
                ex0 = rn[EX]
                ez0 = rn[EZ]
            nx = L[k, 0]
            nz = L[k, 1]
            c = L[k, 2]
            voted = False
            for ps in range(2 if it == 0 else 1):
                # t along the current direction (absolute t moves with it: recompute the limits)
                t_lo = dx * sx0 + dz * sz0 + band_lo[k]
                t_hi = dx * ex0 + dz * ez0 - band_hi[k]
                gate = max(k_sig * s_face[k], gate_floor)
                a_lo = t_lo
                a_hi = t_hi
                i_lo = lo[k]
                i_hi = hi[k]
                if it == 0 and ps == 0:
                    # Start from the middle half of the face: ghosts and rounding sit at the ridges.
                    gate = max(gate, tol)
                    a_lo = t_lo + 0.25 * (t_hi - t_lo)
                    a_hi = t_hi - 0.25 * (t_hi - t_lo)
                    q = (i_hi - i_lo) // 5
                    i_lo += q
                    i_hi -= q
                sw, mx, mz, cxx, cxz, czz, n_rng = gated_fit(xs, zs, i_lo, i_hi, nx, nz, c, dx, dz, a_lo, a_hi,
                                                              gate)
                if sw < min_pts:
                    if it == 0 and ps == 0:
                        continue
                    npts[k] = int(sw)
                    info[3] = k
                    return SHORT_SEGMENT, info, corners, cov, lines, sig, npts, cand_out
                theta = 0.5 * np.arctan2(2.0 * cxz, cxx - czz)
                ndx = np.cos(theta)
                ndz = np.sin(theta)
                if ndx * dx + ndz * dz < 0.0:
                    ndx = -ndx
                    ndz = -ndz
                half = 0.5 * (cxx + czz)
                root = np.sqrt(0.25 * (cxx - czz) ** 2 + cxz * cxz)
                s_nn = max(half - root, 0.0)
                dx = ndx
                dz = ndz
                nx = -dz
                nz = dx
                c = nx * mx + nz * mz
                rms = np.sqrt(s_nn / sw)
                if it == 0 and not voted and (rms > 2.0 * sigma_n or sw < 0.7 * n_rng):
                    # A ghost or a bump fills much of the face: let its stretches vote, with a
                    # gate tight enough that a line between a shallow ghost and the face loses.
                    voted = True
                    lean = 0.0
                    if k > 0 and turn_scan[k - 1] < 0.0:
                        lean += 1.0             # starts at a valley: trust its far end
                    if k < n and turn_scan[k] < 0.0:
                        lean -= 1.0             # ends at a valley
                    okq, qnx, qnz, qc = consensus_line(xs, zs, lo[k], hi[k], dx, dz, t_lo, t_hi,
                                                        max(2.5 * sigma_n, gate_floor), lean)
                    if okq:
                        nx = qnx
                        nz = qnz
                        c = qc
                        dx = nz
                        dz = -nx
                        s_face[k] = max(sigma_n, prm[P_SIGFLOOR])
                        continue
                s_face[k] = max(rms * np.sqrt(sw / max(sw - 2.0, 1.0)), prm[P_SIGFLOOR])
                npts[k] = int(sw)
                cent[k, 0] = mx
                cent[k, 1] = mz
                cent[k, 2] = half + root
            L[k, 0] = nx
            L[k, 1] = nz
            L[k, 2] = c
            L[k, 3] = dx
            L[k, 4] = dz
        if it == 2:
            break
        # Grow a band while the returns just outside it lean to one side of the line.
        grown = False
        for k in range(n + 1):
            dx = L[k, 3]
            dz = L[k, 4]
            for end in range(2):
                if (end == 0 and k == 0) or (end == 1 and k == n):
                    continue
                pk = corners[k - 1] if end == 0 else corners[k]
                t_c = dx * pk[0] + dz * pk[1]
                while True:
                    band = band_lo[k] if end == 0 else band_hi[k]
                    if band >= prm[P_MAXBAND]:
                        break
                    if end == 0:
                        leans, t_run = edge_leans(xs, zs, lo[k], hi[k], 1, L[k, 0], L[k, 1], L[k, 2], dx, dz,
                                                   t_c + band, s_face[k], t_c + prm[P_MAXBAND])
                    else:
                        leans, t_run = edge_leans(xs, zs, hi[k] - 1, lo[k] - 1, -1, L[k, 0], L[k, 1], L[k, 2],
                                                   dx, dz, t_c - band, s_face[k], t_c - prm[P_MAXBAND])
                    if not leans:
                        break
                    grown = True
                    new = min(abs(t_run - t_c) + 1e-6, prm[P_MAXBAND])
                    if end == 0:
                        band_lo[k] = new
                    else:
                        band_hi[k] = new
        if it == 1 and not grown:
            break

    for k in range(n + 1):
        lines[k, 0] = L[k, 0]
        lines[k, 1] = L[k, 1]
        lines[k, 2] = L[k, 2]
        sig[k] = s_face[k]
    for k in range(n):
        det = L[k, 0] * L[k + 1, 1] - L[k, 1] * L[k + 1, 0]
        if abs(det) < 1e-9:
            info[3] = k
            return PARALLEL, info, corners, cov, lines, sig, npts, cand_out
        corners[k, 0] = (L[k, 2] * L[k + 1, 1] - L[k + 1, 2] * L[k, 1]) / det
        corners[k, 1] = (L[k, 0] * L[k + 1, 2] - L[k + 1, 0] * L[k, 2]) / det
    var_scale = (prm[P_SCALE] * 1e-6) ** 2
    okc, cv, kbad = corner_covariance(lines, cent, sig, npts, corners, prm[P_FACETILT] ** 2, var_scale,
                                      prm[P_SCALEZ])
    if not okc:
        info[3] = kbad
        return PARALLEL, info, corners, cov, lines, sig, npts, cand_out
    return OK, info, corners, cv, lines, sig, npts, cand_out
