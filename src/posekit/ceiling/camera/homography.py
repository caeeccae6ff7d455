"""Camera calibration of the ceiling system: the homography between the ceiling and the image.

The paper (§IV-A) calibrates the fixed camera with the 3×3 homography of eq. (1) from a few
corners of the ceiling grid whose world and image positions are known, by the normalized
DLT. Here that estimate is made robust to a mis-clicked point (RANSAC, from 6 points on) and
refined by minimising the reprojection error in the image.

Frames and units: world (X, Y) on the ceiling plane, in mm (any unit works; it carries through
to ``rms_world`` and the tracked positions); image (u, v) in px, u to the right, v down, the
centre of the top-left pixel at (0, 0) (OpenCV's convention, the one of ``cv2.moments``).
Both homographies are scaled so that ``H[2, 2] == 1``.
"""

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ...errors import CalibrationError
from ...geometry import (
    apply_homography,
    check_correspondences,
    homography_dlt,
    homography_ransac,
    normalize_homography,
    refine_homography,
)
from ...io import check_rows, load_json, number_array, parse_number, read_text, write_text_atomic

__all__ = [
    "Calibration",
    "calibrate_points",
    "CalibrationPoints",
    "RadialPattern",
    "calibrate",
    "undistort_calibration_points",
    "point_residuals",
    "radial_pattern",
    "load_calibration",
    "read_points_csv",
    "write_points_csv",
]

#: The keys of a calibration JSON file (``posekit ceiling calibrate --out``), in order.
JSON_KEYS = ("H_image_world", "H_world_image", "rms_px", "rms_world")
#: Header of a calibration-points CSV file.
CSV_HEADER = ("X", "Y", "u", "v")
#: A homography whose condition number exceeds this is singular.
MAX_COND = 1e12
#: ``H_world_image @ H_image_world`` must be within this (relative) of a multiple of I.
INVERSE_TOL = 1e-6
#: RANSAC is on by default from this many points.
RANSAC_MIN_POINTS = 6
#: Most calibration points a file or a call may hold. A ceiling grid seen by one camera has tens
#: to hundreds of crossings; at this limit RANSAC and the refinement take about a second.
MAX_POINTS = 10_000
#: Two points closer than this (Hartley-normalized units, mean distance √2) coincide: twice the
#: homography's own test, so that test never meets a pile of coinciding points (it lists every
#: pair: N² of them for N copies of one point).
_COINCIDE_TOL = 2e-9


