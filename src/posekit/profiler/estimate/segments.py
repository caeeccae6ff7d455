"""A laser profile as straight segments, and which of them are the gauge's faces.

Compiled building blocks of the model-based corner detector
(:func:`~posekit.profiler.estimate.corners.detect_corners` with a gauge):

1. :func:`clean_points` — valid returns in scan order without isolated spikes (a return
   farther than ``spike_mm`` in z from the median of its 5 neighbours), and a robust
   estimate of the noise from second differences.
2. :func:`split_segments` — Ramer–Douglas–Peucker with a small tolerance (a few noise σ,
   at least ``seg_tol_mm``): every stretch that is straight within the tolerance becomes a
   segment — the faces, but also the mounting plate, fixtures, rounded or chamfered edges,
   multipath clusters, bumps.
3. :func:`segment_table` and :func:`line_candidates` — an orthogonal line fit of each
   segment (from its central moments), the segments at least ``min_face_mm`` long kept as
   candidates, neighbouring candidates on one line merged.
4. :func:`assign_faces` — a dynamic programme that picks, in scan order, one candidate per
   face of the gauge. Consecutive faces must turn like the gauge's cross-section (the
   sign of the turn — ridge or valley — exactly, its size within a tolerance), their
   lines must meet between the two segments (not inside either), and candidates skipped
   between them cost their length. Candidates before the first and after the last face
   (plate, fixtures, background) are free. Both scan directions of the gauge (sensor
   mounted either way round) are tried; the cheaper assignment wins.

A missing or extra segment is thus resolved by the gauge's model: an object on a face, a
chamfer or a ghost cluster is a skipped segment, a plate beside the gauge is background.
"""

import numpy as np

from posekit._jit import njit

from ...geometry._fit import FASTMATH
from ..gauge.model import Gauge

__all__ = ["expected_turns", "clean_points", "chord_deviation", "split_segments", "segment_table", "line_candidates",
           "assign_faces", "NCOL"]

# Columns of a segment table.
I0, I1, NPT, MX, MZ, CXX, CXZ, CZZ, DX, DZ, NX, NZ, C, RMS, LEN, BX, BZ, EX, EZ = range(19)
NCOL = 19


def expected_turns(gauge: Gauge) -> np.ndarray:
    """Turn of the profile at each ridge when the laser crosses the faces in file order.

    In the profile (x, z) of F at the nominal pose (F's x along G's x, z down), face k is
    a line of slope angle ``atan(n_x / n_z)``; the turn at ridge k is the change of that
    angle from face k to face k + 1 — positive at a ridge (peak, the profile bends away
    from the sensor on both sides), negative at a valley. In-plane rotations of the
    sensor leave it unchanged, other rotations change it by a few degrees.

    Parameters
    ----------
    gauge : Gauge

    Returns
    -------
    turns : ndarray, shape (n,)
        Radians.
    """
    phi = np.arctan2(gauge.normals[:, 0], gauge.normals[:, 2])
    return np.diff(phi)


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def _median5(a, b, c, d, e):
    """Median of five scalars, branch-free: med3(e, max(min(a,b), min(c,d)), min(max(a,b), max(c,d)))."""
    f = max(min(a, b), min(c, d))
    g = min(max(a, b), max(c, d))
    return max(min(e, f), min(max(e, f), g))


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def clean_points(profile, spike):
    """Valid returns without spikes: ``(xs, zs, m0, m)``, m0 valid, m kept (first m entries).

    A return is a spike when it is farther than ``spike`` in z from the median of the 5
    returns around it. A return within ``spike`` of both neighbours never is (three of the
    five lie within ``spike`` of it, so the median does too): only the others need the median.
    """
    m_all = profile.shape[0]
    xs0 = np.empty(m_all + 1)
    zs0 = np.empty(m_all + 1)
    m0 = 0
    for i in range(m_all):            # write always, advance when valid: no branch
        x = profile[i, 0]
        z = profile[i, 1]
        xs0[m0] = x
        zs0[m0] = z
        m0 += 1 if (np.isfinite(x) and np.isfinite(z)) else 0
    xs = np.empty(m0 + 1)
    zs = np.empty(m0 + 1)
    if m0 < 5:
        xs[:m0] = xs0[:m0]
        zs[:m0] = zs0[:m0]
        return xs, zs, m0, m0
    m = 0
    for i in range(m0):
        z = zs0[i]
        keep = True
        if i < 2 or i > m0 - 3 or abs(z - zs0[i - 1]) > spike or abs(z - zs0[i + 1]) > spike:
            a = min(max(i - 2, 0), m0 - 5)
            med = _median5(zs0[a], zs0[a + 1], zs0[a + 2], zs0[a + 3], zs0[a + 4])
            keep = abs(z - med) <= spike
        xs[m] = xs0[i]
        zs[m] = z
        m += 1 if keep else 0
    return xs, zs, m0, m


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def _mean_abs_d2(v, m, step, cap):
    """Mean of |v[i+1] - 2 v[i] + v[i-1]| <= cap over every ``step``-th i."""
    acc = 0.0
    cnt = 0.0
    for i in range(1, m - 1, step):
        d = abs(v[i + 1] - 2.0 * v[i] + v[i - 1])
        w = 1.0 if d <= cap else 0.0
        acc += w * d
        cnt += w
    return acc / max(cnt, 1.0)


