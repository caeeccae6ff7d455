"""Simulated 2D laser profiler (a Keyence LJ-X8400-like line scanner) looking at a gauge.

Frame F (the profiler frame), mm: the laser fan lies in F's x–z plane, z is the depth
along the line of sight, x runs along the laser line. The fan leaves the emitter at
``(0, 0, z_apex)``; the measuring range is the trapezoid between depths ``z_near`` and
``z_far`` whose width grows linearly from ``width_near`` to ``width_far`` (so the fan's
edges meet at the apex). A profile is ``n_points`` rays evenly spaced across the far
width, each returning the first gauge face it hits (ray casting, so faces turned away
from the emitter self-occlude) or NaN: no face, a face outside the block's footprint,
or a hit outside the measuring range.

``render_profiles(..., realism=RealismModel.realistic())`` adds what a real cell shows
(rounded and chamfered ridges, the mounting plate and a fixture beside the gauge,
multipath near valleys, machining error, scale error, dropouts on steep faces): see
:mod:`~posekit.profiler.estimate.realism`.
"""

from dataclasses import dataclass

import numpy as np

from posekit._jit import njit

from ...errors import ConfigError
from ...geometry import matrix_from_rotation_vector, transform_from
from .gauge import Gauge
from .raycast import first_face_hit, ray_in_gauge
from .realism import AsBuiltGauge, RealismModel, build_as_built, render_as_built, true_corners

__all__ = ["ProfilerModel", "Workspace", "NoiseModel", "DEFAULT_SCALE_SIGMA_PPM", "LJ_X8400", "nominal_pose",
           "loop_poses",
           "sample_poses", "visible_mask", "render_profiles", "RealismModel", "AsBuiltGauge",
           "build_as_built", "true_corners"]


@dataclass(frozen=True)
class ProfilerModel:
    """Geometry of a 2D laser profiler; defaults are those of the Keyence LJ-X8400.

    Attributes are in mm; ``n_points`` rays per profile.
    """

    n_points: int = 3200
    z_near: float = 285.0
    z_far: float = 600.0
    width_near: float = 163.0
    width_far: float = 320.0

    @property
    def z_apex(self) -> float:
        """Depth of the fan's apex (the emitter) in F, mm."""
        slope = (self.width_far - self.width_near) / (2.0 * (self.z_far - self.z_near))
        return self.z_near - 0.5 * self.width_near / slope

    @property
    def z_mid(self) -> float:
        """Middle of the depth range, mm: the natural stand-off."""
        return 0.5 * (self.z_near + self.z_far)

    def half_width(self, z):
        """Half width of the measuring range at depth z, mm."""
        return 0.5 * self.width_near + (np.asarray(z) - self.z_near) * (
            (self.width_far - self.width_near) / (2.0 * (self.z_far - self.z_near)))

    def ray_directions(self) -> np.ndarray:
        """Unnormalised ray directions in F, shape (n_points, 3), with unit z-component."""
        x_far = np.linspace(-0.5 * self.width_far, 0.5 * self.width_far, self.n_points)
        d = np.zeros((self.n_points, 3))
        d[:, 0] = x_far / (self.z_far - self.z_apex)
        d[:, 2] = 1.0
        return d


LJ_X8400 = ProfilerModel()


#: 1σ of the sensor scale error (x and z, ppm) the estimator allows for unless told
#: (:attr:`NoiseModel.scale_sigma_ppm`): an uncalibrated sensor, the realistic simulator's ±100 ppm.
#: Without it the std of a pose on realistic profiles is far too small (demo-5: ~60 % of the
#: errors within 2σ, rz ~10 %; with it 95.7-97.2 %).
DEFAULT_SCALE_SIGMA_PPM = 100.0
#: Largest allowed ``scale_sigma_ppm`` (1 %).
MAX_SCALE_SIGMA_PPM = 1e4


