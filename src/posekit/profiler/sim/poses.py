"""Where the simulated sensor looks from: the nominal pose, random and smooth pose sets.

Poses are ``T_G_F``, the profiler frame F in the gauge frame G, mm (frames as in
:mod:`posekit.profiler.sensor`). :func:`sample_poses` draws uniform offsets from
:func:`nominal_pose` within a :class:`Workspace` and keeps those that see every corner
(:func:`visible_mask`); :func:`loop_poses` is a smooth closed path, a robot moving over the gauge.
"""

from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError
from ...geometry import matrix_from_rotation_vector, transform_from
from ..gauge.model import Gauge
from ..sensor import LJ_X8400, ProfilerModel

__all__ = ["Workspace", "nominal_pose", "loop_poses", "visible_mask", "sample_poses"]


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
