"""The ceiling camera: its lens (intrinsics, distortion, chessboard calibration) and the
homography between the ceiling plane and the image (paper §IV-A), with the grid-corner finder
that feeds it.

Modules: ``lens`` (the lens model and its chessboard calibration), ``homography`` (the calibration
and its file), ``points`` (the X,Y,u,v points file), ``lens_check`` (do the points agree with the
lens: ``calibrate_points``), ``grid`` (T-bar crossings), ``commands`` (the ``calibrate`` and
``camera`` verbs)."""

from .commands import LensRun, PointsCalibration, calibrate_file, calibrate_lens_files, expand_images
from .grid import CeilingGrid, find_grid_corners
from .homography import Calibration, calibrate, load_calibration, point_residuals
from .lens import CameraModel, LensCalibration, calibrate_camera, find_board, load_camera, save_camera
from .lens_check import radial_pattern
from .points import read_points_csv, undistort_calibration_points, write_points_csv

__all__ = [
    "CameraModel",
    "LensCalibration",
    "calibrate_camera",
    "find_board",
    "load_camera",
    "save_camera",
    "Calibration",
    "calibrate",
    "load_calibration",
    "point_residuals",
    "radial_pattern",
    "read_points_csv",
    "undistort_calibration_points",
    "write_points_csv",
    "CeilingGrid",
    "find_grid_corners",
    "PointsCalibration",
    "calibrate_file",
    "LensRun",
    "calibrate_lens_files",
    "expand_images",
]
