"""The ``cell`` section of a seam configuration: the robot with its tool, the laser sensors, the compliance
model (what the user knows or measures of the installation; :func:`cell_from_config` builds the engine's
:class:`~posekit.seam.model.Cell`)."""

from pathlib import Path

import numpy as np
from pydantic import Field, field_validator, model_validator

from posekit.seam.frontend.config_types import (
    Distance_mm,
    Integer,
    JointSeed_deg,
    Matrix4,
    Number,
    Section,
    check_rigid,
    item,
    num,
)

__all__ = ["DEFAULT_ROBOT", "DEFAULT_SENSOR_DISTANCES_MM", "CellConfig", "RobotConfig", "SensorsConfig",
           "cell_from_config"]

#: The robot of the paper's setup, used when the config names none.
DEFAULT_ROBOT = "puma560"
#: Sensor distances used when ``cell.sensors.distances_mm`` is not given: the first ``count``.
DEFAULT_SENSOR_DISTANCES_MM = (20.0, 40.0, 60.0, 80.0)


class RobotConfig(Section):
    """The cell's arm and its tool (``cell.robot``).

    The robot is a bundled model (``model``, one of ``posekit.robots.MODEL_NAMES``) or the
    user's own URDF file (``urdf`` with optional ``base_link`` / ``tip_link``; a relative path is
    taken relative to the config file). ``robot: NAME`` is short for ``robot: {model: NAME}``.
    ``ik_seed_deg`` is the joint guess from which the program's first pose is solved (the
    bundled models have one that reaches the default seam; a URDF robot starts from the
    middle of its joint ranges, clipped to ±90°).
    """

    model: str | None = None  # None with urdf; the default robot otherwise
    urdf: str | None = None
    base_link: str | None = None
    tip_link: str | None = None
    # at most 64 joints, each -10,000 .. 10,000 deg
    ik_seed_deg: tuple[JointSeed_deg, ...] | None = num(None, unit="deg", max_length=64)
    tool_length_mm: Number = num(150.0, 0.0, 1e4, "mm", lo_open=True)  # flange to TCP along flange z, (0, 10 m]
    # the whole tool as a 4x4 T_flange_tool (mm); None: tool_length_mm along the flange z axis
    tool: Matrix4 | None = None

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
        return None if v is None else check_rigid(v, "T_flange_tool")

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


class SensorsConfig(Section):
    """Laser seam trackers rigidly on the tool (``cell.sensors``): where they sit and how late they read.

    ``distances_mm`` ahead of the TCP along +y (default the first ``count`` of 20, 40, 60, 80 mm), or any
    ``mounts`` (one 4x4 ``T_tool_sensor`` per sensor; the laser plane is the sensor's x-z plane). Each measures
    the seam in its laser plane (across, along the tool axis); with ``angle`` also the workpiece rotation about
    the laser-plane normal. ``latency_s``: how long before a sample's time each sensor took its reading, as
    declared for the cell (null: not declared, the profile's fitted latency applies).
    """

    count: Integer = num(2, 0, 4)  # 0 .. 4 sensors
    distances_mm: tuple[Distance_mm, ...] | None = num(None, unit="mm", max_length=4)  # each (0, 1000] mm
    # any mount: one 4x4 T_tool_sensor (mm) per sensor, the laser plane being the sensor's x-z plane;
    # None: the sensors sit distances_mm ahead of the TCP along tool y, axes parallel to the tool's
    mounts: tuple[Matrix4, ...] | None = Field(None, max_length=4)
    angle: bool = False
    # declared latency per sensor, s (a reading in the sample at time t was taken at t - latency); null: the profile's
    latency_s: tuple[item(0.0, 1.0) | None, ...] | None = num(None, unit="s", max_length=4)  # each 0 .. 1 s

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
            v = tuple(check_rigid(m, f"mounts[{i}] (T_tool_sensor)") for i, m in enumerate(v))
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
        if self.latency_s is not None and len(self.latency_s) != self.count:
            raise ValueError(f"count is {self.count} but latency_s has {len(self.latency_s)} entries")
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


class CellConfig(Section):
    """The installation (``cell``): robot with tool, laser sensors, the compliance model.

    ``compliance_rad_per_nm`` is the joint compliance model ``Cj(τ) = c τ`` the filter uses (paper eq. 5; the
    cell's stiffness identification; 0: none): the particles move with the deflection the measured force
    predicts, the profile's walk covers what it misses. The force sensor reads the force on the tool in the
    tool frame of the measured pose (``fx_n, fy_n, fz_n`` of a recorded log; optionally the torque).
    """

    robot: RobotConfig = RobotConfig()
    sensors: SensorsConfig = SensorsConfig()
    compliance_rad_per_nm: Number = num(1e-6, 0.0, 1e-3, "rad/(N m)")  # 0 .. 1e-3



def cell_from_config(cell: CellConfig):
    """The :class:`~posekit.seam.model.Cell` of a ``cell`` section (robot with tool, sensors, compliance)."""
    from posekit.seam.frontend.trajectories import tool_chain
    from posekit.seam.model import Cell, Sensor

    lat = cell.sensors.latency_s
    sensors = tuple(Sensor(M, None if lat is None or lat[i] is None else float(lat[i]))
                    for i, M in enumerate(cell.sensors.resolved_mounts()))
    return Cell(tool_chain(cell.robot), sensors, float(cell.compliance_rad_per_nm), bool(cell.sensors.angle),
                cell.robot.label)