@dataclass(eq=False)
class Calibration:
    """The homography between the ceiling (world) plane and the image, with its accuracy.

    Attributes
    ----------
    H_image_world : ndarray, shape (3, 3)
        Maps world (X, Y) [mm] to image (u, v) [px]: ``[u, v, 1] ~ H @ [X, Y, 1]``.
    H_world_image : ndarray, shape (3, 3)
        Its inverse, image → world.
    rms_px : float
        Root mean square of the reprojection distance ``‖H(X, Y) - (u, v)‖`` over the
        inliers, px.
    rms_world : float
        Root mean square of ``‖H⁻¹(u, v) - (X, Y)‖`` over the inliers, world units (mm).
    inliers : ndarray of bool, shape (n_points,), or None
        Which calibration points were used (False: rejected by RANSAC); None when unknown.
    n_points : int or None
        Number of calibration points; None when unknown (a file without the key).
    """

    H_image_world: np.ndarray
    H_world_image: np.ndarray
    rms_px: float
    rms_world: float
    inliers: np.ndarray | None = None
    n_points: int | None = None
    camera: object | None = None
    """The :class:`~posekit.ceiling.camera.CameraModel` whose undistorted pixels the homography
    maps (``calibrate --camera``), or None: pixels as seen (a distortion-free camera). The
    homography never undistorts by itself: undistort detected points with this camera first."""
    image_size: tuple | None = None
    """``(width, height)`` px of the images the points were taken in, when known (``--camera``,
    ``--from-image``, ``--image-size``); ``track`` refuses frames of another shape (and scales
    the homography for the same shape at another resolution)."""
    points_extent: tuple | None = None
    """``(u_min, v_min, u_max, v_max)`` px of the calibration points as seen."""
    status: str = "ok"
    """``"ok"``, or ``"suspect"`` when the points contradict the model (the lens file's radial
    pattern left in the residuals); ``track`` then never marks a row ``ok``."""
    reasons: tuple = ()
    """Why the calibration is suspect (empty when ``ok``)."""
    rms_all_px: float = float("nan")
    """Rms reprojection distance over every point, rejected ones included, px."""

    def image_to_world(self, uv, *, invalid="raise"):
        """Map image points to the ceiling.

        Parameters
        ----------
        uv : array_like, shape (..., 2)
            Image points (u, v), px.
        invalid : {"raise", "nan"}, optional
            A pixel on the ceiling's horizon maps to infinity: raise ``GeometryError``
            (default) or return NaN for it.

        Returns
        -------
        XY : ndarray, shape (..., 2)
            World points (X, Y) on the ceiling, mm.
        """
        return apply_homography(self.H_world_image, uv, invalid=invalid)

    def world_to_image(self, XY, *, invalid="raise"):
        """Map ceiling points to the image.

        Parameters
        ----------
        XY : array_like, shape (..., 2)
            World points (X, Y), mm.
        invalid : {"raise", "nan"}, optional
            As :meth:`image_to_world`.

        Returns
        -------
        uv : ndarray, shape (..., 2)
            Image points (u, v), px.
        """
        return apply_homography(self.H_image_world, XY, invalid=invalid)

    def to_json(self, path):
        """Write the calibration file of ``posekit ceiling calibrate`` (``H_image_world``, ``H_world_image``,
        ``rms_px``, ``rms_world``, then ``n_points`` and ``inliers`` when known)."""
        data = {"H_image_world": np.asarray(self.H_image_world, dtype=float).tolist(),
                "H_world_image": np.asarray(self.H_world_image, dtype=float).tolist(),
                "rms_px": float(self.rms_px), "rms_world": float(self.rms_world)}
        if self.n_points is not None:
            data["n_points"] = int(self.n_points)
        if self.inliers is not None:
            data["inliers"] = [bool(b) for b in self.inliers]
        if self.camera is not None:
            data["undistorted"] = True              # H maps undistorted pixels: track needs --camera
            data["camera"] = self.camera.to_json()
        if self.image_size is not None:
            data["image_size"] = [int(self.image_size[0]), int(self.image_size[1])]
        if self.points_extent is not None:
            data["points_extent"] = [round(float(v), 3) for v in self.points_extent]
        if math.isfinite(self.rms_all_px):
            data["rms_all_px"] = float(self.rms_all_px)
        data["status"] = self.status
        data["reasons"] = list(self.reasons)
        text = "{\n" + ",\n".join(f"  {json.dumps(k)}: {json.dumps(v)}" for k, v in data.items()) + "\n}\n"
        write_text_atomic(path, text, error=CalibrationError)


def calibrate(world_xy, image_uv, *, refine=True, ransac=None, threshold_px=3.0, rng=None) -> Calibration:
    """Calibrate the camera from corresponding ceiling and image points (paper §IV-A).

    Parameters
    ----------
    world_xy : array_like, shape (N, 2)
        Points (X, Y) on the ceiling plane, mm; N >= 4, no 3 of 4 on a line.
    image_uv : array_like, shape (N, 2)
        Their images (u, v), px.
    refine : bool, optional
        Minimise the reprojection error in the image after the DLT (default).
    ransac : bool or None, optional
        Reject mismatched points by RANSAC; None (default) turns it on from 6 points.
    threshold_px : float, optional
        RANSAC inlier threshold on the reprojection distance, px.
    rng : numpy.random.Generator or int or None, optional
        RANSAC's random samples; up to 20 points every 4-point sample is tried and the result
        does not depend on it.

    Returns
    -------
    Calibration

    Raises
    ------
    CalibrationError
        Degenerate points (fewer than 4, more than :data:`MAX_POINTS`, two that coincide, on
        one line, ...).
    """
    _check_count_and_distinct(world_xy, image_uv)
    world, image = check_correspondences(world_xy, image_uv, names=("world", "image"))
    n = len(world)
    use_ransac = n >= RANSAC_MIN_POINTS if ransac is None else bool(ransac)
    if use_ransac:
        H, inliers = homography_ransac(world, image, threshold_px, rng=rng, check=False)
    else:
        H, inliers = homography_dlt(world, image, check=False), np.ones(n, dtype=bool)
    if refine:
        for _ in range(3):
            H = refine_homography(H, world[inliers], image[inliers], check=False)
            if not use_ransac:
                break
            err = np.linalg.norm(apply_homography(H, world, invalid="nan") - image, axis=1)
            new = err <= threshold_px
            if new.sum() < 4 or np.array_equal(new, inliers):
                break
            inliers = new
    if np.linalg.cond(H) > MAX_COND:
        raise CalibrationError("calibrate: the homography is singular; the points are inconsistent "
                               "(swapped or mistyped coordinates?)")
    H_world_image = normalize_homography(np.linalg.inv(H))
    w_in, i_in = world[inliers], image[inliers]
    rms_px = math.sqrt(float(np.mean(np.sum((apply_homography(H, w_in) - i_in) ** 2, axis=1))))
    rms_world = math.sqrt(float(np.mean(np.sum((apply_homography(H_world_image, i_in) - w_in) ** 2, axis=1))))
    e_all = np.sum((apply_homography(H, world, invalid="nan") - image) ** 2, axis=1)
    rms_all = math.sqrt(float(np.nanmean(e_all))) if np.isfinite(e_all).any() else math.nan
    return Calibration(H, H_world_image, rms_px, rms_world, inliers, n, rms_all_px=rms_all)


