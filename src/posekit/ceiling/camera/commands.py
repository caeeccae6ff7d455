"""``posekit ceiling calibrate`` and ``posekit ceiling camera`` as library calls.

:func:`calibrate_file` and :func:`calibrate_lens_files` take the commands' arguments by the same
names, write the same files and return what the commands print: which points RANSAC rejected
and why, whether the boards covered the image. The commands parse and print.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..._extras import require
from ...errors import CalibrationError, ConfigError, InputFileError
from .grid import CeilingGrid, find_grid_corners
from .homography import Calibration, point_residuals
from .lens import LensCalibration, calibrate_camera, load_camera, save_camera
from .lens_check import calibrate_points
from .points import read_points_csv, undistort_calibration_points, write_points_csv

__all__ = ["MAX_VIEWS", "LOW_COVERAGE", "PointsCalibration", "calibrate_file", "LensRun", "expand_images",
           "calibrate_lens_files"]

#: Most images one lens calibration reads.
MAX_VIEWS = 500
#: Below this fraction of the image covered by the boards, the lens calibration warns.
LOW_COVERAGE = 0.5


@dataclass
class PointsCalibration:
    """What :func:`calibrate_file` did.

    Attributes
    ----------
    calibration : Calibration
        Written to ``out``; ``status`` ``'suspect'`` (with ``reasons``) when the points contradict the
        lens model or RANSAC kept fewer than half of them.
    radial : RadialPattern or None
        The radial (lens-distortion) pattern of the residuals of a plain homography.
    world, seen, image : ndarray, shape (N, 2)
        The points: ceiling (mm), pixels as seen, pixels undistorted with the lens (= seen without one).
    lines : ndarray or None
        The CSV line of each point (None for crossings found in an image and not written).
    found : int or None
        Crossings found in ``from_image`` (None without it).
    ransac_used : bool
        Whether RANSAC ran (``ransac``, or by default from 6 points).
    residual_px, residual_mm : ndarray, shape (N,)
        Each point's reprojection error in the image and on the ceiling.
    lens_pattern : ndarray of bool, shape (N,)
        Points that follow the lens pattern (within the threshold of it; only without a lens model).
    """

    calibration: Calibration
    radial: object
    world: np.ndarray
    seen: np.ndarray
    image: np.ndarray
    lines: np.ndarray | None
    found: int | None
    ransac_used: bool
    residual_px: np.ndarray
    residual_mm: np.ndarray
    lens_pattern: np.ndarray

    @property
    def rejected(self) -> np.ndarray:
        """Indices of the points RANSAC rejected."""
        return np.flatnonzero(~self.calibration.inliers)

    @property
    def rejected_lens(self) -> int:
        """Rejected points that follow the lens pattern (not mis-clicks)."""
        return int(self.lens_pattern[self.rejected].sum())

    @property
    def too_many_rejected(self) -> bool:
        """More than a third of the points rejected, none explained by the lens: check the points."""
        return self.rejected.size > len(self.world) / 3 and not self.rejected_lens

    @property
    def lens_distortion_seen(self) -> bool:
        """No lens model given and the residuals show lens distortion."""
        return self.radial is not None and bool(self.radial.detected)

    @property
    def exit_code(self) -> int:
        """0; 1 when the calibration is suspect (written, and never ok for track)."""
        return 1 if self.calibration.status == "suspect" else 0


def _points_from_image(path, seeds, grid_mm, origin_mm, bar_mm, light_bars, camera):
    """Crossings found in the reference image: (world (N, 2) mm, pixels as seen (N, 2)). With
    ``camera`` the image is undistorted first (``cv2.undistort``, same K: straight T-bars), the seeds
    with it, and the crossings are distorted back to the pixels as seen."""
    cv2 = require("cv2", "vision", "posekit ceiling calibrate --from-image")
    from ...io import read_image

    img = read_image(path, cv2.IMREAD_GRAYSCALE, error=CalibrationError)
    if img is None:
        raise CalibrationError(f"{path}: cannot decode the image; expected an image file OpenCV reads")
    grid = CeilingGrid(grid_mm, origin_mm, bar_mm)
    seed_uv = seeds.image_uv
    if camera is not None:
        img = cv2.undistort(img, camera.K, camera.dist, None, camera.K)
        seed_uv = undistort_calibration_points(camera, seed_uv, seeds.lines)
    corners = find_grid_corners(img, grid, seed_world=seeds.world_xy, seed_image=seed_uv,
                                polarity="light" if light_bars else "dark")
    seen = corners.image_uv if camera is None else camera.distort_points(corners.image_uv)
    return corners.world_xy, seen, (int(img.shape[1]), int(img.shape[0]))


def calibrate_file(points, out, *, camera=None, image_size=None, refine: bool = True, ransac: bool | None = None,
                   threshold_px: float = 3.0, seed: int = 0, from_image=None, grid=(600.0, 1200.0),
                   grid_origin=(0.0, 0.0), bar_mm: float = 15.0, light_bars: bool = False,
                   write_points=None) -> PointsCalibration:
    """``posekit ceiling calibrate``: the homography from the points CSV ``points`` written to ``out``.

    ``camera``: the lens file (the pixels are undistorted first); ``image_size``: (W, H) px of the
    images the points were clicked in (default the lens's or the reference image's); ``from_image``:
    a reference image whose T-bar crossings (``grid``, ``grid_origin`` mm, ``bar_mm`` wide,
    ``light_bars``) are found from the seed points (and written to ``write_points``); ``ransac``
    (default on from 6 points) at ``threshold_px`` with ``seed``; ``refine`` the reprojection error.
    """
    if not (np.isfinite(threshold_px) and threshold_px > 0):
        raise ConfigError(f"--threshold-px must be a number > 0, got {threshold_px:g}")
    if write_points and not from_image:
        raise ConfigError("--write-points needs --from-image")
    pts = read_points_csv(points)
    lens = load_camera(camera) if camera else None
    found = None
    if from_image:
        world, seen, ref_size = _points_from_image(from_image, pts, tuple(grid), tuple(grid_origin), bar_mm,
                                                   light_bars, lens)
        found = len(seen)
        if write_points:
            write_points_csv(write_points, world, seen)
        lines = np.arange(len(seen)) + 2 if write_points else None
        image_size = image_size or ref_size
    else:
        world, seen, lines = pts.world_xy, pts.image_uv, pts.lines
    cal, radial = calibrate_points(world, seen, camera=lens, lines=lines, image_size=image_size, refine=refine,
                                   ransac=ransac, threshold_px=threshold_px, rng=seed)
    image = seen if lens is None else np.asarray(cal.camera.undistort_points(seen))
    e_px, e_mm = point_residuals(cal, world, image)
    radial = None if lens is not None else radial
    pattern = np.zeros(len(world), dtype=bool)
    if radial is not None and radial.detected and radial.off_px is not None:
        pattern = radial.off_px <= threshold_px
    cal.to_json(Path(out))
    return PointsCalibration(cal, radial, world, seen, image, lines, found,
                             ransac if ransac is not None else cal.n_points >= 6, e_px, e_mm, pattern)


@dataclass
class LensRun:
    """What :func:`calibrate_lens_files` did: the lens calibration (written to ``out``), the images
    that could not be read (name, why), and whether the boards left parts of the image uncovered."""

    result: LensCalibration
    unreadable: list = field(default_factory=list)

    @property
    def views(self) -> int:
        """Every image given."""
        return len(self.result.used) + len(self.result.skipped) + len(self.unreadable)

    @property
    def low_coverage(self) -> bool:
        """The corners cover less than :data:`LOW_COVERAGE` of the image or miss a cell of its 3x3 grid."""
        return self.result.coverage < LOW_COVERAGE or self.result.cells_hit < 9


def expand_images(paths) -> list:
    """The image paths of ``paths``, a folder replaced by its images sorted by name."""
    from ..track.sources import list_images

    out = []
    for p in paths:
        out.extend(list_images(Path(p)) if Path(p).is_dir() else [p])
    return out


def calibrate_lens_files(images, board: tuple[int, int], square_mm: float, out, *, k3: bool = False,
                         on_unreadable=None) -> LensRun:
    """``posekit ceiling camera``: the lens (K, distortion) from chessboard ``images`` (files or folders)
    with ``board`` inner corners (cols, rows) of ``square_mm`` squares, written to ``out``. ``k3``:
    also estimate k3. An image that cannot be read is skipped and named in ``unreadable`` (and passed
    to ``on_unreadable(name, why)`` as it is met)."""
    cv2 = require("cv2", "vision", "posekit ceiling camera")
    from ...io import read_image

    if Path(out).is_dir():                   # before the calibration, not after it
        raise ConfigError(f"--out {out}: is a folder; expected a CAMERA.json file name")
    paths = expand_images(images)
    if len(paths) > MAX_VIEWS:
        raise ConfigError(f"{len(paths)} images; expected at most {MAX_VIEWS}")
    unreadable = []

    def views():
        for p in paths:
            try:
                img = read_image(p, cv2.IMREAD_GRAYSCALE, error=CalibrationError)
            except (CalibrationError, InputFileError) as exc:
                unreadable.append((str(p), str(exc)))
                if on_unreadable is not None:
                    on_unreadable(str(p), str(exc))
                continue
            yield str(p), img

    result = calibrate_camera(views(), board, square_mm, fix_k3=not k3)
    save_camera(result.camera, Path(out))
    return LensRun(result, unreadable)
