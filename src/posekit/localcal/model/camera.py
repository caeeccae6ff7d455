"""The eye-in-hand camera's model: pinhole intrinsics with OpenCV lens distortion (plain data
and its projection; px, mm), and the ZED 2 at 720p that the simulator and the studies use.

Frames: C is the camera in the OpenCV optical convention (x right, y down, z along the optical
axis).
"""

from dataclasses import dataclass

import numpy as np

from posekit.errors import ConfigError

__all__ = ["CameraIntrinsics", "ZED2_720P_DISTORTION", "zed2_720p"]

#: Lens distortion ``(k1, k2, p1, p2, k3)`` of :func:`zed2_720p` with ``distorted=True``: the
#: order of magnitude of a ZED 2 left lens's factory calibration at HD720 (about -0.04 radial,
#: ~45 px at the image corners) — an assumption, not one unit's calibration.
ZED2_720P_DISTORTION = (-0.04, 0.01, 3e-4, -2e-4, -0.004)


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics with OpenCV lens distortion.

    Parameters
    ----------
    fx, fy : float
        Focal lengths, px.
    cx, cy : float
        Principal point, px (pixel centres at integer coordinates, OpenCV convention).
    width, height : int
        Image size, px.
    distortion : tuple of 5 float
        OpenCV distortion coefficients ``(k1, k2, p1, p2, k3)``; zeros for a rectified image.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int
    distortion: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)

    def __post_init__(self):
        vals = (self.fx, self.fy, self.cx, self.cy)
        if not all(np.isfinite(v) for v in vals) or self.fx <= 0 or self.fy <= 0:
            raise ConfigError(
                f"camera intrinsics: expected finite fx, fy > 0 and finite cx, cy, got {vals}"
            )
        if int(self.width) != self.width or int(self.height) != self.height or min(self.width, self.height) < 16:
            raise ConfigError(
                f"camera intrinsics: expected integer width, height >= 16 px, got {self.width}x{self.height}"
            )
        try:
            d = tuple(float(v) for v in self.distortion)
        except (TypeError, ValueError):
            d = ()
        if len(d) != 5 or not all(np.isfinite(v) and abs(v) < 10.0 for v in d):
            raise ConfigError(
                f"camera intrinsics: expected 5 finite distortion coefficients (k1, k2, p1, p2, k3) with "
                f"|value| < 10, got {self.distortion!r}"
            )
        object.__setattr__(self, "distortion", d)

    @property
    def K(self) -> np.ndarray:
        """Camera matrix, shape (3, 3), px."""
        return np.array([[self.fx, 0.0, self.cx], [0.0, self.fy, self.cy], [0.0, 0.0, 1.0]])

    @property
    def dist(self) -> np.ndarray:
        """OpenCV distortion coefficients ``(k1, k2, p1, p2, k3)``, shape (5,)."""
        return np.array(self.distortion)

    @property
    def distorted(self) -> bool:
        """True when the lens has any distortion."""
        return any(v != 0.0 for v in self.distortion)

    def distort_normalized(self, xy) -> np.ndarray:
        """OpenCV's distortion of normalized image coordinates.

        Parameters
        ----------
        xy : array_like, shape (..., 2)
            Ideal normalized coordinates ``(X/Z, Y/Z)``.

        Returns
        -------
        ndarray, shape (..., 2)
            Distorted normalized coordinates.
        """
        k1, k2, p1, p2, k3 = self.distortion
        xy = np.asarray(xy, dtype=np.float64)
        x, y = xy[..., 0], xy[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        return np.stack([x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                         y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y], axis=-1)

    def project(self, p_C, *, distort: bool = True) -> np.ndarray:
        """Pixel coordinates of points in the camera frame.

        Parameters
        ----------
        p_C : array_like, shape (..., 3)
            Points in the camera frame C, mm (z > 0 in front of the camera).
        distort : bool
            Apply the lens distortion (the pixel where the point appears); False gives the
            ideal pinhole pixel.

        Returns
        -------
        uv : ndarray, shape (..., 2)
            Pixel coordinates (u right, v down), px.
        """
        p = np.asarray(p_C, dtype=np.float64)
        xy = p[..., :2] / p[..., 2:3]
        if distort and self.distorted:
            xy = self.distort_normalized(xy)
        return np.stack([self.fx * xy[..., 0] + self.cx, self.fy * xy[..., 1] + self.cy], axis=-1)


def zed2_720p(*, distorted: bool = False) -> CameraIntrinsics:
    """Left lens of a ZED 2 stereo camera at 720p (HD720, 1280×720).

    ``fx = fy = 528 px``, ``cx = 640 px``, ``cy = 360 px``. The focal length is representative
    of the factory calibration files of ZED 2 units at HD720 (about 527–530 px, i.e. ~100° ×
    69° field of view); it is not one unit's calibration. By default the image is rectified
    (no distortion, as the ZED SDK delivers it); ``distorted=True`` gives the raw lens with
    :data:`ZED2_720P_DISTORTION`.
    """
    dist = ZED2_720P_DISTORTION if distorted else (0.0,) * 5
    return CameraIntrinsics(fx=528.0, fy=528.0, cx=640.0, cy=360.0, width=1280, height=720, distortion=dist)
