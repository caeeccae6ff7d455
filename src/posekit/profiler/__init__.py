"""Laser profiler system: 6-DoF pose of a flange from one 2D profile of a multi-plane gauge.

Pipeline: :func:`detect_corners` (paper §II-D; model-based when given the gauge) →
:func:`solve_pose` (closed form eq. 9–14 and maximum-likelihood refinement, with the pose
covariance and a χ² verdict). :func:`estimate_pose` does both.
:mod:`~posekit.profiler.sim.render` simulates an LJ-X8400-like sensor, ideal or with
:class:`RealismModel`'s defects; :func:`calibrate_gauge` recovers the as-built gauge and :func:`estimate_profiles` tests the gauge file
against a whole batch (:func:`check_gauge_file`);
:class:`ProfileSource` is the interface a sensor (or a vendor SDK) plugs into.

Sub-packages: ``estimate/`` (the estimator), ``stream/`` (server, clients, sources, pose
filter), ``loop/`` (the closed loop of §IV-C), ``studies/`` (Table I, Fig. 3, Fig. 4).
"""

from .estimate.closed_form import closed_form
from .estimate.corner_params import CornerParams
from .estimate.corners import Corners, detect_corners
from .estimate.pipeline import BatchResult, estimate_batch, estimate_pose, estimate_profiles
from .estimate.result import PoseEstimate
from .estimate.solve import solve_pose
from .gauge.calibration import GaugeCalibration, calibrate_gauge
from .gauge.check import GaugeCheck, check_gauge_file
from .gauge.model import BUNDLED_GAUGES, Gauge, bundled_gauge, gauge_from_design, load_gauge
from .sensor import LJ_X8400, NoiseModel, ProfilerModel
from .sim.poses import Workspace, nominal_pose, sample_poses
from .sim.realism import RealismModel
from .sim.render import render_profiles
from .stream.pose_filter import ConstantVelocityFilter, WindowFusion
from .stream.reading import read_profile_file
from .stream.sources import ProfileSource
from .studies.evaluate import Evaluation, evaluate, pose_errors

__all__ = [
    "Gauge", "load_gauge", "bundled_gauge", "gauge_from_design", "BUNDLED_GAUGES",
    "ProfilerModel", "NoiseModel", "Workspace", "LJ_X8400", "nominal_pose", "sample_poses", "render_profiles",
    "CornerParams", "Corners", "detect_corners",
    "PoseEstimate", "solve_pose", "closed_form",
    "estimate_pose", "estimate_batch", "estimate_profiles", "BatchResult", "GaugeCheck", "check_gauge_file",
    "Evaluation", "evaluate", "pose_errors",
    "RealismModel", "GaugeCalibration", "calibrate_gauge",
    "ProfileSource", "read_profile_file", "ConstantVelocityFilter", "WindowFusion",
]
