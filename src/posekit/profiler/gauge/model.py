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
  outside) within :data:`~posekit.profiler.gauge.ambiguity.AMBIGUITY_MIN_MISS_UM` (or 5 × ``tolerance_um`` if larger): a
  cross-section symmetric under a 180° turn about the vertical, or one so shallow that the
  two readings differ by less than the noise can separate. With the mounting known
  (``mounting='normal'`` or ``'reversed'``, ``posekit profiler estimate --mounting``) only
  one reading is tried and the gauge is usable.

The check probes a few poses above the gauge (:func:`~posekit.profiler.gauge.ambiguity.gauge_ambiguity`).
"""

from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path
from typing import Annotated

import numpy as np
import yaml
from pydantic import BaseModel, BeforeValidator, ConfigDict, Field, ValidationError

from ...errors import GaugeError
from ...geometry import plane_intersection
from ...io import load_yaml
from .ambiguity import ambiguity_text, reversed_miss_um

__all__ = ["Gauge", "load_gauge", "bundled_gauge", "bundled_gauge_path", "resolve_gauge", "gauge_from_design",
           "gauge_to_yaml", "BUNDLED_GAUGES", "MOUNTINGS"]

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
#: Ridge directions closer than this (in u = dx/dy and w = dz/dy) count as parallel.
PARALLEL_RIDGES_TOL = 1e-9


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
        the probe poses of :func:`~posekit.profiler.gauge.ambiguity.gauge_ambiguity`, µm RMS (NaN: not analysed). The solver
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


def _refuse_metres(where: str, offsets, ridge_q, extent) -> None:
    """A GaugeError when the gauge's sizes fit metres, not mm: every face within 2 of the origin,
    the ridges within 1 of each other and the extent (if any) within ±2. No usable gauge in mm
    is that small (its ridges are at least MIN_RIDGE_GAP_MM apart)."""
    sizes = [np.abs(offsets).max(), np.abs(ridge_q[:, [0, 2]]).max()]
    if extent is not None:
        sizes.append(np.abs(np.asarray(extent, dtype=np.float64)).max())
    span = np.ptp(ridge_q[:, 0])
    if max(sizes) < 2.0 and span < 1.0:
        raise GaugeError(f"{where}: looks like metres (every offset and ridge within 2 of the origin, the ridges span "
                         f"{span:.3g} in x); posekit expects mm (multiply offset and extent by 1000)")


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
    _refuse_metres(where, offsets, q, extent)

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
    return replace(gauge, ambiguity=ambiguity_text(gauge, miss_um), reversed_miss_um=miss_um)
def _check_mounting(mounting: str, where: str) -> None:
    if mounting not in MOUNTINGS:
        raise GaugeError(f"{where}: unknown mounting '{mounting}'; expected one of {', '.join(MOUNTINGS)}")


def _refuse_ambiguous(gauge: Gauge, mounting: str, where: str) -> Gauge:
    """The gauge, or a GaugeError if it is ambiguous and the mounting is not given."""
    if gauge.ambiguity is not None and mounting == "auto":
        raise GaugeError(f"{where}: gauge '{gauge.name}' is ambiguous: {gauge.ambiguity}; give the mounting "
                         "(--mounting normal|reversed)")
    return gauge



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


def resolve_gauge(gauge, mounting: str = "auto") -> Gauge:
    """The gauge a verb is given: a :class:`Gauge` as it is, else a file path, else a bundled name.

    Parameters
    ----------
    gauge : Gauge or str or Path
        A gauge, the path of a gauge YAML file, or the name of a bundled gauge
        (:data:`BUNDLED_GAUGES`, used when no file of that name exists).
    mounting : {'auto', 'normal', 'reversed'}
        As :func:`load_gauge` (a :class:`Gauge` given as such is returned unchanged).

    Raises
    ------
    GaugeError
        As :func:`load_gauge`.
    """
    if isinstance(gauge, Gauge):
        return gauge
    path = Path(gauge)
    if not path.exists() and str(gauge) in BUNDLED_GAUGES:
        path = bundled_gauge_path(str(gauge))
    return load_gauge(path, mounting)
