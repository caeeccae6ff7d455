"""Configuration of a seam-tracking simulation and its particle filter (pydantic v2, YAML).

Every parameter lives here with its default and its unit in its name (mm, deg, N, s). The
defaults are the paper's setup: h = 0.01 s, T = 500 steps, two laser sensors 20 mm and 40 mm
ahead of the tool, the xy trajectory. Unknown keys are errors (``extra='forbid'``), and so are
inf and NaN values, YAML booleans where a number is expected, and every number outside its
range (in the comment beside each key): no value that passes validation can overflow or
allocate absurdly later, and an episode's size is bounded (:data:`MAX_PARTICLE_STEPS`,
:data:`MAX_STEP_SEAM_POINTS`). A range error names the key, the bound, what arrived and the
whole range with its unit: ``filter.d0_mm: expected <= 1000.0, got 1e+308 (allowed 0..1000 mm)``.

Sections
--------
``seed``        the episode seed (int >= 0)
``trajectory``  the seam and the robot program along it (kind xy | yz | line | bend)
``robot``       the arm (a bundled model, PUMA 560 by default, or a URDF file), its tool, joint
                noise and kinematic model error
``process``     the process force and the compliance that turns it into deflection
``sensors``     0..4 laser seam trackers ahead of the tool, their noise and range
``filter``      particle count, resampling, transition / robot / laser densities, trend filter

:func:`load_config` reads a YAML file; :func:`config_from_dict` validates a mapping;
:func:`apply_overrides` sets dotted keys (command-line flags). All three raise
:class:`~posekit.errors.ConfigError` with a one-line message naming the dotted key and the
source (file). ``SeamConfig.model_validate(dict)`` raises pydantic's ``ValidationError``.
"""

import math
from pathlib import Path
from typing import Annotated, Any, Literal, get_args, get_origin

import annotated_types
import numpy as np
import yaml
from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)
from pydantic.fields import FieldInfo
from pydantic_core import PydanticCustomError

from posekit.errors import ConfigError
from posekit.seam.engine.particles import RESAMPLERS

__all__ = [
    "DEFAULT_SENSOR_DISTANCES_MM",
    "MAX_PARTICLES",
    "MAX_PARTICLE_STEPS",
    "MAX_STEPS",
    "MAX_STEP_SEAM_POINTS",
    "SEED_MAX",
    "RESAMPLER_NAMES",
    "TRAJECTORY_KINDS",
    "FilterConfig",
    "ProcessConfig",
    "RobotConfig",
    "SeamConfig",
    "SensorsConfig",
    "TrajectoryConfig",
    "apply_overrides",
    "config_from_dict",
    "dump_config",
    "load_config",
]

TRAJECTORY_KINDS = ("xy", "yz", "line", "bend")
RESAMPLER_NAMES = tuple(RESAMPLERS)             # the one list: posekit.seam.engine.particles.RESAMPLERS
#: The robot of the paper's setup, used when the config names none.
DEFAULT_ROBOT = "puma560"
#: Sensor distances used when ``sensors.distances_mm`` is not given: the first ``count``.
DEFAULT_SENSOR_DISTANCES_MM = (20.0, 40.0, 60.0, 80.0)

class _Section(BaseModel):
    # inf and NaN are no parameter values: a NaN noise would turn every estimate into NaN
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


# ------------------------------------------------------------------ numbers and their ranges
#
# Every number has a documented range (in the comment beside it) chosen so that no value that
# passes validation can overflow or allocate absurdly later: lengths up to 10 m of seam, noise
# and plateau widths up to 1 m or 180 deg, strictly positive standard deviations at least 1e-9
# (they divide), and the episode's size bounded (steps <= 100,000, particles <= 1,000,000,
# steps x particles <= MAX_PARTICLE_STEPS). A YAML boolean is never read as a number.

#: Largest seed: NumPy's SeedSequence takes any int >= 0; 2**63 - 1 fits every int64 column.
SEED_MAX = 2**63 - 1
#: Most time steps of one episode (1,000 s of welding at the paper's 100 Hz).
MAX_STEPS = 100_000
#: Most particles of the filter (about 0.1 GiB per (N, 4, 4) pose array).
MAX_PARTICLES = 1_000_000
#: Most filter work of one episode, ``trajectory.steps × filter.particles`` particle-steps
#: (0.3-1 µs each on one core: at most a few minutes to a quarter of an hour per episode).
MAX_PARTICLE_STEPS = 10**9
#: Most ``trajectory.steps × seam points`` (the seam is sampled every 0.5 mm over ``length_mm +
#: seam_extension_mm``): the simulator cuts every step's laser planes with every seam segment
#: at once, about 110 bytes each, so 1 GiB at this limit (500 steps on the default 260 mm seam: 2.6e5).
MAX_STEP_SEAM_POINTS = 10**7


def _not_bool(value):
    """Refuse YAML ``true`` / ``false`` where a number is expected (pydantic would read 1 / 0)."""
    if isinstance(value, bool):
        raise PydanticCustomError("bool_not_number", "expected a number, got a boolean")
    return value


#: A float field that refuses booleans; numbers and numeric strings ('1e-3' in YAML) are read.
Number = Annotated[float, BeforeValidator(_not_bool)]
#: An int field that refuses booleans.
Integer = Annotated[int, BeforeValidator(_not_bool)]


def _item(lo: float | None, hi: float) -> Any:
    """The type of one element of a tuple field: a number in ``lo..hi`` (not a boolean)."""
    return Annotated[float, BeforeValidator(_not_bool), Field(ge=lo, le=hi)]


def _num(default, lo=None, hi=None, unit: str = "", *, lo_open: bool = False, hi_open: bool = False, **kw):
    """A ``Field`` with its range (``lo..hi``, either end open) and its unit for error messages."""
    bounds = {}
    if lo is not None:
        bounds["gt" if lo_open else "ge"] = lo
    if hi is not None:
        bounds["lt" if hi_open else "le"] = hi
    return Field(default, json_schema_extra={"unit": unit}, **bounds, **kw)


Coord_mm = _item(-1e5, 1e5)            # a position in the robot base frame: within 100 m of the base
Force_n = _item(-1e5, 1e5)             # a force component: within 100 kN
Distance_mm = _item(None, 1e3)         # a sensor distance ahead of the tool: <= 1 m (> 0 checked below)
JointSeed_deg = _item(-1e4, 1e4)       # an IK seed joint value
_Entry = _item(-1e5, 1e5)              # an entry of a 4x4 rigid transform (rotation or mm), within 100 m
#: A 4x4 rigid transform as four rows of four numbers (rotation part orthonormal, last row 0 0 0 1).
Matrix4 = tuple[tuple[_Entry, _Entry, _Entry, _Entry], tuple[_Entry, _Entry, _Entry, _Entry],
                tuple[_Entry, _Entry, _Entry, _Entry], tuple[_Entry, _Entry, _Entry, _Entry]]