@dataclass(frozen=True)
class NoiseModel:
    """Measurement errors of the profiler.

    Attributes
    ----------
    sigma_x_um, sigma_z_um : float
        Standard deviation of the Gaussian noise along x and z of F, µm
        (LJ-X8400 repeatability: 10 µm in x, 5 µm in z).
    outlier_rate : float
        Fraction of returns replaced by a spike of ±0.3–3 mm in z.
    dropouts_per_profile : float
        Mean number (Poisson) of runs of 5–40 consecutive missing returns.
    scale_sigma_ppm : float
        1σ of the sensor's unknown x and z scale errors that the *estimator* allows for, ppm
        (default :data:`DEFAULT_SCALE_SIGMA_PPM`, an uncalibrated sensor; a sensor whose
        scale was calibrated against a reference declares what is left, 0 none). It enters
        every pose's covariance and consistency test (:func:`~posekit.profiler.estimate.verdict.scale_covariance`)
        and the batch test of the gauge file (:mod:`~posekit.profiler.estimate.gauge_check`).
        The simulators do not read it: their scale error is ``RealismModel.scale_x_ppm``,
        ``scale_z_ppm``.
    """

    sigma_x_um: float = 10.0
    sigma_z_um: float = 5.0
    outlier_rate: float = 0.0
    dropouts_per_profile: float = 0.0
    scale_sigma_ppm: float = DEFAULT_SCALE_SIGMA_PPM

    def __post_init__(self):
        for key in ("sigma_x_um", "sigma_z_um", "outlier_rate", "dropouts_per_profile", "scale_sigma_ppm"):
            v = getattr(self, key)
            if not np.isfinite(v) or v < 0:
                raise ConfigError(f"noise: '{key}' must be a finite number >= 0, got {v}")
        if self.scale_sigma_ppm > MAX_SCALE_SIGMA_PPM:
            raise ConfigError(f"noise: 'scale_sigma_ppm' must be <= {MAX_SCALE_SIGMA_PPM:g} ppm, got "
                              f"{self.scale_sigma_ppm:g}")
        if self.outlier_rate > 0.5:
            raise ConfigError(f"noise: 'outlier_rate' must be <= 0.5, got {self.outlier_rate}")


@dataclass(frozen=True)
class Workspace:
    """Where poses are sampled: uniform offsets from the nominal pose.

    Attributes
    ----------
    translation_mm : tuple of 3 float
        Half-ranges of the uniform offset along x, y, z of G, mm.
    rotation_deg : tuple of 3 float
        Half-ranges of a uniform rotation vector about x, y, z of F (applied in F, about
        the point at the stand-off depth on F's z-axis), deg.
    standoff_mm : float or None
        Depth of the gauge below the sensor at the nominal pose, mm (None: mid-range).
    """

    translation_mm: tuple[float, float, float] = (10.0, 10.0, 40.0)
    rotation_deg: tuple[float, float, float] = (4.0, 4.0, 8.0)
    standoff_mm: float | None = None

    def __post_init__(self):
        for key in ("translation_mm", "rotation_deg"):
            v = np.asarray(getattr(self, key), dtype=float)
            if v.shape != (3,) or not np.all(np.isfinite(v)) or np.any(v < 0):
                raise ConfigError(f"workspace: '{key}' must be 3 finite numbers >= 0, got {getattr(self, key)}")


def nominal_pose(gauge: Gauge, model: ProfilerModel = LJ_X8400, standoff_mm: float | None = None) -> np.ndarray:
    """Sensor pose ``T_G_F`` straight above the gauge's centre, shape (4, 4), mm.

    F's x runs along G's x (the laser crosses the faces in file order), F's z looks
    down (-z of G), and the gauge's mean ridge height sits at the stand-off depth.
    """
    standoff = model.z_mid if standoff_mm is None else standoff_mm
    R = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
    cx = 0.5 * (gauge.ridge_q[0, 0] + gauge.ridge_q[-1, 0])
    z = float(np.mean(gauge.ridge_q[:, 2])) + standoff
    return transform_from(R, np.array([cx, 0.0, z]))


