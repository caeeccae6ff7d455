"""Configuration of a seam-tracking simulation and its particle filter (pydantic v2, YAML).

A configuration has four parts, as DESIGN.md's seam contract says:

``cell``        what the user knows or measures of the installation: the robot (bundled or URDF) and its
                tool, each laser sensor's mount and (when known) latency, the force sensor's readings
                (tool frame), the joint compliance model the filter uses
``filter``      the algorithm: 15 keys, each with its meaning beside it (particles, resampling, tempering,
                the integrity tests' levels, the seam polyline)
``profile``     the fitted parameters (walk, jitter, plateau, tails, joint and laser noise, latency):
                ``default`` (the shipped profile, fitted on simulated episodes by ``posekit seam tune``), a
                PROFILE.yaml path (relative to the config file) or a mapping of values replacing the default's
                (:mod:`posekit.seam.frontend.profile`)
``simulation``  the world the simulator makes, which the filter never reads: the true robot's kinematic error,
                joint noise and encoder offset, the process force, the true compliance, the force sensor's
                noise and bias, the lasers' noise, range, dropout and true latency, a wrong start

plus ``seed`` and ``trajectory`` (the simulated seam and robot program). Every number has its unit in its
name (mm, deg, N, s) and its range beside it; unknown keys are errors (``extra='forbid'``), and so are inf and
NaN, YAML booleans where a number is expected and every number outside its range, with a one-line message
naming the dotted key: ``cfg.yaml: filter.particles: expected >= 1, got 0``. An episode's size is bounded
(:data:`MAX_PARTICLE_STEPS`, :data:`MAX_STEP_SEAM_POINTS`).

A configuration in the layout before issue 26 (sections ``robot``, ``process``, ``sensors`` and a 65-key
``filter``) is mapped onto this one with a one-line :class:`LayoutNote` (:mod:`.config_legacy`); a key that
no longer exists fails in one line naming what replaced it, unless it holds its old default.

:func:`load_config` reads a YAML file; :func:`config_from_dict` validates a mapping; :func:`apply_overrides`
sets dotted keys (command-line flags); :func:`cell_from_config`, :meth:`FilterConfig.settings` and
:meth:`SeamConfig.profile_model` build what the engine reads.
"""

import math
import warnings
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import BeforeValidator, Field, ValidationError, model_validator

from posekit.errors import ConfigError
from posekit.seam.engine.particles import RESAMPLERS
from posekit.seam.frontend.config_cell import (
    DEFAULT_ROBOT,
    DEFAULT_SENSOR_DISTANCES_MM,
    CellConfig,
    RobotConfig,
    SensorsConfig,
    cell_from_config,
)
from posekit.seam.frontend.config_messages import describe
from posekit.seam.frontend.config_types import (
    MAX_PARTICLE_STEPS,
    MAX_PARTICLES,
    MAX_STEP_SEAM_POINTS,
    MAX_STEPS,
    SEED_MAX,
    Coord_mm,
    Force_n,
    Integer,
    Matrix4,
    Number,
    Section,
    check_rigid,
    item,
    num,
)
from posekit.seam.frontend.profile import ProfileModel, resolve_profile

__all__ = [
    "DEFAULT_ROBOT",
    "DEFAULT_SENSOR_DISTANCES_MM",
    "MAX_PARTICLES",
    "MAX_PARTICLE_STEPS",
    "MAX_STEPS",
    "MAX_STEP_SEAM_POINTS",
    "SEED_MAX",
    "RESAMPLER_NAMES",
    "TRAJECTORY_KINDS",
    "CellConfig",
    "FilterConfig",
    "LayoutNote",
    "RobotConfig",
    "SeamConfig",
    "SensorsConfig",
    "SimulationConfig",
    "TrajectoryConfig",
    "Matrix4",
    "check_rigid",
    "apply_overrides",
    "cell_from_config",
    "config_from_dict",
    "dump_config",
    "load_config",
]

TRAJECTORY_KINDS = ("xy", "yz", "line", "bend")
RESAMPLER_NAMES = tuple(RESAMPLERS)  # the one list: posekit.seam.engine.particles.RESAMPLERS


class LayoutNote(UserWarning):
    """A configuration in an earlier layout was mapped onto the current one (the one-line note says how)."""