def _check_rigid(m, what: str):
    """``m`` (4 rows of 4 numbers) unchanged when it is a rigid transform; ValueError otherwise."""
    a = np.array(m, dtype=np.float64)
    if not np.allclose(a[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
        raise ValueError(f"{what}: expected the last row [0, 0, 0, 1], got {a[3].tolist()}")
    R = a[:3, :3]
    err = float(np.abs(R.T @ R - np.eye(3)).max())
    if err > 1e-6 or np.linalg.det(R) < 0.0:
        raise ValueError(f"{what}: expected a rotation (orthonormal, det +1) in the upper-left 3x3, "
                         f"off by {err:.2g}" + (" (a reflection)" if np.linalg.det(R) < 0.0 else ""))
    return m


class TrajectoryConfig(_Section):
    """The seam and the nominal robot program along it (paper §III-B, Fig. 9).

    The path is given in the tool frame at the start (y along the travel, z along the tool
    axis) and the tool keeps its orientation: ``xy`` is ``length_mm`` along y with a smooth
    triangle wave of ``amplitude_mm`` in x (default 20 mm, period 100 mm); ``yz`` is
    ``length_mm`` along y with a sine of ``amplitude_mm`` in z (default 100 mm, period 200 mm);
    ``line`` is straight along y; ``bend`` is straight along y up to ``bend_at`` of the length,
    then turns by ``bend_deg`` about the tool z axis (a sharp corner, the seam feature of Fig. 5).
    With ``tool_orientation: tangent`` the tool turns with the seam (its y axis along the seam
    tangent projected on the workpiece plane, averaged over ``turn_mm`` of travel), as in the
    authors' simulator; ``fixed`` keeps the start orientation (the paper's Fig. 9 programs).
    """

    kind: Literal["xy", "yz", "line", "bend"] = "xy"
    length_mm: Number = _num(200.0, 1.0, 1e4, "mm")  # 1 mm .. 10 m (the seam is sampled every 0.5 mm)
    amplitude_mm: Number | None = _num(None, 0.0, 1e3, "mm")  # 0 .. 1 m; None: 20 (xy), 100 (yz), 0 otherwise
    period_mm: Number | None = _num(None, 1.0, 1e4, "mm")  # 1 mm .. 10 m; None: 100 (xy), 200 (yz)
    corner_smoothing: Number = _num(0.1, 0.0, 0.5, hi_open=True)  # corner blend, fraction of the period, [0, 0.5)
    steps: Integer = _num(500, 2, MAX_STEPS)  # 2 .. 100,000 samples
    dt_s: Number = _num(0.01, 1e-5, 10.0, "s")  # 10 µs (100 kHz) .. 10 s
    bend_at: Number = _num(0.5, 0.0, 1.0, lo_open=True, hi_open=True)  # fraction of length_mm, (0, 1)
    bend_deg: Number = _num(30.0, -90.0, 90.0, "deg")  # -90 .. 90 deg (a right-angle corner included)
    # the tool orientation along the program: fixed (that of the start) or tangent (its y axis follows
    # the seam's tangent in the workpiece plane, the authors' simulator; it turns over turn_mm at a corner)
    tool_orientation: Literal["fixed", "tangent"] = "fixed"
    turn_mm: Number = _num(10.0, 0.0, 1e3, "mm")  # 0 .. 1 m of travel over which the heading is averaged
    start_mm: tuple[Coord_mm, Coord_mm, Coord_mm] = _num((450.0, -100.0, 0.0), unit="mm")  # seam start, base frame
    seam_extension_mm: Number = _num(60.0, 0.0, 1e3, "mm")  # 0 .. 1 m of seam beyond the end, seen by the sensors

    def resolved_amplitude_mm(self) -> float:
        """The wave amplitude in mm (the paper's value for the kind when not given)."""
        if self.amplitude_mm is not None:
            return float(self.amplitude_mm)
        return {"xy": 20.0, "yz": 100.0}.get(self.kind, 0.0)

    def resolved_period_mm(self) -> float:
        """The wave period in mm (100 mm for xy, 200 mm for yz when not given)."""
        if self.period_mm is not None:
            return float(self.period_mm)
        return {"xy": 100.0, "yz": 200.0}.get(self.kind, 200.0)


class RobotConfig(_Section):
    """The arm: model, tool, joint measurement noise and the kinematic model error.

    The robot is a bundled model (``model``, one of ``posekit.robots.MODEL_NAMES``) or the
    user's own URDF file (``urdf`` with optional ``base_link`` / ``tip_link``; a relative path is
    taken relative to the config file). ``robot: NAME`` is short for ``robot: {model: NAME}``.
    ``ik_seed_deg`` is the joint guess from which the program's first pose is solved (the
    bundled models have one that reaches the default seam; a URDF robot starts from the
    middle of its joint ranges, clipped to ±90°).

    The simulated (true) robot has its kinematic lengths perturbed by ``kinematic_error_mm`` and
    its angles by ``kinematic_error_deg`` (standard deviations, drawn once per episode: DH
    parameters for a DH model, the joint origins for a URDF robot); the filter and the
    kinematics-only estimate use the nominal model.
    """

    model: str | None = None  # None with urdf; the default robot otherwise
    urdf: str | None = None
    base_link: str | None = None
    tip_link: str | None = None
    # at most 64 joints, each -10,000 .. 10,000 deg
    ik_seed_deg: tuple[JointSeed_deg, ...] | None = _num(None, unit="deg", max_length=64)
    tool_length_mm: Number = _num(150.0, 0.0, 1e4, "mm", lo_open=True)  # flange to TCP along flange z, (0, 10 m]
    # the whole tool as a 4x4 T_flange_tool (mm); None: tool_length_mm along the flange z axis
    tool: Matrix4 | None = None
    joint_noise_deg: Number = _num(0.005, 0.0, 180.0, "deg")  # std, 0 .. 180 deg
    kinematic_error_mm: Number = _num(0.3, 0.0, 1e3, "mm")  # std, 0 .. 1 m
    kinematic_error_deg: Number = _num(0.05, 0.0, 180.0, "deg")  # std, 0 .. 180 deg

    @model_validator(mode="before")
    @classmethod
    def _name_shorthand(cls, data):
        if isinstance(data, str):
            return {"model": data}
        if isinstance(data, dict) and data.get("urdf") is None and data.get("model") is None:
            return {**data, "model": DEFAULT_ROBOT}
        return data

    @field_validator("model")
    @classmethod
    def _known_model(cls, v: str | None) -> str | None:
        from posekit.robots import MODEL_NAMES

        if v is not None and v not in MODEL_NAMES:
            raise ValueError(f"expected one of {list(MODEL_NAMES)} (or urdf: PATH), got {v!r}")
        return v

    @model_validator(mode="after")
    def _model_or_urdf(self):
        if self.urdf is None and (self.base_link is not None or self.tip_link is not None):
            raise ValueError("base_link and tip_link need urdf: PATH")
        if self.urdf is not None and self.model is not None:
            raise ValueError("give either model (a bundled robot) or urdf (a file), not both")
        return self

    @field_validator("tool")
    @classmethod
    def _rigid_tool(cls, v):
        return None if v is None else _check_rigid(v, "T_flange_tool")

    def tool_matrix(self) -> np.ndarray:
        """``T_flange_tool`` (4, 4), mm: ``tool``, or ``tool_length_mm`` along the flange z axis."""
        if self.tool is not None:
            return np.array(self.tool, dtype=np.float64)
        T = np.eye(4)
        T[2, 3] = self.tool_length_mm
        return T

    @property
    def label(self) -> str:
        """The robot's name in messages: the bundled name or the URDF file name."""
        return Path(self.urdf).name if self.urdf is not None else self.model


class ProcessConfig(_Section):
    """The process force on the tool and the compliance that turns it into deflection.

    ``force_n`` is the mean force on the tool in the tool frame (x across, y along the travel,
    z along the tool axis); it varies slowly by ``force_drift`` (relative amplitude of a
    sinusoid over the episode) plus white noise ``force_noise_n``. The filter reads it through a
    force sensor with noise ``force_sensor_noise_n``. Deflection = joint compliance
    (``Δq = c τ``, ``τ = J_vᵀ f``) + an unmodelled Cartesian part (translation along f,
    rotation about ``z_tool × f``).
    """

    force_n: tuple[Force_n, Force_n, Force_n] = _num((100.0, -1000.0, -5000.0), unit="N")  # each -100 .. 100 kN
    force_drift: Number = _num(0.2, 0.0, 10.0)  # relative amplitude, 0 .. 10
    force_noise_n: Number = _num(50.0, 0.0, 1e5, "N")  # std, 0 .. 100 kN
    force_sensor_noise_n: Number = _num(20.0, 0.0, 1e5, "N")  # std, 0 .. 100 kN
    joint_compliance_rad_per_nm: Number = _num(1e-6, 0.0, 1e-3, "rad/(N m)")  # 0 .. 1e-3
    cartesian_compliance_mm_per_n: Number = _num(1e-4, 0.0, 1.0, "mm/N")  # 0 .. 1 mm/N
    cartesian_compliance_deg_per_n: Number = _num(5e-4, 0.0, 1.0, "deg/N")  # 0 .. 1 deg/N


class SensorsConfig(_Section):
    """Laser seam trackers rigidly on the tool, ``distances_mm`` ahead of the TCP along +y.

    Each measures the seam in its laser plane (across, along the tool axis) with Gaussian noise
    ``noise_mm``; a measurement is missing when the plane does not cut the seam, when
    ``|m| > range_mm`` or with probability ``dropout``. With ``angle`` the sensors also measure
    the workpiece rotation about the laser-plane normal (noise ``angle_noise_deg``).
    ``distances_mm`` defaults to the first ``count`` of 20, 40, 60, 80 mm.
    """

    count: Integer = _num(2, 0, 4)  # 0 .. 4 sensors
    distances_mm: tuple[Distance_mm, ...] | None = _num(None, unit="mm", max_length=4)  # each (0, 1000] mm
    # any mount: one 4x4 T_tool_sensor (mm) per sensor, the laser plane being the sensor's x-z plane;
    # None: the sensors sit distances_mm ahead of the TCP along tool y, axes parallel to the tool's
    mounts: tuple[Matrix4, ...] | None = Field(None, max_length=4)
    noise_mm: Number = _num(0.05, 0.0, 1e3, "mm")  # std, 0 .. 1 m
    range_mm: Number = _num(150.0, 0.0, 1e4, "mm", lo_open=True)  # (0, 10 m]
    dropout: Number = _num(0.0, 0.0, 1.0)  # probability, 0 .. 1
    angle: bool = False
    angle_noise_deg: Number = _num(0.1, 0.0, 180.0, "deg")  # std, 0 .. 180 deg

    @field_validator("distances_mm")
    @classmethod
    def _ahead_of_tool(cls, v):
        if v is not None:
            for i, d in enumerate(v):
                if not d > 0.0:
                    raise ValueError(
                        f"sensor {i} is at {d:g} mm, expected > 0 mm (ahead of the tool)"
                    )
        return v

    @field_validator("mounts")
    @classmethod
    def _rigid_mounts(cls, v):
        if v is not None:
            v = tuple(_check_rigid(m, f"mounts[{i}] (T_tool_sensor)") for i, m in enumerate(v))
        return v

    @model_validator(mode="after")
    def _count_matches(self):
        if self.distances_mm is not None and len(self.distances_mm) != self.count:
            raise ValueError(
                f"count is {self.count} but distances_mm has {len(self.distances_mm)} entries"
            )
        if self.mounts is not None:
            if self.distances_mm is not None:
                raise ValueError("give either distances_mm or mounts (4x4 T_tool_sensor per sensor), not both")
            if len(self.mounts) != self.count:
                raise ValueError(f"count is {self.count} but mounts has {len(self.mounts)} entries")
            if self.angle and any(not np.allclose(np.array(m)[:3, :3], np.eye(3), atol=1e-9) for m in self.mounts):
                raise ValueError("angle: the angle measurement needs sensor axes parallel to the tool's "
                                 "(mounts with an identity rotation)")
        return self

    def resolved_distances_mm(self) -> tuple[float, ...]:
        """The sensor distances ahead of the tool in mm, one per sensor (a mount's y offset)."""
        if self.mounts is not None:
            return tuple(float(m[1][3]) for m in self.mounts)
        if self.distances_mm is not None:
            return tuple(float(d) for d in self.distances_mm)
        return DEFAULT_SENSOR_DISTANCES_MM[: self.count]

    def resolved_mounts(self) -> np.ndarray:
        """``T_tool_sensor`` of every sensor, shape (S, 4, 4), mm: ``mounts``, or a pure translation
        ``[0, d, 0]`` per distance ``d`` (the sensor's x-z plane is its laser plane)."""
        if self.mounts is not None:
            return np.array(self.mounts, dtype=np.float64).reshape(-1, 4, 4)
        d = self.resolved_distances_mm()
        M = np.repeat(np.eye(4)[None], len(d), axis=0)
        M[:, 1, 3] = d
        return M


class FilterConfig(_Section):
    """The particle filter (paper §II-B/C/E).

    Transition (eq. 3): per-step noise in the tool frame with widths
    ``sigma_t_mm + k_force_t ‖f‖`` (k_force_t in mm/N) and ``sigma_r_deg + k_force_r ‖f‖``
    (k_force_r in deg/N). Robot measurement (eq. 7/8): uniform plateau of radius
    ``d0_mm + kd_mm_per_n ‖f‖`` (translation) and ``d0_deg + kd_deg_per_n ‖f‖`` (rotation),
    Gaussian tails of covariance ``J Σq Jᵀ`` (``joint_sigma_deg``) plus a floor
    (``robot_floor_t_mm``, ``robot_floor_r_deg``). With ``bending_plateau`` the rotation
    plateau is an ellipsoid: radius ``d0_deg`` about the force direction and
    ``d0_deg + kd_deg_per_n ‖f‖`` about the axes across it (a force at the tool centre point
    bends the tool about axes across it; False: a ball). ``compliance_rad_per_nm`` is the filter's
    joint compliance model Cj(τ) (0: none). Laser (eq. 9): Gaussian ``laser_sigma_mm`` on the
    in-plane error, the seam searched within ``search_window_mm`` of the nominal intersection
    on the trend-filtered knot polyline (eq. 10: ``trend_lambda``, ``trend_eps_mm``). An update
    leaving fewer than ``anneal_ess · N`` effective particles is tempered in up to
    ``anneal_stages`` stages with kernel jitter ``anneal_jitter`` (times the cloud's covariance);
    resampling draws from a kernel density of bandwidth ``regularize_h`` that keeps the cloud's
    mean and covariance (0: plain resampling; see :mod:`posekit.seam.engine.filter`).

    Issue 15 (defaults describe the simulated cell): ``transition_force: rate`` widens the
    transition with the force change since the last step (``k_rate_*``, the paper's ḟ; the
    simulated cell moves ≈ 2e-4 mm and 2.8e-4 deg per N of force change per step), the force
    low-passed over ``force_rate_smoothing`` steps first (the difference of two raw readings is
    mostly their noise: ≈ 130 N per step at any load, so the width did not grow with the load);
    ``magnitude`` keeps ``k_force_* ‖f‖``. The width also grows with the step's travel,
    ``k_travel_*`` (the kinematic error is a function of the configuration) plus ``k_load_travel_*
    ‖f‖`` (the deflection ``C(q) f`` changes with ``q``: the simulated deviation from the nominal
    path drifts ≈ 0.007 mm and 0.0017 deg per mm at 5.1 kN, ≈ 0.035 mm and 0.0076 deg per mm at
    25 kN), and ``reacquire_transition_scale`` times after a step that was not ``tracking``.
    The unloaded width is scaled per tool axis (``axis_scale_*``) and the load's part too
    (``load_axis_scale_*``): the simulated cell's pose error drifts about x and the yaw rz ~10× less
    than along z and about rx, and one isotropic walk made the spread 2× too wide on x (2σ coverage
    0.999); chosen by the 2σ coverage of 30 default episodes per seam (seeds 0–29, xy and yz: every
    axis in 0.90–0.99), checked on seeds 30–59. For ``reacquire_isotropic_steps`` after a ``lost``
    step the walk is isotropic again (the cloud was rebuilt from few survivors; with the scales at
    once, a wrong start left rz 3σ off for tens of steps: 1.3 % of the steps confidently wrong).
    ``walk_adapt_*``: the walk follows the data (covariance matching on the lasers' NIS per degree
    of freedom, averaged over ``walk_adapt_window`` steps, within 1 .. ``walk_adapt_max`` times the
    configured width): on a robot the defaults do not describe (the bundled UR10 with its own
    plateau, 10 runs) the confidently wrong steps fell from 6.0 % to 0.6 %; on the PUMA 560 cell
    the coverage stays in 0.94-0.99. Per step one reading counts at most 3 (without the average
    and the cap a 90° seam corner blew the walk up and the track was lost).
    ``d0 + kd ‖f‖`` is the largest expected positioning error, as the paper prescribes (max over
    30 simulated default episodes of ``|truth - Fk(q_meas + Cj(τ))|``, the error the compliance model leaves: 2.9 mm /
    0.34 deg at 0 N, 3.3 mm / 0.89 deg at 5.1 kN, 3.8 mm / 1.48 deg at 10.2 kN; without the model 4.8 mm at 5.1 kN and
    7.0 mm at 10.2 kN, and kd_mm_per_n was 4.5e-4); ``laser_sigma_mm`` = ``sensors.noise_mm``;
    ``compliance_rad_per_nm`` = ``process.joint_compliance_rad_per_nm`` (the same cell: the particles move with the
    deflection the measured force predicts, the walk covers what the model misses). ``init_from_robot``
    draws the first cloud from the robot density; ``init_offset_*`` moves it (a wrong start, for
    tests). ``integrity_*``: the status tests of :mod:`posekit.seam.engine.integrity`.
    ``spread_bound``: the reported spread is at least the one the data support
    (:mod:`posekit.seam.engine.spread_bound`; the value scales its process noise, 0: off;
    ``spread_bound_k_travel`` adds translation noise per mm travelled). ``integrity_recovery``:
    steps after a ``lost`` step reported ``degraded`` at best; ``plateau_max_force_n``: above this
    force the plateau is extrapolated and every step ``degraded`` at best. ``cloud_floor``: the
    cloud kept at least this times the bound's covariance; ``bound_inflation`` (always) and
    ``bound_inflation_reacquire`` (for ``bound_reacquire_steps`` after a ``lost`` step): the bound weighs the
    lasers as the particles do; ``spread_shrink_reacquire``: within those steps the reported spread shrinks by at
    most this factor per step. ``regularize_h`` 0.5 (was 0.3;
    ``posekit seam simulate --runs 10 --seed 0``): xy RMSE rx/ry 0.18/0.22 -> 0.16/0.20 deg, the rest
    within 0.002; yz rx 0.24 -> 0.20 deg, z 0.76 -> 0.80 mm; yz y/z/rx coverage 0.88/0.87/0.87 -> 0.91/0.90/0.91.
    """

    particles: Integer = _num(500, 1, MAX_PARTICLES)  # N, 1 .. 1,000,000
    resampler: Literal[RESAMPLER_NAMES] = "systematic"
    ess_threshold: Number = _num(0.5, 0.0, 1.0, lo_open=True)  # fraction of the particle count, (0, 1]
    anneal_ess: Number = _num(0.05, 0.0, 1.0)  # temper an update leaving fewer (fraction of N), 0 .. 1
    anneal_stages: Integer = _num(20, 0, 100)  # 0 .. 100 tempering stages per update
    anneal_jitter: Number = _num(0.5, 0.0, 10.0)  # kernel bandwidth, times the cloud's covariance, 0 .. 10
    regularize_h: Number = _num(0.5, 0.0, 1.0, hi_open=True)  # resampling kernel bandwidth (0: plain), [0, 1)
    sigma_t_mm: Number = _num(0.01, 0.0, 1e3, "mm")  # std per step, 0 .. 1 m
    sigma_r_deg: Number = _num(0.005, 0.0, 180.0, "deg")  # std per step, 0 .. 180 deg
    # the transition width follows the force rate f-dot (paper eq. 3: p(x+ | x, f-dot)): "rate" adds
    # k_rate_* times the change of the measured force since the last step; "magnitude" adds k_force_* |f|
    transition_force: Literal["rate", "magnitude"] = "rate"
    k_force_t: Number = _num(4e-6, 0.0, 1.0, "mm/N")  # 0 .. 1 mm/N ("magnitude")
    k_force_r: Number = _num(4e-7, 0.0, 1.0, "deg/N")  # 0 .. 1 deg/N ("magnitude")
    k_rate_t_mm_per_n: Number = _num(2e-4, 0.0, 1.0, "mm/N")  # per N of force change per step, 0 .. 1 ("rate")
    k_rate_r_deg_per_n: Number = _num(4e-4, 0.0, 1.0, "deg/N")  # per N of force change per step, 0 .. 1 ("rate")
    force_rate_smoothing: Number = _num(5.0, 0.0, 1e4, "steps")  # "rate": f-dot of the force low-passed over
    # this many steps (exponential, time constant; 0: the raw difference of two noisy readings), 0 .. 1e4
    # the transition also widens with the travel (the robot's error is a function of its configuration) ...
    k_travel_t_mm_per_mm: Number = _num(0.02, 0.0, 1.0, "mm/mm")  # per mm travelled, 0 .. 1
    k_travel_r_deg_per_mm: Number = _num(0.01, 0.0, 10.0, "deg/mm")  # per mm travelled, 0 .. 10
    # ... and with the travel under load (the deflection C(q) f changes with q), per N of force
    k_load_travel_t: Number = _num(2.8e-6, 0.0, 1e-2, "mm/(N mm)")  # 0 .. 0.01
    k_load_travel_r: Number = _num(1.2e-6, 0.0, 1e-2, "deg/(N mm)")  # 0 .. 0.01
    # the unloaded width (sigma_*, k_rate_* or k_force_*, k_travel_*) per tool axis (x, y, z; rx, ry, rz), times:
    # the pose error does not drift alike on every axis (1, 1, 1: isotropic as the paper's eq. 3)
    axis_scale_t: tuple[_item(0.0, 100.0), _item(0.0, 100.0), _item(0.0, 100.0)] = _num((0.1, 0.3, 1.0))  # each 0 .. 100
    axis_scale_r: tuple[_item(0.0, 100.0), _item(0.0, 100.0), _item(0.0, 100.0)] = _num((1.0, 0.8, 0.07))  # each 0 .. 100
    # the load's part of the width (k_load_travel_*) per tool axis, times (the deflection is not alike on every axis)
    load_axis_scale_t: tuple[_item(0.0, 100.0), _item(0.0, 100.0), _item(0.0, 100.0)] = _num((1.0, 1.0, 1.0))  # 0 .. 100
    load_axis_scale_r: tuple[_item(0.0, 100.0), _item(0.0, 100.0), _item(0.0, 100.0)] = _num((1.0, 1.0, 0.7))  # 0 .. 100
    # the walk adapts to the data (covariance matching): per tracking step with laser readings it is multiplied by
    # exp(rate (avg NIS/dof - walk_adapt_nis)), the average over walk_adapt_window steps, kept within
    # 1 .. walk_adapt_max times the configured width (0: off)
    walk_adapt_rate: Number = _num(0.2, 0.0, 1.0)  # 0 .. 1
    walk_adapt_window: Number = _num(20.0, 1.0, 1e4, "steps")  # 1 .. 1e4
    walk_adapt_max: Number = _num(10.0, 1.0, 1e3)  # 1 .. 1000
    walk_adapt_nis: Number = _num(1.0, 0.1, 10.0)  # the NIS per degree of freedom it steers to, 0.1 .. 10
    # for this many steps after a "lost" step the axis scales are not applied (re-acquiring: an isotropic walk)
    reacquire_isotropic_steps: Integer = _num(200, 0, 100000)  # 0 .. 100000
    # after a step that was not "tracking" the transition is this many times wider (re-acquire; 1: off)
    reacquire_transition_scale: Number = _num(5.0, 1.0, 1e3)  # 1 .. 1000
    d0_mm: Number = _num(3.0, 0.0, 1e3, "mm")  # plateau radius, 0 .. 1 m
    kd_mm_per_n: Number = _num(1e-4, 0.0, 1.0, "mm/N")  # 0 .. 1 mm/N
    d0_deg: Number = _num(0.35, 0.0, 180.0, "deg")  # plateau radius, 0 .. 180 deg
    kd_deg_per_n: Number = _num(1.1e-4, 0.0, 1.0, "deg/N")  # 0 .. 1 deg/N
    bending_plateau: bool = True  # rotation plateau: kd_deg_per_n ‖f‖ only across the force
    # the largest force magnitude d0/kd were measured at (the default cell: episodes at 0, 5.1 and 10.2 kN whose
    # force drifts by 20 %, up to 12 kN); above it the plateau is extrapolated and the status degraded at best
    # (engine/integrity.py; 0: no limit)
    plateau_max_force_n: Number = _num(12000.0, 0.0, 1e7, "N")  # 0 .. 10 MN
    joint_sigma_deg: Number = _num(0.005, 0.0, 180.0, "deg")  # std, 0 .. 180 deg
    robot_floor_t_mm: Number = _num(0.3, 1e-9, 1e3, "mm")  # std, 1e-9 mm .. 1 m (it divides)
    robot_floor_r_deg: Number = _num(0.05, 1e-9, 180.0, "deg")  # std, 1e-9 .. 180 deg (it divides)
    compliance_rad_per_nm: Number = _num(1e-6, 0.0, 1e-3, "rad/(N m)")  # 0 .. 1e-3
    laser_sigma_mm: Number = _num(0.05, 1e-9, 1e3, "mm")  # std, 1e-9 mm .. 1 m (it divides)
    angle_sigma_deg: Number = _num(0.2, 1e-9, 180.0, "deg")  # std, 1e-9 .. 180 deg (it divides)
    search_window_mm: Number = _num(10.0, 0.0, 1e3, "mm", lo_open=True)  # (0, 1 m]
    init_sigma_t_mm: Number = _num(1.0, 0.0, 1e3, "mm")  # std, 0 .. 1 m
    init_sigma_r_deg: Number = _num(0.4, 0.0, 180.0, "deg")  # std, 0 .. 180 deg
    # the initial cloud drawn at the first step from the robot density (plateau d(f) + tails around the
    # kinematic pose: the paper's prior, where the robot can be); false: init_sigma_* around the start pose
    init_from_robot: bool = True
    # the initial cloud's centre offset from the given start pose (tool frame): a deliberately wrong
    # start, to test the integrity monitor; zero normally
    init_offset_mm: tuple[_item(-1e3, 1e3), _item(-1e3, 1e3), _item(-1e3, 1e3)] = _num(
        (0.0, 0.0, 0.0), unit="mm")  # each -1 .. 1 m
    init_offset_deg: tuple[_item(-180.0, 180.0), _item(-180.0, 180.0), _item(-180.0, 180.0)] = _num(
        (0.0, 0.0, 0.0), unit="deg")  # rotation vector, each -180 .. 180 deg
    # integrity (engine/integrity.py): chi-square tests over a window of steps, at two levels
    integrity_window: Integer = _num(10, 1, 1000)  # steps in the consistency window, 1 .. 1000
    integrity_alpha_degraded: Number = _num(1e-3, 0.0, 0.5, lo_open=True)  # test level for degraded, (0, 0.5]
    integrity_alpha_lost: Number = _num(1e-7, 0.0, 0.5, lo_open=True)  # test level for lost, (0, 0.5]
    integrity_ess_min: Number = _num(0.002, 0.0, 1.0)  # ESS collapse: the update's ESS below this x N, 0 .. 1
    integrity_recovery: Integer = _num(20, 0, 100000)  # steps after a lost step that are at most degraded
    # report at least the spread the data support (engine/spread_bound.py: a Kalman covariance from the lasers'
    # Jacobian, capped at the robot plateau) where the particle cloud is narrower; the value is the bound's
    # process noise as a fraction of the transition width (0: no bound). 1 (was 0.5): the bound runs the particles'
    # own random walk (issue 15, 10 runs at 25 kN with the raw force rate: steps beyond 3 sigma 13.4 % -> 0.7 %, rx/ry
    # 2-sigma coverage 0.72/0.73 -> 0.91/0.94; nominal yz y/z/rx 0.94/0.91/0.92 -> 0.99/0.98/0.98)
    spread_bound: Number = _num(1.0, 0.0, 10.0)  # 0 .. 10
    # ... plus translation noise per mm travelled in the bound alone (0: the transition's own travel terms,
    # k_travel_* and k_load_travel_*, already widen the walk the bound runs; it was 0.03 before they existed)
    spread_bound_k_travel: Number = _num(0.0, 0.0, 1.0, "mm/mm")  # 0 .. 1
    # keep the cloud's covariance at least cloud_floor x the bound's (engine/filter.py floor_factor): a cloud narrower
    # than what the data support cannot move where new information puts the pose (0: off). 0.2 (30 episodes, seeds
    # 0-29 / 30-59, against 0): yz steps tracking beyond 3 sigma 0.76 / 0.74 % -> 0.30 / 0.31 %, wrong start 0.53 /
    # 0.57 % -> 0.19 / 0.10 %, xy unchanged (0.8 %); yz z RMSE 0.33 / 0.35 -> 0.29 mm; 0.25 put the yz yaw's 2-sigma
    # coverage at 0.996 (too wide), 0.5-1 made rx/ry up to 20 % less accurate
    cloud_floor: Number = _num(0.2, 0.0, 10.0)  # 0 .. 10
    # the share of the particles' laser inflation (laser_inflation) the bound takes: 0 the true sigma, 1 the variance
    # the particles weigh each reading with (~1.35 sigma^2 when converged, ~1.7 sigma^2 while re-acquiring). 0 (issue
    # 15; it was 1 for one session): at 1 always, the 2-sigma coverage of xy z and yaw was 0.991-0.993 (seeds 0-179,
    # above the 0.99 asked) for a wrong start's sake; the tails it removed come only after a loss, where
    # bound_inflation_reacquire applies. Nominal, 180 episodes (seeds 0-179), 1 -> 0 with the re-acquire keys below:
    # xy coverage z / yaw 0.992 / 0.993 -> 0.987 / 0.987, steps confidently wrong 0.17 -> 0.34 % (a spread that is
    # exact has up to ~1.6 % with six axes); accuracy unchanged
    bound_inflation: Number = _num(0.0, 0.0, 1.0)  # 0 .. 1
    # ... for bound_reacquire_steps after a lost step: the cloud was rebuilt from few survivors and its estimate may
    # be off in the directions the lasers have not seen again since; at the true sigma the bound contracted faster than
    # that estimate follows when a seam corner brought the information (a wrong start's late tails: 3-4 sigma off, the
    # spread halved in 10 steps, 200-480 steps after the loss, so 500 steps, not reacquire_isotropic_steps' 200)
    bound_inflation_reacquire: Number = _num(1.0, 0.0, 1.0)  # 0 .. 1
    bound_reacquire_steps: Integer = _num(500, 0, 100000)  # 0 .. 100000
    # ... and within those steps the reported spread shrinks by at most this factor per step (0: off; 0.97: halved in
    # no fewer than 23 steps). Wrong start (stress-wrong-start.yaml), of its steps beyond 3 sigma the share tracking,
    # seeds 0-179 / 180-359: the inflation after the loss alone 4.6 / 5.1 % (1 always: 3.3 / 6.0 %), with the shrink
    # limit 0.97 1.4 / 2.5 % (0.99: 0.5 / 0.7 %; the shrink limit alone 9.1 / 9.3 %); nominal runs never lose the track
    spread_shrink_reacquire: Number = _num(0.97, 0.0, 1.0)  # 0 .. 1
    # the pose drifts by bound_drift_share^2 times the walk's variance (the walk is wider: it must re-acquire and absorb
    # what the models miss): outside those steps the reported spread is scaled per axis by sqrt(diag A / diag P), A the
    # error covariance of the bound's gain under that drift (engine/spread_bound.py; 1: off)
    bound_drift_share: Number = _num(0.5, 0.0, 1.0)  # 0 .. 1
    # the particle approximation's own noise in the bound: this times the cloud's covariance over its ESS per step (0: off)
    bound_particle_noise: Number = _num(1.0, 0.0, 100.0)  # 0 .. 100
    # the particles weigh each laser reading with variance sigma^2 + min(laser_inflation x the cloud's spread of
    # in-plane errors, laser_inflation_cap x sigma^2) (engine/filter.py): the likelihood at the true noise is too
    # narrow for a few hundred particles; the integrity test and the spread bound keep the true sigma (0: off)
    laser_inflation: Number = _num(0.5, 0.0, 10.0)  # 0 .. 10
    laser_inflation_cap: Number = _num(3.0, 0.0, 100.0)  # x sigma^2, 0 .. 100
    trend_lambda: Number = _num(100.0, 0.0, 1e6)  # weight of the l1 term, 0 .. 1e6
    # the knot polyline is the filter's seam model: its error is a systematic laser error. 0.001 (was 0.02, issue 15):
    # on the xy seam the trend filter tilts the straight runs within the tube, and the two sensors' readings of the
    # knot polyline differ from the seam's by a yaw of 0.039 deg rms (0.057 max), as large as the filter's yaw RMSE;
    # the nominal yaw error was biased by -1.0 sigma after each peak and +0.6 sigma after each trough (60 episodes).
    # With 0.001: the same yaw 0.002 deg rms, no bias, yaw RMSE 0.036 -> 0.031 deg; xy knots unchanged (107), yz 476 -> 509
    trend_eps_mm: Number = _num(0.001, 1e-6, 1e3, "mm")  # largest deviation, 1e-6 mm .. 1 m


class SeamConfig(_Section):
    """The whole configuration of a seam-tracking episode (see the module docstring).

    Besides each key's own range, an episode's size is bounded:
    ``trajectory.steps × filter.particles <= MAX_PARTICLE_STEPS`` (10⁹ particle-steps) and
    ``trajectory.steps × seam points <= MAX_STEP_SEAM_POINTS`` (10⁷; the seam is sampled every
    0.5 mm over ``length_mm + seam_extension_mm``).
    """

    seed: Integer = _num(0, 0, SEED_MAX)  # 0 .. 2**63 - 1
    trajectory: TrajectoryConfig = TrajectoryConfig()
    robot: RobotConfig = RobotConfig()
    process: ProcessConfig = ProcessConfig()
    sensors: SensorsConfig = SensorsConfig()
    filter: FilterConfig = FilterConfig()

    @model_validator(mode="after")
    def _episode_size(self):
        from posekit.seam.frontend.trajectories import SEAM_SPACING_MM

        steps, n = self.trajectory.steps, self.filter.particles
        if steps * n > MAX_PARTICLE_STEPS:
            raise ValueError(
                f"trajectory.steps × filter.particles = {steps} × {n} = {steps * n:.3g} particle-steps; "
                f"expected at most {MAX_PARTICLE_STEPS:.0e} (minutes of filtering per episode): lower one of them"
            )
        seam_mm = self.trajectory.length_mm + self.trajectory.seam_extension_mm
        points = math.ceil(seam_mm / SEAM_SPACING_MM) + 2
        if steps * points > MAX_STEP_SEAM_POINTS:
            raise ValueError(
                f"trajectory.steps × seam points = {steps} × {points} = {steps * points:.3g} (the seam, "
                f"length_mm + seam_extension_mm = {seam_mm:g} mm, is sampled every {SEAM_SPACING_MM:g} mm); "
                f"expected at most {MAX_STEP_SEAM_POINTS:.0e} (1 GiB of laser-plane intersections in the "
                "simulator): lower trajectory.steps or trajectory.length_mm"
            )
        return self


# --------------------------------------------------------------------------- errors


def _show(value) -> str:
    """An offending value for a message: its ``repr``, at most 80 characters."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def _fmt(x) -> str:
    """A bound for messages: ``100000`` (not ``100000.0``), ``1e-09``, ``0.5``."""
    if isinstance(x, float):
        return str(int(x)) if x.is_integer() and abs(x) < 1e16 else f"{x:g}"
    return str(x)


def _item_metadata(annotation) -> list:
    """The constraints of one element of a tuple annotation (``tuple[X, ...] | None`` included)."""
    for arg in get_args(annotation):
        if get_origin(arg) is tuple:
            return _item_metadata(arg)
        if get_origin(arg) is Annotated:
            out = []
            for m in get_args(arg)[1:]:
                out.extend(m.metadata if isinstance(m, FieldInfo) else [m])
            return out
    return []


def _allowed(loc) -> tuple[str, bool] | None:
    """``('0..1000 mm', is_integer)`` for the numeric key at ``loc``; None for other keys."""
    model, field, item = SeamConfig, None, False
    for part in loc:
        if isinstance(part, int):
            item = True
        elif model is not None:
            field = model.model_fields.get(str(part))
            if field is None:
                return None
            ann = field.annotation
            model = ann if isinstance(ann, type) and issubclass(ann, BaseModel) else None
        # a further string part is pydantic's name of a union member: the field is known
    if field is None or model is not None:
        return None
    meta = _item_metadata(field.annotation) if item else field.metadata
    lo = hi = None
    lo_open = hi_open = False
    for m in meta:
        if isinstance(m, (annotated_types.Ge, annotated_types.Gt)):
            lo, lo_open = (m.ge, False) if isinstance(m, annotated_types.Ge) else (m.gt, True)
        elif isinstance(m, (annotated_types.Le, annotated_types.Lt)):
            hi, hi_open = (m.le, False) if isinstance(m, annotated_types.Le) else (m.lt, True)
    if lo is None and hi is None:
        return None
    if lo is not None and hi is not None and not lo_open and not hi_open:
        text = f"{_fmt(lo)}..{_fmt(hi)}"
    else:
        parts = [f"{'>' if lo_open else '>='} {_fmt(lo)}"] if lo is not None else []
        parts += [f"{'<' if hi_open else '<='} {_fmt(hi)}"] if hi is not None else []
        text = " and ".join(parts)
    unit = (field.json_schema_extra or {}).get("unit", "") if isinstance(field.json_schema_extra, dict) else ""
    return (f"{text} {unit}" if unit else text), isinstance(lo if lo is not None else hi, int)


def _describe(err: dict) -> str:
    """One-line description of one pydantic error: ``key: what was expected, got what``.

    A number out of its range also gets the key's whole range and unit,
    ``filter.d0_mm: expected <= 1000.0, got 1e+308 (allowed 0..1000 mm)``, except an integer
    under its lower bound, whose bound says it all (``filter.particles: expected >= 1, got 0``).
    """
    loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
    kind = err["type"]
    ctx = err.get("ctx") or {}
    got = err.get("input")
    allowed = _allowed(err["loc"])
    tail = f" (allowed {allowed[0]})" if allowed else ""
    if kind == "extra_forbidden":
        return f"unknown key '{loc}'"
    if kind == "missing":
        *parent, last = err["loc"]
        if isinstance(last, int) and isinstance(got, (list, tuple)):  # a tuple with too few items
            return f"{'.'.join(str(p) for p in parent)}: too few values (no item {last}), got {_show(list(got))}"
        return f"missing key '{loc}'"
    if kind == "too_long":
        return f"{loc}: expected at most {ctx.get('max_length', '?')} values, got {_show(got)}"
    if kind == "finite_number":
        return f"{loc}: expected a finite number, got {_show(got)}{tail}"
    if kind == "bool_not_number":
        return f"{loc}: expected a number, got the boolean {str(got).lower()}{tail}"
    if kind == "int_parsing_size":  # a float far beyond any integer key's range (1e30)
        return f"{loc}: expected an integer, got {_show(got)}{tail}"
    bounds = {
        "greater_than": ">",
        "greater_than_equal": ">=",
        "less_than": "<",
        "less_than_equal": "<=",
    }
    if kind in bounds:
        limit = next(iter(ctx.values())) if ctx else "?"
        if kind.startswith("greater") and allowed and allowed[1]:
            tail = ""  # an integer under its lower bound (a count, a seed): the bound says it all
        return f"{loc}: expected {bounds[kind]} {limit}, got {_show(got)}{tail}"
    if kind == "literal_error":
        return f"{loc}: expected one of {ctx.get('expected', '?')}, got {_show(got)}"
    if kind == "value_error":
        return f"{loc}: {ctx.get('error', err['msg'])}" if loc != "(top level)" else str(
            ctx.get("error", err["msg"])
        )
    if kind in ("model_type", "dict_type"):
        return f"{loc}: expected a mapping, got {type(got).__name__}"
    if kind.endswith(("_type", "_parsing", "_from_float")):
        return f"{loc}: {err['msg'][0].lower() + err['msg'][1:]} (got {_show(got)}){tail}"
    return f"{loc}: {err['msg']}{tail}"


def config_from_dict(data: Any, source: str = "config") -> SeamConfig:
    """Validate a mapping into a :class:`SeamConfig`.

    Parameters
    ----------
    data : mapping or None
        Nested sections as in the YAML file; ``None`` or ``{}`` gives the defaults.
    source : str
        Name used at the start of error messages (a file name).

    Raises
    ------
    ConfigError
        ``"{source}: {key}: {problem}"`` for the first problem found, on one line.
    """
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"{source}: expected a mapping of sections (seed, trajectory, robot, process, "
            f"sensors, filter), got {type(data).__name__}"
        )
    try:
        return SeamConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(f"{source}: {_describe(exc.errors()[0])}") from None


def load_config(path) -> SeamConfig:
    """Read and validate a YAML configuration file.

    Parameters
    ----------
    path : str or Path
        The file; missing sections and keys take their defaults.

    Returns
    -------
    SeamConfig

    Raises
    ------
    ConfigError
        Unreadable file, invalid YAML, unknown key, impossible value; the message names the
        file and the dotted key, e.g. ``cfg.yaml: filter.particles: expected >= 1, got 0``.
    """
    from posekit.io import load_yaml

    path = Path(path)
    data = load_yaml(path, expected="a seam configuration YAML file", error=ConfigError)
    return config_from_dict(_resolve_urdf(data, path.parent), str(path))


def _resolve_urdf(data: Any, folder: Path) -> Any:
    """``robot.urdf`` made absolute relative to the config file's folder (other data as is)."""
    robot = data.get("robot") if isinstance(data, dict) else None
    if isinstance(robot, dict) and isinstance(robot.get("urdf"), str):
        urdf = Path(robot["urdf"]).expanduser()
        if not urdf.is_absolute():
            urdf = (folder / urdf).resolve()
        data = {**data, "robot": {**robot, "urdf": str(urdf)}}
    return data


def apply_overrides(cfg: SeamConfig, overrides: dict[str, Any], source: str = "command line") -> SeamConfig:
    """A copy of ``cfg`` with dotted keys set (``{"sensors.count": 1}``), re-validated.

    ``None`` values are skipped (a flag that was not given). Lowering ``sensors.count``
    without giving ``sensors.distances_mm`` keeps the first ``count`` distances. Raises
    :class:`ConfigError` naming the key for an unknown key or an impossible value.
    """
    data = cfg.model_dump(mode="python")
    count = overrides.get("sensors.count")
    dists = data["sensors"]["distances_mm"]
    whole = ((isinstance(count, int) and not isinstance(count, bool))
             or (isinstance(count, float) and math.isfinite(count) and count.is_integer()))  # else: validation says
    if whole and overrides.get("sensors.distances_mm") is None and dists is not None and 0 <= count <= len(dists):
        data["sensors"]["distances_mm"] = tuple(dists[: int(count)])  # fewer sensors: the nearest ones
    mounts = data["sensors"].get("mounts")
    if whole and overrides.get("sensors.mounts") is None and mounts is not None and 0 <= count <= len(mounts):
        data["sensors"]["mounts"] = tuple(mounts[: int(count)]) if count else None  # the first ones
    for key, value in overrides.items():
        if value is None:
            continue
        node = data
        parts = key.split(".")
        for part in parts[:-1]:
            if not isinstance(node.get(part), dict):
                raise ConfigError(f"{source}: unknown key '{key}'")
            node = node[part]
        if parts[-1] not in node:
            raise ConfigError(f"{source}: unknown key '{key}'")
        node[parts[-1]] = value
    return config_from_dict(data, source)


def dump_config(cfg: SeamConfig) -> str:
    """The effective configuration as YAML text (loadable by :func:`load_config`)."""
    return yaml.safe_dump(cfg.model_dump(mode="json"), sort_keys=False)
