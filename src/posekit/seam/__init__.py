"""Particle-filter 6-DoF tool pose relative to a weld seam from 2D laser seam trackers.

Model (:mod:`.model`): the cell as the filter sees it — :class:`Cell` (robot with tool, sensors with
their latency, compliance model) and :class:`Profile` (the fitted walk, jitter, plateau, noise, latency).
Engine (:mod:`.engine`, imports no front end): particle-set primitives on SE(3) (``particles``), the
densities of the paper's §II-C (``densities``), l1 trend filtering of the nominal path (``trend``), the
laser-plane/seam intersection (``seamline``), the particle filter (``filter``), its integrity tests
(``integrity``), the spread the data support (``spread_bound``) and the linearised filter whose
likelihood the tuner maximises (``ekf``). Front end (:mod:`.frontend`): configuration (``config``), the
profile file (``profile``), the tuner (``tune``, ``posekit seam tune``), seams and robot programs
(``trajectories``), simulated episodes and their metrics (``simulate``), recorded episodes (``logs``),
the online tracker (``tracker``: :class:`SeamTracker`, ``posekit seam track``), the sensor-placement
design (``design``), comparisons (``compare``), the Monte-Carlo study (``study``), figures (``plots``)
and report files (``report``).

Frames and units: mm and rad inside; ``T_base_tool`` poses of the TCP in the robot base frame;
the tool's y axis points along the travel, z along the tool axis; errors are reported in the
nominal seam frame (translation mm, rotation deg).
"""

# --- engine ------------------------------------------------------------------------------
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
from .frontend.profile import (
    DEFAULT_PROFILE,
    ProfileModel,
    default_profile,
    dump_profile,
    load_profile,
    write_profile,
)
from .frontend.simulate import (
    AXES,
    EpisodeResult,
    SimulatedData,
    measurement_hypotheses,
    metrics,
    pose_coords,
    run_episode,
    seam_frame_errors,
    seam_knots,
    simulate_data,
)
from .frontend.trajectories import (
    NominalTrajectory,
    nominal_trajectory,
    program_rotations_T0,
    seam_headings_T0,
    seam_points_T0,
)
from .model import Cell, Profile, Sensor

__all__ = [
    "AXES",
    # particles
    "RESAMPLERS",
    # config
    "RESAMPLER_NAMES",
    "TRAJECTORY_KINDS",
    "EpisodeResult",
    "Cell",
    "CellConfig",
    "DEFAULT_PROFILE",
    "FilterConfig",
    "FilterSettings",
    "LayoutNote",
    "Profile",
    "ProfileModel",
    "Sensor",
    "SimulationConfig",
    "cell_from_config",
    "default_profile",
    "dump_profile",
    "load_profile",
    "write_profile",
    "Intersection",
    "NominalTrajectory",
    "RobotConfig",
    "RobotMeasurement",
    "SeamConfig",
    # seam geometry, trend filter, trajectories
    "SeamLine",
    # filter and episodes
    "SeamParticleFilter",
    "SensorsConfig",
    "SimulatedData",
    "StepEstimate",
    "StepInputs",
    "TrajectoryConfig",
    "TrendResult",
    "angle_loglik",
    "apply_overrides",
    "config_from_dict",
    "dump_config",
    "effective_sample_size",
    "joint_compliance",
    "laser_loglik",
    "load_config",
    "metrics",
    "measurement_hypotheses",
    "nominal_trajectory",
    "program_rotations_T0",
    "seam_headings_T0",
    "normalize_log_weights",
    "plateau_logpdf",
    "plateau_pdf_1d",
    "pose_coords",
    "seam_frame_errors",
    "resample",
    "residual_resample",
    "robot_loglik",
    "robot_measurement",
    "run_episode",
    "seam_knots",
    "seam_points_T0",
    "simulate_data",
    "stratified_resample",
    "systematic_resample",
    # densities
    "transition",
    "trend_filter",
    "weighted_mean_se3",
]

# --- front end (figures import matplotlib lazily, inside the functions) --------------------
from .frontend.compare import (
    FIG8_SENSORS,
    FIG8_TRAJECTORIES,
    ConfigurationSet,
    compare_configurations,
    episode_seeds,
    run_episodes,
    with_sensors,
)
from .frontend.design import (
    RANKING_COLUMNS,
    DesignConfiguration,
    SensorDesign,
    design_configurations,
    distance_grid,
    sensor_design,
    write_design,
)
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
from .frontend.report import (
    ERROR_AXES,
    ERROR_COLUMNS,
    ESTIMATE_COLUMNS,
    html_figure,
    html_table,
    read_estimates_csv,
    write_csv,
    write_estimates_csv,
    write_html,
    write_json,
    write_simulation,
)
from .frontend.study import (
    DEFAULT_FACTORS,
    ERROR_NAMES,
    RANKED_COLUMNS,
    RUN_COLUMNS,
    Factor,
    ParameterEffects,
    SeamStudy,
    factor_value,
    fit_parameter_effects,
    get_dotted,
    make_factors,
    rank_parameters,
    seam_study,
    set_dotted,
    study_task,
    write_study,
)
from .frontend.tracker import SeamTracker, SeamTrackResult, TrackEstimate, track_log, track_metrics, write_track
from .frontend.tune import TunedValue, TuneResult, tune_profile, tune_report, tune_simulated

__all__ += [
    # the profile's tuner (issue 26)
    "TuneResult",
    "TunedValue",
    "tune_profile",
    "tune_report",
    "tune_simulated",
    # recorded episodes and the online tracker (issue 15)
    "EpisodeLog",
    "LogSetup",
    "SeamTracker",
    "TrackEstimate",
    "SeamTrackResult",
    "log_columns",
    "read_episode_log",
    "track_log",
    "track_metrics",
    "write_episode_log",
    "write_track",
    # sensor-placement design
    "RANKING_COLUMNS",
    "DesignConfiguration",
    "SensorDesign",
    "design_configurations",
    "distance_grid",
    "sensor_design",
    "write_design",
    "plot_design_ranking",
    "plot_ess",
    "plot_measurement_hypotheses",
    "factor_value",
    # plots
    "AXIS_LABELS",
    # study (Fig. 6)
    "DEFAULT_FACTORS",
    # report
    "ERROR_AXES",
    "ERROR_COLUMNS",
    "ERROR_NAMES",
    "ESTIMATE_COLUMNS",
    # compare (Fig. 8)
    "FIG8_SENSORS",
    "FIG8_TRAJECTORIES",
    "RANKED_COLUMNS",
    "RUN_COLUMNS",
    "ConfigurationSet",
    "Factor",
    "ParameterEffects",
    "SeamStudy",
    "compare_configurations",
    "episode_seeds",
    "fit_parameter_effects",
    "get_dotted",
    "html_figure",
    "html_table",
    "make_factors",
    "particle_histogram",
    "plot_error_distributions",
    "plot_tracking_errors",
    "plot_particle_density",
    "plot_pvalue_heatmap",
    "plot_tool_paths",
    "positions_in_frame",
    "rank_parameters",
    "read_estimates_csv",
    "run_episodes",
    "seam_study",
    "set_dotted",
    "study_task",
    "with_sensors",
    "write_csv",
    "write_estimates_csv",
    "write_html",
    "write_json",
    "write_simulation",
    "write_study",
]
