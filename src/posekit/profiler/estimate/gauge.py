"""Multi-plane gauge: YAML model, validation and ridge lines.

Frame G (the gauge frame), mm: x runs across the gauge in the order the laser line
crosses the faces, y along the ridges, z out of the gauge towards the sensor. Face k is
the plane ``{p : normal_k · p = offset_k}`` with its normal pointing out of the material
(so ``normal_z > 0`` for a face the sensor can see). Ridge k is the line where faces k
and k+1 meet, written as in the paper's eq. (2): ``q_k + λ s_k`` with ``q_k`` in the
plane y = 0 and ``s_k = [u_k, 1, w_k]``.

Gauge file (YAML, as in ``examples/gauges/``; ``extent`` and ``tolerance_um`` are optional)::

    name: demo-5
    planes:                      # consecutive faces, in the order the laser line crosses them
      - {normal: [nx, ny, nz], offset: d}
      - ...
    extent: {x: [xmin, xmax], y: [ymin, ymax]}   # optional: footprint of the block, mm
    tolerance_um: 5              # optional: 1σ of each face's position on the as-built gauge

Without ``extent`` the block reaches 25 % of the ridge span beyond the outer ridges in x,
and ±25 mm in y. Without ``tolerance_um`` the gauge is taken as exactly its drawing (0 µm).
``tolerance_um`` is the standard deviation of each face's offset along its normal (the
faces independent); the estimator adds it to the corners' covariance, so it widens the
pose's standard deviations and the consistency (χ²) test accepts a gauge that differs
from its drawing by about that much.

Ambiguous gauges. A gauge whose profiles cannot tell two sensor poses apart is refused
(:class:`~posekit.errors.GaugeError`) unless the mounting is given:

* all ridges parallel — a shift along them leaves every profile unchanged (refused always);
* the reversed reading fits — the corners read in reverse order match the ridges at
  another physically possible pose (the sensor above the gauge, every face seen from its
  outside) within :data:`AMBIGUITY_MIN_MISS_UM` (or 5 × ``tolerance_um`` if larger): a
  cross-section symmetric under a 180° turn about the vertical, or one so shallow that the
  two readings differ by less than the noise can separate. With the mounting known
  (``mounting='normal'`` or ``'reversed'``, ``posekit profiler estimate --mounting``) only
  one reading is tried and the gauge is usable.

The check probes a few poses above the gauge (:func:`gauge_ambiguity`).
"""

from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Annotated

import numpy as np
import yaml
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError

from ...errors import GaugeError
from ...geometry import matrix_from_rotation_vector, plane_intersection
from ...io import load_yaml
from .raycast import seen_from_behind

__all__ = ["Gauge", "load_gauge", "bundled_gauge", "bundled_gauge_path", "gauge_from_design",
           "gauge_to_yaml", "gauge_ambiguity", "pose_is_possible", "BUNDLED_GAUGES", "MOUNTINGS"]

#: Gauges shipped in ``examples/gauges`` (and inside the installed package).
BUNDLED_GAUGES = ("demo-4", "demo-5", "demo-7", "demo-10")

MIN_RIDGES = 4
#: Most ridges of a gauge (the bundled ones have 4-10; a laser line crosses a few dozen faces at most).
MAX_RIDGES = 64
#: Largest gauge YAML file, bytes (65 planes take about 10 kB; comments are welcome).
MAX_GAUGE_BYTES = 2**20
#: Adjacent faces closer than this to parallel have no usable ridge.
MIN_FACE_ANGLE_DEG = 2.0
#: A ridge must leave the x–z plane at least this much: |ŝ_y| >= MIN_RIDGE_Y.
MIN_RIDGE_Y = 0.1
#: Smallest x gap between neighbouring ridges anywhere in the y-extent, mm.
MIN_RIDGE_GAP_MM = 1.0
DEFAULT_Y_HALF_MM = 25.0
#: How the corners' scan order relates to the ridge order (``auto``: decided per profile).
MOUNTINGS = ("auto", "normal", "reversed")
#: The reversed reading of a usable gauge misses its ridges by at least this (RMS, µm) at
#: every probe pose, or by 5 × ``tolerance_um`` if that is larger. The bundled gauges miss
#: by 180 µm or more; a corner's noise at the LJ-X8400's 10/5 µm is about 1-3 µm.
AMBIGUITY_MIN_MISS_UM = 10.0
AMBIGUITY_TOLERANCE_FACTOR = 5.0
#: Ridge directions closer than this (in u = dx/dy and w = dz/dy) count as parallel.
PARALLEL_RIDGES_TOL = 1e-9
#: Depth of the probe poses below the sensor, mm (any depth gives the same answer).
_PROBE_STANDOFF_MM = 440.0


