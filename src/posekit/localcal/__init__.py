"""Look-then-move positioning of a long-reach manipulator with motion-based local calibration.

After Mäkinen et al., "Vision-aided precise positioning for long-reach robotic manipulators
using local calibration" (Advanced Robotics, 2023). Frames (mm, rad): B robot base, F the TCP,
C the eye-in-hand camera (OpenCV optical axes), M the tool marker, O the object of interest,
W the VO world frame (the camera frame at the first VO pose).

Layout (model · estimator · simulator · studies)
------------------------------------------------
model/
    What the world is, as plain data: :class:`Trajectory` (s, mm, 4x4 poses), exchanged by
    every other part, and the camera's intrinsics with lens distortion (:class:`CameraIntrinsics`,
    :func:`zed2_720p`).
registration/, methods/
    The estimator, pure on its inputs. ``registration``: trajectory files (TUM, KITTI, EuRoC,
    ROS bags), timestamp association, robust Umeyama alignment, correspondence-free coarse
    alignment and rigid CPD, the verdict on a match, hand-eye calibration
    (:func:`match_trajectories`, ``calibrate_handeye``). ``methods``: orientation adjustment
    (eq. 7–8), line-equation range adjustment with the circular path (eq. 10–16),
    trajectory-matching range adjustment (eq. 17–22).
sim/
    The simulator, every part seeded: hydraulic long-reach arm with non-kinematic errors,
    OpenCV ArUco rendering and detection in the model's camera, the work cell (camera ~0.5 m off
    the tool point), a stereo VO whose noise and drift grow with depth.
studies/
    Experiments: one look-then-move episode (:func:`run_localcal_episode` →
    :class:`LocalcalEpisode`, settings :class:`EpisodeConfig`), repeated runs with the paper's
    Tables 2–4 (:func:`run_experiment`; every run's :class:`posekit.verdict.Verdict` in
    :attr:`ExperimentResult.verdicts`), figures (Figs. 5–9) and ``report.html`` (``studies.plots``
    imports matplotlib only when drawing; not re-exported here); the ``simulate`` and ``demo``
    commands as :func:`simulate` and :func:`demo`.
commands, match_report
    The ``match`` and ``handeye`` commands on files (:func:`match_files`, :func:`handeye_files`:
    read, register, write) and what ``match --plot/--residuals`` writes.

The rule (tested by ``tests/test_architecture.py``): the simulator may import the model, never
the estimator; the estimator never imports the simulator or the studies; the studies may import
everything; localcal imports only posekit's core, never another system.
"""

from .commands import handeye_files, match_files
from .methods.line_method import (
    CIRCLE_POINTS,
    CIRCLE_RADIUS_MM,
    LineAdjustment,
    circle_path,
    line_range_adjustment,
    line_reference,
    planar_distance_error,
)
from .methods.orientation import orientation_reference, rotation_difference, rotation_errors_deg
from .methods.trajectory_method import (
    PATH_LENGTHS_MM,
    PATH_XI_RAD,
    STANDOFF_MM,
    asymmetric_path,
    calibrate_trajectories,
    trajectory_reference,
)
from .model.camera import ZED2_720P_DISTORTION, CameraIntrinsics, zed2_720p
from .model.trajectory import Trajectory
from .registration.alignment import umeyama
from .registration.association import associate
from .registration.formats.tum import read_tum, write_tum
from .registration.match import Registration, match_trajectories
from .sim.arm import DEFAULT_Q0, ArmLog, LongReachArm
from .sim.arm_errors import NonKinematicErrors, sample_nonkinematic_errors
from .sim.camera import ARUCO_DICTIONARY, marker_corners, render_markers
from .sim.marker_detector import MarkerDetector
from .sim.scene import (
    GroundTruth,
    Observation,
    Workcell,
    default_workcell,
    ground_truth_errors,
    marker_errors,
    observe,
    ooi_pose,
)
from .sim.vo import StereoNoise, VONoise, depth_along_axis, simulate_vo
from .studies.episode import LocalcalEpisode, run_localcal_episode
from .studies.episode_config import METHODS, OCCLUSIONS, START_Q, EpisodeConfig
from .studies.experiments import (
    PAPER_TABLE2_MEAN,
    PAPER_TABLE3,
    PAPER_TABLE4_MEAN,
    ExperimentResult,
    format_table,
    run_experiment,
    table_columns,
)
from .studies.simulate import demo, episode_config, robot_options, simulate

__all__ = [
    # methods
    "orientation_reference",
    "rotation_difference",
    "rotation_errors_deg",
    "CIRCLE_RADIUS_MM",
    "CIRCLE_POINTS",
    "circle_path",
    "planar_distance_error",
    "line_reference",
    "LineAdjustment",
    "line_range_adjustment",
    "PATH_LENGTHS_MM",
    "PATH_XI_RAD",
    "STANDOFF_MM",
    "asymmetric_path",
    "trajectory_reference",
    "calibrate_trajectories",
    # trajectories and matching
    "Trajectory",
    "read_tum",
    "write_tum",
    "Registration",
    "match_trajectories",
    "umeyama",
    "associate",
    # simulator
    "DEFAULT_Q0",
    "ArmLog",
    "LongReachArm",
    "NonKinematicErrors",
    "sample_nonkinematic_errors",
    "ARUCO_DICTIONARY",
    "ZED2_720P_DISTORTION",
    "CameraIntrinsics",
    "MarkerDetector",
    "marker_corners",
    "render_markers",
    "zed2_720p",
    "GroundTruth",
    "Observation",
    "Workcell",
    "default_workcell",
    "ground_truth_errors",
    "marker_errors",
    "observe",
    "ooi_pose",
    "StereoNoise",
    "VONoise",
    "depth_along_axis",
    "simulate_vo",
    # episodes and experiments
    "METHODS",
    "OCCLUSIONS",
    "START_Q",
    "EpisodeConfig",
    "LocalcalEpisode",
    "run_localcal_episode",
    "ExperimentResult",
    "run_experiment",
    "table_columns",
    "format_table",
    "PAPER_TABLE2_MEAN",
    "PAPER_TABLE3",
    "PAPER_TABLE4_MEAN",
    # one function per command (posekit localcal match, handeye, simulate, demo)
    "match_files",
    "handeye_files",
    "simulate",
    "demo",
    "episode_config",
    "robot_options",
]
