"""The background model of the laser-dot detector (:class:`~posekit.ceiling.detect.dots.DotDetector`):
per-byte running statistics of the scene and what the detector does with them.

* The background is a mean and a variance per byte (float32 (H, W, 3)): each frame updates one
  band of ``1 / background_stride`` of the rows (cycling, with the learning rate compounded so
  the time constant is that of updating every row every frame), in one compiled pass
  (:func:`~posekit.ceiling.detect._kernels._update_band`); outlying bytes are absorbed
  ``outlier_slowdown`` times slower (a parked object becomes background in minutes, a passing
  person does not). The windows of the tracked dots (``protect``) are left out of the update,
  static lights (``absorb``) are absorbed at the full rate.
* The bar of a byte is ``max(z sqrt(σ² + σ²_scene), contrast)``, stored as uint8 with
  ``thr = min(mean + bar, 255)``.
* Exposure steps rescale the background (``relights``); only when the scene itself changed is
  it rebuilt from the frame (``rebuilds``).
* The first background comes from a frame with its small saturated spots replaced by the median
  of their neighbourhood (a robot standing still is found at once).

A mixin: the state (``_bg``, ``_var``, ``_bg_u8``, ``_bar_u8``, ``_thr``, ``_guessed``, ...) and
the parameters are the detector's.
"""

from __future__ import annotations

import numpy as np

from posekit._extras import lazy

from . import _kernels as K

cv2 = lazy("cv2", "vision", "the ceiling system (laser-dot detection)")

__all__ = ["BackgroundModel"]


class BackgroundModel:
    """Running mean and variance of the scene per byte, the bars, relighting and rebuilding
    (mixed into :class:`~posekit.ceiling.detect.dots.DotDetector`)."""

    @property
    def background(self) -> np.ndarray | None:
        """The current background model, float32 (H, W, 3) BGR grey levels (a copy), or None."""
        return None if self._bg is None else self._bg.copy()

    def _set_background(self, bg_u8: np.ndarray, bg_f: np.ndarray | None = None) -> None:
        if getattr(self, "_guessed", None) is None or self._guessed.shape != bg_u8.shape[:2]:
            self._guessed = np.zeros(bg_u8.shape[:2], np.uint8)
        self._bg = bg_u8.astype(np.float32) if bg_f is None else bg_f
        self._z = float(self._ndtri(1.0 - self.alpha_pixel))
        if self._var is None or self._var.shape != self._bg.shape:
            # until measured frame to frame: the frame's own fine-scale noise (MAD of the
            # difference to a 3×3 median, per byte) stands for every byte's variance
            grey = cv2.absdiff(bg_u8, cv2.medianBlur(bg_u8, 3))
            s0 = max(1.4826 * float(np.median(grey)), 1.0)
            self._var = np.full(self._bg.shape, s0 * s0, np.float32)
            self._v_scene = s0 * s0
        self._bg_u8 = bg_u8.copy()
        self._thr = np.empty_like(self._bg_u8)
        self._bar_u8 = np.empty_like(self._bg_u8)
        self._threshold_rows(0, bg_u8.shape[0])
        cap = max(256, int(self.max_lit_fraction * bg_u8.shape[0] * bg_u8.shape[1]))
        self._coords = np.empty((cap, 2), np.int32)

    @property
    def bar_floor(self) -> float:
        """The smallest bar, grey levels: ``contrast`` when given, else ``z σ_scene``."""
        return float(self.contrast) if self.contrast is not None else self._z * float(np.sqrt(self._v_scene))

    def _threshold_rows(self, r0: int, r1: int) -> None:
        """The bar ``max(z sqrt(σ² + σ²_scene), contrast)`` (uint8) and ``thr = mean + bar`` (uint8,
        saturated) for rows r0:r1."""
        h = self._bg.shape[0]
        K._thresholds(self._var.reshape(h, -1), self._bg_u8.reshape(h, -1), self._bar_u8.reshape(h, -1),
                    self._thr.reshape(h, -1), r0, r1, self._z, self._v_scene, float(self.contrast or 0.0))

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
        """Background from a frame: the pixels that could be a laser dot — small spots (at most
        ``max_area_px``) where a laser's own channel is at the white level (``core_level``),
        grown by the glow — replaced by the median of their neighbourhood (a robot standing
        still is found at once; a lamp found there is absorbed once the static-light test calls
        it static; large clipped areas, a sunlit wall or the sky, stay)."""
        mask = np.zeros(frame.shape[:2], np.uint8)
        for spec in self._specs:
            clipped = (frame[..., spec.channel] >= self.core_level).astype(np.uint8)
            n, labels, stats, _ = cv2.connectedComponentsWithStats(clipped, connectivity=8)
            small = np.zeros(n, np.uint8)
            small[1:] = stats[1:, cv2.CC_STAT_AREA] <= self.max_area_px
            mask |= small[labels]
        bg = frame.copy()
        self._guessed = np.zeros(frame.shape[:2], np.uint8)
        if mask.any():
            mask = cv2.dilate(mask, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (11, 11))) > 0
            bg[mask] = cv2.medianBlur(frame, 21)[mask]
            # a guess until the running mean has had a time constant of updates there: no evidence
            # for the ring test (the median misses a grid bar or an edge under the spot)
            self._guessed[mask] = min(int(np.ceil(1.0 / self.learning_rate / self.background_stride)) + 1, 255)
        self._set_background(bg)

    def _update_background(self, frame: np.ndarray, rects: np.ndarray) -> None:
        h = frame.shape[0]
        stride = self.background_stride
        band = self._frames % stride
        r0, r1 = band * h // stride, (band + 1) * h // stride
        if r1 <= r0:
            return
        alpha = 1.0 - (1.0 - self.learning_rate) ** stride
        views = (frame.reshape(h, -1), self._bg.reshape(h, -1), self._var.reshape(h, -1), self._bg_u8.reshape(h, -1),
                 self._bar_u8.reshape(h, -1), self._thr.reshape(h, -1))
        floor = float(self.contrast or 0.0)
        K._update_band(*views, r0, r1, np.float32(alpha), np.float32(alpha / self.outlier_slowdown), self._z,
                       self._v_scene, floor, rects, False, self._guessed)
        absorb = rects[rects[:, 4] == 2]
        if len(absorb):               # static lights fade in every frame, whatever the band (no band-wise
            rest = rects.copy()       # shrinking of a lit spot, which would walk its centroid steadily)
            rest[(rest[:, 0] < r1) & (rest[:, 1] > r0) & (rest[:, 4] == 2), 4] = 1   # this band's: done above
            y0, y1 = int(max(absorb[:, 0].min(), 0)), int(min(absorb[:, 1].max(), h))
            rate = np.float32(self.learning_rate)
            K._update_band(*views, y0, y1, rate, rate, self._z, self._v_scene, floor, rest, True, self._guessed)
