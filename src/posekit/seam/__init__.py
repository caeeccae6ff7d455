"""Particle-filter 6-DoF tool pose relative to a weld seam from 2D laser seam trackers.

Model (:mod:`.model`): the cell as the filter sees it — :class:`Cell` (robot with tool, sensors with
their latency, compliance model) and :class:`Profile` (the fitted walk, jitter, plateau, noise, latency).
Engine (:mod:`.engine`, imports no front end): particle-set primitives on SE(3) (``particles``), the
densities of the paper's §II-C (``densities``), l1 trend filtering of the nominal path (``trend``), the
laser-plane/seam intersection (``seamline``), the particle filter (``filter``), its integrity tests
(``integrity``), the spread the data support (``spread_bound``) and the linearised filter whose
likelihood the tuner maximises (``ekf``). Front end (:mod:`.frontend`): configuration (``config``), the
profile file (``profile``), the tuner (``tune``, ``posekit seam tune``), seams and robot programs
(``trajectories``), the simulated world (``simulate``), the filter over a simulated episode
(``episode``) and the episodes' metrics (``episode_metrics``) with errors in the seam frame
(``seam_frame``), recorded episodes (``logs``), the online tracker (``tracker``: :class:`SeamTracker`,
``posekit seam track``), the sensor-placement design (``design``), comparisons (``compare``), the
Monte-Carlo study (``study``, its factors ``study_factors`` and effects ``study_effects``), figures
(``plots``) and report files (``report``).

Frames and units: mm and rad inside; ``T_base_tool`` poses of the TCP in the robot base frame;
the tool's y axis points along the travel, z along the tool axis; errors are reported in the
nominal seam frame (translation mm, rotation deg).
"""

# figures import matplotlib lazily, inside the functions
from posekit.report import html_figure, write_csv, write_html, write_json  # the core's, listed here as before

from .engine.densities import (
    RobotMeasurement,
    angle_loglik,
    joint_compliance,
    laser_loglik,
    plateau_logpdf,
    plateau_pdf_1d,
    robot_loglik,
    robot_measurement,
    transition,
)
from .engine.filter import SeamParticleFilter
from .engine.particles import (
    RESAMPLERS,
    effective_sample_size,
    normalize_log_weights,
    resample,
    residual_resample,
    stratified_resample,
    systematic_resample,
    weighted_mean_se3,
)
from .engine.seamline import Intersection, SeamLine
from .engine.step import FilterSettings, StepEstimate, StepInputs
from .engine.trend import TrendResult, trend_filter
from .frontend.commands import (
    SeamDemo,
    SeamSimulation,
    SeamTrackRun,
    check_kept,
    demo,
    episode_config,
    record_count,
    simulate_episodes,
    track_episode,
    two_sensor_wins,
    with_profile,
)
from .frontend.commands_batch import (
    DesignRun,
    StudyRun,
    check_design_size,
    check_study_size,
    design,
    study,
    tune,
    tune_command,
    tune_config,
)
from .frontend.compare import (
    FIG8_SENSORS,
    FIG8_TRAJECTORIES,
    ConfigurationSet,
    compare_configurations,
    episode_seeds,
    run_episodes,
    with_sensors,
)
from .frontend.config import (
    RESAMPLER_NAMES,
    TRAJECTORY_KINDS,
    FilterConfig,
    LayoutNote,
    SeamConfig,
    SimulationConfig,
    TrajectoryConfig,
    apply_overrides,
    config_from_dict,
    dump_config,
    load_config,
)
from .frontend.config_cell import CellConfig, RobotConfig, SensorsConfig, cell_from_config
from .frontend.design import (
    RANKING_COLUMNS,
    DesignConfiguration,
    SensorDesign,
    design_configurations,
    distance_grid,
    sensor_design,
    write_design,
)
from .frontend.episode import EpisodeResult, measurement_hypotheses, run_episode, seam_knots
from .frontend.episode_metrics import metrics
from .frontend.logs import EpisodeLog, log_columns, read_episode_log, write_episode_log
from .frontend.logs_setup import LogSetup
from .frontend.plots import (
    AXIS_LABELS,
    particle_histogram,
    plot_design_ranking,
    plot_error_distributions,
    plot_ess,
    plot_measurement_hypotheses,
    plot_particle_density,
    plot_pvalue_heatmap,
    plot_tool_paths,
    plot_tracking_errors,
    positions_in_frame,
)
from .frontend.profile import (
    DEFAULT_PROFILE,
    ProfileModel,
    default_profile,
    dump_profile,
    load_profile,
    write_profile,
)
from .frontend.report import (
    ERROR_AXES,
    ERROR_COLUMNS,
    ESTIMATE_COLUMNS,
    html_table,
    read_estimates_csv,
    write_estimates_csv,
    write_simulation,
)
from .frontend.seam_frame import AXES, pose_coords, seam_frame_errors
from .frontend.simulate import SimulatedData, simulate_data
from .frontend.study import RUN_COLUMNS, SeamStudy, seam_study, study_task, write_study
from .frontend.study_effects import (
    ERROR_NAMES,
    RANKED_COLUMNS,
    ParameterEffects,
    fit_parameter_effects,
    rank_parameters,
)
from .frontend.study_factors import DEFAULT_FACTORS, Factor, factor_value, get_dotted, make_factors, set_dotted
from .frontend.tracker import SeamTracker, SeamTrackResult, TrackEstimate, track_log, track_metrics, write_track
from .frontend.trajectories import (
    NominalTrajectory,
    nominal_trajectory,
    program_rotations_T0,
    seam_headings_T0,
    seam_points_T0,
)
from .frontend.tune import TunedValue, TuneResult, tune_profile, tune_report, tune_simulated
from .model import Cell, Profile, Sensor

