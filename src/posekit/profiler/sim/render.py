"""Simulated profiles: the sensor's fan cast at a gauge, with its noise.

Each of the ``n_points`` rays of :class:`~posekit.profiler.sensor.ProfilerModel` returns the
first gauge face it hits (ray casting, so faces turned away from the emitter self-occlude) or
NaN: no face, a face outside the block's footprint, or a hit outside the measuring range;
then :class:`~posekit.profiler.sensor.NoiseModel`'s Gaussian noise, spikes and dropouts are added.

``render_profiles(..., realism=RealismModel.realistic())`` renders an as-built gauge with what
a real cell shows instead (rounded and chamfered ridges, the mounting plate and a fixture
beside the gauge, multipath near valleys, machining error, scale error, dropouts on steep
faces): see :mod:`~posekit.profiler.sim.realism`.
"""

import numpy as np

from posekit._jit import njit

from ...errors import ConfigError
from ..gauge.model import Gauge
from ..gauge.raycast import first_face_hit, ray_in_gauge
from ..sensor import LJ_X8400, NoiseModel, ProfilerModel
from .realism import AsBuiltGauge, RealismModel, build_as_built
from .realism_render import render_as_built

__all__ = ["render_profiles"]


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
        :class:`~posekit.profiler.sim.realism.RealismModel` draws one as-built gauge with its
        surroundings from ``rng`` first (``RealismModel.realistic()`` for every defect of a
        real cell; the options and their defaults are listed in
        :mod:`~posekit.profiler.sim.realism`), then renders it at every pose. An
        :class:`~posekit.profiler.sim.realism.AsBuiltGauge` (from
        :func:`~posekit.profiler.sim.realism.build_as_built`) renders that gauge again;
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
