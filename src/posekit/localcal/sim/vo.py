"""A simulated VO/SLAM camera trajectory (the paper ran ORB-SLAM2 stereo on a ZED2).

The VO world frame W is the camera frame at the first VO pose, as ORB-SLAM2 defines it. The
estimate drifts and is noisy:

``T_W_C_vo[k] = D[k] · S(T_W_C[k]) · N[k]``

where ``T_W_C[k] = T_B_C[0]⁻¹ T_B_C[k]`` is the true camera pose in W, ``S`` scales its
translation by ``1 + ε`` (stereo scale error), ``D[k]`` a drift transform that random-walks
with the distance travelled (``D[0] = I``) and ``N[k]`` the frame noise, in the camera frame
(none at the first pose, which defines W).

Two error models add up:

* **isotropic** (``noise_mm``, ``noise_rad``, ``drift_mm_per_sqrt_m``,
  ``drift_rad_per_sqrt_m``): white noise per axis and a random-walk drift about the W axes
  after one metre of travel — the model of the first simulator, kept as a floor;
* **stereo** (``stereo=StereoNoise(...)`` with the scene depth ``depth_mm`` per pose): a
  stereo camera triangulates a feature at depth z from its disparity ``d = f b / z``, so a
  disparity error ``σ_d`` is a depth error ``σ_z = z² σ_d / (f b)`` while an image error
  ``σ_px`` is a lateral error ``z σ_px / f``. The pose of the camera, fitted to ``n``
  independent features, inherits per camera axis
  ``σ = (z σ_px, z σ_px, z² σ_d / b) / (f √n)`` (mm) and a rotation error
  ``σ_px / (f √n)`` (rad) — :meth:`StereoNoise.sigma_mm`. Consecutive frames track the same
  features, so the frame noise is correlated in time (first-order, time constant
  ``corr_s``). Drift accumulates the same anisotropy: per √metre travelled
  ``drift_mm_per_sqrt_m`` laterally and ``drift_mm_per_sqrt_m · z σ_d / (b σ_px)`` along the
  optical axis, about the *current* camera axes. A disparity bias ``δd`` (calibration,
  ``N(0, disparity_bias_px²)`` drawn once) scales every depth by ``1 - z δd / (f b)``: the VO
  translation by the same factor.

VO runs at a lower rate than the robot (every ``stride``-th robot sample), on its own clock
(``time_offset_s`` added to the timestamps); a fraction of the frames can be gross outliers
(tracking glitches, ``outlier_mm`` per axis). The same seed with a longer history gives the
same estimates for the common prefix (without outliers), so VO can 'keep running'. The
default magnitudes are assumptions (no ORB-SLAM2 error budget is published for this setup):
ZED2 baseline 120 mm and the focal length of :func:`posekit.localcal.model.camera.zed2_720p`,
half-pixel feature noise, ~25 independent features per frame.
"""

from dataclasses import dataclass

import numpy as np

from posekit.errors import ConfigError, TrajectoryError
from posekit.geometry import (
    check_transform,
    invert_transform,
    matrix_from_rotation_vector,
)
from posekit.localcal.model.trajectory import Trajectory

__all__ = ["StereoNoise", "VONoise", "depth_along_axis", "simulate_vo"]


class VONoise:
    """Defaults of :func:`simulate_vo`'s isotropic model (the first simulator's magnitudes;
    assumptions). The episodes use :class:`StereoNoise` with a small isotropic floor instead."""

    noise_mm = 1.0
    noise_rad = np.deg2rad(0.1)
    drift_mm_per_sqrt_m = 3.0
    drift_rad_per_sqrt_m = np.deg2rad(0.2)
    stride = 3                 # robot at 100 Hz -> VO at ~33 Hz
    outlier_fraction = 0.0
    outlier_mm = 50.0


