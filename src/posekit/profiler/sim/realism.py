"""What a real installation adds to the ideal profile: the as-built gauge and its surroundings.

The ideal simulator (:func:`~posekit.profiler.sim.render.render_profiles` without ``realism``)
sees a drawing: sharp ridges, perfect planes, nothing else in the laser line. A real cell
shows, and :class:`RealismModel` simulates (every option off by default; a realistic set in
:meth:`RealismModel.realistic`):

==================  ================================================================  ===================
defect              model                                                             realistic default
==================  ================================================================  ===================
rounded ridges      each ridge is a fillet: a cylinder of radius r (uniform in           0.2–1.0 mm
                    ``edge_radius_mm``) tangent to both faces, cast exactly (the laser
                    plane cuts it in an ellipse arc)
chamfers            a fraction ``chamfer_fraction`` of the ridges is cut flat instead:   30 %, 0.3–1.0 mm
                    a bevel of width ``chamfer_mm`` across, symmetric to both faces
                    (valleys get the bevel filled in, as a fillet weld would)
mounting plate      a horizontal plate ``plate_depth_mm`` below the gauge's lowest       8 mm
                    surface point, seen beside the block (and shadowed by it)
fixture             a clamp block on the plate beside the gauge (random side), top       3–14 mm high,
                    ``fixture_height_mm`` above the plate, ``fixture_width_mm`` wide,    12 mm wide,
                    ``fixture_gap_mm`` from the block; its top and its inner wall        2–10 mm away
                    return light
multipath           near each concave ridge (valley), with probability                   p 0.5,
                    ``multipath_rate`` per profile, a ghost cluster: the returns of one  0.3–2.5 mm long,
                    face from 0–0.3 mm to ``multipath_length_mm`` off the valley seem    0.05–0.8 mm deep
                    ``multipath_depth_mm`` deeper (a ramp halving away from the valley)
machining error     the as-built faces differ from the drawing: each face's offset       10 µm, 0.01°
                    ~ N(0, ``face_offset_um``), its normal tilted ~ N(0,
                    ``face_tilt_deg``) about two axes through the face's middle; the
                    ridges are recomputed from the as-built faces
scale error         the sensor's x and z scales are off: ``x' = (1 + sx) x``,            +100 / -100 ppm
                    ``z' = z_mid + (1 + sz)(z - z_mid)`` (``scale_x_ppm``,
                    ``scale_z_ppm``; z about the middle of the measuring range)
steep dropouts      the return probability falls with the incidence angle θ on the       25°–65°, up to
                    surface: about a share ``steep_dropout_max · clip((θ - θ0) / (θ1 -   60 % lost, runs
                    θ0))`` of the returns is lost, in runs of 1 to 2 ·                   of 1–7 returns
                    ``dropout_run_points`` - 1 returns (``(θ0, θ1) = steep_dropout_deg``)
==================  ================================================================  ===================

The random parts of the as-built gauge (machining, edge radii, chamfers, fixture) are drawn
once per :func:`build_as_built` call, so one call of ``render_profiles(..., realism=R)``
shows one physical gauge at all its poses; pass an :class:`AsBuiltGauge` instead of the
model to render the same gauge again. Same seed, same numbers: every draw happens in a
fixed order whatever the options.
"""

from dataclasses import dataclass, fields, replace

import numpy as np

from ...errors import ConfigError
from ..gauge.model import Gauge

__all__ = ["RealismModel", "AsBuiltGauge", "build_as_built", "DEFECTS"]

#: The defects of :class:`RealismModel`, each with the fields that switch it on.
DEFECTS = {
    "rounded": ("edge_radius_mm",),
    "chamfer": ("chamfer_fraction", "chamfer_mm"),
    "fixture": ("plate_depth_mm", "fixture_height_mm", "fixture_width_mm", "fixture_gap_mm"),
    "multipath": ("multipath_rate", "multipath_length_mm", "multipath_depth_mm"),
    "machining": ("face_offset_um", "face_tilt_deg"),
    "scale": ("scale_x_ppm", "scale_z_ppm"),
    "dropouts": ("steep_dropout_deg", "steep_dropout_max", "dropout_run_points"),
}


