"""Laser profiler system: 6-DoF pose of a flange from one 2D profile of a multi-plane gauge.

Pipeline: :func:`detect_corners` (paper §II-D; model-based when given the gauge) →
:func:`solve_pose` (closed form eq. 9–14 and maximum-likelihood refinement, with the pose
covariance and its verdict, a :class:`posekit.verdict.Verdict`). :func:`estimate_pose` does both;
:func:`estimate_profiles` does a batch and tests the gauge file against it (:func:`check_gauge_file`);
:func:`calibrate_gauge` recovers the as-built gauge. :func:`render_profiles` simulates an
LJ-X8400-like sensor, ideal or with :class:`RealismModel`'s defects; :class:`ProfileSource` is
the interface a sensor (or a vendor SDK) plugs into.

One function per command, with the command's arguments by the same names (the CLI only parses
and prints): ``posekit profiler estimate`` → :func:`estimate_file`, ``simulate`` → :func:`simulate`,
``calibrate-gauge`` → :func:`calibrate_gauge_file`, ``study corners|noise|limits`` → :func:`run_study`,
``loop`` and ``posekit demo`` → :func:`closed_loop`, ``accuracy`` → :func:`accuracy`, ``serve`` →
:func:`serve`, ``replay`` → :func:`replay`.

Layout (DESIGN.md "Layout"; the rule is tested by ``tests/test_architecture.py``): the **model**
— ``gauge/`` and :mod:`~posekit.profiler.sensor` (what the gauge and the sensor are); the
**estimator** — ``estimate/`` (pure on its inputs; never imports the simulator or the
studies); the **simulator** — ``sim/`` (uses the model, never the estimator); the **studies** —
``studies/`` (Table I, Fig. 3, Fig. 4) and ``loop/`` (the closed loop of §IV-C); ``stream/``
carries profiles in and records out (files, the real-time server and its clients).
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
from .loop.closed_loop import closed_loop
from .sensor import LJ_X8400, NoiseModel, ProfilerModel
from .sim.poses import Workspace, nominal_pose, sample_poses
from .sim.realism import RealismModel
from .sim.render import render_profiles
from .sim.simulate import Simulation, simulate
from .stream.files import calibrate_gauge_file, estimate_file
from .stream.pose_filter import ConstantVelocityFilter, WindowFusion
from .stream.reading import read_profile_file
from .stream.replay import replay
from .stream.serve import serve
from .stream.sources import ProfileSource
from .studies.evaluate import Evaluation, accuracy, evaluate, pose_errors
from .studies.study_report import run_study

__all__ = [
    "Gauge", "load_gauge", "bundled_gauge", "gauge_from_design", "BUNDLED_GAUGES",
    "ProfilerModel", "NoiseModel", "Workspace", "LJ_X8400", "nominal_pose", "sample_poses", "render_profiles",
    "CornerParams", "Corners", "detect_corners",
    "PoseEstimate", "solve_pose", "closed_form",
    "estimate_pose", "estimate_batch", "estimate_profiles", "BatchResult", "GaugeCheck", "check_gauge_file",
    "Evaluation", "evaluate", "pose_errors",
    "RealismModel", "GaugeCalibration", "calibrate_gauge",
    "ProfileSource", "read_profile_file", "ConstantVelocityFilter", "WindowFusion",
    "estimate_file", "simulate", "Simulation", "calibrate_gauge_file", "run_study", "closed_loop", "accuracy", "serve",
    "replay",
]
