"""Ceiling system: x, y and heading of a ground robot from laser dots on the ceiling seen by a
fixed camera.

Parts: :mod:`~posekit.ceiling.camera` (lens, homography calibration),
:mod:`~posekit.ceiling.detect` (dots, lines, static lights), :mod:`~posekit.ceiling.track`
(tracker, several cameras or robots, sources and outputs), :mod:`~posekit.ceiling.sim` (the
renderer) and :mod:`~posekit.ceiling.studies`.
"""

from .camera import (
    Calibration,
    CeilingGrid,
    calibrate,
    find_grid_corners,
    load_calibration,
    read_points_csv,
    write_points_csv,
)
from .detect import Dot, DotDetector, DotSignature, Line, LineDetector
from .sim import CeilingScene, SceneConfig, iter_frames, render_video, true_homography
from .studies import heading_std_closed_form, known_points_assessment, run_demo, simulate_heading_error
from .track import (
    Camera,
    MultiCameraTracker,
    MultiRobotTracker,
    Tracker,
    TrackerConfig,
    TrackOutputs,
    iter_track,
    open_frames,
    open_live,
    read_track_csv,
    track_frames,
    track_robots_frames,
    track_robots_video,
    track_video,
    write_track_csv,
)

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
]