def undistort_calibration_points(camera, image_uv, lines=None) -> np.ndarray:
    """Undistorted pixels (N, 2) of calibration points ``image_uv`` (N, 2) px with ``camera``.

    Raises
    ------
    CalibrationError
        A point outside the lens model's image circle (no ray is imaged there), naming its line
        (``lines``, as read from the CSV) or its index.
    """
    uv = np.asarray(image_uv, dtype=float).reshape(-1, 2)
    und = camera.undistort_points(uv)
    bad = np.flatnonzero(~np.isfinite(und).all(axis=1))
    if bad.size:
        k = int(bad[0])
        where = f"line {lines[k]}" if lines is not None else f"point {k}"
        raise CalibrationError(f"{where}: u={uv[k, 0]:g} v={uv[k, 1]:g} is outside the image circle of the "
                               "camera's lens model; expected pixels of the camera the --camera file describes")
    w, h = camera.image_size
    out = np.flatnonzero((uv[:, 0] < -0.5) | (uv[:, 1] < -0.5) | (uv[:, 0] > w - 0.5) | (uv[:, 1] > h - 0.5))
    if out.size:
        k = int(out[0])
        where = f"line {lines[k]}" if lines is not None else f"point {k}"
        raise CalibrationError(f"{where}: u={uv[k, 0]:g} v={uv[k, 1]:g} is outside the {w}x{h} image of the "
                               "--camera file; expected pixels of that camera")
    return und


def point_residuals(cal: "Calibration", world_xy, image_uv) -> tuple[np.ndarray, np.ndarray]:
    """Per-point residuals of a calibration: image (px, ``‖H(X, Y) − (u, v)‖``) and world
    (mm, ``‖H⁻¹(u, v) − (X, Y)‖``), each shape (N,); NaN where a point maps to infinity.
    ``image_uv`` in the pixels the homography maps (undistorted when calibrated with a camera)."""
    world = np.asarray(world_xy, dtype=float).reshape(-1, 2)
    image = np.asarray(image_uv, dtype=float).reshape(-1, 2)
    e_px = np.linalg.norm(cal.world_to_image(world, invalid="nan") - image, axis=1)
    e_mm = np.linalg.norm(cal.image_to_world(image, invalid="nan") - world, axis=1)
    return e_px, e_mm


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


def _check_count_and_distinct(world_xy, image_uv):
    """At most :data:`MAX_POINTS` points, and no two that coincide, found in O(N log N).

    The message of a coinciding pair is the homography's own (the first pair in index order).
    Malformed input (shape, non-finite values) is left to ``check_correspondences``.
    """
    from scipy.spatial import cKDTree

    for pts, name in ((world_xy, "world"), (image_uv, "image")):
        try:
            arr = np.asarray(pts, dtype=np.float64)
        except (TypeError, ValueError):
            return
        if arr.ndim != 2 or arr.shape[1] != 2:
            return
        if len(arr) > MAX_POINTS:
            raise CalibrationError(f"calibrate: {len(arr)} {name} points; expected at most {MAX_POINTS} "
                                   "(a ceiling grid in view has tens to hundreds of crossings)")
        if len(arr) < 2 or not np.isfinite(arr).all():
            continue
        q = arr - arr.mean(axis=0)
        d = np.sqrt(q[:, 0] ** 2 + q[:, 1] ** 2).mean()
        pn = q * (math.sqrt(2.0) / d if d > 0 else 1.0)
        tree = cKDTree(pn)
        dist, _ = tree.query(pn, k=2)                    # column 1: the nearest other point
        close = np.flatnonzero(dist[:, 1] <= _COINCIDE_TOL)
        if close.size:
            i = int(close[0])
            j = min(k for k in tree.query_ball_point(pn[i], _COINCIDE_TOL) if k != i)
            raise CalibrationError(f"homography: {name} points {i} and {j} coincide at "
                                   f"({arr[i, 0]:g}, {arr[i, 1]:g}); expected distinct points")


