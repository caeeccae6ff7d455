"""The profile file: the fitted parameters of a seam cell, versioned, naming the data it was fitted on.

``posekit seam tune`` writes one (:mod:`posekit.seam.frontend.tune`); ``seam track --profile``, ``seam simulate
--profile`` and a configuration's ``profile:`` key read it. The shipped default,
``src/posekit/seam/profiles/default.yaml``, was written by the documented command in its header (fitted on
simulated episodes of the default cell) and a test re-runs that command and compares.

Format (YAML, version 1)::

    format: posekit-seam-profile
    version: 1
    fitted: {method: truth | innovations, command: "...", episodes: [{name, steps, sha256}, ...],
             cell: {robot, joints, tcp_zero_mm, mounts_mm, compliance_rad_per_nm, angle}}   # the cell it was
                        # fitted on (optional; seam track checks it: posekit.seam.frontend.cell_signature)
    sensors:            # one entry per sensor in the cell's order, or one for all
      - {latency_s: 0.0, sigma_mm: 0.05, angle_sigma_deg: 0.2,
         nis_mean_x: 1.0, nis_mean_z: 1.0, nis_dof_x: 1.0, nis_dof_z: 1.0}   # innovations on the training
                        # episodes (the integrity test's calibration; optional, 1: the model's own chi2)
         # bias_mean_x, bias_mean_z, bias_dof_x, bias_dof_z: the same for the squared mean signed innovation
         # over bias_window steps (the bias test; optional)
    walk:               # random walk of the pose about its modelled motion, tool frame, per sqrt(mm travelled)
      {x_mm: .., y_mm: .., z_mm: .., rx_deg: .., ry_deg: .., rz_deg: ..}
    jitter:             # white jitter of the pose about that walk, per sample
      {x_mm: .., ..., rz_deg: ..}
    plateau:            # robot density (eq. 7/8): d(f) = d0 + kd |f|, Gaussian tails, the force range fitted
      {d0_mm: .., kd_mm_per_n: .., d0_deg: .., kd_deg_per_n: .., tail_mm: .., tail_deg: .., max_force_n: ..}
    joints: {sigma_deg: ..}
    spread: {x: .., y: .., z: .., rx: .., ry: .., rz: ..}   # factor on the filter's spread per axis (default 1)
    bias_window: 10     # steps the bias test averages the signed innovations over (0 or absent: no bias test)
    offset:             # the offset test (optional): the estimate's offset from the kinematic pose, tool frame,
                        # averaged over the long window, on the training episodes
      mean: {x_mm: .., ..., rz_deg: ..}   # its mean (signed)
      sd: {x_mm: .., ..., rz_deg: ..}     # the spread of those window means
      samples: {x: .., ..., rz: ..}       # the effective number of independent windows behind that spread
    notes: ["..."]      # the fit's verdicts (values the data did not pin)

Every value is a number (set by hand) or ``{value: v, std: s}`` (fitted, with its 1σ), optionally with a
``note``. A configuration's ``profile:`` may be ``default``, a path, or a mapping of values that replace the
default profile's (``{plateau: {d0_mm: 3.8}}``).
"""

import copy
import hashlib
import math
from functools import lru_cache
from pathlib import Path
from typing import Annotated, Any, Literal

import numpy as np
import yaml
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError, field_validator

from posekit.errors import ConfigError
from posekit.seam.frontend.cell_signature import CellSignature
from posekit.seam.model import Profile

__all__ = [
    "DEFAULT_PROFILE",
    "PRIOR_PROFILE",
    "FORMAT",
    "Fitted",
    "ProfileModel",
    "default_profile",
    "dump_profile",
    "episode_record",
    "load_profile",
    "merge_profile",
    "profile_data",
    "profile_from_dict",
    "resolve_profile",
    "write_profile",
]

FORMAT = "posekit-seam-profile"
#: The shipped default profile (fitted on simulated episodes of the default cell; the command is in its header).
DEFAULT_PROFILE = Path(__file__).resolve().parents[1] / "profiles" / "default.yaml"
#: The hand-set prior the default profile was fitted from (its values kept where the data do not pin them).
PRIOR_PROFILE = DEFAULT_PROFILE.with_name("prior.yaml")
AXES = ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")


