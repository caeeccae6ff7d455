"""Configuration of a seam-tracking simulation and its particle filter (pydantic v2, YAML).

Every parameter lives here with its default and its unit in its name (mm, deg, N, s). The
defaults are the paper's setup: h = 0.01 s, T = 500 steps, two laser sensors 20 mm and 40 mm
ahead of the tool, the xy trajectory. Unknown keys are errors (``extra='forbid'``), and so are
inf and NaN values.

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

from pathlib import Path
from typing import Any, Literal

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from posekit.errors import ConfigError

__all__ = [
    "DEFAULT_SENSOR_DISTANCES_MM",
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
RESAMPLER_NAMES = ("systematic", "stratified", "residual")
#: The robot of the paper's setup, used when the config names none.
DEFAULT_ROBOT = "puma560"
#: Sensor distances used when ``sensors.distances_mm`` is not given: the first ``count``.
DEFAULT_SENSOR_DISTANCES_MM = (20.0, 40.0, 60.0, 80.0)

class _Section(BaseModel):
    # inf and NaN are no parameter values: a NaN noise would turn every estimate into NaN
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class TrajectoryConfig(_Section):
    """The seam and the nominal robot program along it (paper §III-B, Fig. 9).

    The path is given in the tool frame at the start (y along the travel, z along the tool
    axis) and the tool keeps its orientation: ``xy`` is ``length_mm`` along y with a smooth
    triangle wave of ``amplitude_mm`` in x (default 20 mm, period 100 mm); ``yz`` is
    ``length_mm`` along y with a sine of ``amplitude_mm`` in z (default 100 mm, period 200 mm);
    ``line`` is straight along y; ``bend`` is straight along y up to ``bend_at`` of the length,
    then turns by ``bend_deg`` about the tool z axis (a sharp corner, the seam feature of Fig. 5).
    """

    kind: Literal["xy", "yz", "line", "bend"] = "xy"
    length_mm: float = Field(200.0, gt=0.0)
    amplitude_mm: float | None = Field(None, ge=0.0)  # None: 20 (xy), 100 (yz), 0 otherwise
    period_mm: float | None = Field(None, gt=0.0)  # None: 100 (xy), 200 (yz)
    corner_smoothing: float = Field(0.1, ge=0.0, lt=0.5)  # corner blend, fraction of the period
    steps: int = Field(500, ge=2)
    dt_s: float = Field(0.01, gt=0.0)
    bend_at: float = Field(0.5, gt=0.0, lt=1.0)  # fraction of length_mm
    bend_deg: float = Field(30.0, gt=-90.0, lt=90.0)
    start_mm: tuple[float, float, float] = (450.0, -100.0, 0.0)  # seam start, robot base frame
    seam_extension_mm: float = Field(60.0, ge=0.0)  # seam beyond the end, seen by the sensors

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
    ik_seed_deg: tuple[float, ...] | None = None
    tool_length_mm: float = Field(150.0, gt=0.0)  # flange to TCP along the flange z axis
    joint_noise_deg: float = Field(0.005, ge=0.0)
    kinematic_error_mm: float = Field(0.3, ge=0.0)
    kinematic_error_deg: float = Field(0.05, ge=0.0)

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

    force_n: tuple[float, float, float] = (100.0, -1000.0, -5000.0)
    force_drift: float = Field(0.2, ge=0.0)
    force_noise_n: float = Field(50.0, ge=0.0)
    force_sensor_noise_n: float = Field(20.0, ge=0.0)
    joint_compliance_rad_per_nm: float = Field(1e-6, ge=0.0)
    cartesian_compliance_mm_per_n: float = Field(1e-4, ge=0.0)
    cartesian_compliance_deg_per_n: float = Field(5e-4, ge=0.0)


class SensorsConfig(_Section):
    """Laser seam trackers rigidly on the tool, ``distances_mm`` ahead of the TCP along +y.

    Each measures the seam in its laser plane (across, along the tool axis) with Gaussian noise
    ``noise_mm``; a measurement is missing when the plane does not cut the seam, when
    ``|m| > range_mm`` or with probability ``dropout``. With ``angle`` the sensors also measure
    the workpiece rotation about the laser-plane normal (noise ``angle_noise_deg``).
    ``distances_mm`` defaults to the first ``count`` of 20, 40, 60, 80 mm.
    """

    count: int = Field(2, ge=0, le=4)
    distances_mm: tuple[float, ...] | None = None
    noise_mm: float = Field(0.05, ge=0.0)
    range_mm: float = Field(150.0, gt=0.0)
    dropout: float = Field(0.0, ge=0.0, le=1.0)
    angle: bool = False
    angle_noise_deg: float = Field(0.1, ge=0.0)

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

    @model_validator(mode="after")
    def _count_matches(self):
        if self.distances_mm is not None and len(self.distances_mm) != self.count:
            raise ValueError(
                f"count is {self.count} but distances_mm has {len(self.distances_mm)} entries"
            )
        return self

    def resolved_distances_mm(self) -> tuple[float, ...]:
        """The sensor distances ahead of the tool in mm, one per sensor."""
        if self.distances_mm is not None:
            return tuple(float(d) for d in self.distances_mm)
        return DEFAULT_SENSOR_DISTANCES_MM[: self.count]


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
    mean and covariance (0: plain resampling; see :mod:`posekit.seam.filter`).
    """

    particles: int = Field(500, ge=1)
    resampler: Literal["systematic", "stratified", "residual"] = "systematic"
    ess_threshold: float = Field(0.5, gt=0.0, le=1.0)  # fraction of the particle count
    anneal_ess: float = Field(0.05, ge=0.0, le=1.0)  # temper an update leaving fewer (fraction of N)
    anneal_stages: int = Field(20, ge=0)
    anneal_jitter: float = Field(0.5, ge=0.0)  # kernel bandwidth, times the cloud's covariance
    regularize_h: float = Field(0.1, ge=0.0, lt=1.0)  # kernel bandwidth of the resampling (0: plain)
    sigma_t_mm: float = Field(0.02, ge=0.0)
    sigma_r_deg: float = Field(0.005, ge=0.0)
    k_force_t: float = Field(4e-6, ge=0.0)  # mm/N
    k_force_r: float = Field(4e-7, ge=0.0)  # deg/N
    d0_mm: float = Field(1.0, ge=0.0)
    kd_mm_per_n: float = Field(4e-4, ge=0.0)
    d0_deg: float = Field(0.2, ge=0.0)
    kd_deg_per_n: float = Field(2e-4, ge=0.0)
    bending_plateau: bool = True  # rotation plateau: kd_deg_per_n ‖f‖ only across the force
    joint_sigma_deg: float = Field(0.005, ge=0.0)
    robot_floor_t_mm: float = Field(0.3, gt=0.0)
    robot_floor_r_deg: float = Field(0.05, gt=0.0)
    compliance_rad_per_nm: float = Field(0.0, ge=0.0)
    laser_sigma_mm: float = Field(0.1, gt=0.0)
    angle_sigma_deg: float = Field(0.2, gt=0.0)
    search_window_mm: float = Field(10.0, gt=0.0)
    init_sigma_t_mm: float = Field(1.0, ge=0.0)
    init_sigma_r_deg: float = Field(0.4, ge=0.0)
    trend_lambda: float = Field(100.0, ge=0.0)
    trend_eps_mm: float = Field(0.02, gt=0.0)


