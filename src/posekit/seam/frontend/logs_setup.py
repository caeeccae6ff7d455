"""``setup.yaml`` of a recorded seam episode (:mod:`posekit.seam.frontend.logs`): its model, its reader, and the
mapping of a setup in the layout before issue 26."""

from pathlib import Path
from typing import Annotated

from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, field_validator

from posekit.errors import InputFileError
from posekit.seam.frontend.config import FilterConfig, Matrix4, RobotConfig, SeamConfig, check_rigid, config_from_dict
from posekit.seam.frontend.config_messages import describe

__all__ = ["LogSetup", "SensorEntry", "read_setup", "setup_profile"]


class _Noise(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    joint_deg: float | None = Field(None, ge=0.0, le=180.0)
    laser_mm: float | None = Field(None, ge=0.0, le=1e3)
    force_n: float | None = Field(None, ge=0.0, le=1e5)


class SensorEntry(BaseModel):
    """One sensor of ``setup.yaml``: its mount and, when declared, its latency."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    T_tool_sensor: Matrix4
    latency_s: float | None = Field(None, ge=0.0, le=1.0)


def _sensor_entry(v):
    """A bare 4×4 is a mount without a declared latency."""
    return {"T_tool_sensor": v} if isinstance(v, (list, tuple)) else v


class LogSetup(BaseModel):
    """The contents of ``setup.yaml`` (see the module docstring)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    robot: RobotConfig = RobotConfig()
    tool: Matrix4 | None = None
    sensors: tuple[Annotated[SensorEntry, BeforeValidator(_sensor_entry)], ...] = Field((), max_length=4)
    compliance_rad_per_nm: float = Field(0.0, ge=0.0, le=1e-3)
    angle: bool = False
    seam_normal: tuple[float, float, float] = (0.0, 0.0, -1.0)
    seed: int = Field(0, ge=0, le=2**63 - 1)
    noise: _Noise = _Noise()
    filter: FilterConfig = FilterConfig()
    profile: str | dict | None = None

    @field_validator("tool")
    @classmethod
    def _rigid_tool(cls, v):
        return None if v is None else check_rigid(v, "T_flange_tool")

    @field_validator("sensors")
    @classmethod
    def _rigid_sensors(cls, v):
        for i, e in enumerate(v):
            check_rigid(e.T_tool_sensor, f"sensor {i + 1} (T_tool_sensor)")
        return v

    def seam_config(self, source: str = "setup.yaml", profile=None) -> SeamConfig:
        """The :class:`SeamConfig` the filter runs with (robot with this tool, these sensor mounts and
        latencies, the compliance model, the filter keys); ``profile`` (a ProfileModel or a path) replaces
        the setup's own."""
        robot = self.robot.model_dump(mode="python")
        if self.tool is not None:
            robot["tool"] = self.tool
        lat = [e.latency_s for e in self.sensors]
        sensors = {"count": len(self.sensors), "mounts": tuple(e.T_tool_sensor for e in self.sensors) or None,
                   "angle": self.angle, "latency_s": tuple(lat) if any(x is not None for x in lat) else None}
        data = {"seed": self.seed, "trajectory": {"steps": 2},
                "cell": {"robot": robot, "sensors": sensors, "compliance_rad_per_nm": self.compliance_rad_per_nm},
                "filter": self.filter.model_dump(mode="python")}
        prof = self.profile if profile is None else profile
        if prof is not None:
            data["profile"] = prof
        return config_from_dict(data, source)


def read_setup(folder: Path) -> LogSetup:
    from posekit.io import load_yaml

    path = folder / "setup.yaml"
    data = load_yaml(path, expected="the setup of a recorded seam episode (robot, tool, sensors, filter)",
                     error=InputFileError)
    if not isinstance(data, dict):
        raise InputFileError(f"{path}: expected a mapping (robot, tool, sensors, filter), got {type(data).__name__}")
    robot = data.get("robot")
    if isinstance(robot, str):
        robot = {"model": robot}
    if isinstance(robot, dict) and isinstance(robot.get("urdf"), str):
        urdf = Path(robot["urdf"]).expanduser()
        robot = {**robot, "urdf": str(urdf if urdf.is_absolute() else (folder / urdf).resolve())}
    if robot is not None:
        data = {**data, "robot": robot}
    data = _map_old_setup(data, path)
    try:
        return LogSetup.model_validate(data)
    except ValidationError as exc:
        raise InputFileError(f"{path}: {describe(LogSetup, exc.errors()[0])}") from None


def _map_old_setup(data: dict, path: Path) -> dict:
    """A ``setup.yaml`` whose ``filter`` holds keys of the layout before issue 26, mapped (one-line note):
    ``filter.compliance_rad_per_nm`` becomes the setup's, profile values its ``profile``; the rest as for a
    configuration (:mod:`posekit.seam.frontend.config_legacy`)."""
    import warnings

    from posekit.seam.frontend.config import LayoutNote
    from posekit.seam.frontend.config_legacy import map_old_layout

    f = data.get("filter")
    if not isinstance(f, dict):
        return data
    mapped, note = map_old_layout({"filter": f}, str(path))
    if not note:
        return data
    out = {k: v for k, v in data.items() if k != "filter"}
    if "filter" in mapped:
        out["filter"] = mapped["filter"]
    comp = mapped.get("cell", {}).get("compliance_rad_per_nm")
    if comp is not None and "compliance_rad_per_nm" not in data:
        out["compliance_rad_per_nm"] = comp
    if "profile" in mapped and "profile" not in data:
        out["profile"] = mapped["profile"]
    warnings.warn(note, LayoutNote, stacklevel=3)
    return out


def setup_profile(setup: LogSetup, folder: Path):
    """The setup's ``profile`` resolved relative to its folder (None: the default)."""
    from posekit.seam.frontend.profile import resolve_profile

    if setup.profile is None:
        return None
    return resolve_profile(setup.profile, folder, str(folder / "setup.yaml") + ": profile")