class TrajectoryConfig(Section):
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
    length_mm: Number = num(200.0, 1.0, 1e4, "mm")  # 1 mm .. 10 m (the seam is sampled every 0.5 mm)
    amplitude_mm: Number | None = num(None, 0.0, 1e3, "mm")  # 0 .. 1 m; None: 20 (xy), 100 (yz), 0 otherwise
    period_mm: Number | None = num(None, 1.0, 1e4, "mm")  # 1 mm .. 10 m; None: 100 (xy), 200 (yz)
    corner_smoothing: Number = num(0.1, 0.0, 0.5, hi_open=True)  # corner blend, fraction of the period, [0, 0.5)
    steps: Integer = num(500, 2, MAX_STEPS)  # 2 .. 100,000 samples
    dt_s: Number = num(0.01, 1e-5, 10.0, "s")  # 10 µs (100 kHz) .. 10 s
    bend_at: Number = num(0.5, 0.0, 1.0, lo_open=True, hi_open=True)  # fraction of length_mm, (0, 1)
    bend_deg: Number = num(30.0, -90.0, 90.0, "deg")  # -90 .. 90 deg (a right-angle corner included)
    # the tool orientation along the program: fixed (that of the start) or tangent (its y axis follows
    # the seam's tangent in the workpiece plane, the authors' simulator; it turns over turn_mm at a corner)
    tool_orientation: Literal["fixed", "tangent"] = "fixed"
    turn_mm: Number = num(10.0, 0.0, 1e3, "mm")  # 0 .. 1 m of travel over which the heading is averaged
    start_mm: tuple[Coord_mm, Coord_mm, Coord_mm] = num((450.0, -100.0, 0.0), unit="mm")  # seam start, base frame
    seam_extension_mm: Number = num(60.0, 0.0, 1e3, "mm")  # 0 .. 1 m of seam beyond the end, seen by the sensors

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


class SimulationConfig(Section):
    """The simulated world (``simulation``): what a real cell would be, never read by the filter.

    The true robot has its kinematic lengths perturbed by ``kinematic_error_mm`` and its angles by
    ``kinematic_error_deg`` (std, drawn once per episode); the motors track the program, the encoders read them
    with ``joint_noise_deg`` noise plus ``encoder_offset_deg`` (a constant per joint). The process force
    ``force_n`` (tool frame: x across, y along the travel, z along the tool axis) varies slowly by
    ``force_drift`` (relative amplitude of a sinusoid over the episode) plus white ``force_noise_n``; the force
    sensor reads it with ``force_sensor_noise_n`` noise plus ``force_sensor_bias_n`` (tool frame). Deflection =
    joint compliance ``Δq = c J_vᵀ f`` plus an unmodelled Cartesian part (translation along f, rotation about
    ``z_tool × f``). The lasers read the true seam ``laser_latency_s`` before the sample's time (one value per
    sensor, or one for all), with ``laser_noise_mm`` noise; a reading is missing when the plane does not cut the
    seam, beyond ``laser_range_mm`` or with probability ``laser_dropout``; angles with ``angle_noise_deg``.
    ``start_offset_*`` starts the filter's first cloud that far off the kinematic pose (tool frame).
    """

    kinematic_error_mm: Number = num(0.3, 0.0, 1e3, "mm")  # std, 0 .. 1 m
    kinematic_error_deg: Number = num(0.05, 0.0, 180.0, "deg")  # std, 0 .. 180 deg
    joint_noise_deg: Number = num(0.005, 0.0, 180.0, "deg")  # std, 0 .. 180 deg
    # a constant offset per joint of the encoders (deg; fewer values than joints: the rest 0)
    encoder_offset_deg: tuple[item(-180.0, 180.0), ...] = num((), unit="deg", max_length=64)  # each -180 .. 180
    force_n: tuple[Force_n, Force_n, Force_n] = num((100.0, -1000.0, -5000.0), unit="N")  # each -100 .. 100 kN
    force_drift: Number = num(0.2, 0.0, 10.0)  # relative amplitude, 0 .. 10
    force_noise_n: Number = num(50.0, 0.0, 1e5, "N")  # std, 0 .. 100 kN
    force_sensor_noise_n: Number = num(20.0, 0.0, 1e5, "N")  # std, 0 .. 100 kN
    force_sensor_bias_n: tuple[Force_n, Force_n, Force_n] = num((0.0, 0.0, 0.0), unit="N")  # tool frame, each -100 .. 100 kN
    joint_compliance_rad_per_nm: Number = num(1e-6, 0.0, 1e-3, "rad/(N m)")  # 0 .. 1e-3
    cartesian_compliance_mm_per_n: Number = num(1e-4, 0.0, 1.0, "mm/N")  # 0 .. 1 mm/N
    cartesian_compliance_deg_per_n: Number = num(5e-4, 0.0, 1.0, "deg/N")  # 0 .. 1 deg/N
    laser_noise_mm: Number = num(0.05, 0.0, 1e3, "mm")  # std, 0 .. 1 m
    laser_range_mm: Number = num(150.0, 0.0, 1e4, "mm", lo_open=True)  # (0, 10 m]
    laser_dropout: Number = num(0.0, 0.0, 1.0)  # probability, 0 .. 1
    laser_latency_s: tuple[item(0.0, 1.0), ...] = num((0.0,), unit="s", min_length=1, max_length=4)  # each 0 .. 1 s
    angle_noise_deg: Number = num(0.1, 0.0, 180.0, "deg")  # std, 0 .. 180 deg
    start_offset_mm: tuple[item(-1e3, 1e3), item(-1e3, 1e3), item(-1e3, 1e3)] = num(
        (0.0, 0.0, 0.0), unit="mm")  # each -1 .. 1 m
    start_offset_deg: tuple[item(-180.0, 180.0), item(-180.0, 180.0), item(-180.0, 180.0)] = num(
        (0.0, 0.0, 0.0), unit="deg")  # rotation vector, each -180 .. 180 deg

    def latencies_s(self, n: int) -> np.ndarray:
        """The true latency of each of ``n`` sensors (s)."""
        v = np.asarray(self.laser_latency_s, dtype=np.float64)
        if v.size == 1:
            return np.full(n, float(v[0]))
        if v.size != n:
            raise ConfigError(f"simulation.laser_latency_s: {v.size} values for {n} sensors; expected one per "
                              "sensor or one for all")
        return v