class Fitted(BaseModel):
    """One profile value: ``value`` with its 1σ ``std`` (None: set by hand) and a ``note`` (why it is kept)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    value: float
    std: float | None = Field(None, ge=0.0)
    note: str | None = Field(None, max_length=300)

    def __float__(self) -> float:
        return float(self.value)


def _fitted(lo: float, hi: float, unit: str = ""):
    """A field type: a number in ``lo..hi`` (``unit`` for messages) or ``{value, std, note}``; stored as
    :class:`Fitted`."""

    def check(v):
        if isinstance(v, bool):
            raise ValueError("expected a number or {value, std}, got a boolean")
        if isinstance(v, (int, float, str)) and not isinstance(v, bool):
            try:
                v = {"value": float(v)}
            except ValueError:
                raise ValueError(f"expected a number or {{value, std}}, got {v!r}") from None
        f = Fitted.model_validate(v)
        if not (lo <= f.value <= hi) or not math.isfinite(f.value):
            raise ValueError(f"expected {lo:g}..{hi:g}{' ' + unit if unit else ''}, got {f.value:g}")
        return f

    return Annotated[Fitted, BeforeValidator(check)]


_Mm = _fitted(0.0, 1e3, "mm")
_Deg = _fitted(0.0, 180.0, "deg")


class _Part(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class SensorProfile(_Part):
    """Per sensor: latency (s), laser noise (mm, std in the laser plane), angle noise (deg), and what its
    innovations looked like on the training episodes (the integrity monitor's long window,
    :mod:`posekit.seam.engine.integrity`): the mean normalised squared innovation of its x and z reading and their
    effective χ² degrees of freedom per reading (1 and 1: the model's own χ²₁, none fitted), and the same for the
    squared mean of the signed innovations over the profile's ``bias_window`` steps (the bias test; 1 and 1 when
    not fitted: a test that sees only biases far larger than the noise)."""

    latency_s: _fitted(0.0, 1.0, "s")
    sigma_mm: _fitted(1e-9, 1e3, "mm")
    angle_sigma_deg: _fitted(1e-9, 180.0, "deg")
    nis_mean_x: _fitted(1e-3, 1e3, "") = Fitted(value=1.0)
    nis_mean_z: _fitted(1e-3, 1e3, "") = Fitted(value=1.0)
    nis_dof_x: _fitted(1e-3, 1e3, "") = Fitted(value=1.0)
    nis_dof_z: _fitted(1e-3, 1e3, "") = Fitted(value=1.0)
    bias_mean_x: _fitted(1e-6, 1e3, "") = Fitted(value=1.0)
    bias_mean_z: _fitted(1e-6, 1e3, "") = Fitted(value=1.0)
    bias_dof_x: _fitted(1e-6, 1e3, "") = Fitted(value=1.0)
    bias_dof_z: _fitted(1e-6, 1e3, "") = Fitted(value=1.0)


class AxesProfile(_Part):
    """Six values per tool axis: translation (mm) and rotation (deg)."""

    x_mm: _Mm
    y_mm: _Mm
    z_mm: _Mm
    rx_deg: _Deg
    ry_deg: _Deg
    rz_deg: _Deg

    def vector(self) -> np.ndarray:
        """``(6,)`` in mm and rad."""
        v = np.array([float(getattr(self, a)) for a in AXES])
        v[3:] = np.radians(v[3:])
        return v


class SignedAxes(_Part):
    """Six signed values per tool axis: translation (mm) and rotation (deg)."""

    x_mm: _fitted(-1e3, 1e3, "mm")
    y_mm: _fitted(-1e3, 1e3, "mm")
    z_mm: _fitted(-1e3, 1e3, "mm")
    rx_deg: _fitted(-180.0, 180.0, "deg")
    ry_deg: _fitted(-180.0, 180.0, "deg")
    rz_deg: _fitted(-180.0, 180.0, "deg")

    def vector(self) -> np.ndarray:
        """``(6,)`` in mm and rad."""
        v = np.array([float(getattr(self, a)) for a in AXES])
        v[3:] = np.radians(v[3:])
        return v


class Samples(_Part):
    """An effective number of independent samples per tool axis."""

    x: float = Field(ge=0.0, le=1e9)
    y: float = Field(ge=0.0, le=1e9)
    z: float = Field(ge=0.0, le=1e9)
    rx: float = Field(ge=0.0, le=1e9)
    ry: float = Field(ge=0.0, le=1e9)
    rz: float = Field(ge=0.0, le=1e9)

    def vector(self) -> np.ndarray:
        """``(6,)``."""
        return np.array([float(getattr(self, a)) for a in ("x", "y", "z", "rx", "ry", "rz")])


class OffsetProfile(_Part):
    """The integrity monitor's offset test (:mod:`posekit.seam.engine.integrity`): the estimate's offset from the
    kinematic pose, averaged over the long window, on the training episodes — its mean, the spread of those means
    and the effective number of independent windows behind the spread (fitted by ``seam tune``)."""

    mean: SignedAxes
    sd: AxesProfile
    samples: Samples


class SpreadProfile(_Part):
    """Factor per tool axis on the filter's spread (dimensionless; fitted by ``seam tune --with-truth``)."""

    x: _fitted(0.1, 100.0, "")
    y: _fitted(0.1, 100.0, "")
    z: _fitted(0.1, 100.0, "")
    rx: _fitted(0.1, 100.0, "")
    ry: _fitted(0.1, 100.0, "")
    rz: _fitted(0.1, 100.0, "")

    def vector(self) -> np.ndarray:
        """``(6,)``."""
        return np.array([float(getattr(self, a)) for a in ("x", "y", "z", "rx", "ry", "rz")])