class SeamConfig(_Section):
    """The whole configuration of a seam-tracking episode (see the module docstring)."""

    seed: int = Field(0, ge=0)
    trajectory: TrajectoryConfig = TrajectoryConfig()
    robot: RobotConfig = RobotConfig()
    process: ProcessConfig = ProcessConfig()
    sensors: SensorsConfig = SensorsConfig()
    filter: FilterConfig = FilterConfig()


# --------------------------------------------------------------------------- errors


def _describe(err: dict) -> str:
    """One-line description of one pydantic error: ``key: what was expected, got what``."""
    loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
    kind = err["type"]
    ctx = err.get("ctx") or {}
    got = err.get("input")
    if kind == "extra_forbidden":
        return f"unknown key '{loc}'"
    if kind == "missing":
        *parent, last = err["loc"]
        if isinstance(last, int) and isinstance(got, (list, tuple)):  # a tuple with too few items
            return f"{'.'.join(str(p) for p in parent)}: too few values (no item {last}), got {list(got)!r}"
        return f"missing key '{loc}'"
    if kind == "too_long":
        return f"{loc}: expected at most {ctx.get('max_length', '?')} values, got {got!r}"
    if kind == "finite_number":
        return f"{loc}: expected a finite number, got {got!r}"
    bounds = {
        "greater_than": ">",
        "greater_than_equal": ">=",
        "less_than": "<",
        "less_than_equal": "<=",
    }
    if kind in bounds:
        limit = next(iter(ctx.values())) if ctx else "?"
        return f"{loc}: expected {bounds[kind]} {limit}, got {got!r}"
    if kind == "literal_error":
        return f"{loc}: expected one of {ctx.get('expected', '?')}, got {got!r}"
    if kind == "value_error":
        return f"{loc}: {ctx.get('error', err['msg'])}" if loc != "(top level)" else str(
            ctx.get("error", err["msg"])
        )
    if kind in ("model_type", "dict_type"):
        return f"{loc}: expected a mapping, got {type(got).__name__}"
    if kind.endswith(("_type", "_parsing", "_from_float")):
        return f"{loc}: {err['msg'][0].lower() + err['msg'][1:]} (got {got!r})"
    return f"{loc}: {err['msg']}"


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
    if (count is not None and overrides.get("sensors.distances_mm") is None and dists is not None
            and 0 <= int(count) <= len(dists)):
        data["sensors"]["distances_mm"] = tuple(dists[: int(count)])  # fewer sensors: the nearest ones
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
