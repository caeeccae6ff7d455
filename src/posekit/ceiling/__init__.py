"""Ceiling system: x, y and heading of a ground robot from laser dots on the ceiling seen by a
fixed camera (homography calibration, dot detection, tracking, synthetic ceiling videos)."""

from .accuracy import (
    heading_std_closed_form,
    known_points_assessment,
    simulate_heading_error,
)
from .calibration import (
    Calibration,
    calibrate,
    load_calibration,
    read_points_csv,
    write_points_csv,
)
from .cameras import Camera, MultiCameraTracker
from .demo import run_demo
from .detect import Dot, DotDetector, DotSignature
from .detect_line import Line, LineDetector
from .grid import CeilingGrid, find_grid_corners
from .live import TrackOutputs
from .multitrack import MultiRobotTracker, track_robots_frames, track_robots_video
from .pipeline import iter_track, read_track_csv, track_frames, track_video, write_track_csv
from .render import (
    CeilingScene,
    SceneConfig,
    iter_frames,
    render_video,
    true_homography,
)
from .track import Tracker, TrackerConfig
from .video_io import open_frames, open_live

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
