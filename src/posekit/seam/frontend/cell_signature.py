"""The cell a profile was fitted on, and whether a tracked episode's cell is that one.

A profile (``seam tune``) describes one installation: the robot's unmodelled error around its plateau, the
lasers' noise and latency, how their innovations look. Tracked with a profile fitted on another cell, the
filter's spread has nothing behind it: on the independent cell of the tests (its own robot, two lasers 13 / 17
ms late), the shipped default profile (fitted on posekit's simulated PUMA) is ``tracking`` on every step while
66-77 % of the steps are more than 3σ off, and nothing in the innovations shows it (its laser noise is larger
than this cell's, which hides the latency).

``seam tune`` therefore records the cell in the profile (``fitted.cell``): the robot's name and joint count, the
tool centre point at zero joints (``T_base_tool``, 3 × 4 row-major, mm), each sensor's mount ``T_tool_sensor``
(3 × 4, mm), the compliance model and the angle flag, rounded to 1e-6. :class:`~posekit.seam.frontend.tracker.
SeamTracker` (``seam track``, an online tracker) compares its own cell with it: where they differ every step is
``degraded`` at best, with the difference and the command that fits a profile for this cell as the reason.
The numbers agree to :data:`TOLERANCE` (a written-and-read round trip); anything more is another cell, however
small: the profile was not fitted on it. A profile without ``fitted.cell`` (written by hand, or before it
existed) is not checked. Latencies and noise are not part of the cell: they are what the profile fits.
"""

import math

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

__all__ = ["TOLERANCE", "CellSignature", "cell_difference", "cell_signature", "config_mismatch", "fitted_cell",
           "mismatch_reason"]

#: How far two signatures' numbers may differ and still be one cell (mm; dimensionless for rotation entries):
#: the rounding of a written signature (1e-6), with room for the forward kinematics' float error.
TOLERANCE = 1e-5

_Row12 = tuple[float, ...]


class CellSignature(BaseModel):
    """The cell a profile was fitted on (``fitted.cell`` of a profile file; see the module docstring)."""

    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)
    robot: str = Field(max_length=300)
    joints: int = Field(ge=1, le=64)
    tcp_zero_mm: _Row12 = Field(min_length=12, max_length=12)
    mounts_mm: tuple[_Row12, ...] = Field(max_length=4)
    compliance_rad_per_nm: float = Field(ge=0.0)
    angle: bool = False


def _rows(T) -> tuple[float, ...]:
    return tuple(round(float(v), 6) + 0.0 for v in np.asarray(T, dtype=np.float64)[:3, :4].ravel())


def cell_signature(cell) -> CellSignature:
    """The :class:`CellSignature` of a :class:`posekit.seam.model.Cell`."""
    n = cell.chain.n_joints
    return CellSignature(robot=str(cell.label), joints=n,
                         tcp_zero_mm=_rows(cell.chain.forward_kinematics(np.zeros(n), check=False)),
                         mounts_mm=tuple(_rows(s.T_tool_sensor) for s in cell.sensors),
                         compliance_rad_per_nm=float(cell.compliance_rad_per_nm), angle=bool(cell.angle))


def _offset(a, b) -> tuple[float, float]:
    """Translation (mm) and rotation (deg; 0 below 1e-3 deg, the rounding of a signature's rotation entries)
    between two 3 × 4 row-major poses."""
    A, B = np.reshape(a, (3, 4)), np.reshape(b, (3, 4))
    dt = float(np.linalg.norm(A[:, 3] - B[:, 3]))
    D = A[:, :3].T @ B[:, :3]
    skew = 0.5 * np.array([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]])
    dr = math.degrees(math.atan2(float(np.linalg.norm(skew)), (float(np.trace(D)) - 1.0) / 2.0))
    return dt, dr if dr >= 1e-3 else 0.0


def _differ(a, b) -> bool:
    return bool(np.max(np.abs(np.asarray(a, dtype=np.float64) - np.asarray(b, dtype=np.float64))) > TOLERANCE)


def cell_difference(fitted: CellSignature, cell: CellSignature) -> str | None:
    """What differs between the cell a profile was fitted on (``fitted``) and ``cell`` (None: nothing), in words."""
    if fitted.robot != cell.robot or fitted.joints != cell.joints:
        return f"robot {cell.robot} ({cell.joints} joints), the profile's {fitted.robot} ({fitted.joints} joints)"
    if len(fitted.mounts_mm) != len(cell.mounts_mm):
        return f"{len(cell.mounts_mm)} sensors, the profile's {len(fitted.mounts_mm)}"
    if _differ(fitted.tcp_zero_mm, cell.tcp_zero_mm):
        dt, dr = _offset(fitted.tcp_zero_mm, cell.tcp_zero_mm)
        return f"the tool centre point at zero joints {dt:.3g} mm / {dr:.3g} deg from the profile's"
    for k, (a, b) in enumerate(zip(fitted.mounts_mm, cell.mounts_mm)):
        if _differ(a, b):
            dt, dr = _offset(a, b)
            return f"sensor {k + 1}'s mount {dt:.3g} mm / {dr:.3g} deg from the profile's"
    if not math.isclose(fitted.compliance_rad_per_nm, cell.compliance_rad_per_nm, rel_tol=1e-6, abs_tol=1e-15):
        return f"compliance {cell.compliance_rad_per_nm:.4g} rad/(N m), the profile's {fitted.compliance_rad_per_nm:.4g}"
    if fitted.angle != cell.angle:
        return f"sensors.angle {str(cell.angle).lower()}, the profile's {str(fitted.angle).lower()}"
    return None


def mismatch_reason(fitted: CellSignature | None, cell) -> str | None:
    """The reason every step of ``cell`` (:class:`posekit.seam.model.Cell`) tracked with a profile fitted on
    ``fitted`` is ``degraded`` at best (None: the same cell, or a profile that names none)."""
    if fitted is None:
        return None
    what = cell_difference(fitted, cell_signature(cell))
    if what is None:
        return None
    return (f"the profile was fitted on another cell ({what}): fit one for this cell with "
            "posekit seam tune EPISODE [EPISODE ...] --out PROFILE.yaml")


def fitted_cell(logs) -> CellSignature | None:
    """The cell of recorded episodes (:func:`posekit.seam.frontend.logs.read_episode_log`), or None when they
    come from more than one."""
    from posekit.seam.frontend.config_cell import cell_from_config

    sigs = [cell_signature(cell_from_config(log.config.cell)) for log in logs]
    if not sigs or any(cell_difference(sigs[0], s) is not None for s in sigs[1:]):
        return None
    return sigs[0]


def config_mismatch(cfg) -> str | None:
    """:func:`mismatch_reason` of a :class:`~posekit.seam.frontend.config.SeamConfig`'s profile and cell."""
    from posekit.seam.frontend.config_cell import cell_from_config

    fitted = cfg.profile.fitted
    return mismatch_reason(None if fitted is None else fitted.cell, cell_from_config(cfg.cell))
