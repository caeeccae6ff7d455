"""What one step of the seam particle filter reads and returns, its settings, and the pose jitter a reading sees.

:class:`FilterSettings` is the algorithm's part of a configuration (the ``filter`` section), :class:`StepInputs`
one sample of a cell, :class:`StepEstimate` the filter's answer to it (:mod:`posekit.seam.engine.filter`).
"""

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["FilterSettings", "StepEstimate", "StepInputs", "jitter_variances"]


@dataclass(frozen=True)
class FilterSettings:
    """The algorithm's settings (the ``filter`` section of a seam configuration; meaning of each there).

    Attributes
    ----------
    particles : int
    resampler : str
        ``systematic``, ``stratified`` or ``residual``.
    ess_threshold : float
        Resample when the ESS falls below this fraction of the particles.
    regularize_h : float
        Bandwidth of the resampling kernel (and of the tempering moves), in [0, 1).
    anneal_ess : float
        Temper an update that would leave fewer effective particles than this fraction.
    anneal_stages : int
        Most tempering stages per step.
    reacquire_walk_scale : float
        The walk is this many times wider after a step that was not ``tracking``.
    integrity_window, integrity_window_long, integrity_alpha_degraded, integrity_alpha_lost, integrity_ess_min,
    integrity_recovery
        The status tests (:class:`~posekit.seam.engine.integrity.IntegrityMonitor`).
    """

    particles: int
    resampler: str
    ess_threshold: float
    regularize_h: float
    anneal_ess: float
    anneal_stages: int
    reacquire_walk_scale: float
    integrity_window: int
    integrity_window_long: int
    integrity_alpha_degraded: float
    integrity_alpha_lost: float
    integrity_ess_min: float
    integrity_recovery: int


@dataclass
class StepInputs:
    """Everything the filter reads at one time step.

    Attributes
    ----------
    T_increment : ndarray, shape (4, 4)
        Program increment ``Fk(q̄+) Fk(q̄)⁻¹`` (base frame, mm); identity at the first step.
    T_nominal : ndarray, shape (4, 4)
        Programmed tool pose ``Fk(q̄)`` of the step, mm.
    q_meas : ndarray, shape (n,)
        Measured joints, rad.
    force_n : ndarray, shape (3,)
        Measured process force on the tool in the base frame, N.
    time_s : float
        The step's time (s; increasing).
    q_ref : ndarray, shape (n,)
        The program's joints ``q̄`` of the step (rad): the robot at a reading's own time is the program
        interpolated between steps.
    laser_mm : ndarray, shape (S, 2), optional
        Laser readings ``(x, z)`` in each sensor frame, mm, NaN rows where a sensor has none.
    angle_rad : ndarray, shape (S,), optional
        Angle readings (rad), NaN where missing.
    reading_lag_s : ndarray, shape (S,), optional
        How long before ``time_s`` each reading was taken (s, >= 0; a log's ``m{k}_t_s`` stamps; NaN or None:
        the sensor's latency, the cell's declared one, else the profile's).
    """

    T_increment: np.ndarray
    T_nominal: np.ndarray
    q_meas: np.ndarray
    force_n: np.ndarray
    time_s: float
    q_ref: np.ndarray
    laser_mm: np.ndarray | None = None
    angle_rad: np.ndarray | None = None
    reading_lag_s: np.ndarray | None = None


@dataclass
class StepEstimate:
    """Output of one filter step.

    Attributes
    ----------
    T : ndarray, shape (4, 4)
        Weighted mean tool pose ``T_base_tool`` (mm).
    spread : ndarray, shape (6,)
        Reported standard deviation about the mean in its frame: x, y, z (mm), rx, ry, rz (rad): the cloud's or
        the spread bound's, whichever is wider, with the profile's jitter added.
    ess : float
        Effective sample size after the measurement update, in [1, N].
    resampled : bool
        Whether the particles were resampled at this step.
    recovered : bool
        Whether all weights vanished and were reset to uniform at this step.
    T_kinematic : ndarray, shape (4, 4)
        The robot measurement mean ``Fk(q + Cj(τ))`` (kinematics-only pose), mm.
    lasers_used : int
        Number of laser readings used.
    anneal_stages : int
        Tempering stages used at this step.
    status : str
        ``tracking``, ``degraded`` or ``lost`` (:mod:`posekit.seam.engine.integrity`).
    reason : str or None
        Which consistency test failed (None when tracking).
    nis : float
        Normalised innovation squared of this step's laser readings (0 without readings).
    ess_update : float
        ESS of the measurement update before tempering, in [1, N].
    nis_components : ndarray, shape (2 S,) or None
        Each reading component's normalised squared innovation (sensor k's x at ``2k``, z at ``2k + 1``; NaN: no
        reading): what the long integrity window tests and ``seam tune`` calibrates.
    innovations : ndarray, shape (2 S,) or None
        The same, signed and not squared (``ē_j / √C_jj``): what the bias test averages.
    """

    T: np.ndarray
    spread: np.ndarray
    ess: float
    resampled: bool
    recovered: bool
    T_kinematic: np.ndarray
    lasers_used: int
    anneal_stages: int = 0
    status: str = "tracking"
    reason: str | None = None
    nis: float = 0.0
    ess_update: float = math.nan
    nis_components: np.ndarray | None = None
    innovations: np.ndarray | None = None


def jitter_variances(mounts: np.ndarray, jitter: np.ndarray) -> np.ndarray:
    """Variance the pose jitter adds to each sensor's reading along its x and z axes, shape (S, 2), mm².

    Parameters
    ----------
    mounts : ndarray, shape (S, 4, 4)
        ``T_tool_sensor`` (mm).
    jitter : ndarray, shape (6,)
        The pose jitter, tool frame (mm, rad).

    Notes
    -----
    A tool-frame offset ``δ = [t, r]`` moves the sensor's seam point ``p`` (its origin; mm, tool frame) by
    ``t + r × p``; its components along the sensor's x and z axes are what the reading sees.
    """
    from posekit.seam.engine import _kernels as _k  # here: reading a configuration does not load numba

    M = np.ascontiguousarray(mounts, dtype=np.float64).reshape(-1, 4, 4)
    j2 = np.asarray(jitter, dtype=np.float64) ** 2
    axes = np.empty((M.shape[0], 2, 3))                          # the sensor's x and z axes
    lever = np.empty((M.shape[0], 2, 3))                         # d(r x p)/dr along each axis: p x axis
    _k.sensor_axes_levers(M, axes, lever)
    return (axes * axes) @ j2[:3] + (lever * lever) @ j2[3:]
