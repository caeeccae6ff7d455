"""Look-then-move positioning of a long-reach manipulator with motion-based local calibration.

After Mäkinen et al., "Vision-aided precise positioning for long-reach robotic manipulators
using local calibration" (Advanced Robotics, 2023). Frames (mm, rad): B robot base, F the TCP,
C the eye-in-hand camera (OpenCV optical axes), M the tool marker, O the object of interest,
W the VO world frame (the camera frame at the first VO pose).

Modules
-------
orientation, line_method, trajectory_method
    The methods: orientation adjustment (eq. 7–8), line-equation range adjustment with the
    circular path (eq. 10–16), trajectory-matching range adjustment (eq. 17–22).
tum, registration (alignment, association, coarse, cpd)
    TUM trajectories and trajectory matching (timestamped robust Umeyama; correspondence-free
    never-mirrored coarse alignment + rigid CPD).
arm, camera, scene, vo
    The simulator: hydraulic long-reach arm with non-kinematic errors, ZED2-like camera with
    lens distortion and OpenCV ArUco rendering and detection, the work cell (camera ~0.5 m off
    the tool point), a stereo VO whose noise and drift grow with depth.
episode, experiments, plots
    One look-then-move episode (:func:`run_localcal_episode` → :class:`LocalcalEpisode`),
    repeated runs with the paper's Tables 2–4, figures (Figs. 5–9) and ``report.html``
    (``plots`` imports matplotlib only when drawing; not re-exported here).
"""

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
from .registration.match import Registration, associate, match_trajectories, umeyama
from .registration.tum import Trajectory, read_tum, write_tum
from .sim.arm import (
    DEFAULT_Q0,
    ArmLog,
    LongReachArm,
    NonKinematicErrors,
    sample_nonkinematic_errors,
)
from .sim.camera import (
    ARUCO_DICTIONARY,
    ZED2_720P_DISTORTION,
    CameraIntrinsics,
    marker_corners,
    render_markers,
    zed2_720p,
)
from .sim.episode import (
    METHODS,
    OCCLUSIONS,
    START_Q,
    EpisodeConfig,
    LocalcalEpisode,
    run_localcal_episode,
)
from .sim.experiments import (
    PAPER_TABLE2_MEAN,
    PAPER_TABLE3,
    PAPER_TABLE4_MEAN,
    ExperimentResult,
    format_table,
    run_experiment,
    table_columns,
)
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
]