def loop_poses(gauge: Gauge, count: int, model: ProfilerModel = LJ_X8400) -> np.ndarray:
    """A smooth closed loop of sensor poses around the nominal pose: a robot moving over the gauge.

    Over one period the sensor turns about the point at mid-range on its line of sight by
    ±3°, ±3° and ±6° about its x, y and z and shifts by ±6, ±6 and ±20 mm along G's x, y, z
    (sines of different frequencies and phases), so neighbouring poses are close: a stream.

    Parameters
    ----------
    gauge : Gauge
    count : int
        Poses along one period.
    model : ProfilerModel

    Returns
    -------
    Ts_G_F : ndarray, shape (count, 4, 4)
        Poses of F in G, mm.
    """
    th = 2 * np.pi * np.arange(count) / count
    T0 = nominal_pose(gauge, model)
    pivot_F = np.array([0.0, 0.0, model.z_mid])
    pivot_G = T0[:3, :3] @ pivot_F + T0[:3, 3]
    dt = np.stack([6 * np.sin(th), 6 * np.sin(2 * th), 20 * np.sin(3 * th)], axis=1)
    rv = np.radians(np.stack([3 * np.sin(th + 1), 3 * np.sin(2 * th + 2), 6 * np.sin(th + 3)], axis=1))
    R = T0[:3, :3] @ matrix_from_rotation_vector(rv)
    return transform_from(R, pivot_G - np.einsum("kij,j->ki", R, pivot_F) + dt)


def visible_mask(gauge: Gauge, Ts_G_F, model: ProfilerModel = LJ_X8400, margin_mm: float = 3.0) -> np.ndarray:
    """Which poses see every corner of the gauge, shape (K,) bool.

    A pose qualifies when, in the laser plane, every ridge's piercing point and the middle
    of each outer face lie inside the measuring range by ``margin_mm`` and inside the
    block's y-extent, and every face is lit from its outside (no self-occlusion: the
    paper's α < β, §III-D).

    Parameters
    ----------
    gauge : Gauge
    Ts_G_F : array_like, shape (K, 4, 4)
    model : ProfilerModel
    margin_mm : float
    """
    Ts = np.asarray(Ts_G_F, dtype=np.float64).reshape(-1, 4, 4)
    R = Ts[:, :3, :3]
    t = Ts[:, :3, 3]
    # Laser plane in G: normal = F's y axis, through F's origin.
    ny = R[:, :, 1]                                         # (K, 3)
    off = np.sum(ny * t, axis=1)                            # (K,)
    # Ridge piercing points: q + λ s with ny·(q + λ s) = off.
    lam = (off[:, None] - (gauge.ridge_q @ ny.T).T) / (gauge.ridge_s @ ny.T).T
    P = gauge.ridge_q[None] + lam[..., None] * gauge.ridge_s[None]      # (K, n, 3)
    # Outer face ends: the laser plane ∩ face ∩ the block edge x = const.
    ends = []
    for face, x_edge, ridge in ((0, gauge.x_range[0], 0), (gauge.n_corners, gauge.x_range[1], -1)):
        nf = gauge.normals[face]
        # Unknowns (y, z) with x = x_edge: nf·p = d_f and ny·p = off.
        a11, a12 = nf[1], nf[2]
        a21, a22 = ny[:, 1], ny[:, 2]
        b1 = gauge.offsets[face] - nf[0] * x_edge
        b2 = off - ny[:, 0] * x_edge
        det = a11 * a22 - a12 * a21
        y = (b1 * a22 - a12 * b2) / det
        z = (a11 * b2 - a21 * b1) / det
        edge = np.stack([np.full_like(y, x_edge), y, z], axis=1)
        ends.append(0.5 * (edge + P[:, ridge]))
    pts = np.concatenate([P, np.stack(ends, axis=1)], axis=1)       # (K, n + 2, 3)
    p_F = np.einsum("kji,kmj->kmi", R, pts - t[:, None, :])          # R^T (p - t)
    z = p_F[..., 2]
    ok = (z >= model.z_near + margin_mm) & (z <= model.z_far - margin_mm)
    ok &= np.abs(p_F[..., 0]) <= model.half_width(z) - margin_mm
    ok &= (pts[..., 1] >= gauge.y_range[0] + margin_mm) & (pts[..., 1] <= gauge.y_range[1] - margin_mm)
    # Each face must face the emitter: normal · (point - emitter) < 0 at the face's middle.
    emitter = t + R[:, :, 2] * model.z_apex                           # (K, 3)
    chain = np.concatenate([pts[:, -2:-1], P, pts[:, -1:]], axis=1)   # edge0, ridges..., edge1
    mids = 0.5 * (chain[:, :-1] + chain[:, 1:])                       # (K, n + 1, 3) one per face
    lit = np.einsum("fi,kfi->kf", gauge.normals, mids - emitter[:, None, :]) < 0
    return np.all(ok, axis=1) & np.all(lit, axis=1)