def _number(value):
    """A YAML number (or numeric text); never a boolean or bytes (pydantic would read 1 / 0)."""
    if isinstance(value, bool | bytes | bytearray):
        raise ValueError(f"expected a number, got {type(value).__name__} {value!r:.20}")
    return value


_Number = Annotated[float, BeforeValidator(_number)]


class _PlaneModel(BaseModel):
    model_config = ConfigDict(extra="forbid")
    normal: tuple[_Number, _Number, _Number]
    offset: _Number


class _ExtentModel(BaseModel):
    model_config = ConfigDict(extra="forbid")
    x: tuple[_Number, _Number]
    y: tuple[_Number, _Number]


class _GaugeModel(BaseModel):
    model_config = ConfigDict(extra="forbid")
    name: str = Field(min_length=1, max_length=200)
    planes: list[_PlaneModel] = Field(max_length=MAX_RIDGES + 1)
    extent: _ExtentModel | None = None
    tolerance_um: _Number = 0.0


@dataclass(frozen=True, eq=False)
class Gauge:
    """A validated multi-plane gauge.

    Attributes
    ----------
    name : str
    normals : ndarray, shape (n + 1, 3)
        Unit outward normals of the faces in G, in crossing order.
    offsets : ndarray, shape (n + 1,)
        Face offsets for the unit normals, mm: face k is ``normals[k] · p = offsets[k]``.
    ridge_q : ndarray, shape (n, 3)
        Point of each ridge in the plane y = 0 of G, mm (``ridge_q[:, 1] == 0``).
    ridge_s : ndarray, shape (n, 3)
        Ridge directions ``[u, 1, w]`` (unit y-component), as in eq. (2).
    x_range, y_range : tuple of float
        Footprint of the block in G, mm; no return outside it.
    tolerance_um : float
        1σ of each face's position (offset along its normal) on the as-built gauge, µm.
    ambiguity : str or None
        Why the gauge's profiles cannot tell the two corner readings (normal, reversed)
        apart, or None. Such a gauge is only usable with a known mounting.
    reversed_miss_um : float
        How far the reversed reading of noise-free corners misses the ridges at best over
        the probe poses of :func:`gauge_ambiguity`, µm RMS (NaN: not analysed). The solver
        skips the other corner order when this is large (:mod:`~posekit.profiler.estimate.solve`).
    """

    name: str
    normals: np.ndarray
    offsets: np.ndarray
    ridge_q: np.ndarray
    ridge_s: np.ndarray
    x_range: tuple[float, float]
    y_range: tuple[float, float]
    tolerance_um: float = 0.0
    ambiguity: str | None = None
    reversed_miss_um: float = float("nan")

    @property
    def n_corners(self) -> int:
        """Number of ridges, i.e. corners in a complete profile."""
        return self.ridge_q.shape[0]

    @property
    def face_slope_deg(self) -> np.ndarray:
        """Tilt of each face from the horizontal x–y plane of G, degrees, shape (n + 1,)."""
        return np.degrees(np.arccos(np.clip(self.normals[:, 2], -1.0, 1.0)))

    @property
    def beta_deg(self) -> float:
        """Smallest angle between a face and the vertical (the paper's β), degrees.

        Tilting the laser more than β from the vertical self-occludes the steepest face.
        """
        return float(90.0 - self.face_slope_deg.max())

    def ridge_x(self, y):
        """x of every ridge at height-independent y, mm; shape (..., n) for y of shape (...)."""
        y = np.asarray(y, dtype=np.float64)
        return self.ridge_q[:, 0] + self.ridge_s[:, 0] * y[..., None]

    def ridge_points(self, lam):
        """Points ``q_k + λ_k s_k`` of the ridges, mm, shape (n, 3) for λ of shape (n,)."""
        return self.ridge_q + np.asarray(lam, dtype=np.float64)[:, None] * self.ridge_s

    def surface_z(self, x, y):
        """Height of the gauge surface at (x, y) in G, mm (NaN outside the footprint)."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        rx = self.ridge_x(y)
        face = np.sum(x[..., None] > rx, axis=-1)
        n = self.normals[face]
        z = (self.offsets[face] - n[..., 0] * x - n[..., 1] * y) / n[..., 2]
        inside = (x >= self.x_range[0]) & (x <= self.x_range[1]) & (y >= self.y_range[0]) & (y <= self.y_range[1])
        return np.where(inside, z, np.nan)


def _build(name: str, normals, offsets, extent, source: str, tolerance_um: float = 0.0) -> Gauge:
    normals = np.asarray(normals, dtype=np.float64)
    offsets = np.asarray(offsets, dtype=np.float64)
    where = f"{source}: gauge '{name}'"
    if not (np.all(np.isfinite(normals)) and np.all(np.isfinite(offsets))):
        raise GaugeError(f"{where}: face normals and offsets must be finite numbers")
    n_faces = normals.shape[0]
    if n_faces > MAX_RIDGES + 1:
        raise GaugeError(f"{where}: {n_faces} faces; expected at most {MAX_RIDGES + 1} ({MAX_RIDGES} ridges)")
    if n_faces < MIN_RIDGES + 1:
        raise GaugeError(f"{where}: expected at least {MIN_RIDGES + 1} faces ({MIN_RIDGES} ridges), got {n_faces}")
    lengths = np.linalg.norm(normals, axis=1)
    for k in np.flatnonzero(lengths == 0):
        raise GaugeError(f"{where}: face {k} has a zero normal; expected a non-zero vector")
    normals = normals / lengths[:, None]
    offsets = offsets / lengths
    for k in np.flatnonzero(normals[:, 2] <= 0):
        raise GaugeError(
            f"{where}: face {k} faces away from the sensor (normal z = {normals[k, 2]:.3f}); "
            "normals must point out of the material, towards +z"
        )
    cos_adj = np.clip(np.sum(normals[:-1] * normals[1:], axis=1), -1.0, 1.0)
    angle = np.degrees(np.arccos(cos_adj))
    for k in np.flatnonzero(angle < MIN_FACE_ANGLE_DEG):
        raise GaugeError(
            f"{where}: faces {k} and {k + 1} are parallel (angle {angle[k]:.2f} deg, "
            f"expected >= {MIN_FACE_ANGLE_DEG} deg); adjacent faces must meet in a ridge"
        )
    _, direction = plane_intersection(normals[:-1], offsets[:-1], normals[1:], offsets[1:])
    for k in np.flatnonzero(np.abs(direction[:, 1]) < MIN_RIDGE_Y):
        raise GaugeError(
            f"{where}: ridge {k} (faces {k}/{k + 1}) has no y-component "
            f"(direction {np.round(direction[k], 3).tolist()}); the laser plane cannot cross it"
        )
    s = direction / direction[:, 1:2]
    if np.ptp(s[:, 0]) < PARALLEL_RIDGES_TOL and np.ptp(s[:, 2]) < PARALLEL_RIDGES_TOL:
        raise GaugeError(
            f"{where}: all {len(s)} ridges are parallel (direction [u, 1, w] = "
            f"{np.round(s[0], 3).tolist()}); a shift of the sensor along them leaves every profile "
            "unchanged, so the profiles cannot tell those poses apart; skew at least one ridge"
        )
    if not (np.isfinite(tolerance_um) and tolerance_um >= 0):
        raise GaugeError(f"{where}: tolerance_um must be a finite number >= 0 (µm), got {tolerance_um}")
    # q with q_y = 0: solve the two face equations for (x, z).
    a = normals[:-1][:, [0, 2]]
    b = normals[1:][:, [0, 2]]
    mats = np.stack([a, b], axis=1)
    rhs = np.stack([offsets[:-1], offsets[1:]], axis=1)
    xz = np.linalg.solve(mats, rhs[..., None])[..., 0]
    q = np.stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]], axis=1)

    if extent is None:
        span = q[-1, 0] - q[0, 0]
        x_range = (float(q[0, 0] - 0.25 * abs(span)), float(q[-1, 0] + 0.25 * abs(span)))
        y_range = (-DEFAULT_Y_HALF_MM, DEFAULT_Y_HALF_MM)
    else:
        x_range = (float(extent[0][0]), float(extent[0][1]))
        y_range = (float(extent[1][0]), float(extent[1][1]))
        if not (x_range[0] < x_range[1] and y_range[0] < y_range[1]):
            raise GaugeError(f"{where}: extent must be [min, max] with min < max, got x {x_range}, y {y_range}")

    for y in (y_range[0], 0.0, y_range[1]):
        rx = q[:, 0] + s[:, 0] * y
        gaps = np.diff(rx)
        for k in np.flatnonzero(gaps < MIN_RIDGE_GAP_MM):
            raise GaugeError(
                f"{where}: faces do not meet in order: at y = {y:g} mm ridge {k + 1} "
                f"(x = {rx[k + 1]:.2f} mm) is not right of ridge {k} (x = {rx[k]:.2f} mm) "
                f"by at least {MIN_RIDGE_GAP_MM} mm"
            )
        if rx[0] <= x_range[0] or rx[-1] >= x_range[1]:
            raise GaugeError(
                f"{where}: at y = {y:g} mm the ridges span x = {rx[0]:.2f}..{rx[-1]:.2f} mm, "
                f"outside the block's x extent {list(x_range)}"
            )
    gauge = Gauge(name=name, normals=normals, offsets=offsets, ridge_q=q, ridge_s=s,
                  x_range=x_range, y_range=y_range, tolerance_um=float(tolerance_um))
    miss_um = reversed_miss_um(gauge)
    return replace(gauge, ambiguity=_ambiguity(gauge, miss_um), reversed_miss_um=miss_um)


# --------------------------------------------------------------------------- ambiguity


def _check_mounting(mounting: str, where: str) -> None:
    if mounting not in MOUNTINGS:
        raise GaugeError(f"{where}: unknown mounting '{mounting}'; expected one of {', '.join(MOUNTINGS)}")


def _refuse_ambiguous(gauge: Gauge, mounting: str, where: str) -> Gauge:
    """The gauge, or a GaugeError if it is ambiguous and the mounting is not given."""
    if gauge.ambiguity is not None and mounting == "auto":
        raise GaugeError(f"{where}: gauge '{gauge.name}' is ambiguous: {gauge.ambiguity}; give the mounting "
                         "(--mounting normal|reversed)")
    return gauge


def _probe_poses(gauge: Gauge) -> list:
    """Sensor poses ``T_G_F`` above the gauge: level and tilted by 3-5°, at three places along y."""
    R0 = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    y_lo, y_hi = gauge.y_range
    yc = 0.5 * (y_lo + y_hi)
    tilts = np.radians([[0, 0, 0], [3, 0, 0], [-3, 0, 0], [0, 3, 0], [0, -3, 0], [0, 0, 5], [0, 0, -5]])
    poses = []
    for y in (yc, yc - 0.25 * (y_hi - y_lo), yc + 0.25 * (y_hi - y_lo)):
        ridge = gauge.ridge_q + y * gauge.ridge_s
        pivot = np.array([0.5 * (ridge[0, 0] + ridge[-1, 0]), y, float(np.mean(ridge[:, 2]))])
        for rv in tilts:
            T = np.eye(4)
            T[:3, :3] = R0 @ matrix_from_rotation_vector(rv)
            T[:3, 3] = pivot - T[:3, :3] @ np.array([0.0, 0.0, _PROBE_STANDOFF_MM])
            poses.append(T)
    return poses


def _piercing_points(gauge: Gauge, R_G_F, t_G_F):
    """Where each ridge crosses F's plane y = 0: (n, 2) corners (x, z) in F, ridge order, mm."""
    R_F_G = R_G_F.T
    q = gauge.ridge_q @ R_F_G.T - R_F_G @ t_G_F
    s = gauge.ridge_s @ R_F_G.T
    if np.any(np.abs(s[:, 1]) < 1e-9):
        return None
    p = q - (q[:, 1] / s[:, 1])[:, None] * s
    return np.ascontiguousarray(p[:, [0, 2]])