def _matrix(data, key, path):
    value = data[key]
    try:
        H = number_array(value, "", CalibrationError)      # never a boolean read as 1
    except CalibrationError:
        raise CalibrationError(f"{path}: '{key}' must be a 3x3 matrix of numbers, "
                               f"got {json.dumps(value)[:60]}") from None
    if H.shape != (3, 3):
        raise CalibrationError(f"{path}: '{key}' must be a 3x3 matrix of numbers, got shape {H.shape}")
    if not np.all(np.isfinite(H)):
        raise CalibrationError(f"{path}: '{key}' contains NaN or infinity; expected finite numbers")
    if np.linalg.cond(H) > MAX_COND:
        raise CalibrationError(f"{path}: '{key}' is singular; expected an invertible homography")
    return normalize_homography(H)


def _rms(data, key, path):
    value = data[key]
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
        raise CalibrationError(f"{path}: '{key}' must be a finite number >= 0, got {json.dumps(value)[:60]}")
    return float(value)


def load_calibration(path) -> Calibration:
    """Read a calibration JSON file written by :meth:`Calibration.to_json`.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Calibration

    Raises
    ------
    CalibrationError
        Missing or unreadable file, invalid JSON, a missing key, a matrix that is not 3x3,
        not finite or singular, two matrices that are not inverses of each other, a
        negative rms; the message names the file and the key.
    """
    path = Path(path)
    data = load_json(path, expected="a calibration JSON file", error=CalibrationError)
    if not isinstance(data, dict):
        raise CalibrationError(f"{path}: expected a JSON object with the keys {', '.join(JSON_KEYS)}")
    for key in JSON_KEYS:
        if key not in data:
            raise CalibrationError(f"{path}: missing key '{key}'; expected the keys {', '.join(JSON_KEYS)}")
    H_iw = _matrix(data, "H_image_world", path)
    H_wi = _matrix(data, "H_world_image", path)
    P = H_wi @ H_iw
    if np.abs(P / P[2, 2] - np.eye(3)).max() > INVERSE_TOL:
        raise CalibrationError(f"{path}: 'H_world_image' is not the inverse of 'H_image_world'")
    rms_px, rms_world = _rms(data, "rms_px", path), _rms(data, "rms_world", path)
    n_points = data.get("n_points")
    if n_points is not None and (isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 0):
        raise CalibrationError(f"{path}: 'n_points' must be an integer >= 0, got {json.dumps(n_points)[:60]}")
    inliers = data.get("inliers")
    if inliers is not None:
        if not (isinstance(inliers, list) and all(isinstance(b, bool) for b in inliers)
                and (n_points is None or len(inliers) == n_points)):
            raise CalibrationError(f"{path}: 'inliers' must be a list of true/false, one per point")
        inliers = np.array(inliers, dtype=bool)
    camera = None
    if data.get("camera") is not None:                    # written by calibrate --camera
        from .lens import CameraModel
        camera = CameraModel.from_dict(data["camera"], f"{path}: camera")
    size = data.get("image_size")
    if size is not None and not (isinstance(size, list) and len(size) == 2 and all(
            isinstance(s, int) and not isinstance(s, bool) and 0 < s <= 100_000 for s in size)):
        raise CalibrationError(f"{path}: 'image_size' must be [width, height] in px (two positive integers)")
    extent = data.get("points_extent")
    if extent is not None and not (isinstance(extent, list) and len(extent) == 4 and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in extent)):
        raise CalibrationError(f"{path}: 'points_extent' must be [u_min, v_min, u_max, v_max] in px")
    status = data.get("status", "ok")
    if status not in ("ok", "suspect"):
        raise CalibrationError(f"{path}: 'status' must be \"ok\" or \"suspect\", got {json.dumps(status)[:40]}")
    reasons = data.get("reasons", [])
    if not (isinstance(reasons, list) and all(isinstance(r, str) for r in reasons)):
        raise CalibrationError(f"{path}: 'reasons' must be a list of strings")
    rms_all = data.get("rms_all_px")
    rms_all = math.nan if rms_all is None else _rms(data, "rms_all_px", path)
    return Calibration(H_iw, H_wi, rms_px, rms_world, inliers, n_points, camera,
                       None if size is None else (size[0], size[1]), None if extent is None else tuple(extent),
                       status, tuple(reasons), rms_all)