class FilterConfig(Section):
    """The algorithm (``filter``, paper §II-B/C/E): 15 hand-set keys, the meaning of each beside it.

    Nothing here describes a cell: what a cell's data decide (the walk, the plateau, the noise, the latency) is in
    the profile (``posekit seam tune``). These are the algorithm's choices: how many particles, when and how to
    resample (a kernel density of bandwidth ``regularize_h`` that keeps the cloud's mean and covariance), when to
    temper an update that would leave too few effective particles, how much wider the walk is after a step whose
    data the model could not explain, the levels of the integrity tests (:mod:`posekit.seam.engine.integrity`:
    χ² tests of the lasers' innovations over a short window and of the estimate against the robot plateau; a test
    failing at ``integrity_alpha_degraded`` gives ``degraded``, at ``integrity_alpha_lost`` ``lost``; a second,
    long window catches a small inconsistency that persists, such as a latency nobody declared), and the
    seam polyline the lasers are compared with (the l1 trend filter of eq. 10: ``trend_lambda``,
    ``trend_eps_mm``; its error is a systematic laser error, keep it far below the laser noise).
    """

    particles: Integer = num(500, 1, MAX_PARTICLES)  # N, 1 .. 1,000,000
    resampler: Literal[RESAMPLER_NAMES] = "systematic"  # the resampling scheme, by name
    ess_threshold: Number = num(0.5, 0.0, 1.0, lo_open=True)  # resample below this x N effective particles, (0, 1]
    regularize_h: Number = num(0.5, 0.0, 1.0, hi_open=True)  # resampling kernel bandwidth (0: plain), [0, 1)
    anneal_ess: Number = num(0.05, 0.0, 1.0)  # temper an update leaving fewer than this x N effective, 0 .. 1
    anneal_stages: Integer = num(20, 0, 100)  # at most this many tempering stages per step, 0 .. 100
    reacquire_walk_scale: Number = num(5.0, 1.0, 1e3)  # the walk x this after a step not tracking, 1 .. 1000
    integrity_window: Integer = num(10, 1, 1000)  # steps of the laser NIS test, 1 .. 1000
    integrity_window_long: Integer = num(300, 0, 100000)  # steps of a second NIS test at the degraded level (0: none)
    integrity_alpha_degraded: Number = num(1e-3, 0.0, 0.5, lo_open=True)  # test level for degraded, (0, 0.5]
    integrity_alpha_lost: Number = num(1e-7, 0.0, 0.5, lo_open=True)  # test level for lost, (0, 0.5]
    integrity_ess_min: Number = num(0.002, 0.0, 1.0)  # an update's ESS below this x N: degraded, 0 .. 1
    integrity_recovery: Integer = num(20, 0, 100000)  # steps after a lost step that are degraded at best
    trend_lambda: Number = num(100.0, 0.0, 1e6)  # weight of the l1 term of the seam polyline (eq. 10), 0 .. 1e6
    trend_eps_mm: Number = num(0.001, 1e-6, 1e3, "mm")  # the polyline's largest deviation, 1e-6 mm .. 1 m

    @model_validator(mode="after")
    def _levels(self):
        if self.integrity_alpha_lost > self.integrity_alpha_degraded:
            raise ValueError(f"integrity_alpha_lost {self.integrity_alpha_lost:g} is above integrity_alpha_degraded "
                             f"{self.integrity_alpha_degraded:g}; expected lost to be the stricter level")
        return self

    def settings(self):
        """The :class:`~posekit.seam.engine.filter.FilterSettings` the engine reads."""
        from posekit.seam.engine.step import FilterSettings

        return FilterSettings(**{k: getattr(self, k) for k in FilterSettings.__dataclass_fields__})