def sample_poses(gauge: Gauge, count: int, rng=None, workspace: Workspace = Workspace(),
                 model: ProfilerModel = LJ_X8400, visible_only: bool = True) -> np.ndarray:
    """Random sensor poses ``T_G_F`` around the nominal pose.

    Parameters
    ----------
    gauge : Gauge
    count : int
    rng : numpy.random.Generator or int or None
    workspace : Workspace
    model : ProfilerModel
    visible_only : bool
        Keep only poses that see every corner (:func:`visible_mask`), drawing more until
        there are ``count``; False keeps every draw, gauge cut off or not.

    Returns
    -------
    Ts_G_F : ndarray, shape (count, 4, 4)
        Poses of F in G, mm.

    Raises
    ------
    ConfigError
        If fewer than 2 % of the workspace's poses see the whole gauge.
    """
    rng = np.random.default_rng(rng)
    T0 = nominal_pose(gauge, model, workspace.standoff_mm)
    standoff = model.z_mid if workspace.standoff_mm is None else workspace.standoff_mm
    pivot_F = np.array([0.0, 0.0, standoff])
    pivot_G = T0[:3, :3] @ pivot_F + T0[:3, 3]
    kept = []
    drawn = 0
    while sum(len(k) for k in kept) < count:
        m = max(count, 64)
        dt = rng.uniform(-1, 1, (m, 3)) * np.asarray(workspace.translation_mm)
        rv = np.radians(rng.uniform(-1, 1, (m, 3)) * np.asarray(workspace.rotation_deg))
        R = T0[:3, :3] @ matrix_from_rotation_vector(rv)
        # Rotate about the pivot where the laser meets the gauge, not about the sensor
        # (a 4 deg tilt about the sensor would sweep the line 30 mm over the gauge).
        Ts = transform_from(R, pivot_G - R @ pivot_F + dt)
        drawn += m
        kept.append(Ts[visible_mask(gauge, Ts, model)] if visible_only else Ts)
        n_kept = sum(len(k) for k in kept)
        if drawn >= 1000 and n_kept < 0.02 * drawn:
            raise ConfigError(
                f"workspace too large for gauge '{gauge.name}': only {n_kept} of {drawn} sampled poses "
                "see every corner; reduce --translation-mm / --rotation-deg")
    return np.concatenate(kept)[:count]


@njit(cache=True, nogil=True)
def _cast_kernel(normals, offsets, ridge_q, ridge_s, x_lo, x_hi, y_lo, y_hi, Rs, ts, d_F, z_apex,
                 z_near, z_far, out):
    """First-hit ray casting, compiled: out[k, i] = (x, z) in F of ray i at pose k, or NaN."""
    for k in range(Rs.shape[0]):
        for i in range(d_F.shape[0]):
            dxF = d_F[i, 0]
            dzF = d_F[i, 2]
            ox, oy, oz, dx, dy, dz = ray_in_gauge(Rs[k], ts[k], z_apex, dxF, dzF)
            best, _ = first_face_hit(normals, offsets, ridge_q, ridge_s, x_lo, x_hi, y_lo, y_hi, ox, oy, oz,
                                     dx, dy, dz)
            z = z_apex + best * dzF
            if best < np.inf and z >= z_near and z <= z_far:
                out[k, i, 0] = best * dxF
                out[k, i, 1] = z
            else:
                out[k, i, 0] = np.nan
                out[k, i, 1] = np.nan