class CalibrationPoints(NamedTuple):
    """Correspondences read from a points CSV file."""

    world_xy: np.ndarray
    """(N, 2) ceiling points (X, Y), mm."""
    image_uv: np.ndarray
    """(N, 2) image points (u, v), px."""
    lines: np.ndarray
    """(N,) the line of each point in the file (1-based, the header is line 1)."""


def read_points_csv(path) -> CalibrationPoints:
    """Read calibration points from a CSV file with the header ``X,Y,u,v``.

    Blank lines and lines starting with ``#`` are skipped.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    CalibrationPoints
        ``(world_xy (N, 2) mm, image_uv (N, 2) px, lines (N,))``.

    Raises
    ------
    CalibrationError
        Missing or empty file, wrong header, a row without 4 finite numbers (naming the
        line), fewer than 4 or more than :data:`MAX_POINTS` points, a world or image point
        that repeats an earlier line.
    """
    path = Path(path)
    text = read_text(path, expected="a CSV of calibration points 'X,Y,u,v'", error=CalibrationError)
    check_rows(text, str(path), "lines (points, comments and blank lines)", error=CalibrationError,
               limit=2 * MAX_POINTS + 1000)         # before splitting the text into lines
    rows, lines, header_seen = [], [], False
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = [f.strip() for f in stripped.split(",")]
        if not header_seen:
            if tuple(fields) != CSV_HEADER:
                raise CalibrationError(f"{path} line {lineno}: expected the header 'X,Y,u,v', got '{stripped[:60]}'")
            header_seen = True
            continue
        if len(fields) != 4:
            raise CalibrationError(f"{path} line {lineno}: expected 4 values X,Y,u,v, got {len(fields)} "
                                   f"('{stripped[:60]}')")
        values = []
        for name, field in zip(CSV_HEADER, fields):
            try:
                value = parse_number(field)
            except ValueError:
                raise CalibrationError(f"{path} line {lineno}: {name} is '{field[:30]}'; expected a number") from None
            if not math.isfinite(value):
                raise CalibrationError(f"{path} line {lineno}: {name} is '{field}'; expected a finite number")
            values.append(value)
        if len(rows) == MAX_POINTS:
            raise CalibrationError(f"{path} line {lineno}: more than {MAX_POINTS} calibration points; expected "
                                   f"at most {MAX_POINTS} (a ceiling grid in view has tens to hundreds of crossings)")
        rows.append(values)
        lines.append(lineno)
    if not header_seen:
        raise CalibrationError(f"{path}: file is empty; expected the header 'X,Y,u,v' and one point per line")
    if len(rows) < 4:
        raise CalibrationError(f"{path}: {len(rows)} calibration points; a homography needs at least 4 "
                               "(6 or more let RANSAC reject a mis-clicked one)")
    for cols, what, why in (((0, 1), "world point X={:g}, Y={:g}", "each ceiling point once"),
                            ((2, 3), "image point u={:g}, v={:g}",
                             "distinct pixels (two ceiling points cannot share one)")):
        seen = {}
        for k, row in enumerate(rows):
            key = (row[cols[0]], row[cols[1]])
            first = seen.setdefault(key, k)
            if first != k:
                raise CalibrationError(f"{path} line {lines[k]}: {what.format(*key)} repeats line {lines[first]}; "
                                       f"expected {why}")
    arr = np.array(rows, dtype=np.float64)
    return CalibrationPoints(arr[:, :2], arr[:, 2:], np.array(lines))


def write_points_csv(path, world_xy, image_uv):
    """Write correspondences as a points CSV (``X,Y,u,v``; world mm, image px).

    Parameters
    ----------
    path : str or Path
    world_xy : array_like, shape (N, 2)
    image_uv : array_like, shape (N, 2)
    """
    world = np.asarray(world_xy, dtype=float).reshape(-1, 2)
    image = np.asarray(image_uv, dtype=float).reshape(-1, 2)
    body = "".join(f"{X:.6g},{Y:.6g},{u:.4f},{v:.4f}\n" for (X, Y), (u, v) in zip(world, image))
    write_text_atomic(path, ",".join(CSV_HEADER) + "\n" + body, error=CalibrationError)


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
