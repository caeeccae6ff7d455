"""Timestamp association of two trajectories and estimation of a constant clock offset.

Clock convention: ``offset_s`` is what must be added to a src timestamp to read the dst clock,
``t_dst ≈ t_src + offset_s``.
"""

import numpy as np
from scipy.optimize import minimize_scalar

from posekit.errors import TrajectoryError
from posekit.geometry import rotation_angle_between
from posekit.localcal.registration.alignment import MIN_POSES, robust_principal_axes, umeyama

__all__ = ["associate", "estimate_time_offset", "interpolate_positions"]

#: Largest number of src samples the offset search evaluates (evenly thinned beyond).
_OFFSET_SAMPLES = 600
#: Offsets whose cost is within this factor of the best one fit as well as it (the noise level).
_OFFSET_TIE_FACTOR = 1.5
#: Two such offsets whose rotations differ by more than this make the offset ambiguous, deg.
#: On the test data (real TUM pairs, synthetic and simulated paths) tied offsets differ by at most
#: 0.6 deg (neighbouring grid points); a circle or helix at constant speed by 6-108 deg.
_OFFSET_AMBIGUOUS_DEG = 2.0
#: The ambiguity check applies only when the best offset fits, i.e. its median residual is below
#: this fraction of the dst path's extent (std along its main axis). When nothing fits (e.g. a
#: mirror image) every offset ties and the residuals already tell the user.
_OFFSET_FIT_FRACTION = 0.05
#: When even the best offset leaves a median residual above this fraction of the extent, nothing
#: fits (random data: 190 %; a true offset 0.6 s beyond the search edge: 24 %).
_OFFSET_NOTHING_FITS = 0.5


def associate(t_src, t_dst, *, max_dt_s: float = 0.02, offset_s: float = 0.0):
    """Nearest-timestamp, one-to-one association of two timestamp sequences.

    Every src stamp (shifted by ``offset_s``) is paired with the nearest dst stamp; pairs further
    apart than ``max_dt_s`` are dropped, and when several src stamps pick the same dst stamp only
    the closest keeps it.

    Parameters
    ----------
    t_src : array_like, shape (M,)
        Source timestamps, s, non-decreasing.
    t_dst : array_like, shape (N,)
        Destination timestamps, s, non-decreasing.
    max_dt_s : float
        Largest accepted time difference of a pair, s.
    offset_s : float
        Clock offset, s: ``t_src + offset_s`` is compared with ``t_dst``.

    Returns
    -------
    i_src, i_dst : ndarray of int, shape (K,)
        Indices of the paired stamps, in increasing src order.
    """
    ts = np.asarray(t_src, dtype=np.float64) + offset_s
    td = np.asarray(t_dst, dtype=np.float64)
    if ts.size == 0 or td.size == 0:
        return np.zeros(0, dtype=int), np.zeros(0, dtype=int)
    j = np.clip(np.searchsorted(td, ts), 1, td.size - 1) if td.size > 1 else np.zeros(ts.size, int)
    if td.size > 1:
        left_closer = np.abs(ts - td[j - 1]) <= np.abs(td[j] - ts)
        j = np.where(left_closer, j - 1, j)
    dt = np.abs(td[j] - ts)
    ok = np.flatnonzero(dt <= max_dt_s)
    # one-to-one: for each dst index keep the src with the smallest |dt|
    order = ok[np.lexsort((dt[ok], j[ok]))]
    first = np.ones(order.size, dtype=bool)
    first[1:] = j[order][1:] != j[order][:-1]
    i_src = np.sort(order[first])
    return i_src, j[i_src]


def interpolate_positions(t_dst, p_dst, t_query, *, max_gap_s: float):
    """Linear interpolation of dst positions at query times, where dst has data.

    Parameters
    ----------
    t_dst : ndarray, shape (N,)
        Timestamps of the dst positions, s, non-decreasing.
    p_dst : ndarray, shape (N, 3)
        Positions, mm.
    t_query : ndarray, shape (M,)
        Query times on the dst clock, s.
    max_gap_s : float
        A query between two dst samples further apart than this is invalid (a gap in the data).

    Returns
    -------
    p : ndarray, shape (M, 3)
        Interpolated positions, mm (NaN where invalid).
    valid : ndarray, shape (M,), bool
    """
    j = np.searchsorted(t_dst, t_query, side="right")
    inside = (j > 0) & (j < t_dst.size)
    jc = np.clip(j, 1, t_dst.size - 1)
    gap = t_dst[jc] - t_dst[jc - 1]
    valid = inside & (gap <= max_gap_s)
    denom = np.where(gap > 0, gap, 1.0)
    a = np.clip((t_query - t_dst[jc - 1]) / denom, 0.0, 1.0)[:, None]
    p = (1.0 - a) * p_dst[jc - 1] + a * p_dst[jc]
    p[~valid] = np.nan
    return p, valid


