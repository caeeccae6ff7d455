"""The ceiling camera: its lens (intrinsics, distortion, chessboard calibration) and the
homography between the ceiling plane and the image (paper §IV-A), with the grid-corner finder
that feeds it."""

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