@dataclass(frozen=True)
class RealismModel:
    """Options of the realistic simulator; all off by default (see the module docstring).

    Attributes
    ----------
    edge_radius_mm : (float, float)
        Range of the fillet radius of each ridge, mm (uniform).
    chamfer_fraction : float
        Fraction of ridges chamfered instead of rounded, 0..1.
    chamfer_mm : (float, float)
        Range of the chamfer width across its flat, mm.
    plate_depth_mm : float or None
        Depth of the mounting plate below the gauge's lowest surface point, mm; None: no plate.
    fixture_height_mm : (float, float) or None
        Range of the fixture's top above the plate, mm; None: no fixture (needs a plate).
    fixture_width_mm : float
        Width of the fixture along x of G, mm.
    fixture_gap_mm : (float, float)
        Range of its gap from the gauge block along x, mm.
    multipath_rate : float
        Probability per profile and concave ridge of a ghost cluster, 0..1.
    multipath_length_mm, multipath_depth_mm : (float, float)
        Ranges of the cluster's length along the face and of its apparent extra depth, mm.
    face_offset_um : float
        1σ of each as-built face's offset from the drawing, µm.
    face_tilt_deg : float
        1σ of each as-built face's tilt about each of two axes in the face, degrees.
    scale_x_ppm, scale_z_ppm : float
        The sensor's scale errors in x (about x = 0) and z (about the middle of the
        measuring range), ppm.
    steep_dropout_deg : (float, float)
        Incidence angles between which the dropout probability rises from 0 to its maximum.
    steep_dropout_max : float
        Largest share of returns lost on steep surfaces (a run starts at a return with
        this probability, times the ramp, divided by the mean run length), 0..1.
    dropout_run_points : int
        Mean length of a steep-face dropout run, in returns.
    """

    edge_radius_mm: tuple[float, float] = (0.0, 0.0)
    chamfer_fraction: float = 0.0
    chamfer_mm: tuple[float, float] = (0.0, 0.0)
    plate_depth_mm: float | None = None
    fixture_height_mm: tuple[float, float] | None = None
    fixture_width_mm: float = 12.0
    fixture_gap_mm: tuple[float, float] = (2.0, 10.0)
    multipath_rate: float = 0.0
    multipath_length_mm: tuple[float, float] = (0.3, 2.5)
    multipath_depth_mm: tuple[float, float] = (0.05, 0.8)
    face_offset_um: float = 0.0
    face_tilt_deg: float = 0.0
    scale_x_ppm: float = 0.0
    scale_z_ppm: float = 0.0
    steep_dropout_deg: tuple[float, float] = (25.0, 65.0)
    steep_dropout_max: float = 0.0
    dropout_run_points: int = 4

    def __post_init__(self):
        def bad(key, what):
            raise ConfigError(f"realism: '{key}' {what}, got {getattr(self, key)}")

        for key in ("edge_radius_mm", "chamfer_mm", "fixture_gap_mm", "multipath_length_mm",
                    "multipath_depth_mm", "steep_dropout_deg", "fixture_height_mm"):
            v = getattr(self, key)
            if v is None and key == "fixture_height_mm":
                continue
            a = np.asarray(v, dtype=float)
            if a.shape != (2,) or not np.all(np.isfinite(a)) or a[0] < 0 or a[1] < a[0]:
                bad(key, "must be a range (lo, hi) of finite numbers with 0 <= lo <= hi")
        for key in ("chamfer_fraction", "multipath_rate", "steep_dropout_max"):
            v = getattr(self, key)
            if not (np.isfinite(v) and 0 <= v <= 1):
                bad(key, "must lie in [0, 1]")
        for key in ("face_offset_um", "face_tilt_deg", "fixture_width_mm"):
            v = getattr(self, key)
            if not (np.isfinite(v) and v >= 0):
                bad(key, "must be a finite number >= 0")
        for key in ("scale_x_ppm", "scale_z_ppm"):
            if not (np.isfinite(getattr(self, key)) and abs(getattr(self, key)) <= 1e5):
                bad(key, "must be a finite number within ±1e5 ppm")
        if self.plate_depth_mm is not None and not (np.isfinite(self.plate_depth_mm) and self.plate_depth_mm > 0):
            bad("plate_depth_mm", "must be a number > 0 or None")
        if self.fixture_height_mm is not None and self.plate_depth_mm is None:
            bad("fixture_height_mm", "needs a plate to stand on (plate_depth_mm)")
        if self.dropout_run_points < 1:
            bad("dropout_run_points", "must be >= 1")
        if self.steep_dropout_deg[1] > 90 or self.steep_dropout_deg[1] <= self.steep_dropout_deg[0]:
            bad("steep_dropout_deg", "must be (lo, hi) with lo < hi <= 90")

    @classmethod
    def realistic(cls) -> "RealismModel":
        """Every defect on, at the magnitudes of a machined gauge in a robot cell."""
        return cls(edge_radius_mm=(0.2, 1.0), chamfer_fraction=0.3, chamfer_mm=(0.3, 1.0),
                   plate_depth_mm=8.0, fixture_height_mm=(3.0, 14.0), multipath_rate=0.5,
                   face_offset_um=10.0, face_tilt_deg=0.01, scale_x_ppm=100.0, scale_z_ppm=-100.0,
                   steep_dropout_max=0.6)

    def only(self, *defects: str) -> "RealismModel":
        """A copy with only the named defects (keys of :data:`DEFECTS`) kept, the rest off."""
        unknown = [d for d in defects if d not in DEFECTS]
        if unknown:
            raise ConfigError(f"realism: unknown defect(s) {unknown}; expected some of {', '.join(DEFECTS)}")
        keep = {f for d in defects for f in DEFECTS[d]}
        off = RealismModel()
        return replace(off, **{f.name: getattr(self, f.name) for f in fields(self) if f.name in keep})