class PlateauProfile(_Part):
    """The robot density (eq. 7/8): plateau ``d0 + kd |f|`` (mm; deg), tails beyond it, the force range."""

    d0_mm: _Mm
    kd_mm_per_n: _fitted(0.0, 1.0, "mm/N")
    d0_deg: _Deg
    kd_deg_per_n: _fitted(0.0, 1.0, "deg/N")
    tail_mm: _fitted(1e-9, 1e3, "mm")
    tail_deg: _fitted(1e-9, 180.0, "deg")
    max_force_n: _fitted(0.0, 1e7, "N")


class JointsProfile(_Part):
    """Joint encoder noise (deg, std)."""

    sigma_deg: _Deg


class Episode(_Part):
    """One episode a profile was fitted on: its folder name, steps and the SHA-256 of its ``log.csv``."""

    name: str = Field(max_length=300)
    steps: int = Field(ge=0)
    sha256: str = Field(max_length=64)


class Provenance(_Part):
    """How a profile was made."""

    method: Literal["truth", "innovations", "hand"]
    command: str = Field("", max_length=2000)
    episodes: tuple[Episode, ...] = Field((), max_length=10_000)
    cell: CellSignature | None = None


class ProfileModel(_Part):
    """A profile file (see the module docstring)."""

    format: Literal["posekit-seam-profile"] = FORMAT
    version: Literal[1] = 1
    fitted: Provenance | None = None
    sensors: tuple[SensorProfile, ...] = Field(min_length=1, max_length=4)
    walk: AxesProfile
    jitter: AxesProfile
    plateau: PlateauProfile
    joints: JointsProfile
    spread: SpreadProfile = SpreadProfile(x=1.0, y=1.0, z=1.0, rx=1.0, ry=1.0, rz=1.0)
    bias_window: int = Field(0, ge=0, le=1000)
    offset: OffsetProfile | None = None
    notes: tuple[str, ...] = Field((), max_length=100)

    @field_validator("notes")
    @classmethod
    def _short_notes(cls, v):
        return tuple(str(x)[:300] for x in v)

    def to_model(self) -> Profile:
        """The :class:`~posekit.seam.model.Profile` the filter reads (mm, rad)."""
        p = self.plateau
        return Profile(
            walk=self.walk.vector(), jitter=self.jitter.vector(),
            laser_sigma_mm=np.array([float(s.sigma_mm) for s in self.sensors]),
            latency_s=np.array([float(s.latency_s) for s in self.sensors]),
            angle_sigma_rad=math.radians(float(self.sensors[0].angle_sigma_deg)),
            d0_mm=float(p.d0_mm), kd_mm_per_n=float(p.kd_mm_per_n), d0_rad=math.radians(float(p.d0_deg)),
            kd_rad_per_n=math.radians(float(p.kd_deg_per_n)), tail_mm=float(p.tail_mm),
            tail_rad=math.radians(float(p.tail_deg)), joint_sigma_rad=math.radians(float(self.joints.sigma_deg)),
            max_force_n=float(p.max_force_n), spread_scale=self.spread.vector(),
            nis_mean=np.array([[float(s.nis_mean_x), float(s.nis_mean_z)] for s in self.sensors]),
            nis_dof=np.array([[float(s.nis_dof_x), float(s.nis_dof_z)] for s in self.sensors]),
            bias_window=int(self.bias_window),
            bias_mean=np.array([[float(s.bias_mean_x), float(s.bias_mean_z)] for s in self.sensors]),
            bias_dof=np.array([[float(s.bias_dof_x), float(s.bias_dof_z)] for s in self.sensors]),
            offset_mean=None if self.offset is None else self.offset.mean.vector(),
            offset_sd=None if self.offset is None else self.offset.sd.vector(),
            offset_samples=None if self.offset is None else self.offset.samples.vector())

    def plain(self) -> dict:
        """The profile as a mapping of bare numbers (no std, no provenance): what a study perturbs."""
        def strip(v):
            if isinstance(v, dict) and "value" in v:
                return float(v["value"])
            if isinstance(v, dict):
                return {k: strip(x) for k, x in v.items()}
            if isinstance(v, (list, tuple)):
                return [strip(x) for x in v]
            return v

        data = strip(self.model_dump(mode="python", exclude_none=True))
        data.pop("fitted", None)
        data.pop("notes", None)
        return data

    def check_sensors(self, n: int, source: str = "profile") -> None:
        """ConfigError unless the profile has one sensor entry, or one per each of ``n`` sensors."""
        k = len(self.sensors)
        if k != 1 and k != n and n > 0:
            raise ConfigError(f"{source}: {k} sensor entries for a cell with {n} sensor(s); expected one per "
                              "sensor or one for all")


