"""Laser dot detection on ceiling images (paper §IV-B): background subtraction with a running
average that follows the illumination, colour thresholds per laser, morphological opening,
connected components gated by area and shape, and a sub-pixel intensity-weighted centroid.

Pixel convention: ``(u, v)`` in px, u to the right (column), v down (row), **pixel-centre
convention** -- the centre of the top-left pixel is (0, 0), so pixel ``[row, col]`` is at
``(u, v) = (col, row)``. This is the convention of OpenCV's point functions
(``cv2.perspectiveTransform``, ``cv2.findHomography``) and of :mod:`posekit.ceiling.render`.

How a frame is processed (``DotDetector.detect``):

1. *Lit pixels.* A byte (one channel of one pixel) is lit when it exceeds the background mean
   by ``max(contrast, k_sigma · σ)`` grey levels, σ the running standard deviation of that
   byte (grass, brick texture, compression noise, leaves in the wind raise their own bar). The test runs on the whole frame, or only in a square of side
   ``2 * roi_radius_px + 1`` around each predicted dot position (the fast path). A compiled
   kernel rejects a row with one vectorised pass and lists the lit pixels of the few rows that
   have any.
2. *Colour.* For each lit pixel the light the laser adds, ``frame - background`` (positive
   part, per channel), is converted to hue and saturation; a pixel is of a laser colour when its
   hue is in the colour's range (red wraps through 0°) and its saturation is high enough. The
   colour of the added light is the laser's whatever the ceiling's tint, which a threshold on
   the raw frame cannot say of a faint glow on a bright tile. Pixels whose three channels all
   exceed ``core_level`` are the saturated white core of a dot and take the colour of the blob
   they belong to.
3. *Blobs.* Lit pixels are grouped, opened morphologically (3×3 cross) and labelled with
   ``cv2.connectedComponentsWithStats``; a blob is kept if its area is within
   ``[min_area_px, max_area_px]``, its elongation (ratio of the principal axes) is at most
   ``max_elongation`` and enough of its pixels have one of the requested colours.
4. *Centroid.* In the blob's bounding box grown by ``window_margin_px``, each pixel weighs the
   sum over channels of its positive background difference minus ``weight_threshold``; the
   dot is the weighted mean of the pixel centres.
5. *Background update.* The background is per-byte running statistics of the frame — a mean
   and a variance (float32 (H, W, 3)): each frame updates one band of ``1 / background_stride``
   of the rows (cycling, with the learning rate compounded so the time constant is that of
   updating every row every frame); lit bytes are absorbed 20 times slower (a parked object
   becomes background in minutes, a passing person does not), the windows of the detected dots
   not at all. People, cars and moving shadows are foreground, never a reason to rebuild.
6. *Illumination.* Every frame the median ratio of the frame to the background on a sparse
   grid gives the exposure gain; a step of more than ``relight_gain`` rescales the background
   (``relights``). Only when more than ``max_lit_fraction`` of the frame is still lit after that
   is the background rebuilt from the frame (``rebuilds``: expected to stay 0 on a steady
   scene; the track summary reports it).

The first frame (or the first after :meth:`DotDetector.reset`) builds the background from the
frame itself, with the pixels of laser colour (thresholds on the raw frame) and the saturated
ones replaced by a median of their neighbourhood, so a robot standing still is found at once;
an image of the ceiling without dots can be given instead (``background=``).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from posekit._extras import lazy

from ...errors import ConfigError, InputFileError
from ._kernels import _AREA, _COUNTS, _ELONG, _PEAK, _PLAIN, _U, _V, _VAR_UV, _blob_table, _lit_pixels

cv2 = lazy("cv2", "vision", "the ceiling system (laser-dot detection)")

__all__ = ["Dot", "LaserColor", "LASER_COLORS", "DotDetector", "DotSignature"]


@dataclass(frozen=True)
class LaserColor:
    """Colour thresholds of one laser.

    ``hue_deg = (lo, hi)`` is the accepted hue range in degrees on [0, 360); ``lo > hi`` wraps
    through 0° (red). ``min_saturation`` applies to the added light (on [0, 1]);
    ``raw_min_saturation`` to the raw frame (used only to build the first background).
    """

    name: str
    hue_deg: tuple[float, float]
    min_saturation: float = 0.45
    raw_min_saturation: float = 0.18

    def hue_mask(self, hue_deg: np.ndarray) -> np.ndarray:
        lo, hi = self.hue_deg
        return (hue_deg >= lo) & (hue_deg <= hi) if lo <= hi else (hue_deg >= lo) | (hue_deg <= hi)


#: Red ~650 nm and green ~532 nm laser pointers as an RGB camera sees them. The red dot's
#: halo keeps a saturation of only ~0.3-0.45 after JPEG/H.264 4:2:0 chroma (measured on a
#: saturated dot at quality 50-90), hence its lower threshold; white lamps and glints add
#: light of saturation near 0.
LASER_COLORS = {
    "red": LaserColor("red", (330.0, 30.0), min_saturation=0.3),
    "green": LaserColor("green", (75.0, 170.0)),
}


@dataclass(frozen=True)
class Dot:
    """A detected laser dot.

    ``u, v``: sub-pixel position in px (pixel-centre convention: the top-left pixel's centre
    is (0, 0)); ``area_px``: pixels in its blob; ``peak``: the largest background difference
    in the blob, summed over the three channels (grey levels, 0-765); ``stray``: the blob is a
    static light (:class:`~posekit.ceiling.detect.scene.StaticLights`; set by the caller, never
    by the detector), so it must not start or re-acquire a track; ``saturated``: some pixel of
    the blob reaches ``core_level`` in a channel — a laser pointer is far brighter than the
    room it lights, so its core saturates a camera exposed for the room (only such blobs may
    start a track; a dim reflection or a person's red shirt does not); ``noise_px``: 1σ per
    axis of the centroid that the background's measured noise under the blob's window gives
    (px; a dot on flickering tape or a compressed, textured background moves by this much).
    """

    color: str
    u: float
    v: float
    area_px: int
    peak: float
    stray: bool = False
    saturated: bool = False
    noise_px: float = 0.0


class DotDetector:
    """Finds laser dots of the given colours in BGR frames of a fixed camera.

    Parameters
    ----------
    colors : tuple of str
        Laser colours to report, names of :data:`LASER_COLORS` (``("red",)``,
        ``("red", "green")``). Every blob of a requested colour that passes the gates is a
        dot, so two red lasers give two red dots.
    learning_rate : float
        Weight of the new frame in the running-average background, per frame (0.05: a time
        constant of 20 frames, 1.3 s at 15 fps).
    contrast : int
        Least grey levels by which a channel must exceed the background mean to be lit.
    k_sigma : float
        ... or this many running standard deviations of that byte, if more (4: a Gaussian
        byte exceeds it 3 times in 100,000).
    core_level : int
        A pixel with all three channels at or above it is a saturated dot core.
    min_area_px, max_area_px, max_elongation
        Gates on a blob (after the opening).
    roi_radius_px : int
        Half-size of the square searched around a predicted position.
    roi_fallback : bool
        Search the whole frame when the windows around the predictions find no dot for one of
        them.
    weight_threshold : float
        Subtracted from the centroid weights (summed background difference, grey levels).
    window_margin_px : int
        Growth of a blob's bounding box for the centroid window.
    background_stride : int
        The background update covers 1 / stride of the rows per frame (1: all rows).
    max_lit_fraction : float
        Fraction of the frame lit (after the exposure gain was applied) above which the
        scene is taken to have changed and the background is rebuilt from the frame.
    relight_gain : float
        An exposure gain (median frame / background ratio on a sparse grid) further than this
        from 1 rescales the background.
    background : ndarray, shape (H, W, 3), optional
        An image of the ceiling without dots (uint8 BGR) to start the background from.
    min_color_fraction : float
        A blob is of a laser colour when at least this fraction of its unsaturated pixels
        (and at least 2) have that colour (0.2: compressed video, whose 4:2:0 chroma smears
        a small dot's colour, keeps its dots; a white lamp has none).

    Attributes
    ----------
    status : str
        What the last :meth:`detect` did with the background: ``"ok"`` (updated),
        ``"started"`` (built from this frame or ``background``), ``"relit"`` (rescaled by an
        exposure step), ``"rebuilt"`` (the scene changed; rebuilt from this frame); ``"empty"``
        before the first frame.
    rebuilds, relights : int
        How many times the background was rebuilt / rescaled since :meth:`reset`.

    Examples
    --------
    >>> det = DotDetector(("red", "green"))
    >>> dots = det.detect(frame)                                   # doctest: +SKIP
    >>> dots = det.detect(next_frame, {d.color: (d.u, d.v) for d in dots})  # doctest: +SKIP
    """

    def __init__(self, colors=("red",), *, learning_rate: float = 0.05, contrast: int = 25,
                 core_level: int = 250, min_area_px: int = 8, max_area_px: int = 900,
                 max_elongation: float = 3.0, roi_radius_px: int = 24, roi_fallback: bool = True,
                 weight_threshold: float = 12.0, window_margin_px: int = 3, background_stride: int = 4,
                 max_lit_fraction: float = 0.3, background: np.ndarray | None = None,
                 min_color_fraction: float = 0.2, k_sigma: float = 4.0, relight_gain: float = 0.08):
        colors = (colors,) if isinstance(colors, str) else tuple(colors)
        unknown = [c for c in colors if c not in LASER_COLORS]
        if not colors or unknown or len(set(colors)) != len(colors):
            raise ConfigError(f"colors: expected distinct names among {', '.join(LASER_COLORS)}, "
                              f"got {', '.join(colors) or 'nothing'}")
        if not 0.0 < learning_rate <= 1.0:
            raise ConfigError(f"learning_rate: expected a number in (0, 1], got {learning_rate}")
        if not 1 <= int(contrast) <= 254:
            raise ConfigError(f"contrast: expected 1..254 grey levels, got {contrast}")
        if int(background_stride) < 1 or int(roi_radius_px) < 4:
            raise ConfigError("background_stride must be >= 1 and roi_radius_px >= 4")
        self.colors = colors
        self._specs = [LASER_COLORS[c] for c in colors]
        self._spec_table = np.array([[*sp.hue_deg, sp.min_saturation] for sp in self._specs], np.float64)
        self.learning_rate = float(learning_rate)
        self.contrast = int(contrast)
        self.core_level = int(core_level)
        self.min_area_px = int(min_area_px)
        self.max_area_px = int(max_area_px)
        self.max_elongation = float(max_elongation)
        self.roi_radius_px = int(roi_radius_px)
        self.roi_fallback = bool(roi_fallback)
        self.weight_threshold = float(weight_threshold)
        self.window_margin_px = int(window_margin_px)
        self.background_stride = int(background_stride)
        self.max_lit_fraction = float(max_lit_fraction)
        if not 0.0 < float(min_color_fraction) <= 1.0:
            raise ConfigError(f"min_color_fraction: expected a number in (0, 1], got {min_color_fraction}")
        self.min_color_fraction = float(min_color_fraction)
        if not (k_sigma >= 0 and 0 < relight_gain < 1 and 0 < max_lit_fraction <= 1):
            raise ConfigError("k_sigma must be >= 0, relight_gain in (0, 1), max_lit_fraction in (0, 1]")
        self.k_sigma = float(k_sigma)
        self.relight_gain = float(relight_gain)
        self._kernel = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
        self.reset()
        self._initial = None if background is None else self._check_frame(background, "background").copy()

    # -- state --
    def reset(self) -> None:
        """Forget the background (the next frame starts a new one) and the frame count."""
        self._bg = None           # float32 (H, W, 3) running mean
        self._var = None          # float32 (H, W, 3) running variance
        self._bg_u8 = None        # rounded background, uint8 (H, W, 3)
        self._thr = None          # min(mean + max(contrast, k_sigma σ), 255), uint8 (H, W, 3)
        self._frames = 0
        self._coords = None
        self.status = "empty"     # 'ok', 'started', 'relit', 'rebuilt'
        self.rebuilds = 0
        self.relights = 0

    @property
    def background(self) -> np.ndarray | None:
        """The current background model, float32 (H, W, 3) BGR grey levels (a copy), or None."""
        return None if self._bg is None else self._bg.copy()

    def _check_frame(self, frame, name="frame") -> np.ndarray:
        frame = np.asarray(frame)
        if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
            raise InputFileError(f"{name}: expected a uint8 BGR image (H, W, 3), got {frame.dtype} {frame.shape}")
        if self._bg is not None and frame.shape != self._bg.shape:
            raise InputFileError(f"{name}: expected {self._bg.shape[1]}×{self._bg.shape[0]} like the previous "
                                 f"frames, got {frame.shape[1]}×{frame.shape[0]}")
        return np.ascontiguousarray(frame)

    def _set_background(self, bg_u8: np.ndarray, bg_f: np.ndarray | None = None) -> None:
        self._bg = bg_u8.astype(np.float32) if bg_f is None else bg_f
        if self._var is None or self._var.shape != self._bg.shape:
            s0 = self.contrast / max(self.k_sigma, 1.0)       # until measured: the bar is ``contrast``
            self._var = np.full(self._bg.shape, s0 * s0, np.float32)
        self._bg_u8 = bg_u8.copy()
        self._thr = np.empty_like(self._bg_u8)
        self._bar_u8 = np.empty_like(self._bg_u8)
        self._bar2 = np.empty_like(self._bg)
        self._threshold_rows(0, bg_u8.shape[0])
        cap = max(256, int(self.max_lit_fraction * bg_u8.shape[0] * bg_u8.shape[1]))
        self._coords = np.empty((cap, 2), np.int32)

    def _threshold_rows(self, r0: int, r1: int) -> None:
        """The bar ``max(contrast, k σ)`` (uint8 and squared, float32) and ``thr = mean + bar``
        (uint8, saturated) for rows r0:r1."""
        h = r1 - r0
        bar = cv2.max(cv2.sqrt(self._var[r0:r1].reshape(h, -1)) * self.k_sigma, float(self.contrast))
        cv2.multiply(bar, bar, self._bar2[r0:r1].reshape(h, -1))
        cv2.convertScaleAbs(bar, self._bar_u8[r0:r1].reshape(h, -1))
        cv2.add(self._bg_u8[r0:r1].reshape(h, -1), self._bar_u8[r0:r1].reshape(h, -1), self._thr[r0:r1].reshape(h, -1))

    def _relight(self, frame: np.ndarray) -> None:
        """Exposure steps: rescale the background by the median frame/background ratio on a
        sparse grid when it is further than ``relight_gain`` from 1; rebuild when, after that,
        more than ``max_lit_fraction`` of the grid is still lit (the scene itself changed)."""
        fs = frame[4::16, 4::16].astype(np.float32)
        bs = self._bg[4::16, 4::16]
        g = np.median((fs + 1.0) / (bs + 1.0), axis=(0, 1))
        if np.all(np.abs(g - 1.0) <= self.relight_gain):
            return
        self._bg *= g.astype(np.float32)
        self._bg_u8 = cv2.convertScaleAbs(self._bg)
        self._threshold_rows(0, self._bg.shape[0])
        self.relights += 1
        self.status = "relit"
        lit = np.any(frame[4::16, 4::16] > self._thr[4::16, 4::16], axis=2)
        if lit.mean() > self.max_lit_fraction:
            self._rebuild(frame)

    def _rebuild(self, frame: np.ndarray) -> None:
        self._start_background(frame)
        self.rebuilds += 1
        self.status = "rebuilt"

    def blind_fraction(self, uv, radius_px: int = 6) -> float:
        """Fraction of the pixels within ``radius_px`` of ``uv`` (px) where no channel can exceed
        the background (every channel's bar at 255): a dot there cannot be told from the scene
        (a saturated lamp, a sunlit wall). 0 before the first frame."""
        if self._thr is None:
            return 0.0
        u, v = int(round(float(uv[0]))), int(round(float(uv[1])))
        h, w = self._thr.shape[:2]
        y0, y1, x0, x1 = max(v - radius_px, 0), min(v + radius_px + 1, h), max(u - radius_px, 0), min(u + radius_px + 1, w)
        if y0 >= y1 or x0 >= x1:
            return 0.0
        return float(np.mean(np.min(self._thr[y0:y1, x0:x1], axis=2) >= 255))

    def _start_background(self, frame: np.ndarray) -> None:
        """Background from a frame: laser-coloured and saturated pixels (raw thresholds, grown
        by the glow) replaced by the median of their neighbourhood."""
        hsv = cv2.cvtColor(frame, cv2.COLOR_BGR2HSV_FULL)
        h, s, v = hsv[..., 0].astype(np.float32) * (360.0 / 256.0), hsv[..., 1] / 255.0, hsv[..., 2]
        mask = np.all(frame >= self.core_level, axis=2)
        grey = frame.max(axis=2)
        mask |= cv2.subtract(grey, cv2.medianBlur(grey, 15)) > 2 * self.contrast   # a small bright spot
        for spec in LASER_COLORS.values():
            mask |= spec.hue_mask(h) & (s >= spec.raw_min_saturation) & (v >= 100)
        bg = frame.copy()
        if mask.any():
            mask = cv2.dilate(mask.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (11, 11))) > 0
            bg[mask] = cv2.medianBlur(frame, 21)[mask]
        self._set_background(bg)

    # -- detection --
    def detect(self, frame_bgr: np.ndarray, predicted_uv=None) -> list[Dot]:
        """Dots in one frame, and the background update.

        Parameters
        ----------
        frame_bgr : ndarray, shape (H, W, 3), uint8
            The frame, BGR as OpenCV reads it; every frame of a sequence has the same size.
        predicted_uv : None, (u, v), sequence of (u, v), or mapping colour -> (u, v)
            Where the dots are expected (px): only squares around them are searched (the fast
            path; the whole frame if one of them finds nothing and ``roi_fallback``). None, or
            a mapping without a prediction for one of ``colors``, searches the whole frame.

        Returns
        -------
        list of Dot
            In the order of ``colors``, then by decreasing ``peak``.
        """
        frame = self._check_frame(frame_bgr)
        self.status = "ok"
        self._protect = []
        if self._bg is None:
            if self._initial is not None and self._initial.shape == frame.shape:
                self._set_background(self._initial)
            else:
                self._start_background(frame)
            self.status = "started"
        elif self._frames % self.background_stride == 0:    # exposure drift: once a band cycle
            self._relight(frame)
        dots = None
        rects = self._rois(predicted_uv, frame.shape)
        if rects:
            dots = self._search(frame, rects)
            if dots is not None and self.roi_fallback and len(dots) < len(rects):
                dots = None if self._unmatched(dots, rects) else dots
        if dots is None:
            dots = self._search(frame, [(0, frame.shape[0], 0, frame.shape[1])])
            if dots is None and self.status not in ("relit", "rebuilt"):   # an exposure step?
                self._relight(frame)
                dots = self._search(frame, [(0, frame.shape[0], 0, frame.shape[1])])
            if dots is None:                         # most of the frame lit: the scene changed
                if self.status != "rebuilt":         # (once a frame)
                    self._rebuild(frame)
                dots = self._search(frame, [(0, frame.shape[0], 0, frame.shape[1])]) or []
        self._update_background(frame)
        self._frames += 1
        return dots

    def _rois(self, predicted_uv, shape) -> list[tuple[int, int, int, int]]:
        if predicted_uv is None:
            return []
        if isinstance(predicted_uv, Mapping):
            pts = [predicted_uv.get(c) for c in self.colors]
            if any(p is None for p in pts):       # a colour without a prediction: search everywhere
                return []
        else:
            arr = np.asarray(predicted_uv, float)
            pts = [arr] if arr.ndim == 1 else list(arr)
        rects = []
        r = self.roi_radius_px
        for p in pts:
            p = np.asarray(p, float).reshape(-1)
            if p.size != 2 or not np.all(np.isfinite(p)):
                raise InputFileError(f"predicted_uv: expected (u, v) pixel positions, got {predicted_uv!r}")
            u, v = int(round(p[0])), int(round(p[1]))
            y0, y1, x0, x1 = max(v - r, 0), min(v + r + 1, shape[0]), max(u - r, 0), min(u + r + 1, shape[1])
            if y0 < y1 and x0 < x1:
                rects.append((y0, y1, x0, x1))
        return rects

    @staticmethod
    def _unmatched(dots, rects) -> bool:
        """True if some window holds none of the dots."""
        for y0, y1, x0, x1 in rects:
            if not any(x0 - 0.5 <= d.u < x1 - 0.5 and y0 - 0.5 <= d.v < y1 - 0.5 for d in dots):
                return True
        return False

    def _search(self, frame: np.ndarray, rects) -> list[Dot] | None:
        """Dots in the union of ``rects`` (row0, row1, col0, col1); None if too much is lit."""
        h, w, _ = frame.shape
        self._protect = []
        f2, t2 = frame.reshape(h, -1), self._thr.reshape(h, -1)
        coords = self._coords
        parts = []
        for y0, y1, x0, x1 in rects:
            n = _lit_pixels(f2, t2, y0, y1, x0, x1, coords)
            if n > len(coords):
                return None
            if n:
                parts.append(coords[:n].copy())
        if not parts:
            return []
        pix = np.concatenate(parts) if len(parts) > 1 else parts[0]      # overlaps repeat: harmless
        dots = []
        for y0, y1, x0, x1 in _clusters(pix, h, w, self.window_margin_px + 2):
            dots += self._blobs(frame, pix, y0, y1, x0, x1)
        order = {c: i for i, c in enumerate(self.colors)}
        dots.sort(key=lambda d: (order[d.color], -d.peak, d.v, d.u))
        return dots

    def _blobs(self, frame, pix, y0, y1, x0, x1) -> list:
        sel = (pix[:, 0] >= y0) & (pix[:, 0] < y1) & (pix[:, 1] >= x0) & (pix[:, 1] < x1)
        mask = np.zeros((y1 - y0, x1 - x0), np.uint8)
        mask[pix[sel, 0] - y0, pix[sel, 1] - x0] = 1
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, self._kernel)
        n, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
        if n <= 1:
            return []
        table = _blob_table(frame[y0:y1, x0:x1], self._bg[y0:y1, x0:x1], self._var[y0:y1, x0:x1], labels, stats, n,
                            self._spec_table, self.core_level, self.window_margin_px, self.weight_threshold)
        out = []
        for k in range(1, n):
            row = table[k]
            if not (self.min_area_px <= row[_AREA] <= self.max_area_px and np.isfinite(row[_U])):
                continue
            counts = row[_COUNTS:]
            best = int(np.argmax(counts))
            if counts[best] < max(2.0, self.min_color_fraction * row[_PLAIN]):
                continue
            found = self._make(self.colors[best], row, x0, y0)
            if found is not None:
                bx, by, bw, bh = stats[k, :4]
                if isinstance(found, Dot):
                    win = frame[y0 + by:y0 + by + bh, x0 + bx:x0 + bx + bw]
                    sat = bool(win[labels[by:by + bh, bx:bx + bw] == k].max() >= self.core_level)
                    found = replace(found, saturated=sat)
                self._protect.append((y0 + by - 8, y0 + by + bh + 8, x0 + bx - 8, x0 + bx + bw + 8))
                out.append(found)
        return out

    def _make(self, color: str, row: np.ndarray, x0: int, y0: int) -> Dot | None:
        """The detection of one blob that passed the area and colour gates (None: rejected)."""
        if row[_ELONG] > self.max_elongation:
            return None
        return Dot(color, float(row[_U] + x0), float(row[_V] + y0), int(row[_AREA]), float(row[_PEAK]),
                   noise_px=float(np.sqrt(max(row[_VAR_UV], 0.0))))

    def _update_background(self, frame: np.ndarray) -> None:
        h, w, _ = frame.shape
        stride = self.background_stride
        band = self._frames % stride
        r0, r1 = band * h // stride, (band + 1) * h // stride
        if r1 <= r0:
            return
        alpha = 1.0 - (1.0 - self.learning_rate) ** stride
        keep = []
        for y0, y1, x0, x1 in self._protect:      # the detected dots are masked out of the update
            y0, y1, x0, x1 = max(y0, r0), min(y1, r1), max(x0, 0), min(x1, w)
            if y0 < y1 and x0 < x1:
                keep.append((y0, y1, x0, x1, self._bg[y0:y1, x0:x1].copy(), self._var[y0:y1, x0:x1].copy()))
        n = r1 - r0
        f = frame[r0:r1].reshape(n, -1)
        bg = self._bg[r0:r1].reshape(n, -1)
        var = self._var[r0:r1].reshape(n, -1)
        d = cv2.absdiff(f, self._bg_u8[r0:r1].reshape(n, -1))
        inlier = cv2.compare(d, self._bar_u8[r0:r1].reshape(n, -1), cv2.CMP_LE)    # |d| within the bar
        cv2.accumulateWeighted(cv2.multiply(d, d, dtype=cv2.CV_32F), var, alpha, inlier)
        cv2.accumulateWeighted(f, bg, alpha, inlier)
        # what stays becomes background, slowly; an outlier tells only that |d| exceeded the bar
        # (its squared deviation counts as the bar's square)
        outlier = cv2.bitwise_not(inlier)
        cv2.accumulateWeighted(self._bar2[r0:r1].reshape(n, -1), var, alpha / 20.0, outlier)
        cv2.accumulateWeighted(f, bg, alpha / 20.0, outlier)
        for y0, y1, x0, x1, saved, saved_var in keep:
            self._bg[y0:y1, x0:x1] = saved
            self._var[y0:y1, x0:x1] = saved_var
        cv2.convertScaleAbs(bg, self._bg_u8[r0:r1].reshape(n, -1))
        self._threshold_rows(r0, r1)


class DotSignature:
    """What the tracked laser dot looks like, learned from the dots the tracker accepted.

    The laser's brightness above the background (``peak``) and blob size (``area_px``) stay
    within a factor of a few along a track (exposure steps, vignetting), while a lamp, a
    reflection or a dim LED differ. Running means of their logarithms over the accepted dots
    (a time constant of ``memory`` acceptances) give the reference; a candidate is
    consistent with it when its peak is at least ``min_peak_ratio`` of the reference and its
    area within a factor ``area_factor``. Until ``warmup`` dots were accepted everything
    passes. Used for eligibility (starting or re-acquiring a track), never to drop a dot the
    track follows.
    """

    def __init__(self, *, memory: float = 30.0, warmup: int = 5, min_peak_ratio: float = 0.35,
                 area_factor: float = 4.0):
        self.memory, self.warmup = float(memory), int(warmup)
        self.min_peak_ratio, self.area_factor = float(min_peak_ratio), float(area_factor)
        self.n = 0
        self.log_peak = 0.0
        self.log_area = 0.0
        self.recent_area = 0.0

    def update(self, dot: Dot) -> None:
        """Learn from a dot the tracker accepted."""
        lp, la = math.log(max(dot.peak, 1.0)), math.log(max(dot.area_px, 1))
        a = 1.0 / min(self.n + 1, self.memory)
        self.log_peak += a * (lp - self.log_peak)
        self.log_area += a * (la - self.log_area)
        b = 1.0 / min(self.n + 1, 10.0)
        self.recent_area += b * (dot.area_px - self.recent_area)
        self.n += 1

    def std_px(self, dot: Dot, floor_px: float = 0.1) -> float:
        """1σ per axis of the dot's centroid, px: ``0.04 sqrt(area)`` for a blooming or blurred
        blob, or the noise the background under it gives (``dot.noise_px``), whichever is
        larger (at least ``floor_px``); for a blob smaller than the recent ones (cut by an
        occluder's edge, a vent or the image border) up to the dot's radius in proportion to
        the missing area, since the centroid of a clipped dot moves away from the cut; for a
        blob larger than the recent ones (merged with a bright thing beside it: the halo on a
        white stripe saturates on that side) by ``extra/(1 + extra)`` of the radius, the shift
        of a centroid by an added area ``extra`` times the dot's at about a radius."""
        s = max(floor_px, 0.04 * math.sqrt(max(dot.area_px, 1)), getattr(dot, "noise_px", 0.0))
        if self.n >= self.warmup and self.recent_area > 0:
            r = math.sqrt(self.recent_area / math.pi)
            missing = 1.0 - dot.area_px / self.recent_area
            if missing > 0.15:
                s = max(s, missing * r)
            extra = dot.area_px / self.recent_area - 1.0
            if extra > 0.15:                         # merged with something bright beside it
                s = max(s, extra / (1.0 + extra) * r)
        return s

    def consistent(self, dot: Dot) -> bool:
        """True if ``dot`` could be the laser that was tracked."""
        if self.n < self.warmup:
            return True
        if math.log(max(dot.peak, 1.0)) < self.log_peak + math.log(self.min_peak_ratio):
            return False
        return abs(math.log(max(dot.area_px, 1)) - self.log_area) <= math.log(self.area_factor)


def _clusters(pix: np.ndarray, h: int, w: int, margin: int, cell: int = 16) -> list[tuple[int, int, int, int]]:
    """Bounding boxes (row0, row1, col0, col1), grown by ``margin``, of groups of lit pixels
    (n, 2) (row, col); pixels closer than about a cell are in the same group."""
    r, c = pix[:, 0], pix[:, 1]
    if (r.max() - r.min()) < 4 * cell and (c.max() - c.min()) < 4 * cell:
        boxes = [(r.min(), r.max() + 1, c.min(), c.max() + 1)]
    else:
        grid = np.zeros((h // cell + 1, w // cell + 1), np.uint8)
        grid[r // cell, c // cell] = 1
        grid = cv2.dilate(grid, np.ones((3, 3), np.uint8))
        n, labels = cv2.connectedComponents(grid, connectivity=8)
        lab = labels[r // cell, c // cell]
        boxes = []
        for k in range(1, n):
            sel = lab == k
            if sel.any():
                boxes.append((r[sel].min(), r[sel].max() + 1, c[sel].min(), c[sel].max() + 1))
    return [(max(int(y0) - margin, 0), min(int(y1) + margin, h), max(int(x0) - margin, 0), min(int(x1) + margin, w))
            for y0, y1, x0, x1 in boxes]
