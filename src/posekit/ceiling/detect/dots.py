"""Laser dot detection on ceiling images (paper §IV-B): background subtraction with a running
average that follows the illumination, colour thresholds per laser, morphological opening,
connected components gated by area and shape, and a sub-pixel intensity-weighted centroid.

Pixel convention: ``(u, v)`` in px, u to the right (column), v down (row), **pixel-centre
convention** -- the centre of the top-left pixel is (0, 0), so pixel ``[row, col]`` is at
``(u, v) = (col, row)``. This is the convention of OpenCV's point functions
(``cv2.perspectiveTransform``, ``cv2.findHomography``) and of :mod:`posekit.ceiling.sim.render`.

How a frame is processed (``DotDetector.detect``):

1. *Lit pixels.* A byte (one channel of one pixel) is lit when it exceeds the background mean
   by more than its bar ``z σ_eff``: ``z`` the one-sided normal quantile of ``alpha_pixel``
   (by default one over the bytes of a frame: about one byte of the whole frame lit by noise,
   z = 4.6 at 320×240, 4.9 at 864×480), ``σ_eff² = σ² + σ²_scene`` with σ the running standard deviation of that byte
   (grass, brick texture, compression noise, leaves in the wind raise their own bar) and
   ``σ²_scene`` the scene's median byte variance, measured once a band cycle (a byte whose own
   variance happened to come out small, on a flat or clipped patch, is not lit by the
   scene's ordinary noise). An explicit ``contrast`` is a floor on the bar. The test runs on
   the whole frame, or only in a square of side ``2 * roi_radius_px + 1`` around each
   predicted dot position (the fast path). A compiled kernel rejects a row with one
   vectorised pass and lists the lit pixels of the few rows that have any.
2. *Blobs.* Lit pixels are grouped, opened morphologically (3×3 cross) and labelled with
   ``cv2.connectedComponentsWithStats``; a blob is kept if its area is within
   ``[min_area_px, max_area_px]`` and its elongation (ratio of the principal axes) is at
   most ``max_elongation``.
3. *Colour.* The colour of a blob is that of the light it adds, ``frame - background``
   (positive part) **summed over its weighted pixels** (clipped white pixels left out: a pixel
   cut in every channel tells nothing of the colour), as hue and saturation. Per pixel, the
   colour of a small spot does not survive compression: 4:2:0 chroma (JPEG, MJPG, H.264)
   keeps one colour per 2×2 pixels and quantises it over 16×16-pixel blocks, so a 3-pixel red
   halo comes out pink or grey pixel by pixel; the sum over the spot is (nearly) the blocks'
   DC, which the codec keeps. The colour of the added light is the laser's whatever the
   ceiling's tint, which a threshold on the raw frame cannot say of a faint glow on a bright
   tile.
4. *Centroid.* In the blob's bounding box grown by ``window_margin_px``, each pixel weighs the
   sum over channels of its positive background difference minus ``weight_threshold``; the
   dot is the weighted mean of the pixel centres.
5. *What it looks like.* ``saturated``: the laser's own channel (red for a red laser) reaches
   ``core_level`` somewhere in the blob (a laser pointer drives its channel to the sensor's
   white level in a camera exposed for the room; compression leaves it within a few levels:
   measured >= 237 at JPEG quality 60). ``background_p``: the surroundings of the spot — the
   ring of ``block_px`` blocks around the blocks it lies in (a codec's blocks: the spot's own
   ringing stays inside them) — agree with the background model: the p-value of the number
   of ring pixels beyond their bar under a binomial law at the scene's own outlier rate
   (measured every frame on a sparse grid). A dot on the ceiling is light added to an
   unchanged ceiling; a tail light, a glint on a car or a red sleeve sits on something that
   is not the background.
6. *Background update.* The background is per-byte running statistics of the frame — a mean
   and a variance (float32 (H, W, 3)): each frame updates one band of ``1 / background_stride``
   of the rows (cycling, with the learning rate compounded so the time constant is that of
   updating every row every frame), in one compiled pass; outlying bytes are absorbed
   ``outlier_slowdown`` times slower (a parked object becomes background in minutes, a
   passing person does not). The caller says what the blobs are: the windows of the tracked
   dots (``protect``) are left out of the update, static lights (``absorb``) are absorbed at
   the full rate — a lamp, a cone or a glint that a test found static is part of the scene.
   People, cars and moving shadows are foreground, never a reason to rebuild.
7. *Illumination.* Once a band cycle the median ratio of the frame to the background on a
   sparse grid gives the exposure gain; a step of more than ``relight_gain`` rescales the
   background (``relights``). Only when more than ``max_lit_fraction`` of the frame is still
   lit after that is the background rebuilt from the frame (``rebuilds``: expected to stay 0
   on a steady scene; the track summary reports it).

The first frame (or the first after :meth:`DotDetector.reset`) builds the background from the
frame itself, with the pixels of laser colour (thresholds on the raw frame) and the saturated
ones replaced by a median of their neighbourhood, so a robot standing still is found at once;
an image of the ceiling without dots can be given instead (``background=``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from posekit._extras import lazy

from ...errors import ConfigError, InputFileError
from . import _kernels as K
from .background import BackgroundModel
from .spots import LASER_COLORS, Dot

cv2 = lazy("cv2", "vision", "the ceiling system (laser-dot detection)")

__all__ = ["DotDetector"]


class DotDetector(BackgroundModel):
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
    contrast : int, optional
        A floor (grey levels) on the bar by which a channel must exceed the background mean
        to be lit; None: no floor, the bar is the scene's (``alpha_pixel``).
    alpha_pixel : float, optional
        One-sided significance of a lit byte: the bar is ``z σ_eff`` with ``z`` the normal
        quantile of ``1 - alpha_pixel``. Default: one over the number of bytes of the frame
        (about one noise byte lit per frame, whatever the resolution).
    core_level : int
        The laser's own channel at or above it somewhere in a blob makes it ``saturated``.
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
    block_px : int
        Block size of the codec for the ring test (8: JPEG, MJPG, H.264 transforms).
    outlier_slowdown : float
        Outlying bytes (foreground) move the background this many times slower than inliers.
    max_lit_fraction : float
        Fraction of the frame lit (after the exposure gain was applied) above which the
        scene is taken to have changed and the background is rebuilt from the frame.
    relight_gain : float
        An exposure gain (median frame / background ratio on a sparse grid) further than this
        from 1 rescales the background.
    background : ndarray, shape (H, W, 3), optional
        An image of the ceiling without dots (uint8 BGR) to start the background from.

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

    def __init__(self, colors=("red",), *, learning_rate: float = 0.05, contrast: int | None = None,
                 alpha_pixel: float | None = None, core_level: int = 250, min_area_px: int = 5, max_area_px: int = 900,
                 max_elongation: float = 3.0, roi_radius_px: int = 24, roi_fallback: bool = True,
                 weight_threshold: float = 12.0, window_margin_px: int = 3, background_stride: int = 4,
                 max_lit_fraction: float = 0.3, background: np.ndarray | None = None, relight_gain: float = 0.08,
                 block_px: int = 8, outlier_slowdown: float = 20.0):
        colors = (colors,) if isinstance(colors, str) else tuple(colors)
        unknown = [c for c in colors if c not in LASER_COLORS]
        if not colors or unknown or len(set(colors)) != len(colors):
            raise ConfigError(f"colors: expected distinct names among {', '.join(LASER_COLORS)}, "
                              f"got {', '.join(colors) or 'nothing'}")
        if not 0.0 < learning_rate <= 1.0:
            raise ConfigError(f"learning_rate: expected a number in (0, 1], got {learning_rate}")
        if contrast is not None and not 1 <= int(contrast) <= 254:
            raise ConfigError(f"contrast: expected 1..254 grey levels, got {contrast}")
        if alpha_pixel is not None and not 0.0 < float(alpha_pixel) < 0.5:
            raise ConfigError(f"alpha_pixel: expected a probability in (0, 0.5), got {alpha_pixel}")
        if int(background_stride) < 1 or int(roi_radius_px) < 4:
            raise ConfigError("background_stride must be >= 1 and roi_radius_px >= 4")
        self.colors = colors
        self._specs = [LASER_COLORS[c] for c in colors]
        self._own = np.array([sp.channel for sp in self._specs], np.int64)
        self.learning_rate = float(learning_rate)
        self.contrast = None if contrast is None else int(contrast)
        from scipy.special import ndtri
        self._alpha_pixel = None if alpha_pixel is None else float(alpha_pixel)
        self._ndtri = ndtri
        self._z = 4.0 if alpha_pixel is None else float(ndtri(1.0 - float(alpha_pixel)))
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
        if not (0 < relight_gain < 1 and 0 < max_lit_fraction <= 1 and int(block_px) >= 1
                and float(outlier_slowdown) >= 1):
            raise ConfigError("relight_gain must be in (0, 1), max_lit_fraction in (0, 1], block_px >= 1, "
                              "outlier_slowdown >= 1")
        self.relight_gain = float(relight_gain)
        self.block_px = int(block_px)
        self.outlier_slowdown = float(outlier_slowdown)
        self._kernel = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
        self._found = []
        self.reset()
        self._initial = None if background is None else self._check_frame(background, "background").copy()

    # -- state --
    def reset(self) -> None:
        """Forget the background (the next frame starts a new one) and the frame count."""
        self._bg = None           # float32 (H, W, 3) running mean
        self._guessed = None      # uint8 (H, W): updates to come before a guessed pixel counts (ring test)
        self._var = None          # float32 (H, W, 3) running variance
        self._bg_u8 = None        # rounded background, uint8 (H, W, 3)
        self._thr = None          # min(mean + bar, 255), uint8 (H, W, 3)
        self._v_scene = 0.0       # the scene's median byte variance (grey levels²)
        self.outlier_rate = 0.0   # the scene's rate of background outliers (sparse grid, smoothed)
        self._frames = 0
        self._coords = None
        self.status = "empty"     # 'ok', 'started', 'relit', 'rebuilt'
        self.rebuilds = 0
        self.relights = 0

    def _check_frame(self, frame, name="frame") -> np.ndarray:
        frame = np.asarray(frame)
        if frame.dtype != np.uint8 or frame.ndim != 3 or frame.shape[2] != 3:
            raise InputFileError(f"{name}: expected a uint8 BGR image (H, W, 3), got {frame.dtype} {frame.shape}")
        if self._bg is not None and frame.shape != self._bg.shape:
            raise InputFileError(f"{name}: expected {self._bg.shape[1]}×{self._bg.shape[0]} like the previous "
                                 f"frames, got {frame.shape[1]}×{frame.shape[0]}")
        return np.ascontiguousarray(frame)

    @property
    def alpha_pixel(self) -> float:
        """Significance of a lit byte (one over the bytes of the frame unless given)."""
        if self._alpha_pixel is not None or self._bg is None:
            return self._alpha_pixel or 1e-6
        return 1.0 / self._bg.size

    # -- detection --
    def detect(self, frame_bgr: np.ndarray, predicted_uv=None, *, protect=None, absorb=None) -> list[Dot]:
        """Dots in one frame, and the background update.

        Parameters
        ----------
        frame_bgr : ndarray, shape (H, W, 3), uint8
            The frame, BGR as OpenCV reads it; every frame of a sequence has the same size.
        predicted_uv : None, (u, v), sequence of (u, v), or mapping colour -> (u, v)
            Where the dots are expected (px): only squares around them are searched (the fast
            path; the whole frame if one of them finds nothing and ``roi_fallback``). None, or
            a mapping without a prediction for one of ``colors``, searches the whole frame.
        protect : sequence of (u, v), optional
            Positions (px) of the tracked dots: a detected blob there is left out of this
            frame's background update (a robot that stops does not fade into the ceiling).
            Default: ``predicted_uv``'s positions; with neither, every detected blob.
        absorb : sequence of (u, v), optional
            Positions (px) of static lights (:class:`~posekit.ceiling.detect.scene.StaticLights`):
            a detected blob there is absorbed into the background at the full rate.

        Returns
        -------
        list of Dot
            In the order of ``colors``, then by decreasing ``peak``.
        """
        frame = self._check_frame(frame_bgr)
        self.status = "ok"
        self._found = []
        if self._bg is None:
            if self._initial is not None and self._initial.shape == frame.shape:
                self._set_background(self._initial)
            else:
                self._start_background(frame)
            self.status = "started"
        elif self._frames % self.background_stride == 0:    # exposure drift, the scene's noise: once a band cycle
            self._relight(frame)
            self._v_scene = float(np.median(self._var[4::16, 4::16]))
        h = frame.shape[0]
        rate = K._outlier_rate(frame, self._bg_u8, self._bar_u8, 16)
        self.outlier_rate = rate if self._frames == 0 else 0.9 * self.outlier_rate + 0.1 * rate
        dots = None
        rects = self._rois(predicted_uv, frame.shape)
        if rects:
            dots = self._search(frame, rects)
            if dots is not None and self.roi_fallback and len(dots) < len(rects):
                dots = None if self._unmatched(dots, rects) else dots
        if dots is None:
            dots = self._search(frame, [(0, h, 0, frame.shape[1])])
            if dots is None and self.status not in ("relit", "rebuilt"):   # an exposure step?
                self._relight(frame)
                dots = self._search(frame, [(0, h, 0, frame.shape[1])])
            if dots is None:                         # most of the frame lit: the scene changed
                if self.status != "rebuilt":         # (once a frame)
                    self._rebuild(frame)
                dots = self._search(frame, [(0, h, 0, frame.shape[1])]) or []
        if protect is None and predicted_uv is not None:
            protect = self._points(predicted_uv)
        self._update_background(frame, self._modes(protect, absorb))
        self._frames += 1
        return dots

    def _points(self, predicted_uv) -> list:
        if isinstance(predicted_uv, Mapping):
            return [p for p in predicted_uv.values() if p is not None]
        arr = np.asarray(predicted_uv, float)
        return [arr] if arr.ndim == 1 else list(arr)

    def _modes(self, protect, absorb) -> np.ndarray:
        """(R, 5) rows y0, y1, x0, x1, mode of the blobs' windows (grown by 8 px) for the
        background update: 1 protected (a tracked dot; every blob when the caller says nothing),
        2 absorbed (a static light); others are updated as usual."""
        rows = []
        for y0, y1, x0, x1 in dict.fromkeys(self._found):
            mode = 0
            if protect is None:
                mode = 1
            elif any(y0 - 4 <= p[1] < y1 + 4 and x0 - 4 <= p[0] < x1 + 4 for p in protect):
                mode = 1
            elif absorb is not None and any(y0 - 2 <= p[1] < y1 + 2 and x0 - 2 <= p[0] < x1 + 2 for p in absorb):
                mode = 2
            if mode:
                rows.append((y0 - 8, y1 + 8, x0 - 8, x1 + 8, mode))
        return np.array(rows, np.int64).reshape(-1, 5)

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
        self._found = []
        f2, t2 = frame.reshape(h, -1), self._thr.reshape(h, -1)
        coords = self._coords
        parts = []
        for y0, y1, x0, x1 in rects:
            n = K._lit_pixels(f2, t2, y0, y1, x0, x1, coords)
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
        table = K._blob_table(frame[y0:y1, x0:x1], self._bg[y0:y1, x0:x1], self._var[y0:y1, x0:x1], labels, stats, n,
                            self._own, self.core_level, self.window_margin_px, self.weight_threshold)
        out = []
        for k in range(1, n):
            row = table[k]
            if not (self.min_area_px <= row[K._AREA] <= self.max_area_px and np.isfinite(row[K._U])):
                continue
            c, known = self._colour(row[K._ADD_B], row[K._ADD_G], row[K._ADD_R], row[K._OWN:])
            if c is None:
                continue
            found = self._make(self.colors[c], row, x0, y0)
            if found is None:
                continue
            bx, by, bw, bh = (int(v) for v in stats[k, :4])
            box = (y0 + by, y0 + by + bh, x0 + bx, x0 + bx + bw)
            if isinstance(found, Dot):
                m = self.window_margin_px              # the spot's glow reaches past its lit blob
                n_ring, n_out = K._ring_outliers(frame, self._bg_u8, self._bar_u8, self._guessed, max(box[0] - m, 0),
                                                 box[1] + m, max(box[2] - m, 0), box[3] + m, self.block_px)
                found = replace(found, saturated=bool(row[K._OWN + c] >= self.core_level), bbox=box,
                                background_p=_binomial_sf(n_out, n_ring, self._null_rate()), colour_known=known)
            self._found.append(box)
            out.append(found)
        return out

    def _null_rate(self) -> float:
        """The rate of background outliers of a pixel on the unchanged scene: the scene's measured
        rate, at least the nominal one of three two-sided byte tests at ``alpha_pixel``."""
        return min(max(self.outlier_rate, 6.0 * self.alpha_pixel), 0.5)

    def _colour(self, b: float, g: float, r: float, own_max) -> tuple[int | None, bool]:
        """``(index in colors or None, colour known)`` of a blob: the added light (b, g, r) has
        the laser's hue and saturation (known); or, where compression and clipping left no
        colour to judge, the blob is saturated in the laser's own channel
        (``own_max[i] >= core_level``) and that channel took the largest share of the light
        (unknown: a white spot pushed to the white level carries no colour; it may continue a
        track, never start one)."""
        mx, mn = max(b, g, r), min(b, g, r)
        if mx <= 0:
            return None, False
        span = mx - mn
        sat = span / mx
        if span <= 0:
            hue = 0.0
        elif mx == r:
            hue = 60.0 * (((g - b) / span) % 6.0)
        elif mx == g:
            hue = 60.0 * ((b - r) / span + 2.0)
        else:
            hue = 60.0 * ((r - g) / span + 4.0)
        for i, sp in enumerate(self._specs):
            if sat >= sp.min_saturation and bool(sp.hue_mask(np.array(hue))):
                return i, True
        shares = (b, g, r)
        for i, sp in enumerate(self._specs):
            if own_max[i] >= self.core_level and shares[sp.channel] >= mx:
                return i, False
        return None, False

    def _make(self, color: str, row: np.ndarray, x0: int, y0: int) -> Dot | None:
        """The detection of one blob that passed the area and colour gates (None: rejected)."""
        if row[K._ELONG] > self.max_elongation:
            return None
        return Dot(color, float(row[K._U] + x0), float(row[K._V] + y0), int(row[K._AREA]), float(row[K._PEAK]),
                   noise_px=float(np.sqrt(max(row[K._VAR_UV], 0.0))), clipped_px=int(row[K._CLIPPED]))

def _binomial_sf(k: int, n: int, p: float) -> float:
    """P(X >= k) for X ~ Binomial(n, p) (1 for k <= 0)."""
    if k <= 0 or n <= 0:
        return 1.0
    from scipy.special import bdtrc
    return float(bdtrc(k - 1, n, p))


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
    grown = [[max(int(y0) - margin, 0), min(int(y1) + margin, h), max(int(x0) - margin, 0), min(int(x1) + margin, w)]
             for y0, y1, x0, x1 in boxes]
    merged = True
    while merged and len(grown) > 1:                 # overlapping windows: one window (a blob is found once)
        merged = False
        for i in range(len(grown)):
            for j in range(i + 1, len(grown)):
                a, c = grown[i], grown[j]
                if a[0] < c[1] and c[0] < a[1] and a[2] < c[3] and c[2] < a[3]:
                    grown[i] = [min(a[0], c[0]), max(a[1], c[1]), min(a[2], c[2]), max(a[3], c[3])]
                    del grown[j]
                    merged = True
                    break
            if merged:
                break
    return [tuple(g) for g in grown]