@dataclass(frozen=True, eq=False)
class AsBuiltGauge:
    """One physical gauge as drawn by :func:`build_as_built` (G frame, mm).

    Attributes
    ----------
    gauge : Gauge
        The as-built faces (machining error applied) and their sharp ridges: the truth the
        corners of a profile should be compared with (:func:`~posekit.profiler.sim.realism_render.true_corners`).
    nominal : Gauge
        The drawing.
    edge_kind : ndarray of int, shape (n,)
        0 sharp, 1 fillet, 2 chamfer, per ridge.
    edge_size : ndarray, shape (n,)
        Fillet radius or chamfer width, mm.
    convex : ndarray of bool, shape (n,)
        True for a ridge (peak), False for a valley.
    axis_q : ndarray, shape (n, 3)
        A point of each fillet's axis, mm.
    chamfer_plane : ndarray, shape (n, 4)
        Unit normal and offset of each chamfer's plane.
    plate_z : float
        Height of the mounting plate in G, mm (NaN: none).
    fixture : ndarray, shape (4,)
        ``x0, x1, z_top, side`` of the fixture block (side +1 right of the gauge, -1 left;
        NaN: none).
    realism : RealismModel
    """

    gauge: Gauge
    nominal: Gauge
    edge_kind: np.ndarray
    edge_size: np.ndarray
    convex: np.ndarray
    axis_q: np.ndarray
    chamfer_plane: np.ndarray
    plate_z: float
    fixture: np.ndarray
    realism: RealismModel


