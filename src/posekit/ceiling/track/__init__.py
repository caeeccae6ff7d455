"""From detections to poses: the world-plane tracker, several cameras, several robots, a laser
line, the frame sources (files, folders, cameras, streams) and the per-row outputs."""

from .cameras import Camera, MultiCameraTracker
from .command import TrackPlan, TrackRun, plan_track, track_input
from .linetrack import LineTracker, LineTrackerConfig
from .multitrack import MultiRobotTracker, track_robots_frames, track_robots_video
from .outputs import TrackOutputs
from .pipeline import iter_track, read_track_csv, track_frames, track_video, write_track_csv
from .results import TrackResult
from .scene_learning import SceneLearning, learn_scene
from .sources import open_frames, open_live
from .tracker import Tracker
from .types import STATUSES, TrackerConfig, TrackRow

__all__ = [
    "TrackPlan",
    "TrackRun",
    "plan_track",
    "track_input",
    "STATUSES",
    "TrackerConfig",
    "TrackRow",
    "Tracker",
    "Camera",
    "MultiCameraTracker",
    "LineTracker",
    "LineTrackerConfig",
    "MultiRobotTracker",
    "track_robots_frames",
    "track_robots_video",
    "TrackResult",
    "iter_track",
    "track_frames",
    "track_video",
    "write_track_csv",
    "read_track_csv",
    "open_frames",
    "open_live",
    "TrackOutputs",
    "SceneLearning",
    "learn_scene",
]