def _alignment_fit(offset, t_src, p_src, t_dst, p_dst, max_gap_s, with_scale):
    """Trimmed Umeyama fit of src to dst interpolated at t_src + offset: (median residual mm, R)."""
    q, valid = interpolate_positions(t_dst, p_dst, t_src + offset, max_gap_s=max_gap_s)
    if valid.sum() < MIN_POSES:
        return np.inf, None
    a, b = p_src[valid], q[valid]
    R, t, s = umeyama(a, b, with_scale=with_scale)
    res = np.linalg.norm(b - (s * a @ R.T + t), axis=1)
    keep = res <= np.quantile(res, 0.8)
    if keep.sum() >= 3:
        R, t, s = umeyama(a[keep], b[keep], with_scale=with_scale)
        res = np.linalg.norm(b - (s * a @ R.T + t), axis=1)
    return float(np.median(res)), R


def _alignment_cost(offset, *args):
    """Median residual of :func:`_alignment_fit`, mm."""
    return _alignment_fit(offset, *args)[0]


def estimate_time_offset(t_src, p_src, t_dst, p_dst, *, max_offset_s: float = 1.0,
                         with_scale: bool = False, names=("src", "dst")) -> float:
    """Constant clock offset that best aligns two position trajectories up to a rigid motion.

    The cost of an offset is the median residual of a trimmed Umeyama fit of the src positions
    to the dst positions linearly interpolated at ``t_src + offset``; it is evaluated on a grid
    over ``[-max_offset_s, max_offset_s]`` and refined by a bounded scalar search around the
    best grid point. Rotation- and translation-invariant, so no prior alignment is needed.

    Parameters
    ----------
    t_src : ndarray, shape (M,)
        src timestamps, s.
    p_src : ndarray, shape (M, 3)
        src positions (src world frame), mm.
    t_dst : ndarray, shape (N,)
        dst timestamps, s.
    p_dst : ndarray, shape (N, 3)
        dst positions (dst world frame), mm.
    max_offset_s : float
        Half-width of the search, s.
    with_scale : bool
        Fit a similarity instead of a rigid transform.
    names : tuple of str
        Names of src and dst for messages.

    Returns
    -------
    offset_s : float
        Estimated offset, s (``t_dst ≈ t_src + offset_s``).

    Raises
    ------
    TrajectoryError
        If no offset in the range gives at least ``MIN_POSES`` overlapping samples, the best
        offset is at the edge of the range (the true one may lie beyond), or the best offset
        fits (``_OFFSET_FIT_FRACTION``) and offsets that fit equally well (within
        ``_OFFSET_TIE_FACTOR`` of its cost) give rotations more than ``_OFFSET_AMBIGUOUS_DEG``
        apart: the path maps onto itself under a time shift (a circle or helix at constant
        speed), so the offset, and with it the rotation, is undetermined.
    """
    if t_src.size > _OFFSET_SAMPLES:
        k = np.linspace(0, t_src.size - 1, _OFFSET_SAMPLES).round().astype(int)
        t_src, p_src = t_src[k], p_src[k]
    dt_d = np.diff(t_dst)
    med = float(np.median(dt_d[dt_d > 0])) if np.any(dt_d > 0) else 0.0
    max_gap_s = max(5.0 * med, 1e-6)
    dt_s = np.diff(t_src)
    med_s = float(np.median(dt_s[dt_s > 0])) if np.any(dt_s > 0) else med
    step = max(min(med, med_s) / 2.0, max_offset_s / 40.0, 1e-4)
    n = int(np.ceil(max_offset_s / step)) if max_offset_s > 0 else 0
    grid = np.linspace(-n * step, n * step, 2 * n + 1)
    args = (t_src, p_src, t_dst, p_dst, max_gap_s, with_scale)
    fits = [_alignment_fit(o, *args) for o in grid]
    cost = np.array([c for c, _ in fits])
    if not np.isfinite(cost).any():
        raise TrajectoryError(
            f"no overlapping timestamps: {names[0]} spans {t_src[0]:.3f}-{t_src[-1]:.3f} s and "
            f"{names[1]} spans {t_dst[0]:.3f}-{t_dst[-1]:.3f} s, which overlap by fewer than "
            f"{MIN_POSES} poses for any clock offset within ±{max_offset_s:g} s")
    best = int(np.argmin(cost))
    if grid.size == 1:
        return float(grid[0])
    extent = robust_principal_axes(p_dst)[2][0]
    if best in (0, grid.size - 1) and cost[best] > _OFFSET_NOTHING_FITS * extent:
        raise TrajectoryError(
            f"no clock offset within ±{max_offset_s:g} s makes {names[0]} and {names[1]} agree: the best "
            f"({grid[best]:+.3f} s) leaves a median residual of {cost[best]:.1f} mm, {cost[best] / extent:.0%} of "
            f"the path's extent; they do not record the same motion (or the offset lies beyond: --max-offset)")
    if best in (0, grid.size - 1):
        raise TrajectoryError(
            f"the clock offset between {names[0]} and {names[1]} fits best at the edge of the search "
            f"({grid[best]:+.3f} s): it may lie beyond ±{max_offset_s:g} s; widen the search "
            f"(max_offset_s, --max-offset) or give the offset (time_offset_s, --time-offset)")
    tied = np.flatnonzero(cost <= _OFFSET_TIE_FACTOR * cost[best])
    angles = np.rad2deg(rotation_angle_between(fits[best][1], np.array([fits[k][1] for k in tied]), check=False))
    fits_well = cost[best] <= _OFFSET_FIT_FRACTION * extent
    if fits_well and angles.max() > _OFFSET_AMBIGUOUS_DEG:
        k = int(tied[np.argmax(angles)])
        raise TrajectoryError(
            f"the clock offset between {names[0]} and {names[1]} is ambiguous: offsets {grid[best]:+.3f} s and "
            f"{grid[k]:+.3f} s fit equally well (median residuals {cost[best]:.1f} and {cost[k]:.1f} mm) but "
            f"give rotations {angles.max():.1f} deg apart, as on a circle or helix run at constant speed; "
            f"give the offset (time_offset_s, --time-offset)")
    lo, hi = grid[max(best - 1, 0)], grid[min(best + 1, grid.size - 1)]
    opt = minimize_scalar(_alignment_cost, bounds=(lo, hi), args=args, method="bounded",
                          options={"xatol": 1e-4})
    offset = float(opt.x) if opt.success and np.isfinite(opt.fun) and opt.fun <= cost[best] else float(grid[best])
    return _refine_offset(offset, t_src, p_src, t_dst, p_dst, max_gap_s, with_scale)