@dataclass(frozen=True)
class StereoNoise:
    """Error model of a stereo VO (see the module docs): errors grow with the scene depth.

    Parameters
    ----------
    baseline_mm : float
        Stereo baseline b, mm (ZED2: 120 mm).
    focal_px : float
        Focal length f of the rectified images, px (ZED2 at 720p: ~528 px).
    pixel_noise_px : float
        Image noise σ_px of a matched feature, px (lateral errors).
    disparity_noise_px : float
        Disparity noise σ_d of a matched feature, px (depth errors).
    features : int
        Independent features the pose is fitted to per frame, n.
    corr_s : float
        Time constant of the frame noise, s (features are tracked over many frames; 0 = white).
    drift_mm_per_sqrt_m : float
        Lateral random-walk drift per √metre travelled, mm; the depth axis drifts
        ``z σ_d / (b σ_px)`` times more.
    drift_rad_per_sqrt_m : float
        Rotation drift per √metre travelled, rad (per axis).
    disparity_bias_px : float
        Std of the constant disparity bias (calibration error) drawn once per trajectory, px.
    """

    baseline_mm: float = 120.0
    focal_px: float = 528.0
    pixel_noise_px: float = 0.5
    disparity_noise_px: float = 0.5
    features: int = 25
    corr_s: float = 0.5
    drift_mm_per_sqrt_m: float = 1.5
    drift_rad_per_sqrt_m: float = float(np.deg2rad(0.2))
    disparity_bias_px: float = 0.1

    def __post_init__(self):
        for name in ("baseline_mm", "focal_px"):
            v = getattr(self, name)
            if not (np.ndim(v) == 0 and np.isfinite(v) and v > 0):
                raise ConfigError(f"StereoNoise: {name} must be a finite number > 0, got {v!r}")
        for name in ("pixel_noise_px", "disparity_noise_px", "corr_s", "drift_mm_per_sqrt_m",
                     "drift_rad_per_sqrt_m", "disparity_bias_px"):
            _nonneg(getattr(self, name), f"StereoNoise: {name}", prefix=False)
        if isinstance(self.features, bool) or int(self.features) != self.features or self.features < 1:
            raise ConfigError(f"StereoNoise: features must be an integer >= 1, got {self.features!r}")

    def sigma_mm(self, depth_mm) -> np.ndarray:
        """Per-frame position noise of the camera along its own axes at a scene depth.

        Parameters
        ----------
        depth_mm : array_like, shape (...)
            Scene depth z (distance of the tracked surface along the optical axis), mm.

        Returns
        -------
        sigma : ndarray, shape (..., 3)
            1σ along the camera's x, y (lateral: ``z σ_px / (f √n)``) and z (depth:
            ``z² σ_d / (f b √n)``) axes, mm.

        Examples
        --------
        >>> StereoNoise().sigma_mm(1000.0).round(2)
        array([0.19, 0.19, 1.58])
        """
        z = np.asarray(depth_mm, dtype=np.float64)
        k = 1.0 / (self.focal_px * np.sqrt(self.features))
        lat = z * self.pixel_noise_px * k
        return np.stack([lat, lat, z * z * self.disparity_noise_px * k / self.baseline_mm], axis=-1)

    def sigma_rad(self) -> float:
        """Per-frame rotation noise per axis, rad (``σ_px / (f √n)``)."""
        return float(self.pixel_noise_px / (self.focal_px * np.sqrt(self.features)))

    def drift_mm(self, depth_mm) -> np.ndarray:
        """Random-walk drift std per √metre along the camera's x, y, z axes, shape (..., 3), mm."""
        z = np.asarray(depth_mm, dtype=np.float64)
        ratio = z * self.disparity_noise_px / (self.baseline_mm * max(self.pixel_noise_px, 1e-12))
        lat = np.full_like(z, self.drift_mm_per_sqrt_m)
        return np.stack([lat, lat, lat * ratio], axis=-1)


def depth_along_axis(T_B_C, T_B_plane) -> np.ndarray:
    """Distance from each camera to a plane along its optical axis (the scene depth VO sees).

    Parameters
    ----------
    T_B_C : array_like, shape (N, 4, 4)
        Camera poses in the base frame B (OpenCV axes: z is the optical axis), mm.
    T_B_plane : array_like, shape (4, 4)
        A frame on the plane, its z axis the plane's normal (e.g. the OOI's wall), mm.

    Returns
    -------
    depth_mm : ndarray, shape (N,)
        Depth along each camera's optical axis, mm (inf where the axis is parallel to the plane).
    """
    T = np.asarray(T_B_C, dtype=np.float64)
    P = np.asarray(T_B_plane, dtype=np.float64)
    n = P[:3, 2]
    along = T[..., :3, 2] @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        d = ((P[:3, 3] - T[..., :3, 3]) @ n) / along
    return np.where(np.isfinite(d), np.abs(d), np.inf)


