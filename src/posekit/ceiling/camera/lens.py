"""The lens of the ceiling camera: intrinsics and distortion (OpenCV's pinhole + Brown–Conrady model).

A real camera's lens bends straight lines; the homography of :mod:`posekit.ceiling.camera.homography`
holds only between the ceiling and the *undistorted* image. :class:`CameraModel` carries the
camera matrix ``K`` and the distortion coefficients ``dist = [k1, k2, p1, p2, k3]`` and maps
pixel coordinates both ways: :meth:`CameraModel.undistort_points` (detected dots and clicked
calibration points, before the homography) and :meth:`CameraModel.distort_points` (the
renderer, to make a distorted image).

Frames and units: image (u, v) in px, u to the right, v down, the centre of the top-left pixel
at (0, 0); undistorted pixels are expressed with the same ``K`` (``cv2.undistortPoints`` with
``P=K``), so an undistorted point stays near where it was seen. Normalized coordinates
``x = (u - cx) / fx``, ``y = (v - cy) / fy``, and with ``r² = x² + y²``::

    x_d = x (1 + k1 r² + k2 r⁴ + k3 r⁶) + 2 p1 x y + p2 (r² + 2 x²)
    y_d = y (1 + k1 r² + k2 r⁴ + k3 r⁶) + p1 (r² + 2 y²) + 2 p2 x y

The JSON file (``posekit ceiling camera --out``) is
``{"K": 3x3, "dist": [k1, k2, p1, p2, k3], "image_size": [w, h], "rms_px": float}``.
"""

import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..._extras import lazy
from ...errors import CalibrationError
from ...io import load_json, number_array, write_text_atomic

cv2 = lazy("cv2", "vision", "the ceiling system (lens undistortion)")

__all__ = ["CameraModel", "load_camera", "save_camera", "JSON_KEYS", "LensCalibration", "find_board",
           "calibrate_camera", "corner_coverage", "MIN_VIEWS"]

#: The keys of a camera JSON file, in order.
JSON_KEYS = ("K", "dist", "image_size", "rms_px")
#: Largest image side accepted in a camera file, px.
MAX_SIDE = 100_000
#: Largest magnitude of a distortion coefficient accepted (real lenses stay well under 10).
MAX_DIST = 1e3
#: Undistortion iterations and tolerance (normalized units): OpenCV's default of 5 iterations
#: leaves ~0.1 px at the corners of a k1 = -0.2 lens; this converges to < 1e-6 px.
_UNDISTORT_CRITERIA = (3, 100, 1e-12)  # cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS


def _as_points(uv, what: str) -> np.ndarray:
    pts = np.asarray(uv, dtype=float)
    if pts.ndim == 1 and pts.size == 0:
        pts = pts.reshape(0, 2)
    if pts.ndim != 2 or pts.shape[1] != 2:
        raise ValueError(f"{what}: expected points of shape (N, 2), got shape {pts.shape}")
    return pts


