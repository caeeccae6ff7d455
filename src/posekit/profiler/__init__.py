"""Laser profiler system: 6-DoF pose of a flange from one 2D profile of a multi-plane gauge.

Pipeline: :func:`detect_corners` (paper §II-D) → :func:`solve_pose` (closed form eq. 9–14
and maximum-likelihood refinement, with the pose covariance). :func:`estimate_pose` does
both. :mod:`~posekit.profiler.estimate.sensor` simulates an LJ-X8400-like sensor.
"""

from .estimate.corners import CornerParams, Corners, detect_corners
from .estimate.evaluate import Evaluation, evaluate, pose_errors
from .estimate.gauge import BUNDLED_GAUGES, Gauge, bundled_gauge, gauge_from_design, load_gauge
from .estimate.pipeline import estimate_batch, estimate_pose
from .estimate.sensor import (
    LJ_X8400,
    NoiseModel,
    ProfilerModel,
    Workspace,
    nominal_pose,
    render_profiles,
    sample_poses,
)
from .estimate.solve import PoseEstimate, closed_form, solve_pose

__all__ = [
    "Gauge", "load_gauge", "bundled_gauge", "gauge_from_design", "BUNDLED_GAUGES",
    "ProfilerModel", "NoiseModel", "Workspace", "LJ_X8400", "nominal_pose", "sample_poses", "render_profiles",
    "CornerParams", "Corners", "detect_corners",
    "PoseEstimate", "solve_pose", "closed_form",
    "estimate_pose", "estimate_batch",
    "Evaluation", "evaluate", "pose_errors",
]