def _profile_spec(value):
    """A ``profile`` value: a resolved :class:`ProfileModel` (``default``, a path, a mapping of replacements);
    :func:`config_from_dict` resolves it first, so that its errors name the file and the key."""
    return resolve_profile(value, None, "profile")


class SeamConfig(Section):
    """The whole configuration of a seam-tracking episode (see the module docstring).

    Besides each key's own range, an episode's size is bounded:
    ``trajectory.steps × filter.particles <= MAX_PARTICLE_STEPS`` (10⁹ particle-steps) and
    ``trajectory.steps × seam points <= MAX_STEP_SEAM_POINTS`` (10⁷; the seam is sampled every
    0.5 mm over ``length_mm + seam_extension_mm``).
    """

    seed: Integer = num(0, 0, SEED_MAX)  # 0 .. 2**63 - 1
    trajectory: TrajectoryConfig = TrajectoryConfig()
    cell: CellConfig = CellConfig()
    simulation: SimulationConfig = SimulationConfig()
    filter: FilterConfig = FilterConfig()
    profile: Annotated[ProfileModel, BeforeValidator(_profile_spec)] = Field("default", validate_default=True)

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
        self.profile.check_sensors(self.cell.sensors.count, "profile")
        if self.simulation.laser_latency_s and len(self.simulation.laser_latency_s) not in (1, self.cell.sensors.count):
            raise ValueError(f"simulation.laser_latency_s has {len(self.simulation.laser_latency_s)} values for "
                             f"{self.cell.sensors.count} sensors; expected one per sensor or one for all")
        return self

    def profile_model(self):
        """The :class:`~posekit.seam.model.Profile` the filter reads."""
        return self.profile.to_model()


# --------------------------------------------------------------------------- reading and writing


def config_from_dict(data: Any, source: str = "config") -> SeamConfig:
    """Validate a mapping into a :class:`SeamConfig`.

    Parameters
    ----------
    data : mapping or None
        Nested sections as in the YAML file; ``None`` or ``{}`` gives the defaults. A mapping in the layout
        before issue 26 is mapped onto the current one first (a :class:`LayoutNote` warning says how).
    source : str
        Name used at the start of error messages (a file name).

    Raises
    ------
    ConfigError
        ``"{source}: {key}: {problem}"`` for the first problem found, on one line.
    """
    from posekit.seam.frontend.config_legacy import map_old_layout

    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise ConfigError(
            f"{source}: expected a mapping of sections (seed, trajectory, cell, simulation, filter, profile), "
            f"got {type(data).__name__}"
        )
    data, note = map_old_layout(data, source)
    if note:
        warnings.warn(note, LayoutNote, stacklevel=2)
    if "profile" in data and not isinstance(data["profile"], ProfileModel):
        data = {**data, "profile": resolve_profile(data["profile"], None, source, prefix="profile.")}
    try:
        return SeamConfig.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(f"{source}: {describe(SeamConfig, exc.errors()[0])}") from None