#: A face counts as seen from behind when the line of sight to its corner makes
#: ``normal · direction`` above this (about 14° behind the face's plane): far beyond the
#: fan's spread, so a real pose never fails it.
SEEN_FROM_BEHIND_COS = 0.25


def pose_is_possible(gauge: Gauge, T_G_F, corners_F, margin_mm: float = 1.0, extent: bool = True) -> bool:
    """Whether a pose could have produced these corners.

    Parameters
    ----------
    gauge : Gauge
    T_G_F : ndarray, shape (4, 4)
        Pose of the profiler in G, mm.
    corners_F : ndarray, shape (n, 2)
        Corners (x, z) in F, mm, in ridge order.
    margin_mm : float
        How far beyond the block's y-extent a corner may lie, mm.
    extent : bool
        Check the y-extent (False: only which side the faces are seen from; a gauge file
        without ``extent`` has a guessed one).

    Returns
    -------
    bool
        False when a face would be seen from behind (through the material, e.g. from
        below the gauge: ``normal · line of sight`` > :data:`SEEN_FROM_BEHIND_COS`) or a
        corner lies beyond the block's ends in y.
    """
    c = np.asarray(corners_F, dtype=np.float64)
    T = np.asarray(T_G_F, dtype=np.float64)
    p_F = np.stack([c[:, 0], np.zeros(len(c)), c[:, 1]], axis=1)
    y = p_F @ T[1, :3] + T[1, 3]
    if extent and np.any((y < gauge.y_range[0] - margin_mm) | (y > gauge.y_range[1] + margin_mm)):
        return False
    return not seen_from_behind(gauge.normals, T, c, SEEN_FROM_BEHIND_COS)


