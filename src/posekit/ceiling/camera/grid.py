"""Find the corners of the ceiling grid in a reference image, to calibrate without clicking.

A suspended ceiling is a lattice of tiles (600 mm × 1200 mm in the paper) held by T-bars,
thin lines darker (or lighter) than the tiles. The centre lines of the T-bars are the world
lines ``X = x0 + i·sx`` and ``Y = y0 + j·sy``; their crossings are the calibration points.

From a rough homography (given, or from 4 or more approximately clicked corners) every crossing
in view is predicted, and refined locally: along each of its two T-bars, intensity profiles
across the bar are sampled at stations away from the crossing, the bar centre on each profile
is found (box matched filter, then the darkness centroid over a linear background), a line is
fitted to the centres of each bar (a homography maps lines to lines), and the crossing is the
intersection of the two lines. The homography is refitted (RANSAC) from the refined crossings
and the refinement repeated with a tighter search.

Image coordinates: px, u to the right, v down, the centre of the top-left pixel at (0, 0).
"""

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ...errors import CalibrationError
from ...geometry import apply_homography, check_correspondences, homography_dlt, homography_ransac, refine_homography

__all__ = ["CeilingGrid", "GridCorners", "find_grid_corners"]

#: Stations along each arm of a T-bar, as fractions of the grid spacing from the crossing.
STATION_FRACTIONS = np.array([0.14, 0.18, 0.22, 0.26, 0.30, 0.34, 0.38])
#: Each profile is the mean of parallel profiles this far along the bar, px (averages noise).
ALONG_PX = np.linspace(-2.0, 2.0, 5)
#: Sampling step along a profile, px.
STEP_PX = 0.25
#: Fewest bar centres (of the 14 stations of a bar) for a line fit.
MIN_STATIONS = 6
#: A bar's depth must exceed this many times the rms noise of the tiles beside it.
NOISE_FACTOR = 2.5
#: Fewest bar centres on each of the 4 arms of a crossing (a T-junction or a bar ending at
#: a wall is not a crossing).
MIN_PER_ARM = 2
#: Largest rms of the bar centres about their line, px.
MAX_LINE_RMS_PX = 0.5
#: Bar centres farther than max(this, 3 rms) from the first line fit are dropped, px.
OUTLIER_FLOOR_PX = 0.25
#: Largest distance from the final homography of an accepted corner, px.
FINAL_THRESHOLD_PX = 1.0
#: The tile levels on the two sides of a bar may differ by at most this fraction of the bar's
#: depth (a bar next to a wall or a lamp is an edge, and its centre would be biased).
MAX_FLANK_STEP = 0.5
#: At most this many grid lines per axis are considered.
MAX_LINES = 400


@dataclass(frozen=True)
class CeilingGrid:
    """The T-bar lattice of the ceiling in world coordinates.

    Attributes
    ----------
    spacing_mm : tuple of float
        (sx, sy), distance between the T-bar centre lines along X and along Y, mm.
    origin_mm : tuple of float
        (x0, y0), world position of one crossing, mm.
    bar_width_mm : float
        Visible width of a T-bar, mm.
    """

    spacing_mm: tuple[float, float] = (600.0, 1200.0)
    origin_mm: tuple[float, float] = (0.0, 0.0)
    bar_width_mm: float = 15.0

    def __post_init__(self):
        sx, sy = (float(v) for v in self.spacing_mm)
        if not (np.isfinite([sx, sy]).all() and sx > 0 and sy > 0):
            raise CalibrationError(f"ceiling grid: spacing must be two numbers > 0 (mm), got {self.spacing_mm}")
        if not np.isfinite(self.origin_mm).all() or len(self.origin_mm) != 2:
            raise CalibrationError(f"ceiling grid: origin must be two finite numbers (mm), got {self.origin_mm}")
        if not (np.isfinite(self.bar_width_mm) and 0 < self.bar_width_mm < 0.1 * min(sx, sy)):
            raise CalibrationError(f"ceiling grid: bar width must be > 0 and < 10 % of the spacing, "
                                   f"got {self.bar_width_mm} mm")