@njit(cache=True, nogil=True)
def noise_sigma(xs, zs, m):
    """Robust noise σ (mm) of the returns from second differences: the larger of x and z.

    The mean |second difference| over every second triple (fourth, from 2,048 returns),
    taken over values below ten times a first estimate from every sixteenth (so corners
    and jumps do not count), times
    sqrt(π/12) (``E|Δ²| = sqrt(6) sqrt(2/π) σ`` for white Gaussian noise).
    """
    if m < 3:
        return 0.0
    step = 2 if m < 2048 else 4
    ex = _mean_abs_d2(xs, m, 16, 1.0)
    ez = _mean_abs_d2(zs, m, 16, 1.0)
    ex = _mean_abs_d2(xs, m, step, 10.0 * ex + 1e-9)
    ez = _mean_abs_d2(zs, m, step, 10.0 * ez + 1e-9)
    return max(ex, ez) / 1.9544


@njit(cache=True, nogil=True)
def chord_deviation(xs, zs, i0, i1, stride, split_coincident):
    """Largest distance of points i0 < i < i1 from the chord i0–i1 (mm), and its index.

    Scans every ``stride``-th point, then every point within ``stride`` of the best one:
    the same vertex as a full scan whenever the deviation peaks at a corner (it rises
    linearly towards it), at a fraction of the cost. ``(-1, -1)`` when there is no point
    between; when the chord's ends coincide, ``(inf, middle index)`` with
    ``split_coincident`` (the segment must be split), else ``(-1, -1)``. The one chord
    deviation of both detectors (:func:`split_segments`; the RDP detector of
    :mod:`~posekit.profiler.estimate.corners`).
    """
    dx = xs[i1] - xs[i0]
    dz = zs[i1] - zs[i0]
    length = np.sqrt(dx * dx + dz * dz)
    if i1 - i0 < 2:
        return -1.0, -1
    if length <= 0.0:
        return (np.inf, (i0 + i1) // 2) if split_coincident else (-1.0, -1)
    x0 = xs[i0]
    z0 = zs[i0]
    best = -1.0
    best_i = -1
    for i in range(i0 + 1, i1, stride):
        d = abs(dz * (xs[i] - x0) - dx * (zs[i] - z0))
        if d > best:
            best = d
            best_i = i
    if stride > 1:
        lo = max(i0 + 1, best_i - stride + 1)
        hi = min(i1, best_i + stride)
        for i in range(lo, hi):
            d = abs(dz * (xs[i] - x0) - dx * (zs[i] - z0))
            if d > best:
                best = d
                best_i = i
    return best / length, best_i


@njit(cache=True, nogil=True)
def split_segments(xs, zs, m, tol, max_vertices):
    """RDP vertices of the first m points at tolerance ``tol`` (mm), sorted; ``(verts, nv, ok)``.

    ``ok`` is False when more than ``max_vertices`` were needed (the split stops there).
    """
    verts = np.empty(max_vertices, dtype=np.int64)
    stack = np.empty((max_vertices + 2, 2), dtype=np.int64)
    nv = 0
    ok = True
    verts[nv] = 0
    nv += 1
    verts[nv] = m - 1
    nv += 1
    sp = 0
    stack[sp, 0] = 0
    stack[sp, 1] = m - 1
    sp += 1
    stride = max(1, min(8, m // 256))
    while sp > 0:
        sp -= 1
        i0 = stack[sp, 0]
        i1 = stack[sp, 1]
        dev, j = chord_deviation(xs, zs, i0, i1, stride, True)
        if dev <= tol or j < 0:
            continue
        if nv >= max_vertices or sp + 2 > stack.shape[0]:
            ok = False
            break
        verts[nv] = j
        nv += 1
        stack[sp, 0] = i0
        stack[sp, 1] = j
        sp += 1
        stack[sp, 0] = j
        stack[sp, 1] = i1
        sp += 1
    out = np.sort(verts[:nv])
    return out, nv, ok


@njit(cache=True, nogil=True)
def _finish_row(row):
    """Line, direction, RMS and length of a table row from its count, centroid and moments."""
    n = row[NPT]
    cxx = row[CXX]
    cxz = row[CXZ]
    czz = row[CZZ]
    theta = 0.5 * np.arctan2(2.0 * cxz, cxx - czz)
    dx = np.cos(theta)
    dz = np.sin(theta)
    if dx * (row[EX] - row[BX]) + dz * (row[EZ] - row[BZ]) < 0.0:
        dx = -dx
        dz = -dz
    half = 0.5 * (cxx + czz)
    root = np.sqrt(0.25 * (cxx - czz) ** 2 + cxz * cxz)
    row[DX] = dx
    row[DZ] = dz
    row[NX] = -dz
    row[NZ] = dx
    row[C] = -dz * row[MX] + dx * row[MZ]
    row[RMS] = np.sqrt(max(half - root, 0.0) / max(n, 1.0))
    row[LEN] = dx * (row[EX] - row[BX]) + dz * (row[EZ] - row[BZ])


@njit(cache=True, nogil=True, fastmath=FASTMATH)
def segment_table(xs, zs, verts, nv):
    """One row per RDP segment (columns I0 … EZ); a vertex ends one segment, the next starts after it.

    The lines are fitted on every second (fourth, from 64 returns) return: they only
    start the face fits; the moments are scaled to the full count.
    """
    tab = np.zeros((max(nv - 1, 0), NCOL))
    for s in range(nv - 1):
        a = verts[s] if s == 0 else verts[s] + 1
        b = verts[s + 1]
        if b < a:
            a = b
        row = tab[s]
        row[I0] = a
        row[I1] = b
        step = 4 if b - a >= 64 else (2 if b - a >= 16 else 1)
        rx = xs[a]
        rz = zs[a]
        sw = 0.0
        sx = 0.0
        sz = 0.0
        sxx = 0.0
        sxz = 0.0
        szz = 0.0
        for i in range(a, b + 1, step):
            x = xs[i] - rx
            z = zs[i] - rz
            sw += 1.0
            sx += x
            sz += z
            sxx += x * x
            sxz += x * z
            szz += z * z
        n = b - a + 1.0
        mx = sx / sw
        mz = sz / sw
        f = n / sw
        row[NPT] = n
        row[MX] = mx + rx
        row[MZ] = mz + rz
        row[CXX] = f * max(sxx - sx * mx, 0.0)
        row[CXZ] = f * (sxz - sx * mz)
        row[CZZ] = f * max(szz - sz * mz, 0.0)
        row[BX] = xs[a]
        row[BZ] = zs[a]
        row[EX] = xs[b]
        row[EZ] = zs[b]
        _finish_row(row)
    return tab


@njit(cache=True, nogil=True)
def line_candidates(tab, min_len, min_pts, merge_deg, sigma):
    """Segments long enough to be a face, neighbours on one line merged; a new table.

    Two neighbouring candidates are one line when their directions differ by less than
    ``merge_deg`` and the line through both fits them about as well as their own lines
    (merged RMS <= 1.5 × the larger RMS + ``sigma``).
    """
    out = np.zeros_like(tab)
    merged = np.zeros(NCOL)
    nc = 0
    cos_merge = np.cos(np.radians(merge_deg))
    for s in range(tab.shape[0]):
        row = tab[s]
        if row[LEN] < min_len or row[NPT] < min_pts:
            continue
        if nc > 0:
            prev = out[nc - 1]
            cosang = prev[DX] * row[DX] + prev[DZ] * row[DZ]
            if cosang >= cos_merge:
                na = prev[NPT]
                nb = row[NPT]
                n = na + nb
                ddx = row[MX] - prev[MX]
                ddz = row[MZ] - prev[MZ]
                f = na * nb / n
                merged[:] = prev
                merged[CXX] += row[CXX] + f * ddx * ddx
                merged[CXZ] += row[CXZ] + f * ddx * ddz
                merged[CZZ] += row[CZZ] + f * ddz * ddz
                merged[MX] = (na * prev[MX] + nb * row[MX]) / n
                merged[MZ] = (na * prev[MZ] + nb * row[MZ]) / n
                merged[NPT] = n
                merged[I1] = row[I1]
                merged[EX] = row[EX]
                merged[EZ] = row[EZ]
                _finish_row(merged)
                if merged[RMS] <= 1.5 * max(prev[RMS], row[RMS]) + sigma:
                    prev[:] = merged
                    continue
        out[nc] = row
        nc += 1
    return out[:nc].copy()


@njit(cache=True, nogil=True)
def _pair_geometry(a, b, tol_in):
    """Where the lines of candidates a, b (a before b) meet: ``(ok, detour, turn)``.

    ``turn`` is the signed angle from a's direction to b's; ``detour`` how much longer the
    way end(a) → intersection → start(b) is than straight; ``ok`` False if the lines are
    parallel or meet more than ``tol_in`` inside either segment.
    """
    det = a[NX] * b[NZ] - a[NZ] * b[NX]
    turn = np.arctan2(a[DX] * b[DZ] - a[DZ] * b[DX], a[DX] * b[DX] + a[DZ] * b[DZ])
    if abs(det) < 1e-9:
        return False, 0.0, turn
    px = (a[C] * b[NZ] - b[C] * a[NZ]) / det
    pz = (a[NX] * b[C] - b[NX] * a[C]) / det
    ta = (px - a[EX]) * a[DX] + (pz - a[EZ]) * a[DZ]
    tb = (b[BX] - px) * b[DX] + (b[BZ] - pz) * b[DZ]
    if ta < -tol_in or tb < -tol_in:
        return False, 0.0, turn
    d1 = np.sqrt((px - a[EX]) ** 2 + (pz - a[EZ]) ** 2)
    d2 = np.sqrt((px - b[BX]) ** 2 + (pz - b[BZ]) ** 2)
    d0 = np.sqrt((a[EX] - b[BX]) ** 2 + (a[EZ] - b[BZ]) ** 2)
    return True, d1 + d2 - d0, turn


@njit(cache=True, nogil=True)
def assign_faces(cand, turns, scan_sign, max_skip, sigma_turn, max_turn_dev, min_turn, tol_in,
                 sigma_detour, max_detour, skip_cost, attach):
    """One candidate per face, in scan order, by dynamic programming.

    Parameters
    ----------
    cand : ndarray, shape (C, NCOL)
        Line candidates in scan order (:func:`line_candidates`).
    turns : ndarray, shape (n,)
        The gauge's turns in file order, rad (:func:`expected_turns`).
    scan_sign : float
        +1 if x grows along the scan, -1 otherwise (turns are measured with x growing).
    max_skip : int
        Most candidates skipped between two consecutive faces.
    sigma_turn, max_turn_dev, min_turn : float
        Tolerance of a turn (rad): its cost scale, its largest deviation, its least size.
    tol_in : float
        How far (mm) two faces' lines may meet inside one of their segments.
    sigma_detour, max_detour : float
        Cost scale and limit (mm) of the detour through the corner.
    skip_cost : float
        Cost per mm of a skipped candidate.
    attach : float
        Candidates before the first face or after the last are free (background) unless
        they continue the gauge's surface: within ``attach`` mm of the first (last) face or
        of another such candidate. Those count as skipped.

    Returns
    -------
    ok : bool
    primary : ndarray of int, shape (n + 1,)
        Candidate of each face in scan order.
    reversed : bool
        True when the faces were crossed in reverse file order.
    cost : float
    """
    n = turns.shape[0]
    C = cand.shape[0]
    best_primary = np.full(n + 1, -1, dtype=np.int64)
    best_cost = np.inf
    best_rev = False
    if C < n + 1:
        return False, best_primary, best_rev, best_cost
    W = max_skip + 1
    geo_ok = np.zeros((C, W), dtype=np.bool_)
    geo_cost = np.zeros((C, W))
    geo_turn = np.zeros((C, W))
    for i in range(C):
        skipped = 0.0
        for w in range(W):
            j = i + 1 + w
            if j >= C:
                break
            if w > 0:
                skipped += cand[j - 1, LEN]
            ok, detour, turn = _pair_geometry(cand[i], cand[j], tol_in)
            turn *= scan_sign
            if ok and detour <= max_detour and abs(turn) >= min_turn:
                geo_ok[i, w] = True
                geo_cost[i, w] = (detour / sigma_detour) ** 2 + skip_cost * skipped
                geo_turn[i, w] = turn
    # Cost of leaving the candidates attached before i (head) and after i (tail) unassigned.
    head = np.zeros(C)
    tail = np.zeros(C)
    for i in range(1, C):
        gap = np.sqrt((cand[i, BX] - cand[i - 1, EX]) ** 2 + (cand[i, BZ] - cand[i - 1, EZ]) ** 2)
        if gap <= attach:
            head[i] = head[i - 1] + skip_cost * cand[i - 1, LEN]
    for i in range(C - 2, -1, -1):
        gap = np.sqrt((cand[i + 1, BX] - cand[i, EX]) ** 2 + (cand[i + 1, BZ] - cand[i, EZ]) ** 2)
        if gap <= attach:
            tail[i] = tail[i + 1] + skip_cost * cand[i + 1, LEN]
    D = np.empty((n + 1, C))
    back = np.empty((n + 1, C), dtype=np.int64)
    for rev in range(2):
        D[:] = np.inf
        D[0, :] = head
        for k in range(n):
            te = turns[n - 1 - k] if rev == 1 else turns[k]
            for i in range(C):
                if not np.isfinite(D[k, i]):
                    continue
                for w in range(W):
                    j = i + 1 + w
                    if j >= C:
                        break
                    if not geo_ok[i, w]:
                        continue
                    t = geo_turn[i, w]
                    if t * te <= 0.0 or abs(t - te) > max_turn_dev:
                        continue
                    c = D[k, i] + geo_cost[i, w] + ((t - te) / sigma_turn) ** 2
                    if c < D[k + 1, j]:
                        D[k + 1, j] = c
                        back[k + 1, j] = i
        j_best = -1
        for j in range(C):
            if D[n, j] + tail[j] < best_cost:
                best_cost = D[n, j] + tail[j]
                j_best = j
        if j_best >= 0:
            best_rev = rev == 1
            j = j_best
            for k in range(n, -1, -1):
                best_primary[k] = j
                if k > 0:
                    j = back[k, j]
    return np.isfinite(best_cost), best_primary, best_rev, best_cost