def _reversed_miss_mm(gauge: Gauge, T_G_F) -> float:
    """Smallest RMS miss (mm) of the reversed reading at a physically possible pose."""
    from .closed_form import cf4_start, cf_kernel
    from .refine import refine_kernel

    c = _piercing_points(gauge, T_G_F[:3, :3], T_G_F[:3, 3])
    if c is None:
        return np.inf
    n = len(c)
    rev = np.ascontiguousarray(c[::-1])
    starts = []
    ok, R, t = (cf_kernel if n >= 5 else cf4_start)(rev, gauge.ridge_q, gauge.ridge_s)
    if ok:
        starts.append((R, t))
    # a 180° turn about the vertical through the middle of the ridges: exact for a symmetric gauge
    cx = 0.5 * (gauge.ridge_q[0, 0] + gauge.ridge_q[-1, 0])
    S = np.diag([-1.0, -1.0, 1.0])
    starts.append((S @ T_G_F[:3, :3], S @ T_G_F[:3, 3] + np.array([2.0 * cx, 0.0, 0.0])))
    W = np.eye(2 * n)
    best = np.inf
    for R_GF, t_GF in starts:
        R_FG = np.ascontiguousarray(R_GF.T)
        ok, R2, t2, _, cost, _ = refine_kernel(R_FG, -(R_FG @ t_GF), rev, W, gauge.ridge_q, gauge.ridge_s, 50)
        if not ok or not np.isfinite(cost):
            continue
        T = np.eye(4)
        T[:3, :3] = R2.T
        T[:3, 3] = -(R2.T @ t2)
        if pose_is_possible(gauge, T, rev):
            best = min(best, float(np.sqrt(cost / (2 * n))))
    return best