def build_as_built(gauge: Gauge, realism: RealismModel, rng=None) -> AsBuiltGauge:
    """Draw one physical gauge (machining error, edges, plate, fixture) from its drawing.

    Parameters
    ----------
    gauge : Gauge
        The drawing.
    realism : RealismModel
    rng : numpy.random.Generator or int or None

    Returns
    -------
    AsBuiltGauge
    """
    rng = np.random.default_rng(rng)
    n = gauge.n_corners
    # Fixed draw order, whatever the options.
    d_off = rng.standard_normal(n + 1) * realism.face_offset_um * 1e-3
    tilt = rng.standard_normal((n + 1, 2)) * np.radians(realism.face_tilt_deg)
    radius = rng.uniform(*realism.edge_radius_mm, n)
    chamfer = rng.uniform(*realism.chamfer_mm, n)
    is_chamfer = rng.random(n) < realism.chamfer_fraction
    fix_u = rng.random(3)

    # Machining: tilt each face about its middle (at y = 0), then shift it.
    N = gauge.normals
    xs = np.concatenate([[gauge.x_range[0]], gauge.ridge_q[:, 0], [gauge.x_range[1]]])
    mid_x = 0.5 * (xs[:-1] + xs[1:])
    mid = np.stack([mid_x, np.zeros(n + 1), (gauge.offsets - N[:, 0] * mid_x) / N[:, 2]], axis=1)
    e_a = np.cross(N, [0.0, 1.0, 0.0])
    e_a /= np.linalg.norm(e_a, axis=1, keepdims=True)
    e_b = np.cross(N, e_a)
    N2 = N + tilt[:, :1] * e_a + tilt[:, 1:] * e_b
    N2 /= np.linalg.norm(N2, axis=1, keepdims=True)
    d2 = np.sum(N2 * mid, axis=1) + d_off
    q, s = _ridges(N2[:-1], d2[:-1], N2[1:], d2[1:])
    built = replace(gauge, normals=N2, offsets=d2, ridge_q=q, ridge_s=s)

    # Edges: convexity from the cross-section at y = 0.
    nk, nk1 = N2[:-1], N2[1:]
    x1 = q[:, 0] + 1.0
    z1 = (d2[1:] - nk1[:, 0] * x1) / nk1[:, 2]
    convex = nk[:, 0] * x1 + nk[:, 2] * z1 < d2[:-1]
    sign = np.where(convex, -1.0, 1.0)           # fillet axis: inside (convex) or outside (valley)
    kind = np.where(is_chamfer & (chamfer > 0), 2, np.where(radius > 0, 1, 0))
    size = np.where(kind == 2, chamfer, np.where(kind == 1, radius, 0.0))
    r = np.where(kind == 1, radius, 0.0)
    axis_q, _ = _ridges(nk, d2[:-1] + sign * r, nk1, d2[1:] + sign * r)
    nc = nk + nk1
    nc /= np.linalg.norm(nc, axis=1, keepdims=True)
    half_turn = 0.5 * np.arccos(np.clip(np.sum(nk * nk1, axis=1), -1, 1))
    h = 0.5 * chamfer * np.tan(half_turn)
    dc = np.sum(nc * q, axis=1) + sign * h
    chamfer_plane = np.concatenate([nc, dc[:, None]], axis=1)

    # Plate and fixture.
    plate_z = np.nan
    fixture = np.full(4, np.nan)
    if realism.plate_depth_mm is not None:
        ys = np.array(gauge.y_range)
        corners = [(x, y) for x in gauge.x_range for y in ys]
        rx = built.ridge_x(ys)                              # (2, n)
        corners += [(rx[j, k], ys[j]) for j in range(2) for k in range(n)]
        cx, cy = np.array(corners).T
        plate_z = float(np.nanmin(built.surface_z(np.clip(cx, *gauge.x_range), cy)) - realism.plate_depth_mm)
        if realism.fixture_height_mm is not None:
            side = 1.0 if fix_u[0] < 0.5 else -1.0
            gap = realism.fixture_gap_mm[0] + fix_u[1] * (realism.fixture_gap_mm[1] - realism.fixture_gap_mm[0])
            hgt = realism.fixture_height_mm[0] + fix_u[2] * (realism.fixture_height_mm[1]
                                                             - realism.fixture_height_mm[0])
            if side > 0:
                x0 = gauge.x_range[1] + gap
                x1_ = x0 + realism.fixture_width_mm
            else:
                x1_ = gauge.x_range[0] - gap
                x0 = x1_ - realism.fixture_width_mm
            fixture = np.array([x0, x1_, plate_z + hgt, side])
    return AsBuiltGauge(gauge=built, nominal=gauge, edge_kind=kind.astype(np.int64), edge_size=size,
                        convex=convex, axis_q=axis_q, chamfer_plane=chamfer_plane, plate_z=plate_z,
                        fixture=fixture, realism=realism)


def _ridges(na, da, nb, db):
    """Lines ``q + λ s`` (q at y = 0, s = [u, 1, w]) where planes ``na·p = da`` and ``nb·p = db`` meet."""
    d = np.cross(na, nb)
    mats = np.stack([na[:, [0, 2]], nb[:, [0, 2]]], axis=1)
    rhs = np.stack([da, db], axis=1)
    xz = np.linalg.solve(mats, rhs[..., None])[..., 0]
    return np.stack([xz[:, 0], np.zeros(len(xz)), xz[:, 1]], axis=1), d / d[:, 1:2]
