"""Timestamp association of two trajectories and estimation of a constant clock offset.

Clock convention: ``offset_s`` is what must be added to a src timestamp to read the dst clock,
``t_dst ≈ t_src + offset_s``.

The offset estimate comes with its 1σ (:func:`offset_std`: the Gauss–Newton variance of the
offset in the joint fit of rotation, translation (scale) and offset, times the residuals'
integrated autocorrelation time — VO drift makes neighbouring residuals alike). A caller can then
tell an offset the data determine from one they do not (:func:`offset_is_determined`).
"""

from statistics import NormalDist

import numpy as np
from scipy.optimize import minimize_scalar

from posekit.errors import TrajectoryError
from posekit.geometry import rotation_angle_between
from posekit.localcal.registration.alignment import (
    MIN_POSES,
    robust_inliers,
    robust_principal_axes,
    thin_indices,
    umeyama,
)

__all__ = ["OFFSET_ALPHA", "associate", "dedupe_stamps", "edge_message", "estimate_time_offset", "interpolate_positions",
           "offset_is_determined", "offset_std", "typical_gap"]

#: Largest number of src samples the offset grid search evaluates (evenly thinned beyond).
_OFFSET_SAMPLES = 600
#: Largest number of src samples the offset refinement and its std use (evenly thinned beyond; for
#: white residuals the std of a longer file is then conservative by sqrt(N / this)).
_REFINE_SAMPLES = 20_000
#: Significance level of the test "the clock offset differs from 0": an estimate within the
#: two-sided (1 - OFFSET_ALPHA) interval of 0 (|z| < 2.58) is not taken as a clock offset.
OFFSET_ALPHA = 0.01
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


def dedupe_stamps(t_s) -> np.ndarray:
    """Indices that keep the last sample of every run of equal timestamps, shape (K,).

    A pose re-published at the same stamp supersedes the earlier one (evo's nearest-stamp match
    picks the last of equal stamps, too).

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        Non-decreasing timestamps, s.
    """
    t_s = np.asarray(t_s, dtype=np.float64)
    if t_s.size < 2:
        return np.arange(t_s.size)
    return np.flatnonzero(np.r_[t_s[1:] != t_s[:-1], True])


def typical_gap(t_s) -> float:
    """Largest gap between samples that counts as continuous data: 5 x the median step, s."""
    d = np.diff(np.asarray(t_s, dtype=np.float64))
    med = float(np.median(d[d > 0])) if np.any(d > 0) else 0.0
    return max(5.0 * med, 1e-6)


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
                         with_scale: bool = False, names=("src", "dst"), edge: str = "raise"):
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

    edge : {'raise', 'return'}
        What a best offset at the edge of the search does: raise (default), or be returned with
        a flag (the caller decides with :func:`offset_std` whether the data determine it).

    Returns
    -------
    offset_s : float
        Estimated offset, s (``t_dst ≈ t_src + offset_s``), within ``±max_offset_s``;
        ``(offset_s, at_edge)`` with ``edge='return'``.

    Raises
    ------
    TrajectoryError
        If no offset in the range gives at least ``MIN_POSES`` overlapping samples, the best
        offset is at the edge of the range (the true one may lie beyond; ``edge='raise'``), or the best offset
        fits (``_OFFSET_FIT_FRACTION``) and offsets that fit equally well (within
        ``_OFFSET_TIE_FACTOR`` of its cost) give rotations more than ``_OFFSET_AMBIGUOUS_DEG``
        apart: the path maps onto itself under a time shift (a circle or helix at constant
        speed), so the offset, and with it the rotation, is undetermined.
    """
    t_all, p_all = np.asarray(t_src, dtype=np.float64), np.asarray(p_src, dtype=np.float64)
    k = thin_indices(t_all.size, _OFFSET_SAMPLES)
    t_src, p_src = t_all[k], p_all[k]
    max_gap_s = typical_gap(t_dst)
    med = max_gap_s / 5.0
    dt_s = np.diff(t_src)
    med_s = float(np.median(dt_s[dt_s > 0])) if np.any(dt_s > 0) else med
    step = max(min(med, med_s) / 2.0, max_offset_s / 40.0, 1e-4)
    n = int(np.ceil(max_offset_s / step)) if max_offset_s > 0 else 0
    grid = np.clip(np.linspace(-n * step, n * step, 2 * n + 1), -max_offset_s, max_offset_s)
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
        return (float(grid[0]), False) if edge == "return" else float(grid[0])
    extent = robust_principal_axes(p_dst)[2][0]
    if best in (0, grid.size - 1) and cost[best] > _OFFSET_NOTHING_FITS * extent:
        raise TrajectoryError(
            f"no clock offset within ±{max_offset_s:g} s makes {names[0]} and {names[1]} agree: the best "
            f"({grid[best]:+.3f} s) leaves a median residual of {cost[best]:.1f} mm, {cost[best] / extent:.0%} of "
            f"the path's extent; they do not record the same motion (or the offset lies beyond: --max-offset)")
    if best in (0, grid.size - 1):
        if edge == "raise":
            raise TrajectoryError(edge_message(names, float(grid[best]), max_offset_s))
        return float(grid[best]), True
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
    k = thin_indices(t_all.size, _REFINE_SAMPLES)
    offset = _refine_offset(offset, t_all[k], p_all[k], t_dst, p_dst, max_gap_s, with_scale, bounds=(lo, hi))
    return (offset, False) if edge == "return" else offset


def edge_message(names, offset_s: float, max_offset_s: float) -> str:
    """The message of a clock offset that fits best at the edge of its search."""
    return (f"the clock offset between {names[0]} and {names[1]} fits best at the edge of the search "
            f"({offset_s:+.3f} s): it may lie beyond ±{max_offset_s:g} s; widen the search "
            f"(max_offset_s, --max-offset) or give the offset (time_offset_s, --time-offset)")


def _refine_offset(offset, t_src, p_src, t_dst, p_dst, max_gap_s, with_scale, bounds, n_iter=8):
    """Gauss-Newton on the offset, alternating with the (trimmed) Umeyama fit, within ``bounds``.

    The median cost above is flat near its minimum; this least-squares step uses the dst velocity:
    ``r_i(offset + d) ≈ r_i(offset) + v_dst(t_i + offset) d``. It never leaves the bracket of
    the grid's best point (inside ``±max_offset_s``): on a drifting VO path the least-squares
    optimum can lie far from where the median cost put it (KITTI 00 S-PTAM: +0.13 s unbounded,
    outside a 0.05 s search).
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
        new = float(np.clip(offset + step, bounds[0], bounds[1]))
        step, offset = new - offset, new
        if abs(step) < 1e-6:
            break
    return offset