def gauge_ambiguity(gauge: Gauge) -> str | None:
    """Why the gauge's profiles cannot tell the normal from the reversed reading, or None.

    At each of 21 probe poses above the gauge (level and tilted by 3-5°, at three places
    along the ridges) the noise-free corners are read in reverse order and fitted to the
    ridges (closed-form start and a 180° turn about the vertical, refined); fits that put
    the sensor where it could not have seen the corners (below the gauge, beyond its ends)
    do not count. The gauge is ambiguous when the best such fit misses by less than
    :data:`AMBIGUITY_MIN_MISS_UM` RMS (or :data:`AMBIGUITY_TOLERANCE_FACTOR` × its
    ``tolerance_um``).

    Parameters
    ----------
    gauge : Gauge

    Returns
    -------
    str or None
        A one-line description naming the ambiguity.
    """
    return _ambiguity(gauge, reversed_miss_um(gauge))


def reversed_miss_um(gauge: Gauge) -> float:
    """The best fit of the reversed reading over the probe poses of :func:`gauge_ambiguity`, µm RMS."""
    return float(1e3 * min(_reversed_miss_mm(gauge, T) for T in _probe_poses(gauge)))


def _ambiguity(gauge: Gauge, miss_um: float) -> str | None:
    """:func:`gauge_ambiguity` from the gauge's :func:`reversed_miss_um`."""
    limit_um = max(AMBIGUITY_MIN_MISS_UM, AMBIGUITY_TOLERANCE_FACTOR * gauge.tolerance_um)
    if miss_um >= limit_um:
        return None
    if miss_um < 0.01:
        return ("its cross-section is symmetric under a 180° turn about the vertical: read in reverse order, "
                "the corners fit the ridges exactly at another pose")
    return (f"read in reverse order, the corners fit the ridges at another pose within {miss_um:.2f} µm RMS "
            f"(a usable gauge misses by >= {limit_um:g} µm): too close to symmetric under a 180° turn")


