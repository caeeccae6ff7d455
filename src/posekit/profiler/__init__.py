"""Laser profiler system: 6-DoF pose of a flange from one 2D profile of a multi-plane gauge.

Pipeline: :func:`detect_corners` (paper §II-D) → :func:`solve_pose` (closed form eq. 9–14
and maximum-likelihood refinement, with the pose covariance). :func:`estimate_pose` does
both. :mod:`~posekit.profiler.sensor` simulates an LJ-X8400-like sensor.
"""

from .corners import CornerParams, Corners, detect_corners
from .estimate import estimate_batch, estimate_pose
from .evaluate import Evaluation, evaluate, pose_errors
from .gauge import BUNDLED_GAUGES, Gauge, bundled_gauge, gauge_from_design, load_gauge
from .sensor import (
    LJ_X8400,
    NoiseModel,
    ProfilerModel,
    Workspace,
    nominal_pose,
    render_profiles,
    sample_poses,
)
from .solve import PoseEstimate, closed_form, solve_pose

__all__ = [
    "Gauge", "load_gauge", "bundled_gauge", "gauge_from_design", "BUNDLED_GAUGES",
    "ProfilerModel", "NoiseModel", "Workspace", "LJ_X8400", "nominal_pose", "sample_poses", "render_profiles",
    "CornerParams", "Corners", "detect_corners",
    "PoseEstimate", "solve_pose", "closed_form",
    "estimate_pose", "estimate_batch",
    "Evaluation", "evaluate", "pose_errors",
]