class GridCorners(NamedTuple):
    """Grid crossings found in an image."""

    image_uv: np.ndarray
    """(N, 2) refined image positions (u, v), px."""
    world_xy: np.ndarray
    """(N, 2) world positions (X, Y) of the same crossings, mm."""


def _gray(image, polarity):
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] in (3, 4):
        img = img[..., :3].astype(np.float64) @ np.array([0.114, 0.587, 0.299])   # BGR (OpenCV order)
    if img.ndim != 2 or min(img.shape) < 16:
        raise CalibrationError(f"find_grid_corners: expected a grey (H, W) or BGR (H, W, 3) image, got shape "
                               f"{np.shape(image)}")
    img = img.astype(np.float64)
    if polarity not in ("dark", "light"):
        raise CalibrationError(f"find_grid_corners: polarity must be 'dark' or 'light', got {polarity!r}")
    return img if polarity == "dark" else -img


def _jacobian(H, W):
    """Image points (..., 2) and d(u, v)/d(X, Y) (..., 2, 2) of world points W (..., 2)."""
    q = W @ H[:, :2].T + H[:, 2]
    w = q[..., 2:3]
    uv = q[..., :2] / w
    J = (H[None, :2, :2] - uv[..., :, None] * H[None, 2:3, :2]) / w[..., None]
    return uv, J


