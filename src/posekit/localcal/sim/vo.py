"""A simulated VO/SLAM camera trajectory (the paper ran ORB-SLAM2 stereo on a ZED2).

The VO world frame W is the camera frame at the first VO pose, as ORB-SLAM2 defines it. The
estimate drifts and is noisy:

``T_W_C_vo[k] = D[k] · T_W_C[k] · N[k]``

where ``T_W_C[k] = T_B_C[0]⁻¹ T_B_C[k]`` is the true camera pose in W, ``D[k]`` a drift
transform that random-walks with the distance travelled (translation std
``drift_mm_per_sqrt_m``·√(metres), rotation std ``drift_rad_per_sqrt_m``·√(metres), about
the W axes; ``D[0] = I``) and ``N[k]`` white noise (``noise_mm`` per axis on the position,
``noise_rad`` per axis on the rotation vector; none at the first pose, which defines W). VO
runs at a lower rate than the robot (every ``stride``-th robot sample), on its own clock
(``time_offset_s`` added to the timestamps); a fraction of the frames can be gross outliers
(tracking glitches, ``outlier_mm`` per axis). The same seed with a longer history gives the
same estimates for the common prefix (without outliers), so VO can 'keep running'. The
default magnitudes are assumptions for a stereo VO at about one metre from a textured wall:
millimetre noise and drift of a few millimetres per metre travelled.
"""

import numpy as np

from posekit.errors import ConfigError, TrajectoryError
from posekit.geometry import (
    check_transform,
    invert_transform,
    matrix_from_rotation_vector,
)
from posekit.localcal.registration.tum import Trajectory

__all__ = ["VONoise", "simulate_vo"]


class VONoise:
    """Default VO error magnitudes (assumptions, see the module docs)."""

    noise_mm = 1.0
    noise_rad = np.deg2rad(0.1)
    drift_mm_per_sqrt_m = 3.0
    drift_rad_per_sqrt_m = np.deg2rad(0.2)
    stride = 3                 # robot at 100 Hz -> VO at ~33 Hz
    outlier_fraction = 0.0
    outlier_mm = 50.0


def _nonneg(value, name):
    if not (np.ndim(value) == 0 and np.isfinite(value) and value >= 0):
        raise ConfigError(f"simulate_vo: {name} must be a finite number >= 0, got {value!r}")
    return float(value)


def simulate_vo(T_B_C_true, t_s, rng, *, noise_mm: float = VONoise.noise_mm,
                noise_rad: float = VONoise.noise_rad,
                drift_mm_per_sqrt_m: float = VONoise.drift_mm_per_sqrt_m,
                drift_rad_per_sqrt_m: float = VONoise.drift_rad_per_sqrt_m,
                stride: int = VONoise.stride, time_offset_s: float = 0.0,
                outlier_fraction: float = VONoise.outlier_fraction,
                outlier_mm: float = VONoise.outlier_mm) -> Trajectory:
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
        White noise std per axis on position (mm) and rotation vector (rad).
    drift_mm_per_sqrt_m, drift_rad_per_sqrt_m : float
        Random-walk drift std per axis after one metre of travel (mm, rad).
    stride : int
        VO keeps every ``stride``-th robot sample (>= 1).
    time_offset_s : float
        Constant offset of the VO clock, s.
    outlier_fraction : float
        Fraction of frames (after the first) replaced by gross outliers, in [0, 0.5].
    outlier_mm : float
        Std per axis of an outlier's position error, mm.

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
        A negative or non-finite magnitude, ``stride < 1``, ``outlier_fraction`` out of range.
    """
    T = check_transform(T_B_C_true, name="T_B_C_true")
    t = np.asarray(t_s, dtype=np.float64)
    if T.ndim != 3 or t.shape != (len(T),):
        raise TrajectoryError(f"simulate_vo: expected poses (N, 4, 4) and times (N,), got {T.shape} and {t.shape}")
    if int(stride) != stride or stride < 1:
        raise ConfigError(f"simulate_vo: stride must be an integer >= 1, got {stride!r}")
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
    z = rng.standard_normal((n, 12))
    drift_p = np.cumsum(drift_t * scale * z[:, 0:3], axis=0)
    drift_w = np.cumsum(drift_r * scale * z[:, 3:6], axis=0)
    noise_p = noise_mm * z[:, 6:9]
    noise_w = noise_rad * z[:, 9:12]
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
