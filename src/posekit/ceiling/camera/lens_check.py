"""Do the calibration points agree with the lens model? The radial pattern of a plain homography's
residuals (:func:`radial_pattern`: the signature of lens distortion left in the points), and the
calibration of ``posekit ceiling calibrate`` checked by it (:func:`calibrate_points`: ``suspect``
when the points contradict the lens model given).

Pixels: u to the right, v down, the centre of the top-left pixel at (0, 0); ceiling points in mm.
"""

import math
from typing import NamedTuple

import numpy as np

from ...geometry import apply_homography, homography_dlt, refine_homography
from .homography import Calibration, calibrate
from .points import undistort_calibration_points

__all__ = ["RadialPattern", "radial_pattern", "MIN_INLIER_SHARE", "calibrate_points"]


class RadialPattern(NamedTuple):
    """The radial part of calibration residuals (:func:`radial_pattern`)."""

    detected: bool
    """True: the residuals grow with the distance from the centre like lens distortion."""
    k_r3_px: float
    """Coefficient of r³ in the radial residual, px at r = 1 (r normalised by the largest radius)."""
    t_stat: float
    """Its t statistic."""
    explained: float
    """Fraction of the residuals' sum of squares the radial model [r, r³] explains (0..1)."""
    rms_px: float
    """Rms residual of the least-squares homography over all points, px."""
    rms_after_px: float
    """Rms residual left after removing the radial model, px."""
    centre: np.ndarray
    """Centre the radius was measured from, px (image centre, or the points' bounding box)."""
    n: int
    """Points used."""
    off_px: np.ndarray | None = None
    """Per point, the distance of its residual from the radial model, px (a point far off it is
    a mis-click, one on it follows the lens)."""


#: A radial pattern must explain at least this fraction of the residuals' sum of squares ...
RADIAL_EXPLAINED = 0.6
#: ... with an r³ coefficient of at least this t statistic ...
RADIAL_T = 6.0
#: ... on residuals of at least this rms, px (below it, clicking noise dominates).
RADIAL_MIN_RMS_PX = 0.5


def radial_pattern(world_xy, image_uv, *, centre=None) -> RadialPattern:
    """Do the residuals of a plain homography show lens distortion?

    Fits one homography to all points (least squares in the image), takes each point's residual
    along the ray from ``centre`` (default: the centre of the points' bounding box, which is the
    image centre when the points fill the image, as the paper asks) and regresses it on
    ``[r, r³]`` (r: distance from the centre / the largest one). The part proportional to r is
    absorbed by the homography's scale; a significant r³ term that explains most of the
    residuals is the signature of radial distortion. Two rounds: points more than 4 robust
    sigmas off the radial model (mis-clicks) are left out of the second.

    Returns
    -------
    RadialPattern
    """
    world = np.asarray(world_xy, dtype=float).reshape(-1, 2)
    image = np.asarray(image_uv, dtype=float).reshape(-1, 2)
    n = len(world)
    c = (np.asarray(centre, dtype=float) if centre is not None
         else 0.5 * (image.min(axis=0) + image.max(axis=0)))
    nothing = RadialPattern(False, 0.0, 0.0, 0.0, 0.0, 0.0, c, n)
    if n < 8:
        return nothing
    use = np.ones(n, dtype=bool)
    result = nothing
    if centre is None:                              # the centre of distortion: search near the bbox centre
        span = image.max(axis=0) - image.min(axis=0)
        grid = np.linspace(-0.3, 0.3, 7)
        centres = [c + span * np.array([a, b]) for a in grid for b in grid]
    else:
        centres = [c]
    for _ in range(2):
        try:
            H = homography_dlt(world[use], image[use], check=False)
            H = refine_homography(H, world[use], image[use], check=False)
        except Exception:                                   # degenerate subsets: no verdict
            return nothing
        e = apply_homography(H, world, invalid="nan") - image
        fits = [_radial_fit(e, image, cc, use) for cc in centres]
        fits = [f for f in fits if f is not None]
        if not fits:
            return nothing
        result, full_off = max(fits, key=lambda f: f[0].explained)
        mad = 1.4826 * np.median(full_off[use & np.isfinite(full_off)]) + 1e-9
        new = np.isfinite(full_off) & (full_off <= 4.0 * mad + 0.5)
        if new.sum() < 8 or np.array_equal(new, use):
            break
        use = new
    if result.detected:
        off, rms_after = _radial_homography_off(world, image, result.centre, H)
        result = result._replace(off_px=off, rms_after_px=rms_after)
    return result


def _radial_homography_off(world, image, c, H0):
    """Per-point residual (px) of a homography followed by radial distortion about ``c``
    (``uv = c + (Hx − c)(1 + k1 ρ² + k2 ρ⁴)``, ρ normalised by the largest radius, the centre
    free near ``c``), fitted by
    robust least squares (soft-L1, 1 px), and the rms over the points within 3 px."""
    from scipy.optimize import least_squares

    s = max(float(np.max(np.hypot(*(image - c).T))), 1.0)

    def model(x):
        H = np.append(x[:8], 1.0).reshape(3, 3)
        cc = c + s * x[10:12]
        q = apply_homography(H, world, invalid="nan") - cc
        rho2 = np.sum(q ** 2, axis=1) / s ** 2
        return cc + q * (1.0 + x[8] * rho2 + x[9] * rho2 ** 2)[:, None]

    def resid(x):
        return np.nan_to_num((model(x) - image).ravel(), nan=1e6)

    x0 = np.concatenate([(H0 / H0[2, 2]).ravel()[:8], [0.0, 0.0, 0.0, 0.0]])
    try:
        sol = least_squares(resid, x0, loss="soft_l1", f_scale=1.0, max_nfev=400)
        off = np.linalg.norm(model(sol.x) - image, axis=1)
    except (ValueError, np.linalg.LinAlgError):
        return None, math.nan
    good = off <= 3.0
    return off, (math.sqrt(float(np.mean(off[good] ** 2))) if good.any() else math.nan)