def _ar1(w, t, corr_s):
    """First-order correlated noise with the same marginal std as the white ``w`` (N, k)."""
    if corr_s <= 0 or len(w) < 2:
        return w
    from scipy.signal import lfilter

    dt = float(np.median(np.diff(t)))
    rho = float(np.exp(-dt / corr_s))
    c = np.sqrt(1.0 - rho * rho)
    y, _ = lfilter([c], [1.0, -rho], w, axis=0, zi=(1.0 - c) * w[:1])
    return y


def _nonneg(value, name, prefix=True):
    if not (np.ndim(value) == 0 and np.isfinite(value) and value >= 0):
        raise ConfigError(f"{'simulate_vo: ' if prefix else ''}{name} must be a finite number >= 0, got {value!r}")
    return float(value)


def simulate_vo(T_B_C_true, t_s, rng, *, noise_mm: float = VONoise.noise_mm,
                noise_rad: float = VONoise.noise_rad,
                drift_mm_per_sqrt_m: float = VONoise.drift_mm_per_sqrt_m,
                drift_rad_per_sqrt_m: float = VONoise.drift_rad_per_sqrt_m,
                stride: int = VONoise.stride, time_offset_s: float = 0.0,
                outlier_fraction: float = VONoise.outlier_fraction,
                outlier_mm: float = VONoise.outlier_mm,
                stereo: StereoNoise | None = None, depth_mm=None) -> Trajectory:
    """Simulate the VO estimate of a camera trajectory.

    Parameters
    ----------
    T_B_C_true : array_like, shape (N, 4, 4)
        True camera poses in the robot base frame B at the robot's samples, mm.
    t_s : array_like, shape (N,)
        Their times, s (increasing).
    rng : numpy.random.Generator or int or None
        Source of the noise.
    noise_mm, noise_rad : float
        Isotropic white noise std per axis on position (mm) and rotation vector (rad).
    drift_mm_per_sqrt_m, drift_rad_per_sqrt_m : float
        Isotropic random-walk drift std per axis after one metre of travel (mm, rad).
    stride : int
        VO keeps every ``stride``-th robot sample (>= 1).
    time_offset_s : float
        Constant offset of the VO clock, s.
    outlier_fraction : float
        Fraction of frames (after the first) replaced by gross outliers, in [0, 0.5].
    outlier_mm : float
        Std per axis of an outlier's position error, mm.
    stereo : StereoNoise, optional
        Adds the depth-dependent stereo errors (module docs); needs ``depth_mm``.
    depth_mm : float or array_like, shape (N,), optional
        Scene depth seen by the camera at each robot sample (e.g. :func:`depth_along_axis`), mm.

    Returns
    -------
    Trajectory
        VO poses ``T_W_C`` (mm) with W = the camera frame at the first VO pose, and their
        timestamps (s, VO clock).

    Raises
    ------
    TrajectoryError
        Fewer than 3 poses, shapes that do not match, or non-increasing times.
    ConfigError
        A negative or non-finite magnitude, ``stride < 1``, ``outlier_fraction`` out of range,
        ``stereo`` without a depth or a depth that is not finite and > 0.
    """
    T = check_transform(T_B_C_true, name="T_B_C_true")
    t = np.asarray(t_s, dtype=np.float64)
    if T.ndim != 3 or t.shape != (len(T),):
        raise TrajectoryError(f"simulate_vo: expected poses (N, 4, 4) and times (N,), got {T.shape} and {t.shape}")
    if int(stride) != stride or stride < 1:
        raise ConfigError(f"simulate_vo: stride must be an integer >= 1, got {stride!r}")
    if stereo is not None:
        if not isinstance(stereo, StereoNoise):
            raise ConfigError(f"simulate_vo: stereo must be a StereoNoise, got {type(stereo).__name__}")
        if depth_mm is None:
            raise ConfigError("simulate_vo: the stereo model needs depth_mm (the scene depth per pose, mm)")
        z = np.broadcast_to(np.asarray(depth_mm, dtype=np.float64), t.shape)
        if not np.all(np.isfinite(z) & (z > 0)):
            raise ConfigError("simulate_vo: depth_mm must be finite and > 0 (mm) at every pose")
        z = z[::int(stride)]
    T, t = T[::int(stride)], t[::int(stride)]
    if len(T) < 3:
        raise TrajectoryError(f"simulate_vo: too few poses: expected at least 3 VO frames, got {len(T)}")
    if not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise TrajectoryError("simulate_vo: times must be finite and strictly increasing")
    noise_mm, noise_rad = _nonneg(noise_mm, "noise_mm"), _nonneg(noise_rad, "noise_rad")
    drift_t = _nonneg(drift_mm_per_sqrt_m, "drift_mm_per_sqrt_m")
    drift_r = _nonneg(drift_rad_per_sqrt_m, "drift_rad_per_sqrt_m")
    outlier_mm = _nonneg(outlier_mm, "outlier_mm")
    if not (np.isfinite(outlier_fraction) and 0.0 <= outlier_fraction <= 0.5):
        raise ConfigError(f"simulate_vo: outlier_fraction must be in [0, 0.5], got {outlier_fraction!r}")
    rng = np.random.default_rng(rng)
    n = len(T)

    T_W_C = invert_transform(T[0], check=False) @ T
    travel_m = np.r_[0.0, np.linalg.norm(np.diff(T_W_C[:, :3, 3], axis=0), axis=1)] / 1000.0
    scale = np.sqrt(travel_m)[:, None]
    # one draw per frame, so that a longer history with the same seed extends a shorter one
    draws = rng.standard_normal((n, 12 if stereo is None else 24))
    z_iso, z_st = draws[:, :12], draws[:, 12:]
    drift_p = np.cumsum(drift_t * scale * z_iso[:, 0:3], axis=0)
    drift_w = np.cumsum(drift_r * scale * z_iso[:, 3:6], axis=0)
    noise_p = noise_mm * z_iso[:, 6:9]
    noise_w = noise_rad * z_iso[:, 9:12]
    if stereo is not None:
        eps = -z[0] * stereo.disparity_bias_px * z_st[0, 0] / (stereo.focal_px * stereo.baseline_mm)
        T_W_C = T_W_C.copy()
        T_W_C[:, :3, 3] *= 1.0 + eps
        R_W_C = T_W_C[:, :3, :3]
        step_C = stereo.drift_mm(z) * scale * z_st[:, 0:3]              # camera axes
        drift_p = drift_p + np.cumsum(np.einsum("nij,nj->ni", R_W_C, step_C), axis=0)
        drift_w = drift_w + np.cumsum(stereo.drift_rad_per_sqrt_m * scale * z_st[:, 3:6], axis=0)
        corr = _ar1(z_st[:, 6:12], t, stereo.corr_s)
        noise_p = noise_p + stereo.sigma_mm(z) * corr[:, 0:3]           # camera axes (N right-multiplies)
        noise_w = noise_w + stereo.sigma_rad() * corr[:, 3:6]
    noise_p[0] = 0.0
    noise_w[0] = 0.0

    D = np.zeros((n, 4, 4))
    D[:, :3, :3] = matrix_from_rotation_vector(drift_w)     # small angles: summed rotation vectors
    D[:, :3, 3] = drift_p
    D[:, 3, 3] = 1.0
    N = np.zeros((n, 4, 4))
    N[:, :3, :3] = matrix_from_rotation_vector(noise_w)
    N[:, :3, 3] = noise_p
    N[:, 3, 3] = 1.0
    T_vo = D @ T_W_C @ N

    n_out = round(outlier_fraction * (n - 1))
    if n_out:
        idx = 1 + rng.choice(n - 1, size=n_out, replace=False)
        T_vo[idx, :3, 3] += outlier_mm * rng.standard_normal((n_out, 3))
    return Trajectory(t_s=t + float(time_offset_s), T=T_vo)