def _lattice(H, grid, shape, sign, bounds_mm, min_spacing_px):
    """World crossings (K, 2) in view whose neighbours are >= min_spacing_px away in the image."""
    h, w = shape
    uu, vv = np.meshgrid(np.linspace(0, w - 1, 33), np.linspace(0, h - 1, 33))
    P = np.stack([uu.ravel(), vv.ravel(), np.ones(uu.size)])
    Xh = np.linalg.solve(H, P)
    good = np.sign(Xh[2]) == sign
    good &= np.abs(Xh[2]) > 1e-12 * np.abs(Xh).max(axis=0)
    if not good.any():
        return np.zeros((0, 2))
    XY = (Xh[:2, good] / Xh[2, good]).T
    lo, hi = XY.min(axis=0), XY.max(axis=0)
    if bounds_mm is not None:
        lo = np.maximum(lo, [bounds_mm[0], bounds_mm[2]])
        hi = np.minimum(hi, [bounds_mm[1], bounds_mm[3]])
    sp, org = np.asarray(grid.spacing_mm, float), np.asarray(grid.origin_mm, float)
    i0, i1 = np.ceil((lo - org) / sp - 1e-9), np.floor((hi - org) / sp + 1e-9)
    centre = np.round((XY.mean(axis=0) - org) / sp)
    i0, i1 = np.maximum(i0, centre - MAX_LINES // 2), np.minimum(i1, centre + MAX_LINES // 2)
    if np.any(i1 < i0):
        return np.zeros((0, 2))
    ii, jj = np.meshgrid(np.arange(i0[0], i1[0] + 1), np.arange(i0[1], i1[1] + 1), indexing="ij")
    W = org + np.stack([ii.ravel(), jj.ravel()], axis=1) * sp
    q = W @ H[:, :2].T + H[:, 2]
    keep = np.sign(q[:, 2]) == sign
    W = W[keep]
    uv, J = _jacobian(H, W)
    keep = (uv[:, 0] >= 0) & (uv[:, 0] <= w - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= h - 1)
    keep &= np.linalg.norm(J[..., 0], axis=-1) * sp[0] >= min_spacing_px
    keep &= np.linalg.norm(J[..., 1], axis=-1) * sp[1] >= min_spacing_px
    return W[keep]


def _box_means(vals, valid, lo, hi):
    """Mean of vals[p, lo:hi] (P, M) for index arrays lo, hi (P, C); NaN where any invalid."""
    P, M = vals.shape
    cs = np.concatenate([np.zeros((P, 1)), np.cumsum(np.where(valid, vals, 0.0), axis=1)], axis=1)
    cn = np.concatenate([np.zeros((P, 1)), np.cumsum(~valid, axis=1)], axis=1)
    lo, hi = np.clip(lo, 0, M), np.clip(hi, 0, M)
    n = hi - lo
    s = np.take_along_axis(cs, hi, 1) - np.take_along_axis(cs, lo, 1)
    bad = (np.take_along_axis(cn, hi, 1) - np.take_along_axis(cn, lo, 1)) > 0
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(bad | (n <= 0), np.nan, s / n)


def _bar_centres(prof, s, width_px, radius_px, min_contrast):
    """Sub-pixel bar centre offsets (P,) along profiles (P, M) sampled at s (M,); NaN if none."""
    valid = np.isfinite(prof)
    cand = np.flatnonzero(np.abs(s) <= radius_px.max())                   # candidate centres only
    m = cand[None, :]
    hi_in = np.maximum(np.round(0.5 * width_px / STEP_PX), 2).astype(int)[:, None]
    wo = np.maximum(np.round(width_px / STEP_PX), 4).astype(int)[:, None]
    inner = _box_means(prof, valid, m - hi_in, m + hi_in + 1)
    left = _box_means(prof, valid, m - hi_in - wo, m - hi_in)
    right = _box_means(prof, valid, m + hi_in + 1, m + hi_in + 1 + wo)
    resp = 0.5 * (left + right) - inner
    resp = np.where(np.isfinite(resp) & (np.abs(s[cand])[None, :] <= radius_px[:, None]), resp, -np.inf)
    c = s[cand][np.argmax(resp, axis=1)]
    ok = np.max(resp, axis=1) > 0
    half = 0.5 * width_px + 1.0
    fw = np.maximum(width_px, 2.0)
    for _ in range(4):
        t = s[None, :] - c[:, None]
        win = np.clip(half[:, None] - np.abs(t) + 0.5, 0.0, 1.0)           # tapered window
        fl = valid & (np.abs(t) > half[:, None] + 0.5) & (np.abs(t) <= (half + 0.5 + fw)[:, None])
        pv = np.where(valid, prof, 0.0)
        S0, S1, S2 = fl.sum(1), (fl * t).sum(1), (fl * t * t).sum(1)
        Z0, Z1 = (fl * pv).sum(1), (fl * t * pv).sum(1)
        det = S0 * S2 - S1 * S1
        with np.errstate(invalid="ignore", divide="ignore"):
            a = (Z0 * S2 - Z1 * S1) / det
            b = (S0 * Z1 - S1 * Z0) / det
            dark = np.where(valid, (a[:, None] + b[:, None] * t - pv) * win, np.nan)
            total = np.sum(dark, axis=1)
            c = c + np.sum(dark * t, axis=1) / total
    res = np.where(fl, pv - (a[:, None] + b[:, None] * t), 0.0)
    with np.errstate(invalid="ignore", divide="ignore"):
        noise = np.sqrt((res**2).sum(1) / np.maximum(S0 - 2, 1))
        peak = np.nanmax(np.where(win > 0, dark, -np.inf), axis=1)
        left = (fl * (t < 0) * pv).sum(1) / (fl * (t < 0)).sum(1)
        right = (fl * (t > 0) * pv).sum(1) / (fl * (t > 0)).sum(1)
    ok &= (S0 >= 6) & (total > 0) & (peak > np.maximum(min_contrast, NOISE_FACTOR * noise))
    ok &= np.abs(left - right) <= MAX_FLANK_STEP * peak               # a valley, not an edge
    ok &= np.abs(c) <= radius_px + 0.5
    return np.where(ok, c, np.nan)


def _fit_lines(pts, ok):
    """TLS lines through the valid points (L, S, 2): unit normals (L, 2), offsets, rms, counts."""
    normal = np.zeros(pts.shape[:-2] + (2,))
    offset = np.zeros(pts.shape[:-2])
    rms = np.full(pts.shape[:-2], np.inf)
    for _ in range(2):                                  # fit, drop outliers, refit
        w = ok.astype(float)
        n = w.sum(-1)
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = (w[..., None] * np.where(ok[..., None], pts, 0.0)).sum(-2) / n[..., None]
            d = np.where(ok[..., None], pts - mean[..., None, :], 0.0)
            cxx, cxy, cyy = (d[..., 0] ** 2).sum(-1), (d[..., 0] * d[..., 1]).sum(-1), (d[..., 1] ** 2).sum(-1)
            theta = 0.5 * np.arctan2(2 * cxy, cxx - cyy)
            normal = np.stack([-np.sin(theta), np.cos(theta)], axis=-1)
            offset = (normal * mean).sum(-1)
            r = np.where(ok, (d * normal[..., None, :]).sum(-1), 0.0)
            rms = np.sqrt((r**2).sum(-1) / np.maximum(n - 2, 1))
        ok = ok & (np.abs(r) <= np.maximum(3.0 * rms, OUTLIER_FLOOR_PX)[..., None])
    return normal, offset, rms, ok.sum(-1)


def _refine_crossings(gray, H, W, grid, radius_px, min_contrast):
    """Refined image positions (K, 2) of the crossings W (K, 2) and which were found (K,)."""
    from scipy.ndimage import map_coordinates

    sx, sy = grid.spacing_mm
    f = np.concatenate([-STATION_FRACTIONS[::-1], STATION_FRACTIONS])
    S = len(f)
    st = np.empty((len(W), 2, S, 2))
    st[:, 0] = W[:, None, :] + f[None, :, None] * np.array([0.0, sy])     # bar X = const, runs along Y
    st[:, 1] = W[:, None, :] + f[None, :, None] * np.array([sx, 0.0])     # bar Y = const, runs along X
    uv, J = _jacobian(H, st)
    along = np.stack([J[:, 0, :, :, 1], J[:, 1, :, :, 0]], axis=1)       # image of e_y, e_x
    across = np.stack([J[:, 0, :, :, 0], J[:, 1, :, :, 1]], axis=1)
    d = along / np.linalg.norm(along, axis=-1, keepdims=True)
    n = np.stack([-d[..., 1], d[..., 0]], axis=-1)
    gain = np.abs((n * across).sum(-1))                                   # px per mm across the bar
    width_px = grid.bar_width_mm * gain
    spacing_px = np.stack([sx * gain[:, 0], sy * gain[:, 1]], axis=1)
    radius = np.minimum(radius_px, 0.3 * spacing_px)
    L = radius_px + 2.0 * float(width_px.max()) + 4.0
    s = np.arange(-L, L + 1e-9, STEP_PX)
    coords = (uv[..., None, None, :] + s[:, None, None] * n[..., None, None, :]
              + ALONG_PX[:, None] * d[..., None, None, :])               # (K, 2, S, M, A, 2)
    prof = map_coordinates(gray, [coords[..., 1].ravel(), coords[..., 0].ravel()], order=1,
                           mode="constant", cval=np.nan).reshape(coords.shape[:-1]).mean(axis=-1)
    c = _bar_centres(prof.reshape(-1, len(s)), s, width_px.ravel(), radius.ravel(), min_contrast)
    c = c.reshape(width_px.shape)
    ok = np.isfinite(c)
    centres = uv + np.where(ok, c, 0.0)[..., None] * n
    normal, offset, rms, count = _fit_lines(centres, ok)
    half = S // 2
    arms_ok = (ok[..., :half].sum(-1) >= MIN_PER_ARM) & (ok[..., half:].sum(-1) >= MIN_PER_ARM)
    line_ok = (count >= MIN_STATIONS) & (rms <= MAX_LINE_RMS_PX) & arms_ok
    n0, n1, c0, c1 = normal[:, 0], normal[:, 1], offset[:, 0], offset[:, 1]
    det = n0[:, 0] * n1[:, 1] - n0[:, 1] * n1[:, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        p = np.stack([(c0 * n1[:, 1] - c1 * n0[:, 1]) / det, (n0[:, 0] * c1 - n1[:, 0] * c0) / det], axis=1)
    found = line_ok.all(axis=1) & (np.abs(det) > 0.1)
    found &= np.linalg.norm(p - apply_homography(H, W), axis=1) <= radius_px + 1.0
    return p, found


def find_grid_corners(image, grid=CeilingGrid(), *, initial_H=None, seed_world=None, seed_image=None,
                      search_px=10.0, bounds_mm=None, polarity="dark", min_spacing_px=12.0,
                      min_contrast=None, rng=0) -> GridCorners:
    """Find the crossings of the ceiling's T-bars in an image, to sub-pixel accuracy.

    Parameters
    ----------
    image : ndarray, shape (H, W) or (H, W, 3)
        Reference image of the ceiling, grey or BGR (OpenCV's channel order).
    grid : CeilingGrid, optional
        Spacing, origin and bar width of the lattice, mm.
    initial_H : array_like, shape (3, 3), optional
        Approximate ``H_image_world`` (world mm → image px); or give the seeds instead.
    seed_world, seed_image : array_like, shape (N, 2), optional
        N >= 4 approximately located crossings: world (X, Y) mm, image (u, v) px (e.g. four
        clicks; a few px off is fine).
    search_px : float, optional
        How far from its predicted position a bar may be found in the first pass, px.
    bounds_mm : tuple of float, optional
        (X_min, X_max, Y_min, Y_max): only crossings in this world rectangle, mm.
    polarity : {"dark", "light"}, optional
        T-bars darker (default) or lighter than the tiles.
    min_spacing_px : float, optional
        Skip crossings whose neighbours are closer than this in the image (far away, near
        the horizon), px.
    min_contrast : float, optional
        Least depth of a bar below the tile, in grey levels; default 2 % of the image's
        1–99 % intensity range.
    rng : numpy.random.Generator or int or None, optional
        RANSAC's samples (default fixed: the same image gives the same corners).

    Returns
    -------
    GridCorners
        ``(image_uv (N, 2) px, world_xy (N, 2) mm)``, the crossings found, each within
        ``FINAL_THRESHOLD_PX`` of the homography fitted to all of them.

    Raises
    ------
    CalibrationError
        Neither or both of ``initial_H`` and the seeds, bad seeds, a bad image, or fewer
        than 4 crossings found.
    """
    gray = _gray(image, polarity)
    if (initial_H is None) == (seed_world is None and seed_image is None):
        raise CalibrationError("find_grid_corners: give either initial_H or seed_world and seed_image "
                               "(4 or more approximate grid corners)")
    if initial_H is not None:
        H = np.asarray(initial_H, dtype=np.float64)
        if H.shape != (3, 3) or not np.isfinite(H).all() or np.linalg.cond(H) > 1e12:
            raise CalibrationError("find_grid_corners: initial_H must be a finite, invertible 3x3 matrix")
        anchor = np.array([(gray.shape[1] - 1) / 2, (gray.shape[0] - 1) / 2])
    else:
        sw, si = check_correspondences(seed_world, seed_image, names=("seed world", "seed image"))
        H = homography_dlt(sw, si, check=False)
        anchor = si.mean(axis=0)
    sign = np.sign(np.linalg.solve(H, np.append(anchor, 1.0))[2])
    if min_contrast is None:
        p1, p99 = np.percentile(gray, [1, 99])
        min_contrast = 0.02 * (p99 - p1)
    uv = found = W = None
    for k, radius in enumerate((float(search_px), 3.0, 3.0)):
        W = _lattice(H, grid, gray.shape, sign, bounds_mm, min_spacing_px)
        uv, found = _refine_crossings(gray, H, W, grid, radius, min_contrast) if len(W) else (W, W[:, 0] > 0)
        if found.sum() < 4:
            raise CalibrationError(f"find_grid_corners: found {int(found.sum())} grid crossings within "
                                   f"{radius:g} px of their predicted positions ({len(W)} predicted in view); "
                                   "expected at least 4: check the seed points, grid spacing and origin")
        thr = 2.0 if k == 0 else FINAL_THRESHOLD_PX
        Wf, uvf = W[found], uv[found]
        H, inl = homography_ransac(Wf, uvf, thr, rng=rng, check=False)
        H = refine_homography(H, Wf[inl], uvf[inl], check=False)
        found[np.flatnonzero(found)[~inl]] = False
    return GridCorners(uv[found], W[found])
