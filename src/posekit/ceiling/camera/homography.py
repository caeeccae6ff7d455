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
from ...io import load_json, number_array, write_text_atomic
from .points import MAX_POINTS

__all__ = ["Calibration", "calibrate", "point_residuals", "load_calibration"]

#: The keys of a calibration JSON file (``posekit ceiling calibrate --out``), in order.
JSON_KEYS = ("H_image_world", "H_world_image", "rms_px", "rms_world")
#: A homography whose condition number exceeds this is singular.
MAX_COND = 1e12
#: ``H_world_image @ H_image_world`` must be within this (relative) of a multiple of I.
INVERSE_TOL = 1e-6
#: RANSAC is on by default from this many points.
RANSAC_MIN_POINTS = 6
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


def point_residuals(cal: "Calibration", world_xy, image_uv) -> tuple[np.ndarray, np.ndarray]:
    """Per-point residuals of a calibration: image (px, ``‖H(X, Y) − (u, v)‖``) and world
    (mm, ``‖H⁻¹(u, v) − (X, Y)‖``), each shape (N,); NaN where a point maps to infinity.
    ``image_uv`` in the pixels the homography maps (undistorted when calibrated with a camera)."""
    world = np.asarray(world_xy, dtype=float).reshape(-1, 2)
    image = np.asarray(image_uv, dtype=float).reshape(-1, 2)
    e_px = np.linalg.norm(cal.world_to_image(world, invalid="nan") - image, axis=1)
    e_mm = np.linalg.norm(cal.image_to_world(image, invalid="nan") - world, axis=1)
    return e_px, e_mm


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