def _cast(gauge: Gauge, Ts_G_F: np.ndarray, model: ProfilerModel) -> np.ndarray:
    """Noise-free first-hit ray casting; (K, n_points, 2) points (x, z) in F or NaN."""
    out = np.empty((Ts_G_F.shape[0], model.n_points, 2))
    _cast_kernel(gauge.normals, gauge.offsets, gauge.ridge_q, gauge.ridge_s, gauge.x_range[0],
                 gauge.x_range[1], gauge.y_range[0], gauge.y_range[1],
                 np.ascontiguousarray(Ts_G_F[:, :3, :3]), np.ascontiguousarray(Ts_G_F[:, :3, 3]),
                 model.ray_directions(), model.z_apex, model.z_near, model.z_far, out)
    return out


def render_profiles(gauge: Gauge, Ts_G_F, noise: NoiseModel = NoiseModel(), rng=None,
                    model: ProfilerModel = LJ_X8400,
                    realism: RealismModel | AsBuiltGauge | None = None) -> np.ndarray:
    """Simulate the profiles the sensor measures at the given poses.

    Parameters
    ----------
    gauge : Gauge
    Ts_G_F : array_like, shape (K, 4, 4) or (4, 4)
        Sensor poses in G, mm.
    noise : NoiseModel
    rng : numpy.random.Generator or int or None
        Same seed, same profiles.
    model : ProfilerModel
    realism : RealismModel or AsBuiltGauge, optional
        None (default): the ideal gauge of the drawing, nothing else in view. A
        :class:`~posekit.profiler.estimate.realism.RealismModel` draws one as-built gauge with its
        surroundings from ``rng`` first (``RealismModel.realistic()`` for every defect of a
        real cell; the options and their defaults are listed in
        :mod:`~posekit.profiler.estimate.realism`), then renders it at every pose. An
        :class:`~posekit.profiler.estimate.realism.AsBuiltGauge` (from
        :func:`~posekit.profiler.estimate.realism.build_as_built`) renders that gauge again;
        ``gauge`` must then be its drawing.

    Returns
    -------
    profiles : ndarray, shape (K, n_points, 2) (or (n_points, 2) for one pose)
        Points (x, z) in F in scan order, mm; NaN where there is no return.
    """
    rng = np.random.default_rng(rng)
    Ts = np.asarray(Ts_G_F, dtype=np.float64)
    single = Ts.ndim == 2
    Ts = Ts.reshape(-1, 4, 4)
    if realism is None:
        out = _cast(gauge, Ts, model)
    else:
        scene = realism if isinstance(realism, AsBuiltGauge) else build_as_built(gauge, realism, rng)
        if scene.nominal is not gauge and scene.nominal.name != gauge.name:
            raise ConfigError(f"realism: the as-built gauge was drawn from '{scene.nominal.name}', "
                              f"not from '{gauge.name}'")
        out = render_as_built(scene, Ts, model, rng)
    valid = np.isfinite(out[..., 0])
    out[..., 0] += rng.normal(0.0, noise.sigma_x_um * 1e-3, valid.shape)
    out[..., 1] += rng.normal(0.0, noise.sigma_z_um * 1e-3, valid.shape)
    if noise.outlier_rate > 0:
        spike = valid & (rng.random(valid.shape) < noise.outlier_rate)
        mag = rng.uniform(0.3, 3.0, valid.shape) * rng.choice([-1.0, 1.0], valid.shape)
        out[..., 1] += np.where(spike, mag, 0.0)
    if noise.dropouts_per_profile > 0:
        counts = rng.poisson(noise.dropouts_per_profile, Ts.shape[0])
        for k in np.flatnonzero(counts):
            for _ in range(counts[k]):
                start = rng.integers(0, model.n_points)
                out[k, start:start + rng.integers(5, 41)] = np.nan
    return out[0] if single else out
