"""The building blocks of the seam configuration: validated numbers with their ranges and units, rigid 4x4
transforms, and the episode-size limits (:mod:`posekit.seam.frontend.config` uses them)."""

from typing import Annotated, Any

import numpy as np
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field
from pydantic_core import PydanticCustomError

__all__ = [
    "MAX_PARTICLES",
    "MAX_PARTICLE_STEPS",
    "MAX_STEPS",
    "MAX_STEP_SEAM_POINTS",
    "SEED_MAX",
    "Coord_mm",
    "Distance_mm",
    "Force_n",
    "Integer",
    "JointSeed_deg",
    "Matrix4",
    "Number",
    "Section",
    "check_rigid",
    "item",
    "num",
]


class Section(BaseModel):
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


def item(lo: float | None, hi: float) -> Any:
    """The type of one element of a tuple field: a number in ``lo..hi`` (not a boolean)."""
    return Annotated[float, BeforeValidator(_not_bool), Field(ge=lo, le=hi)]


def num(default, lo=None, hi=None, unit: str = "", *, lo_open: bool = False, hi_open: bool = False, **kw):
    """A ``Field`` with its range (``lo..hi``, either end open) and its unit for error messages."""
    bounds = {}
    if lo is not None:
        bounds["gt" if lo_open else "ge"] = lo
    if hi is not None:
        bounds["lt" if hi_open else "le"] = hi
    return Field(default, json_schema_extra={"unit": unit}, **bounds, **kw)


Coord_mm = item(-1e5, 1e5)            # a position in the robot base frame: within 100 m of the base
Force_n = item(-1e5, 1e5)             # a force component: within 100 kN
Distance_mm = item(None, 1e3)         # a sensor distance ahead of the tool: <= 1 m (> 0 checked below)
JointSeed_deg = item(-1e4, 1e4)       # an IK seed joint value
_Entry = item(-1e5, 1e5)              # an entry of a 4x4 rigid transform (rotation or mm), within 100 m
#: A 4x4 rigid transform as four rows of four numbers (rotation part orthonormal, last row 0 0 0 1).
Matrix4 = tuple[tuple[_Entry, _Entry, _Entry, _Entry], tuple[_Entry, _Entry, _Entry, _Entry],
                tuple[_Entry, _Entry, _Entry, _Entry], tuple[_Entry, _Entry, _Entry, _Entry]]


def check_rigid(m, what: str):
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


