"""The sensor model: what a 2D laser profiler is (a Keyence LJ-X8400-like line scanner).

Plain data, read by every part of the system: :class:`ProfilerModel` (the fan's geometry,
:data:`LJ_X8400`) and :class:`NoiseModel` (its measurement errors). The estimator reads the
noise it assumes (``sigma_x_um``, ``sigma_z_um``, ``scale_sigma_ppm``), the simulators
(:mod:`posekit.profiler.sim`) the geometry and the noise they add; neither behaviour lives here.

Frame F (the profiler frame), mm: the laser fan lies in F's x–z plane, z is the depth
along the line of sight, x runs along the laser line. The fan leaves the emitter at
``(0, 0, z_apex)``; the measuring range is the trapezoid between depths ``z_near`` and
``z_far`` whose width grows linearly from ``width_near`` to ``width_far`` (so the fan's
edges meet at the apex). A profile is ``n_points`` rays evenly spaced across the far width.

The noise rule of the LJ-X8400 — its repeatability is 10 µm along the line (x) and 5 µm in
depth (z), so x-noise is :data:`X_PER_Z` times z-noise unless told otherwise — lives in one
place, :meth:`NoiseModel.from_z_um`, which every command that takes ``--noise-um`` calls.
"""

from dataclasses import dataclass

import numpy as np

from ..errors import ConfigError

__all__ = ["ProfilerModel", "LJ_X8400", "NoiseModel", "X_PER_Z", "DEFAULT_SCALE_SIGMA_PPM", "MAX_SCALE_SIGMA_PPM"]

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
#: The LJ-X8400's noise along its line (x) per noise in depth (z): repeatability 10 µm / 5 µm.
X_PER_Z = 2.0


@dataclass(frozen=True)
class NoiseModel:
    """Measurement errors of the profiler.

    Attributes
    ----------
    sigma_x_um, sigma_z_um : float
        Standard deviation of the Gaussian noise along x and z of F, µm
        (LJ-X8400 repeatability: 10 µm in x, 5 µm in z; :meth:`from_z_um` keeps that ratio).
    outlier_rate : float
        Fraction of returns replaced by a spike of ±0.3–3 mm in z.
    dropouts_per_profile : float
        Mean number (Poisson) of runs of 5–40 consecutive missing returns.
    scale_sigma_ppm : float
        1σ of the sensor's unknown x and z scale errors that the *estimator* allows for, ppm
        (default :data:`DEFAULT_SCALE_SIGMA_PPM`, an uncalibrated sensor; a sensor whose
        scale was calibrated against a reference declares what is left, 0 none). It enters
        every pose's covariance and consistency test (:func:`~posekit.profiler.estimate.consistency.scale_covariance`)
        and the batch test of the gauge file (:mod:`~posekit.profiler.gauge.check`).
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

    @classmethod
    def from_z_um(cls, sigma_z_um: float, sigma_x_um: float | None = None, **kw) -> "NoiseModel":
        """The noise model of a sensor with ``sigma_z_um`` in depth; x-noise :data:`X_PER_Z` times that unless given.

        The rule behind every ``--noise-um`` (with ``--noise-x-um`` where a verb has it).

        Parameters
        ----------
        sigma_z_um : float
            1σ of the noise in z of F, µm.
        sigma_x_um : float, optional
            1σ of the noise in x of F, µm (default ``X_PER_Z * sigma_z_um``).
        **kw
            The other fields (``outlier_rate``, ``dropouts_per_profile``, ``scale_sigma_ppm``).

        Examples
        --------
        >>> NoiseModel.from_z_um(5.0)
        NoiseModel(sigma_x_um=10.0, sigma_z_um=5.0, outlier_rate=0.0, dropouts_per_profile=0.0, scale_sigma_ppm=100.0)
        """
        return cls(sigma_x_um=X_PER_Z * sigma_z_um if sigma_x_um is None else sigma_x_um, sigma_z_um=sigma_z_um, **kw)