def load_config(path) -> SeamConfig:
    """Read and validate a YAML configuration file.

    Parameters
    ----------
    path : str or Path
        The file; missing sections and keys take their defaults; ``robot.urdf`` and a ``profile`` path are
        relative to the file's folder.

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
    return config_from_dict(_resolve_paths(data, path.parent), str(path))


def _resolve_paths(data: Any, folder: Path) -> Any:
    """``robot.urdf`` (in ``cell`` or the old top-level ``robot``) and a ``profile`` path made absolute relative
    to the config file's folder (other data as is)."""
    if not isinstance(data, dict):
        return data
    data = dict(data)
    cell = data.get("cell")
    for holder, key in ((data, "robot"), (cell if isinstance(cell, dict) else None, "robot")):
        robot = holder.get(key) if holder is not None else None
        if isinstance(robot, dict) and isinstance(robot.get("urdf"), str):
            urdf = Path(robot["urdf"]).expanduser()
            if not urdf.is_absolute():
                urdf = (folder / urdf).resolve()
            holder[key] = {**robot, "urdf": str(urdf)}
    if isinstance(cell, dict):
        data["cell"] = cell
    prof = data.get("profile")
    if isinstance(prof, str) and prof != "default":
        p = Path(prof).expanduser()
        data["profile"] = str(p if p.is_absolute() else (folder / p).resolve())
    return data


def apply_overrides(cfg: SeamConfig, overrides: dict[str, Any], source: str = "command line") -> SeamConfig:
    """A copy of ``cfg`` with dotted keys set (``{"sensors.count": 1}``), re-validated.

    ``None`` values are skipped (a flag that was not given). Lowering ``cell.sensors.count``
    without giving ``cell.sensors.distances_mm`` keeps the first ``count`` distances (and mounts, latencies).
    Raises :class:`ConfigError` naming the key for an unknown key or an impossible value.
    """
    data = cfg.model_dump(mode="python", exclude_none=False)
    data["profile"] = cfg.profile.model_dump(mode="python", exclude_none=True)
    sens = data["cell"]["sensors"]
    count = overrides.get("cell.sensors.count")
    dists = sens["distances_mm"]
    whole = ((isinstance(count, int) and not isinstance(count, bool))
             or (isinstance(count, float) and math.isfinite(count) and count.is_integer()))  # else: validation says
    if whole and overrides.get("cell.sensors.distances_mm") is None and dists is not None and 0 <= count <= len(dists):
        sens["distances_mm"] = tuple(dists[: int(count)])  # fewer sensors: the nearest ones
    mounts = sens.get("mounts")
    if whole and overrides.get("cell.sensors.mounts") is None and mounts is not None and 0 <= count <= len(mounts):
        sens["mounts"] = tuple(mounts[: int(count)]) if count else None  # the first ones
    lat = sens.get("latency_s")
    if whole and overrides.get("cell.sensors.latency_s") is None and lat is not None and 0 <= count <= len(lat):
        sens["latency_s"] = tuple(lat[: int(count)]) if count else None
    for key, value in overrides.items():
        if value is None:
            continue
        node = data
        if key.startswith("profile."):  # a profile value: through the merge (a bare number or {value, std})
            *path, last = key.split(".")[1:]
            over: dict = {}
            leaf = over
            for part in path:
                leaf = leaf.setdefault(part, {})
            leaf[last] = value
            from posekit.seam.frontend.profile import merge_profile, profile_from_dict

            current = profile_from_dict(data["profile"], source)
            data["profile"] = merge_profile(current, over, source).model_dump(mode="python", exclude_none=True)
            continue
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
    """The effective configuration as YAML text (loadable by :func:`load_config`; the profile inline)."""
    from posekit.seam.frontend.profile import profile_data

    data = cfg.model_dump(mode="json", exclude_none=False)
    data["profile"] = profile_data(cfg.profile)
    return yaml.safe_dump(data, sort_keys=False)