__all__ = [
    "angle_loglik",
    "apply_overrides",
    "AXES",
    "AXIS_LABELS",
    "Cell",
    "cell_from_config",
    "CellConfig",
    "compare_configurations",
    "SeamSimulation",
    "SeamDemo",
    "SeamTrackRun",
    "episode_config",
    "with_profile",
    "record_count",
    "check_kept",
    "simulate_episodes",
    "demo",
    "two_sensor_wins",
    "track_episode",
    "StudyRun",
    "DesignRun",
    "tune_command",
    "tune_config",
    "tune",
    "check_study_size",
    "study",
    "check_design_size",
    "design",
    "config_from_dict",
    "ConfigurationSet",
    "DEFAULT_FACTORS",
    "DEFAULT_PROFILE",
    "default_profile",
    "design_configurations",
    "DesignConfiguration",
    "distance_grid",
    "dump_config",
    "dump_profile",
    "effective_sample_size",
    "episode_seeds",
    "EpisodeLog",
    "EpisodeResult",
    "ERROR_AXES",
    "ERROR_COLUMNS",
    "ERROR_NAMES",
    "ESTIMATE_COLUMNS",
    "Factor",
    "factor_value",
    "FIG8_SENSORS",
    "FIG8_TRAJECTORIES",
    "FilterConfig",
    "FilterSettings",
    "fit_parameter_effects",
    "get_dotted",
    "html_figure",
    "html_table",
    "Intersection",
    "joint_compliance",
    "laser_loglik",
    "LayoutNote",
    "load_config",
    "load_profile",
    "log_columns",
    "LogSetup",
    "make_factors",
    "measurement_hypotheses",
    "metrics",
    "nominal_trajectory",
    "NominalTrajectory",
    "normalize_log_weights",
    "ParameterEffects",
    "particle_histogram",
    "plateau_logpdf",
    "plateau_pdf_1d",
    "plot_design_ranking",
    "plot_error_distributions",
    "plot_ess",
    "plot_measurement_hypotheses",
    "plot_particle_density",
    "plot_pvalue_heatmap",
    "plot_tool_paths",
    "plot_tracking_errors",
    "pose_coords",
    "positions_in_frame",
    "Profile",
    "ProfileModel",
    "program_rotations_T0",
    "rank_parameters",
    "RANKED_COLUMNS",
    "RANKING_COLUMNS",
    "read_episode_log",
    "read_estimates_csv",
    "resample",
    "RESAMPLER_NAMES",
    "RESAMPLERS",
    "residual_resample",
    "robot_loglik",
    "robot_measurement",
    "RobotConfig",
    "RobotMeasurement",
    "RUN_COLUMNS",
    "run_episode",
    "run_episodes",
    "seam_frame_errors",
    "seam_headings_T0",
    "seam_knots",
    "seam_points_T0",
    "seam_study",
    "SeamConfig",
    "SeamLine",
    "SeamParticleFilter",
    "SeamStudy",
    "SeamTracker",
    "SeamTrackResult",
    "Sensor",
    "sensor_design",
    "SensorDesign",
    "SensorsConfig",
    "set_dotted",
    "simulate_data",
    "SimulatedData",
    "SimulationConfig",
    "StepEstimate",
    "StepInputs",
    "stratified_resample",
    "study_task",
    "systematic_resample",
    "track_log",
    "track_metrics",
    "TrackEstimate",
    "TRAJECTORY_KINDS",
    "TrajectoryConfig",
    "transition",
    "trend_filter",
    "TrendResult",
    "tune_profile",
    "tune_report",
    "tune_simulated",
    "TunedValue",
    "TuneResult",
    "weighted_mean_se3",
    "with_sensors",
    "write_csv",
    "write_design",
    "write_episode_log",
    "write_estimates_csv",
    "write_html",
    "write_json",
    "write_profile",
    "write_simulation",
    "write_study",
    "write_track",
]