def offset_std(offset_s, t_src, p_src, t_dst, p_dst, *, with_scale: bool = False) -> float:
    """1σ of a clock offset estimated from positions, s (inf when the data do not determine it).

    The residuals ``r_i = p_dst(t_i + offset) - (s R p_src_i + t)`` of the pairs within the robust
    inlier gate (:func:`.alignment.robust_inliers`) are linearised in the rotation
    (3), translation (3), scale (with ``with_scale``) and offset (the dst velocity ``v_i``); the
    offset's variance is the corresponding entry of ``σ² (JᵀJ)⁻¹`` (``σ²`` the residual variance),
    times the residuals' integrated autocorrelation time (:func:`posekit._autocorr.autocorrelation_time`).

    Parameters
    ----------
    offset_s : float
        The offset, s.
    t_src, t_dst : ndarray, shape (M,), (N,)
        Timestamps, s.
    p_src, p_dst : ndarray, shape (M, 3), (N, 3)
        Positions, mm.
    with_scale : bool
        A similarity fit (the scale is a parameter too).

    Returns
    -------
    float
        The offset's standard deviation, s; ``inf`` when fewer than ``MIN_POSES`` samples overlap
        or the dst path does not move at the paired samples (stop-and-go captures).
    """
    from posekit._autocorr import autocorrelation_time

    t_src, p_src = np.asarray(t_src, dtype=np.float64), np.asarray(p_src, dtype=np.float64)
    k = thin_indices(t_src.size, _REFINE_SAMPLES)
    t_src, p_src = t_src[k], p_src[k]
    gap = typical_gap(t_dst)
    h = gap / 5.0
    q, ok = interpolate_positions(t_dst, p_dst, t_src + offset_s, max_gap_s=gap)
    qa, va = interpolate_positions(t_dst, p_dst, t_src + offset_s + h, max_gap_s=gap)
    qb, vb = interpolate_positions(t_dst, p_dst, t_src + offset_s - h, max_gap_s=gap)
    ok &= va & vb
    if ok.sum() < MIN_POSES:
        return float("inf")
    a, b, v = p_src[ok], q[ok], (qa[ok] - qb[ok]) / (2.0 * h)
    R, t, s = umeyama(a, b, with_scale=with_scale)
    keep = robust_inliers(np.linalg.norm(b - (s * a @ R.T + t), axis=1))     # gross outliers out
    if keep.sum() < MIN_POSES:
        return float("inf")
    a, b, v = a[keep], b[keep], v[keep]
    R, t, s = umeyama(a, b, with_scale=with_scale)
    m = s * a @ R.T
    r = b - m - t
    npar = 8 if with_scale else 7
    J = np.zeros((len(a), 3, npar))
    J[:, 0, 1], J[:, 0, 2] = m[:, 2], -m[:, 1]              # d(exp([δ]x) m)/dδ = -[m]x
    J[:, 1, 0], J[:, 1, 2] = -m[:, 2], m[:, 0]
    J[:, 2, 0], J[:, 2, 1] = m[:, 1], -m[:, 0]
    J[:, :, 3:6] = np.eye(3)
    J[:, :, 6] = -v                                          # r(offset + d) = r - ... : only the sign
    if with_scale:
        J[:, :, 7] = m / s
    H = np.einsum("nij,nik->jk", J, J)
    dof = max(3 * len(a) - npar, 1)
    try:
        var = float(np.linalg.inv(H)[6, 6]) * float((r ** 2).sum()) / dof
    except np.linalg.LinAlgError:
        return float("inf")
    if not np.isfinite(var) or var <= 0 or float((v ** 2).sum()) <= 1e-18 * max(float((b ** 2).sum()), 1.0):
        return float("inf")
    return float(np.sqrt(var * autocorrelation_time(r)))


def offset_is_determined(estimate_s: float, std_s: float, alpha: float = OFFSET_ALPHA) -> bool:
    """Whether an offset estimate differs from 0 at significance ``alpha`` (two-sided z test)."""
    if not (np.isfinite(estimate_s) and np.isfinite(std_s)) or std_s <= 0:
        return False
    return abs(estimate_s) > NormalDist().inv_cdf(1.0 - alpha / 2.0) * std_s
