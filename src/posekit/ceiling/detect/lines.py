"""Laser line segments on ceiling images (the paper's case C), with the machinery of
:class:`~posekit.ceiling.detect.DotDetector`: the principal axis of each elongated blob of laser
colour, or a Hough transform of its centre line (``method="hough"``)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError
from ._kernels import _AREA, _ELONG, _MUU, _MUV, _MVV, _PEAK, _U, _V
from .dots import DotDetector, cv2

__all__ = ["LINE_METHODS", "Line", "LineDetector"]


@dataclass(frozen=True)
class Line:
    """A detected laser line segment (case C).

    ``u, v``: intensity-weighted centre in px (pixel-centre convention); ``angle_deg``: the
    segment's direction in the image, in [0, 180) degrees from +u towards +v (a line has no
    sense: the heading it gives is ambiguous by 180°); ``length_px``: its length estimated
    from the second moments (``sqrt(12 λ_max)``, exact for a uniform segment); ``area_px`` and
    ``peak`` as for :class:`Dot`.
    """

    color: str
    u: float
    v: float
    angle_deg: float
    length_px: float
    area_px: int
    peak: float

    def endpoints(self) -> np.ndarray:
        """The two ends (2, 2) ``[[u, v], [u, v]]`` in px, centre ∓ half the length."""
        a = math.radians(self.angle_deg)
        d = 0.5 * self.length_px * np.array([math.cos(a), math.sin(a)])
        return np.array([[self.u, self.v]]) + np.array([-d, d])


#: Ways :class:`LineDetector` measures a segment: principal axis of the blob, or Hough transform.
LINE_METHODS = ("moments", "hough")


class LineDetector(DotDetector):
    """Finds laser line segments (the paper's case C) with the machinery of :class:`DotDetector`.

    A segment on the ceiling is one elongated blob of laser colour (or two, where a vent cuts
    it). Its centre and direction are the intensity-weighted mean and principal axis of the
    background-subtracted intensity, which resolve hundredths of a pixel and of a degree where
    ``cv2.HoughLinesP`` quantises angles to its accumulator bins and ends to whole pixels
    (Hough transforms pay off for many or long lines crossing clutter, not for one short
    segment on a blank ceiling).

    Parameters
    ----------
    color : str
        Laser colour (:data:`LASER_COLORS`).
    min_elongation : float
        A blob is a segment if the ratio of its principal axes is at least this.
    min_length_px : float
        Shorter segments are dropped.
    contrast : int
        Floor of the bar (grey levels): the extent of a segment's centre line is where the light
        it adds exceeds it (25 for the paper's laser line on a lit ceiling).
    **kwargs
        Any other :class:`DotDetector` parameter (``roi_radius_px`` defaults to 48 here so a
        window holds a whole segment).
    """

    def __init__(self, color: str = "red", *, min_elongation: float = 3.0, min_length_px: float = 12.0,
                 max_area_px: int = 5000, roi_radius_px: int = 48, method: str = "moments", contrast: int = 25,
                 **kwargs):
        if method not in LINE_METHODS:
            raise ConfigError(f"LineDetector: unknown method '{method}'; expected one of {', '.join(LINE_METHODS)}")
        super().__init__((color,), max_area_px=max_area_px, roi_radius_px=roi_radius_px, contrast=contrast, **kwargs)
        self.min_elongation = float(min_elongation)
        self.min_length_px = float(min_length_px)
        self.method = method

    def detect(self, frame_bgr: np.ndarray, predicted_uv=None) -> list[Line]:
        """Segments in one frame (longest first), and the background update; see
        :meth:`DotDetector.detect`. With ``method="hough"`` each segment's direction comes
        from a standard Hough transform (``cv2.HoughLines``) of its centre line, and its
        centre and length from the extent of the centre line along that direction."""
        bg = None if self.method != "hough" or self._bg is None else self._bg.copy()
        lines = super().detect(frame_bgr, predicted_uv)
        if self.method == "hough":
            bg = self._bg if bg is None else bg
            lines = [h for h in (_hough_line(frame_bgr, bg, line, self.bar_floor) for line in lines) if h is not None]
        return sorted(lines, key=lambda line: -line.length_px)

    def _make(self, color: str, row: np.ndarray, x0: int, y0: int) -> Line | None:
        if row[_ELONG] < self.min_elongation:
            return None
        muu, mvv, muv = row[_MUU], row[_MVV], row[_MUV]
        half_tr, disc = 0.5 * (muu + mvv), math.hypot(0.5 * (muu - mvv), muv)
        length = math.sqrt(12.0 * (half_tr + disc))
        if length < self.min_length_px:
            return None
        angle = math.degrees(0.5 * math.atan2(2.0 * muv, muu - mvv)) % 180.0
        return Line(color, float(row[_U] + x0), float(row[_V] + y0), angle, length, int(row[_AREA]),
                    float(row[_PEAK]))


def _hough_line(frame, bg, line: Line, contrast: int) -> Line | None:
    """Re-measure ``line`` with a Hough transform (the paper's case C) in a window around it.

    A thick bar votes most for its diagonal, so the transform runs on the bar's centre line:
    for every pixel column (or row, for a steep bar) the intensity-weighted centre across
    the bar of the light the laser adds. ``cv2.HoughLines`` (ρ 0.25 px, θ 0.05°) on the
    rasterised centre line gives the direction; the centre line's extent along it gives the
    ends. The ±180° ambiguity is left to the tracker.
    """
    h, w = frame.shape[:2]
    r = int(0.5 * line.length_px) + 8
    x0, x1 = max(0, int(line.u) - r), min(w, int(line.u) + r + 1)
    y0, y1 = max(0, int(line.v) - r), min(h, int(line.v) + r + 1)
    added = np.clip(frame[y0:y1, x0:x1].astype(np.float32) - bg[y0:y1, x0:x1], 0, None).max(axis=2)
    added[added < contrast] = 0.0
    steep = 45.0 < line.angle_deg < 135.0
    a = added.T if steep else added                       # rows of `a` run across the bar
    wsum = a.sum(axis=0)
    cols = np.flatnonzero(wsum > 0)
    if cols.size < 4:
        return None
    centre = (a[:, cols] * np.arange(a.shape[0])[:, None]).sum(axis=0) / wsum[cols]
    pts = np.stack([cols, centre], axis=1) if not steep else np.stack([centre, cols], axis=1)   # (u, v) in window
    scale = 4                                              # rasterise the centre line at 1/4 px
    img = np.zeros(((y1 - y0) * scale, (x1 - x0) * scale), np.uint8)
    iu = np.clip(np.round(pts[:, 0] * scale).astype(int), 0, img.shape[1] - 1)
    iv = np.clip(np.round(pts[:, 1] * scale).astype(int), 0, img.shape[0] - 1)
    img[iv, iu] = 255
    found = cv2.HoughLines(img, 1.0, np.pi / 3600, max(3, cols.size // 3))
    if found is None:
        return None
    rho, theta = np.asarray(found).reshape(-1, 2)[0]
    d = np.array([-math.sin(theta), math.cos(theta)])     # direction of the Hough line (normal at θ)
    n = np.array([math.cos(theta), math.sin(theta)])
    s = pts @ d
    foot = (rho / scale) * n                               # closest point of the line to the window origin
    mid = foot + 0.5 * (s.min() + s.max()) * d - (foot @ d) * d
    angle = math.degrees(math.atan2(d[1], d[0])) % 180.0
    return Line(line.color, float(mid[0] + x0), float(mid[1] + y0), angle, float(s.max() - s.min() + 1.0),
                line.area_px, line.peak)