def load_gauge(path, mounting: str = "auto") -> Gauge:
    """Load and validate a gauge YAML file.

    Parameters
    ----------
    path : str or Path
        The gauge file (format in the module docstring).
    mounting : {'auto', 'normal', 'reversed'}
        How the gauge will be read. With 'auto' (the estimator decides the corner order
        per profile) an ambiguous gauge is refused; with a given mounting it is returned
        (its :attr:`Gauge.ambiguity` says why it needs one).

    Returns
    -------
    Gauge

    Raises
    ------
    GaugeError
        If the file cannot be read or parsed, has unknown or missing keys, or describes
        an unusable gauge (fewer than 4 ridges, parallel adjacent faces, a ridge with no
        y-component, faces that do not meet in order, all ridges parallel), or an
        ambiguous one with ``mounting='auto'``. The message names the file.
    """
    path = Path(path)
    _check_mounting(mounting, str(path))
    data = load_yaml(path, expected="a gauge YAML file", error=GaugeError, limit=MAX_GAUGE_BYTES)
    if not isinstance(data, dict):
        raise GaugeError(f"{path}: expected a mapping with keys 'name' and 'planes', got {type(data).__name__}")
    planes = data.get("planes")
    if isinstance(planes, list) and len(planes) > MAX_RIDGES + 1:      # size before any per-plane work
        raise GaugeError(f"{path}: {len(planes)} planes; expected at most {MAX_RIDGES + 1} ({MAX_RIDGES} ridges)")
    try:
        model = _GaugeModel.model_validate(data)
    except ValidationError as exc:
        err = exc.errors()[0]
        loc = ".".join(str(p) for p in err["loc"]) or "(top level)"
        kind = err["type"]
        if kind == "extra_forbidden":
            msg = f"unknown key '{loc}'"
        elif kind == "missing":
            msg = f"missing key '{loc}'"
        else:
            msg = f"key '{loc}': {err['msg']}"
        raise GaugeError(f"{path}: {msg}") from None
    extent = None if model.extent is None else (model.extent.x, model.extent.y)
    gauge = _build(model.name, [p.normal for p in model.planes], [p.offset for p in model.planes],
                   extent, str(path), model.tolerance_um)
    return _refuse_ambiguous(gauge, mounting, str(path))


