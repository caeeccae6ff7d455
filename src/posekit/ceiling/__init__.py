"""Ceiling system: x, y and heading of a ground robot from laser dots on the ceiling seen by a
fixed camera.

Parts: :mod:`~posekit.ceiling.camera` (lens, homography calibration),
:mod:`~posekit.ceiling.detect` (dots, lines, static lights), :mod:`~posekit.ceiling.track`
(tracker, several cameras or robots, sources and outputs), :mod:`~posekit.ceiling.sim` (the
renderer) and :mod:`~posekit.ceiling.studies`.
"""

from .camera.commands import LensRun, PointsCalibration, calibrate_file, calibrate_lens_files
from .camera.grid import CeilingGrid, find_grid_corners
from .camera.homography import Calibration, calibrate, load_calibration
from .camera.points import read_points_csv, write_points_csv
from .detect.dots import DotDetector
from .detect.lines import Line, LineDetector
from .detect.signature import DotSignature
from .detect.spots import Dot
from .sim.config import SceneConfig
from .sim.render import CeilingScene, iter_frames
from .sim.scene_geometry import true_homography
from .sim.simulation import CeilingSimulation, scene_config, scene_effects, simulate, simulation_dots
from .sim.video import render_video
from .studies.accuracy import heading_std_closed_form, known_points_assessment, simulate_heading_error
from .studies.demo import run_demo
from .studies.demo_command import check_demo_lens, demo
from .track.cameras import Camera, MultiCameraTracker
from .track.command import TrackPlan, TrackRun, plan_track, track_input
from .track.multitrack import MultiRobotTracker, track_robots_frames, track_robots_video
from .track.outputs import TrackOutputs
from .track.pipeline import iter_track, read_track_csv, track_frames, track_video, write_track_csv
from .track.sources import open_frames, open_live
from .track.tracker import Tracker
from .track.types import TrackerConfig

__all__ = [
    "Calibration",
    "calibrate",
    "load_calibration",
    "read_points_csv",
    "write_points_csv",
    "CeilingGrid",
    "find_grid_corners",
    "SceneConfig",
    "CeilingScene",
    "true_homography",
    "iter_frames",
    "render_video",
    "Dot",
    "DotDetector",
    "DotSignature",
    "Line",
    "LineDetector",
    "TrackerConfig",
    "Tracker",
    "Camera",
    "MultiCameraTracker",
    "open_frames",
    "open_live",
    "iter_track",
    "TrackOutputs",
    "MultiRobotTracker",
    "track_robots_frames",
    "track_robots_video",
    "track_video",
    "track_frames",
    "write_track_csv",
    "read_track_csv",
    "known_points_assessment",
    "simulate_heading_error",
    "heading_std_closed_form",
    "run_demo",
    "simulate",
    "scene_config",
    "scene_effects",
    "simulation_dots",
    "CeilingSimulation",
    "demo",
    "check_demo_lens",
    "track_input",
    "calibrate_file",
    "calibrate_lens_files",
    "PointsCalibration",
    "LensRun",
    "plan_track",
    "TrackPlan",
    "TrackRun",
]