@dataclass(frozen=True, eq=False)
class CameraModel:
    """Intrinsics and lens distortion of one camera (OpenCV model).

    Attributes
    ----------
    K : ndarray, shape (3, 3)
        Camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]``, px.
    dist : ndarray, shape (5,)
        Distortion coefficients ``[k1, k2, p1, p2, k3]`` (dimensionless, normalized coordinates).
    image_size : tuple of int
        ``(width, height)`` of the images the model was calibrated on, px.
    rms_px : float
        Root mean square reprojection error of the lens calibration, px (0 for a simulated lens).
    """

    K: np.ndarray
    dist: np.ndarray
    image_size: tuple
    rms_px: float = 0.0

    def __post_init__(self):
        K = np.array(self.K, dtype=float)
        dist = np.array(self.dist, dtype=float).reshape(-1)
        if K.shape != (3, 3):
            raise CalibrationError(f"camera K: expected a 3x3 matrix, got shape {K.shape}")
        if dist.shape == (4,):
            dist = np.append(dist, 0.0)
        if dist.shape != (5,):
            raise CalibrationError(f"camera dist: expected 5 coefficients [k1, k2, p1, p2, k3], got {dist.size}")
        _check_values(K, dist, self.image_size, self.rms_px, "camera")
        K.setflags(write=False)
        dist.setflags(write=False)
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "image_size", (int(self.image_size[0]), int(self.image_size[1])))
        object.__setattr__(self, "rms_px", float(self.rms_px))
        object.__setattr__(self, "_fold", _fold_radius(dist))

    # ------------------------------------------------------------------ construction
    @classmethod
    def ideal(cls, width: int, height: int, *, focal_px: float | None = None, dist=(0, 0, 0, 0, 0)):
        """A camera with the principal point at the image centre and square pixels.

        Parameters
        ----------
        width, height : int
            Image size, px.
        focal_px : float, optional
            Focal length, px; default the image width (a ~53° horizontal field of view).
        dist : array_like, shape (5,), optional
            ``[k1, k2, p1, p2, k3]``; default none.
        """
        f = float(width if focal_px is None else focal_px)
        K = np.array([[f, 0.0, (width - 1) / 2.0], [0.0, f, (height - 1) / 2.0], [0.0, 0.0, 1.0]])
        return cls(K=K, dist=np.asarray(dist, dtype=float), image_size=(int(width), int(height)), rms_px=0.0)

    @property
    def is_distorted(self) -> bool:
        """True when any distortion coefficient is non-zero."""
        return bool(np.any(self.dist != 0.0))

    @property
    def fold_radius(self) -> tuple[float, float]:
        """(r, r_d): the undistorted normalized radius where the radial model stops increasing
        (``d r_d / d r = 0``) and the distorted radius there; (inf, inf) when it never does (up to
        r = 10). Beyond it the polynomial folds back: no real lens images those rays, so
        :meth:`distort_points` and :meth:`undistort_points` return NaN there."""
        return self._fold


    # ------------------------------------------------------------------ mapping
    def undistort_points(self, uv) -> np.ndarray:
        """Undistorted pixel coordinates (same ``K``) of observed pixels.

        Parameters
        ----------
        uv : array_like, shape (N, 2)
            Observed (distorted) image points (u, v), px. NaN rows stay NaN; N may be 0.

        Returns
        -------
        ndarray, shape (N, 2)
            Where each point would be seen by the distortion-free camera with the same ``K``, px.
        """
        pts = _as_points(uv, "undistort_points")
        out = np.full_like(pts, np.nan)
        good = np.isfinite(pts).all(axis=1)
        if not good.any():
            return out
        if not self.is_distorted:
            out[good] = pts[good]
            return out
        src = np.ascontiguousarray(pts[good].reshape(-1, 1, 2))
        dst = cv2.undistortPoints(src, self.K, self.dist, None, None, self.K, _UNDISTORT_CRITERIA)
        out[good] = dst.reshape(-1, 2)
        rf, rdf = self.fold_radius
        if math.isfinite(rf):                       # outside the image circle of the model
            xd = self.pixels_to_normalized(pts)
            xu = self.pixels_to_normalized(out)
            beyond = (np.hypot(*xd.T) > rdf) | (np.hypot(*xu.T) > rf)
            out[beyond] = np.nan
        return out

    def normalized_to_pixels(self, xy) -> np.ndarray:
        """Distorted pixels of normalized (undistorted) camera coordinates ``(x, y)``, shape (N, 2)."""
        xy = _as_points(xy, "normalized_to_pixels")
        k1, k2, p1, p2, k3 = self.dist
        x, y = xy[:, 0], xy[:, 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xd = x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        yd = y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        K = self.K
        return np.stack([K[0, 0] * xd + K[0, 1] * yd + K[0, 2], K[1, 1] * yd + K[1, 2]], axis=1)

    def pixels_to_normalized(self, uv) -> np.ndarray:
        """Undistorted normalized coordinates ``(x, y)`` of undistorted pixels ``uv`` (same ``K``), shape (N, 2)."""
        uv = _as_points(uv, "pixels_to_normalized")
        K = self.K
        y = (uv[:, 1] - K[1, 2]) / K[1, 1]
        x = (uv[:, 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=1)

    def distort_points(self, uv) -> np.ndarray:
        """Observed (distorted) pixels of undistorted pixels — the inverse of :meth:`undistort_points`.

        Parameters
        ----------
        uv : array_like, shape (N, 2)
            Undistorted image points (u, v) in the same ``K``, px. NaN rows stay NaN.

        Returns
        -------
        ndarray, shape (N, 2)
            Where the real lens shows them, px (closed form, no iteration).
        """
        pts = _as_points(uv, "distort_points")
        if not self.is_distorted:
            return pts.copy()
        xy = self.pixels_to_normalized(pts)
        out = self.normalized_to_pixels(xy)
        rf, _ = self.fold_radius
        if math.isfinite(rf):
            out[np.hypot(*xy.T) > rf] = np.nan
        return out

    # ------------------------------------------------------------------ files
    def to_json(self) -> dict:
        """The JSON document of the model (``JSON_KEYS`` in order)."""
        return {
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "image_size": [int(self.image_size[0]), int(self.image_size[1])],
            "rms_px": float(self.rms_px),
        }

    @classmethod
    def from_dict(cls, data, source: str = "camera"):
        """Check and build a model from a parsed JSON document; one-line :class:`CalibrationError`
        naming ``source`` and the key on anything wrong."""
        if not isinstance(data, dict):
            raise CalibrationError(f"{source}: expected a JSON object with keys {', '.join(JSON_KEYS)}")
        missing = [k for k in ("K", "dist", "image_size") if k not in data]
        if missing:
            raise CalibrationError(f"{source}: missing key {missing[0]!r}; expected keys {', '.join(JSON_KEYS)}")
        K = _numbers(data["K"], source, "K")
        if K.shape != (3, 3):
            raise CalibrationError(f"{source}: K: expected a 3x3 matrix, got shape {K.shape}")
        dist = _numbers(data["dist"], source, "dist").reshape(-1) if not _is_scalar(data["dist"]) else None
        if dist is None or dist.size not in (4, 5):
            n = "a number" if dist is None else f"{dist.size} values"
            raise CalibrationError(f"{source}: dist: expected 5 coefficients [k1, k2, p1, p2, k3], got {n}")
        size = data["image_size"]
        if (not isinstance(size, list) or len(size) != 2
                or not all(isinstance(s, int) and not isinstance(s, bool) for s in size)):
            raise CalibrationError(f"{source}: image_size: expected [width, height] in px (two integers)")
        rms = data.get("rms_px", 0.0)
        if isinstance(rms, bool) or not isinstance(rms, (int, float)):
            raise CalibrationError(f"{source}: rms_px: expected a number, got {type(rms).__name__}")
        if dist.size == 4:
            dist = np.append(dist, 0.0)
        _check_values(K, dist, size, rms, source)
        return cls(K=K, dist=dist, image_size=(size[0], size[1]), rms_px=float(rms))


def _fold_radius(dist: np.ndarray) -> tuple[float, float]:
    """See :attr:`CameraModel.fold_radius`."""
    k1, k2, _, _, k3 = dist
    r = np.linspace(0.0, 10.0, 20001)[1:]
    r2 = r * r
    slope = 1.0 + 3.0 * k1 * r2 + 5.0 * k2 * r2 ** 2 + 7.0 * k3 * r2 ** 3
    bad = np.flatnonzero(slope <= 0.0)
    if bad.size == 0:
        return math.inf, math.inf
    rf = float(r[max(bad[0] - 1, 0)])
    rf2 = rf * rf
    return rf, rf * (1.0 + rf2 * (k1 + rf2 * (k2 + rf2 * k3)))


def _is_scalar(v) -> bool:
    return isinstance(v, (int, float, bool)) or v is None


def _numbers(value, source: str, key: str) -> np.ndarray:
    try:
        return number_array(value, "", CalibrationError)     # never a boolean read as 1
    except CalibrationError:
        raise CalibrationError(f"{source}: {key}: expected numbers") from None


def _check_values(K, dist, size, rms, source: str) -> None:
    if not np.all(np.isfinite(K)):
        raise CalibrationError(f"{source}: K: expected finite numbers")
    if not np.all(np.isfinite(dist)):
        raise CalibrationError(f"{source}: dist: expected finite numbers")
    if not (K[0, 0] > 0 and K[1, 1] > 0):
        raise CalibrationError(f"{source}: K: focal lengths fx={K[0, 0]:g}, fy={K[1, 1]:g}; expected both > 0 px")
    if K[1, 0] != 0 or K[2, 0] != 0 or K[2, 1] != 0 or K[2, 2] != 1:
        raise CalibrationError(f"{source}: K: expected [[fx, s, cx], [0, fy, cy], [0, 0, 1]]")
    if np.any(np.abs(dist) > MAX_DIST):
        raise CalibrationError(f"{source}: dist: a coefficient of magnitude > {MAX_DIST:g}; expected a real lens")
    try:
        w, h = int(size[0]), int(size[1])
    except (TypeError, ValueError, IndexError):
        raise CalibrationError(f"{source}: image_size: expected [width, height] in px (two integers)") from None
    if not (0 < w <= MAX_SIDE and 0 < h <= MAX_SIDE):
        raise CalibrationError(f"{source}: image_size: {w}x{h}; expected sides between 1 and {MAX_SIDE} px")
    if not (isinstance(rms, (int, float)) and math.isfinite(rms) and rms >= 0):
        raise CalibrationError(f"{source}: rms_px: expected a finite number >= 0, got {rms!r}")


def load_camera(path) -> CameraModel:
    """Read a camera JSON file (``posekit ceiling camera --out``).

    Raises
    ------
    CalibrationError
        One line naming the file and what is wrong (unreadable, not JSON, a missing key, a bad
        shape, a non-finite number, a focal length <= 0, ...).
    """
    data = load_json(path, expected="a camera JSON file (posekit ceiling camera --out)", error=CalibrationError)
    return CameraModel.from_dict(data, str(path))


def save_camera(model: CameraModel, path) -> Path:
    """Write ``model`` as JSON to ``path`` atomically; returns the path."""
    return write_text_atomic(path, json.dumps(model.to_json(), indent=2) + "\n", flag="--out", error=CalibrationError)


#: Fewest chessboard views a lens calibration accepts (OpenCV needs 3 for the 9 parameters and
#: the poses; more views average the corner noise down).
MIN_VIEWS = 3


def find_board(gray: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """Inner corners (cols·rows, 2) px of a chessboard in a grey image, sub-pixel, or None.

    ``cv2.findChessboardCorners`` (adaptive threshold, normalisation) refined by
    ``cv2.cornerSubPix`` in an 11×11 window.
    """
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, tuple(int(b) for b in board), flags=flags)
    if not found:
        return None
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
    corners = cv2.cornerSubPix(gray, corners.astype(np.float32), (5, 5), (-1, -1), crit)
    return corners.reshape(-1, 2).astype(float)


def corner_coverage(corners_per_view, image_size, cells: int = 3) -> tuple[float, int]:
    """How much of the image the detected boards cover.

    Returns
    -------
    area : float
        Fraction of the image inside the union of the boards' convex hulls (0..1).
    cells_hit : int
        Of a ``cells`` × ``cells`` grid over the image, the cells holding at least one corner.
    """
    w, h = image_size
    scale = min(1.0, 400.0 / max(w, h))
    mask = np.zeros((max(int(h * scale), 1), max(int(w * scale), 1)), np.uint8)
    hit = np.zeros((cells, cells), bool)
    for c in corners_per_view:
        c = np.asarray(c, float)
        hull = cv2.convexHull((c * scale).astype(np.float32)).astype(np.int32)
        cv2.fillConvexPoly(mask, hull, 1)
        ij = np.clip((c / np.array([w, h]) * cells).astype(int), 0, cells - 1)
        hit[ij[:, 1], ij[:, 0]] = True
    return float(mask.mean()), int(hit.sum())


@dataclass
class LensCalibration:
    """Result of :func:`calibrate_camera`.

    Attributes
    ----------
    camera : CameraModel
    used : list of str
        Names of the views whose board was found and used.
    skipped : list of tuple(str, str)
        (name, reason) of the views left out.
    coverage : float
        Fraction of the image covered by the detected boards (0..1).
    cells_hit : int
        Cells of a 3×3 grid over the image that hold corners (of 9).
    per_view_rms_px : ndarray, shape (len(used),)
        Reprojection rms of each used view, px.
    warnings : list of str
        A board with more inner corners in view than ``board`` says (checked on the first views).
    """

    camera: CameraModel
    used: list
    skipped: list
    coverage: float
    cells_hit: int
    per_view_rms_px: np.ndarray = field(default_factory=lambda: np.zeros(0))
    warnings: list = field(default_factory=list)


def calibrate_camera(views, board: tuple[int, int], square_mm: float, *, image_size=None,
                     fix_k3: bool = False) -> LensCalibration:
    """Lens calibration (``cv2.calibrateCamera``, pinhole + [k1, k2, p1, p2, k3]) from chessboard views.

    Parameters
    ----------
    views : iterable of (str, ndarray or None)
        (name, grey image (h, w) uint8) per view; None: the view could not be read (skipped).
    board : (int, int)
        Inner corners (cols, rows) of the chessboard.
    square_mm : float
        Side of a square, mm (sets the unit of the board poses; K and dist do not depend on it).
    image_size : (int, int), optional
        (w, h); default that of the first image.
    fix_k3 : bool
        Keep k3 = 0 (fewer views, or a narrow lens).

    Raises
    ------
    CalibrationError
        Fewer than :data:`MIN_VIEWS` boards found (naming the views without one). A view of
        another size than most views is skipped and named in ``skipped``.
    """
    obj = _board_points_from_outer_corner(board, square_mm)
    found, skipped, larger = [], [], []
    for name, gray in views:
        if gray is None:
            skipped.append((name, "cannot decode the image"))
            continue
        if gray.ndim == 3:
            gray = cv2.cvtColor(gray, cv2.COLOR_BGR2GRAY)
        shape = (gray.shape[1], gray.shape[0])
        c = find_board(gray, board)
        if len(found) + len(skipped) < 3 and not larger:   # more inner corners in view than the board given?
            for bigger in ((board[0] + 1, board[1]), (board[0], board[1] + 1)):
                flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
                if cv2.findChessboardCorners(gray, bigger, flags=flags)[0]:
                    larger.append((name, bigger))
                    break
        if c is None:
            skipped.append((name, f"chessboard {board[0]}x{board[1]} not found"))
            continue
        found.append((name, shape, c))
    size = None if image_size is None else (int(image_size[0]), int(image_size[1]))
    if size is None and found:                      # the resolution of most views, not of the first
        shapes = [s for _, s, _ in found]
        size = max(set(shapes), key=shapes.count)
    img_pts, used = [], []
    for name, shape, c in found:
        if shape != size:
            skipped.append((name, f"image of {shape[0]}x{shape[1]} px; the other views are {size[0]}x{size[1]} "
                                  "(one camera, one resolution)"))
            continue
        img_pts.append(c)
        used.append(name)
    if len(used) < MIN_VIEWS:
        why = "; ".join(f"{Path(n).name}: {r}" for n, r in skipped[:3]) + (f"; {len(skipped) - 3} more"
                                                                            if len(skipped) > 3 else "")
        hint = (f" ({Path(larger[0][0]).name} shows a {larger[0][1][0]}x{larger[0][1][1]} board)") if larger else ""
        raise CalibrationError(f"lens calibration: the board was found in {len(used)} view(s); expected at least "
                               f"{MIN_VIEWS}" + (f" ({why})" if why else "") +
                               f" — check --board (inner corners, COLSxROWS){hint} and that the whole board is in "
                               "view")
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera([obj.astype(np.float32)] * len(img_pts),
                                                     [c.astype(np.float32) for c in img_pts], size, None, None,
                                                     flags=flags, criteria=crit)
    per_view = []
    for c, rv, tv in zip(img_pts, rvecs, tvecs):
        proj, _ = cv2.projectPoints(obj, rv, tv, K, dist)
        per_view.append(math.sqrt(float(np.mean(np.sum((proj.reshape(-1, 2) - c) ** 2, axis=1)))))
    area, cells = corner_coverage(img_pts, size)
    model = CameraModel(K=K, dist=np.asarray(dist, float).reshape(-1)[:5], image_size=size, rms_px=float(rms))
    warnings = [f"{name}: a chessboard of {b[0]}x{b[1]} inner corners is visible, more than --board "
                f"{board[0]}x{board[1]}: give the printed board's full inner-corner count (a smaller one fits "
                "several places on the board)" for name, b in larger]
    return LensCalibration(model, used, skipped, area, cells, np.array(per_view), warnings)


def _board_points_from_outer_corner(board: tuple[int, int], square_mm: float) -> np.ndarray:
    """Inner corners of the board in its own plane, (cols·rows, 3) mm, OpenCV's order."""
    cols, rows = board
    j, i = np.mgrid[0:rows, 0:cols]
    return np.column_stack([(i.ravel() + 1) * square_mm, (j.ravel() + 1) * square_mm, np.zeros(cols * rows)])