def gauge_from_design(name, ridge_x_mm, slopes_x, ridge_u, *, height_mm=20.0, y_slope0=0.0,
                      extent=None, tolerance_um: float = 0.0, mounting: str = "auto") -> Gauge:
    """Build a gauge from its cross-section and ridge directions.

    Face k is the plane ``z = a_k x + b_k y + c_k``; the faces meet at ``x = ridge_x_mm``
    on y = 0 and the ridges run along ``[u_k, 1, ·]``.

    Parameters
    ----------
    name : str
    ridge_x_mm : array_like, shape (n,)
        x of each ridge at y = 0, increasing, mm.
    slopes_x : array_like, shape (n + 1,)
        ``a_k = dz/dx`` of each face.
    ridge_u : array_like, shape (n,)
        ``u_k = dx/dy`` of each ridge; sets the y-slopes ``b_k`` through
        ``b_{k+1} = b_k + u_k (a_k - a_{k+1})``.
    height_mm : float, optional
        Surface height at x = y = 0 ... precisely, ``c`` of the first face is chosen so the
        mean ridge height is ``height_mm``.
    y_slope0 : float, optional
        ``b_0``.
    extent : ((xmin, xmax), (ymin, ymax)), optional
    tolerance_um : float, optional
        1σ of each face's position on the as-built gauge, µm.
    mounting : {'auto', 'normal', 'reversed'}
        As :func:`load_gauge`: an ambiguous design is refused unless the mounting is given.

    Returns
    -------
    Gauge

    Raises
    ------
    GaugeError
        For the design rules of :func:`load_gauge`, the message starting ``design:``.
    """
    _check_mounting(mounting, f"design: gauge '{name}'")
    xr = np.asarray(ridge_x_mm, dtype=np.float64)
    a = np.asarray(slopes_x, dtype=np.float64)
    u = np.asarray(ridge_u, dtype=np.float64)
    if a.shape != (xr.size + 1,) or u.shape != xr.shape:
        raise GaugeError(f"gauge_from_design '{name}': expected n ridges, n + 1 slopes and n u-values, "
                         f"got {xr.size}, {a.size}, {u.size}")
    b = np.empty_like(a)
    c = np.empty_like(a)
    b[0] = y_slope0
    c[0] = 0.0
    for k in range(xr.size):
        b[k + 1] = b[k] + u[k] * (a[k] - a[k + 1])
        c[k + 1] = c[k] + (a[k] - a[k + 1]) * xr[k]
    ridge_z = a[:-1] * xr + c[:-1]
    c += height_mm - ridge_z.mean()
    normals = np.stack([-a, -b, np.ones_like(a)], axis=1)
    return _refuse_ambiguous(_build(name, normals, c, extent, "design", tolerance_um), mounting, "design")


def gauge_to_yaml(gauge: Gauge) -> str:
    """YAML text of a gauge (unit normals), loadable by :func:`load_gauge`."""
    planes = [{"normal": [round(float(v), 12) + 0.0 for v in n], "offset": round(float(d), 12) + 0.0}
              for n, d in zip(gauge.normals, gauge.offsets)]
    doc = {"name": gauge.name, "planes": planes,
           "extent": {"x": list(gauge.x_range), "y": list(gauge.y_range)}}
    if gauge.tolerance_um > 0:
        doc["tolerance_um"] = float(gauge.tolerance_um)
    return yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)


def bundled_gauge_path(name: str) -> Path:
    """Path of a gauge shipped with posekit (``examples/gauges/NAME.yaml``)."""
    if name not in BUNDLED_GAUGES:
        raise GaugeError(f"unknown bundled gauge '{name}'; expected one of {', '.join(BUNDLED_GAUGES)}")
    packaged = resources.files("posekit") / "_examples" / "gauges" / f"{name}.yaml"
    if packaged.is_file():
        return Path(str(packaged))
    # Source checkout / editable install: examples/ beside src/.
    repo = Path(__file__).resolve().parents[4] / "examples" / "gauges" / f"{name}.yaml"
    if repo.is_file():
        return repo
    raise GaugeError(f"bundled gauge '{name}' is not installed (looked for {repo})")


def bundled_gauge(name: str = "demo-5", mounting: str = "auto") -> Gauge:
    """Load a gauge shipped with posekit, e.g. ``bundled_gauge("demo-5")`` (``mounting`` as :func:`load_gauge`)."""
    return load_gauge(bundled_gauge_path(name), mounting)