def _radial_fit(e: np.ndarray, image: np.ndarray, c: np.ndarray, use: np.ndarray):
    """Regression of the radial residual on [r, r³] about ``c``: (RadialPattern, per-point
    distance of the residual from the radial model, px), or None with too few points."""
    d = image - c
    rad = np.hypot(d[:, 0], d[:, 1])
    r = rad / max(rad.max(), 1e-9)
    with np.errstate(invalid="ignore", divide="ignore"):
        er = np.where(rad > 1e-9, np.sum(e * d, axis=1) / np.maximum(rad, 1e-12), 0.0)
    ok = use & np.isfinite(er)
    if ok.sum() < 8:
        return None
    A_all = np.column_stack([r, r ** 3])
    A = A_all[ok]
    beta, *_ = np.linalg.lstsq(A, er[ok], rcond=None)
    rss1 = float(np.sum((er[ok] - A @ beta) ** 2))
    e2 = np.sum(e ** 2, axis=1)
    tangential = float(np.sum(np.maximum(e2[ok] - er[ok] ** 2, 0.0)))
    total = float(np.sum(e2[ok]))
    dof = max(int(ok.sum()) - 2, 1)
    cov = np.linalg.pinv(A.T @ A) * (rss1 / dof)
    t = float(beta[1] / math.sqrt(cov[1, 1])) if cov[1, 1] > 0 else math.inf
    explained = 1.0 - (rss1 + tangential) / total if total > 0 else 0.0
    rms = math.sqrt(total / ok.sum())
    rms_after = math.sqrt(max(rss1 + tangential, 0.0) / ok.sum())
    detected = bool(abs(t) >= RADIAL_T and explained >= RADIAL_EXPLAINED and rms >= RADIAL_MIN_RMS_PX)
    off = np.hypot(er - A_all @ beta, np.sqrt(np.maximum(e2 - er ** 2, 0.0)))
    return RadialPattern(detected, float(beta[1]), t, float(explained), rms, rms_after, c, int(ok.sum()), off), off


#: A calibration whose RANSAC keeps fewer than this share of the points is suspect: the model
#: (homography, with the lens given) explains a minority of the data.
MIN_INLIER_SHARE = 0.5


def calibrate_points(world_xy, image_uv, *, camera=None, lines=None, image_size=None, refine=True, ransac=None,
                     threshold_px=3.0, rng=None) -> tuple[Calibration, "RadialPattern | None"]:
    """``posekit ceiling calibrate``: the homography from clicked points, checked against the lens.

    Parameters
    ----------
    world_xy : array_like, shape (N, 2)
        Ceiling points, mm.
    image_uv : array_like, shape (N, 2)
        Their pixels *as seen* (distorted by the lens when ``camera`` is given), px.
    camera : CameraModel, optional
        The lens: pixels are undistorted before the homography, and the residuals are tested
        for the radial pattern of a lens model the points contradict (k1 of the wrong sign, the
        file of another camera).
    lines : array_like of int, optional
        The points' lines in their file, to name them.
    image_size : (int, int), optional
        Of the images the points were clicked in (default the camera's).
    refine, ransac, threshold_px, rng :
        As :func:`calibrate`.

    Returns
    -------
    calibration : Calibration
        ``status`` ``"suspect"`` with ``reasons`` when the points contradict the lens model (a
        significant radial pattern left after undistortion: :func:`radial_pattern`, or RANSAC
        kept fewer than :data:`MIN_INLIER_SHARE` of them); without a lens model the radial
        pattern is only the hint to calibrate one. ``image_size``, ``points_extent`` and
        ``camera`` set.
    radial : RadialPattern or None
        The radial test of the residuals (without a camera: of the raw pixels, the hint to
        calibrate the lens).
    """
    seen = np.asarray(image_uv, dtype=float).reshape(-1, 2)
    image = seen if camera is None else undistort_calibration_points(camera, seen, lines)
    cal = calibrate(world_xy, image, refine=refine, ransac=ransac, threshold_px=threshold_px, rng=rng)
    cal.camera = camera
    cal.image_size = tuple(image_size) if image_size is not None else (
        None if camera is None else tuple(camera.image_size))
    cal.points_extent = (float(seen[:, 0].min()), float(seen[:, 1].min()), float(seen[:, 0].max()),
                         float(seen[:, 1].max()))
    radial = radial_pattern(world_xy, image)
    reasons = []
    n, n_in = int(cal.n_points), int(cal.inliers.sum())
    names = [f"line {lines[k]}" if lines is not None else f"point {k}" for k in np.flatnonzero(~cal.inliers)]
    shown = ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")
    if camera is not None and radial.detected:
        reasons.append(f"the points contradict the lens model: after undistortion a radial pattern of "
                       f"{radial.rms_px:.1f} px rms remains (r^3 term {radial.k_r3_px:+.1f} px, t = {radial.t_stat:.1f}); "
                       "a wrong or another camera's CAMERA.json (k1's sign?)")
    if camera is not None and n_in < MIN_INLIER_SHARE * n:
        reasons.append(f"RANSAC kept {n_in} of {n} points")
    if reasons:
        if names:
            reasons.append(f"rejected: {shown}")
        cal.status, cal.reasons = "suspect", tuple(reasons)
    return cal, radial