def _describe(err: dict) -> str:
    loc = ".".join(str(p) for p in err["loc"] if not (isinstance(p, str) and p.startswith("function-")))
    kind = err["type"]
    if kind == "extra_forbidden":
        return f"unknown key '{loc}'"
    if kind == "missing":
        return f"missing key '{loc}'"
    ctx = err.get("ctx") or {}
    msg = str(ctx.get("error", err["msg"]))
    return f"{loc}: {msg[0].lower() + msg[1:] if msg else msg}"


def profile_from_dict(data: Any, source: str = "profile", prefix: str = "") -> ProfileModel:
    """Validate a mapping into a :class:`ProfileModel`; ConfigError ``"{source}: {prefix}{key}: {problem}"`` on
    one line (``prefix`` the key of the profile in a configuration, ``profile.``)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: {prefix.rstrip('.') + ': ' if prefix else ''}expected a profile mapping "
                          f"(sensors, walk, jitter, plateau, joints), got {type(data).__name__}")
    try:
        return ProfileModel.model_validate(data)
    except ValidationError as exc:
        raise ConfigError(f"{source}: {prefix}{_describe(exc.errors()[0])}") from None


def load_profile(path) -> ProfileModel:
    """Read and validate a profile file (one-line ConfigError naming the file and the key)."""
    from posekit.io import load_yaml

    path = Path(path)
    data = load_yaml(path, expected="a seam profile (posekit seam tune)", error=ConfigError)
    if isinstance(data, dict) and data.get("format", FORMAT) != FORMAT:
        raise ConfigError(f"{path}: format {data.get('format')!r}; expected {FORMAT!r}")
    return profile_from_dict(data, str(path))


@lru_cache(maxsize=1)
def default_profile() -> ProfileModel:
    """The shipped default profile (:data:`DEFAULT_PROFILE`)."""
    return load_profile(DEFAULT_PROFILE)


def _deep_merge(base: dict, over: dict) -> dict:
    out = copy.deepcopy(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict) and "value" not in v:
            out[k] = _deep_merge(out[k], v)
        elif k == "sensors" and isinstance(v, (list, tuple)) and isinstance(out.get(k), (list, tuple)):
            base_s = list(out[k])
            merged = []
            for i, item in enumerate(v):
                ref = base_s[i] if i < len(base_s) else base_s[-1]
                merged.append(_deep_merge(ref, item) if isinstance(item, dict) and isinstance(ref, dict) else item)
            out[k] = merged
        else:
            out[k] = v
    return out


def merge_profile(base: ProfileModel, overrides: dict, source: str = "profile", prefix: str = "") -> ProfileModel:
    """``base`` with the values of ``overrides`` (a partial profile mapping) replacing its own; re-validated."""
    data = _deep_merge(base.model_dump(mode="python", exclude_none=True), overrides)
    data.pop("fitted", None)
    return profile_from_dict(data, source, prefix)


def resolve_profile(spec: Any, folder: Path | None = None, source: str = "profile", prefix: str = "") -> ProfileModel:
    """A :class:`ProfileModel` from a configuration's ``profile:`` value.

    ``None`` or ``"default"``: the shipped default; a string: a profile file (relative to ``folder``); a
    mapping with ``format``: a whole profile; another mapping: values replacing the default's; a
    :class:`ProfileModel`: itself.
    """
    if isinstance(spec, ProfileModel):
        return spec
    if spec is None or spec == "default":
        return default_profile()
    if isinstance(spec, (str, Path)):
        path = Path(spec).expanduser()
        if folder is not None and not path.is_absolute():
            path = folder / path
        return load_profile(path)
    if isinstance(spec, dict):
        if "format" in spec or "version" in spec:
            return profile_from_dict(spec, source, prefix)
        return merge_profile(default_profile(), spec, source, prefix)
    raise ConfigError(f"{source}: {prefix.rstrip('.') + ': ' if prefix else ''}expected 'default', a profile file or "
                      f"a mapping, got {type(spec).__name__}")


def _plain(v):
    """A value for the YAML file: a bare number when set by hand, else ``{value, std[, note]}`` (4 digits)."""
    if isinstance(v, dict) and "value" in v:
        out = {"value": float(f"{v['value']:.4g}")}
        if v.get("std") is not None:
            out["std"] = float(f"{v['std']:.2g}")
        if v.get("note"):
            out["note"] = v["note"]
        return out["value"] if len(out) == 1 else out
    if isinstance(v, dict):
        return {k: _plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_plain(x) for x in v]
    return v


class _FlowDumper(yaml.SafeDumper):
    pass


def _represent_dict(dumper, data):
    flow = all(not isinstance(v, (dict, list)) for v in data.values()) and len(data) <= 3
    return dumper.represent_mapping("tag:yaml.org,2002:map", data, flow_style=flow)


def _represent_list(dumper, data):
    flow = bool(data) and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in data)
    return dumper.represent_sequence("tag:yaml.org,2002:seq", data, flow_style=flow)


_FlowDumper.add_representer(dict, _represent_dict)
_FlowDumper.add_representer(list, _represent_list)


def profile_data(model: ProfileModel) -> dict:
    """The profile as the mapping its file holds: hand-set values bare, fitted ones ``{value, std}`` (values
    rounded to 4 significant digits, their std to 2)."""
    data = _plain(model.model_dump(mode="python", exclude_none=True))
    if not data.get("notes"):
        data.pop("notes", None)
    return data


def dump_profile(model: ProfileModel, header: str = "") -> str:
    """The profile as YAML text (:func:`profile_data`), with a comment header."""
    data = profile_data(model)
    head = "".join(f"# {line}\n" if line else "#\n" for line in header.splitlines())
    return head + yaml.dump(data, Dumper=_FlowDumper, sort_keys=False, allow_unicode=True, width=110)


def write_profile(path, model: ProfileModel, header: str = "") -> Path:
    """Write :func:`dump_profile` of ``model`` to ``path`` atomically."""
    from posekit.io import write_text_atomic

    return write_text_atomic(Path(path), dump_profile(model, header), flag="--out")


def episode_record(folder) -> dict:
    """``{name, steps, sha256}`` of a recorded episode folder (the SHA-256 of its ``log.csv``)."""
    folder = Path(folder)
    data = (folder / "log.csv").read_bytes()
    steps = max(0, sum(1 for line in data.splitlines() if line.strip() and not line.startswith(b"#")) - 1)
    return {"name": folder.name, "steps": steps, "sha256": hashlib.sha256(data).hexdigest()}