def _refine_offset(offset, t_src, p_src, t_dst, p_dst, max_gap_s, with_scale, n_iter=8):
    """Gauss-Newton on the offset, alternating with the (trimmed) Umeyama fit.

    The median cost above is flat near its minimum; this least-squares step uses the dst velocity:
    ``r_i(offset + d) ≈ r_i(offset) + v_dst(t_i + offset) d``.
    """
    h = max_gap_s / 5.0
    for _ in range(n_iter):
        q, valid = interpolate_positions(t_dst, p_dst, t_src + offset, max_gap_s=max_gap_s)
        qa, va = interpolate_positions(t_dst, p_dst, t_src + offset + h, max_gap_s=max_gap_s)
        qb, vb = interpolate_positions(t_dst, p_dst, t_src + offset - h, max_gap_s=max_gap_s)
        ok = valid & va & vb
        if ok.sum() < MIN_POSES:
            break
        a, b, v = p_src[ok], q[ok], (qa[ok] - qb[ok]) / (2.0 * h)
        R, t, s = umeyama(a, b, with_scale=with_scale)
        r = b - (s * a @ R.T + t)
        e = np.linalg.norm(r, axis=1)
        keep = e <= 3.0 * np.median(e) + 1e-9
        if keep.sum() >= 3:
            R, t, s = umeyama(a[keep], b[keep], with_scale=with_scale)
            r = b - (s * a @ R.T + t)
        vv = (v[keep] ** 2).sum()
        if vv <= 0:
            break
        step = -float((v[keep] * r[keep]).sum() / vv)
        step = float(np.clip(step, -h, h))
        offset += step
        if abs(step) < 1e-6:
            break
    return offset
