"""The camera of a rendered video calibrated the way a user would: the homography from the grid
corners of ``reference.png`` (:func:`calibrate_rendered_points`) and the lens from rendered
chessboard views (:func:`lens_from_chessboards`).

Ceiling points in mm, pixels as seen (distorted) unless said otherwise.
"""

from pathlib import Path

import numpy as np

from ..._extras import require
from ...errors import InputFileError

__all__ = ["calibrate_rendered", "calibrate_rendered_points", "lens_from_chessboards"]


def calibrate_rendered(render_dir, grid=None, lens=None):
    """Calibrate the camera of a rendered video folder; returns ``(calibration, method)``.
    See :func:`calibrate_rendered_points`."""
    cal, method, _, _ = calibrate_rendered_points(render_dir, grid, lens)
    return cal, method


def calibrate_rendered_points(render_dir, grid=None, lens=None):
    """Calibrate the camera of a rendered video folder.

    With ``reference.png``: four grid corners of ``calibration_points.csv`` (the extreme
    ones, rounded to whole pixels as a user would click them) seed
    :func:`~posekit.ceiling.camera.grid.find_grid_corners`, which finds every T-bar crossing to
    sub-pixel accuracy; the homography is fitted to those. Without it: to the points of
    ``calibration_points.csv``. With a ``lens``, the reference image is undistorted first
    (``cv2.undistort`` with the same K: straight T-bars again) and the seeds with it, so the
    homography maps undistorted pixels.

    Parameters
    ----------
    render_dir : path
        Folder written by :func:`~posekit.ceiling.sim.video.render_video`.
    grid : CeilingGrid, optional
        The ceiling lattice (default: the renderer's default tiles).
    lens : CameraModel, optional
        The camera's lens model.

    Returns
    -------
    calibration : Calibration
        ``camera`` set to ``lens``.
    method : str
        How it was obtained (for the report).
    world_xy : ndarray, shape (N, 2)
        The calibration points on the ceiling, mm.
    image_uv : ndarray, shape (N, 2)
        Their pixels as seen (distorted), px.
    """
    from ..camera.homography import calibrate
    from ..camera.points import read_points_csv, undistort_calibration_points

    render_dir = Path(render_dir)
    pts = read_points_csv(render_dir / "calibration_points.csv")
    ref = render_dir / "reference.png"
    lens_note = "" if lens is None else ", through the lens model"
    if ref.exists():
        cv2 = require("cv2", "vision", "posekit ceiling demo")

        from ..camera.grid import CeilingGrid, find_grid_corners
        if grid is None:
            from ..sim.config import SceneConfig
            c = SceneConfig()
            grid = CeilingGrid(spacing_mm=c.tile_size_mm, bar_width_mm=c.tbar_width_mm)
        image = cv2.imread(str(ref))
        if image is None:
            raise InputFileError(f"{ref}: cannot decode this file as an image")
        uv = pts.image_uv
        if lens is not None:
            image = cv2.undistort(image, lens.K, lens.dist, None, lens.K)
            uv = undistort_calibration_points(lens, uv, pts.lines)
        seeds = np.unique([np.argmin(uv.sum(1)), np.argmax(uv.sum(1)),
                           np.argmin(uv[:, 0] - uv[:, 1]), np.argmax(uv[:, 0] - uv[:, 1])])
        with np.errstate(invalid="ignore"):
            corners = find_grid_corners(image, grid, seed_world=pts.world_xy[seeds],
                                        seed_image=np.round(uv[seeds]))
        cal = calibrate(corners.world_xy, corners.image_uv)
        cal.camera = lens
        seen = corners.image_uv if lens is None else lens.distort_points(corners.image_uv)
        return (cal, f"{len(corners.world_xy)} grid corners found in reference.png{lens_note}",
                corners.world_xy, seen)
    image_uv = pts.image_uv if lens is None else undistort_calibration_points(lens, pts.image_uv, pts.lines)
    cal = calibrate(pts.world_xy, image_uv)
    cal.camera = lens
    return cal, f"{len(pts.world_xy)} points of calibration_points.csv{lens_note}", pts.world_xy, pts.image_uv


def lens_from_chessboards(camera, out_dir=None, *, n_views: int = 12, board=(9, 6), square_mm: float = 30.0,
                          seed: int = 0):
    """Calibrate a simulated lens the way a user would: render ``n_views`` chessboard images
    through ``camera`` (:mod:`~posekit.ceiling.sim.chessboard`) and run
    :func:`~posekit.ceiling.camera.calibrate_camera` on them (k3 fixed at 0, as the CLI's
    default). Writes the views as ``chessboard/view_NN.png`` under ``out_dir`` if given.

    Returns
    -------
    LensCalibration
    """
    from ..camera.lens import calibrate_camera
    from ..sim.chessboard import chessboard_poses, render_board_view

    poses = chessboard_poses(camera, board, square_mm, n_views, rng=seed)
    views = [(f"view_{k:02d}", render_board_view(camera, T, board, square_mm, supersample=2, rng=[seed, k]))
             for k, T in enumerate(poses)]
    if out_dir is not None:
        cv2 = require("cv2", "vision", "posekit ceiling demo")
        folder = Path(out_dir) / "chessboard"
        folder.mkdir(parents=True, exist_ok=True)
        for name, img in views:
            cv2.imwrite(str(folder / f"{name}.png"), img)
    return calibrate_camera(views, board, square_mm, fix_k3=True)
