"""Synthetic ceiling videos: a tiled ceiling seen by a fixed camera, with laser dots of a robot.

The scene of the paper's experiment (§V): a 4 m × 6 m ceiling of 60 cm × 120 cm tiles held by
thin darker T-bars, some tiles with air-conditioning vents (a dot that falls into one vanishes),
watched by a fixed 864×480 camera at 15 fps looking up at it obliquely, while a robot with one
or two vertical laser pointers drives a 2.4 m × 4.4 m rectangle.

Frames
    World frame W: the ceiling plane is Z = 0, X and Y along the T-bars in mm, origin at a grid
    corner, Z up (the floor is below, at negative Z). A robot at floor position (x, y) lights the
    ceiling point (x, y); its heading is measured counter-clockwise from +X seen from above.
Pixels
    ``(u, v)`` in pixels, u to the right, v down, **pixel-centre convention**: the centre of the
    top-left pixel is (0, 0) and the image spans [-0.5, W - 0.5] × [-0.5, H - 0.5].
    ``H_image_world`` maps ``(X, Y, 1)`` in mm to homogeneous ``(u, v, 1)``.

Rendering is vectorised: the ceiling (albedo, tile texture, T-bars, vents, vignetting) is
evaluated once with 4×4 supersampling per pixel; each frame then only scales it by the
illumination drift (a slow global gain and offset and a rotating linear gradient) and adds
seeded sensor noise in one compiled pass, then recomposes the small windows of the laser
sprites (pixel-integrated Gaussians: a saturating white core and a coloured glow, scaled by
the albedo where the laser hits, averaged over the exposure for motion blur). Frames come out
uint8 BGR, as OpenCV reads a video. Frame k is shown at time k / fps (the middle of its exposure).

Realism (all off by default; :data:`REALISTIC`, ``SceneConfig.realistic()`` and
``posekit ceiling simulate --realistic`` turn on the set in brackets; every one is a field of
:class:`SceneConfig`, a key of ``simulate --config SCENE.yaml`` and a flag of ``simulate``):

=====================  ============================================================================
``dist``               lens distortion ``[k1, k2, p1, p2, k3]`` (OpenCV's model, K of ``focal_px``,
                       principal point at the image centre) [-0.2, 0.04, 0.0008, -0.0006, 0]. Every
                       pixel of the ceiling, every dot and every calibration point goes through the
                       lens; ``H_image_world`` (:func:`~.scene_geometry.true_homography`) maps *undistorted*
                       pixels; ``camera.json`` (:func:`~.scene_geometry.lens_camera`) holds the lens. Pixels no ray reaches
                       (beyond the polynomial's fold) are black.
``bloom``              a saturated dot bleeding: a wider white core and a halo of the laser's colour
                       of ``bloom_sigma_px`` [1]
``exposure_step_s``    auto-exposure steps: the exposure (scene and laser) jumps by 40-100 % of
                       ``exposure_step_gain`` about every this many seconds [8 s, ±0.3]
``occluders``          people crossing the view (dark soft ellipses, once per
                       ``occluder_period_s``); the dot behind one is invisible: ``red_visible`` 0 [1]
``shadows``            soft shadows drifting over the ceiling (room light down to ~55 %) [2]
``stray_lights``       steady red LEDs fixed on the ceiling, red but not white-saturated [1]
``blinking_lights``    the same, blinking with ``blink_period_s`` (half on) [1]
``reflections``        specular glints of lamps: white, saturated, flickering slightly [2]
``stray_light_xy_mm``  extra steady red LEDs at chosen ceiling points, e.g. beside a vent [none]
``codec``              video compression: ``mjpg`` (quality 95), ``mp4v`` (MPEG-4 Part 2, what
                       OpenCV's FFmpeg writes here), ``xvid``; ``h264`` where an encoder exists
                       (here: none, a one-line error) [mp4v]
``noise_std``          sensor noise [3 grey levels]
=====================  ============================================================================

Stray lights stay at least 250 mm from the robot's path; ``stray_lights.csv`` lists them
(``kind,x,y,u,v,period_s,phase_s``). Effects are drawn from ``seed`` (:mod:`posekit.ceiling.sim.effects`).
The dotted line of §III-C is ``dots=("line",)`` with ``line_pattern="dotted"``: ``line_dots``
dots spread over ``line_length_mm``.

The camera and the robot's path are :mod:`~posekit.ceiling.sim.scene_geometry`; the video file and
its truth, calibration-points and stray-light files are written by :mod:`~posekit.ceiling.sim.video`.
"""


from __future__ import annotations

import functools
import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from ._kernels import (
    NOISE_LUT_BITS,
    albedo_params,
    compose,
    compose_shaded,
    noise_lut,
    render_albedo,
)
from ._kernels import ceiling_albedo as _ceiling_albedo
from .config import NOMINAL_TILE_ALBEDO, SceneConfig
from .effects import LIGHT_APPEARANCE, exposure_at, exposure_levels, occluders, shadows, stray_lights
from .scene_geometry import _apply_h, _camera, lens_camera, robot_path, true_homography

__all__ = ["LASER_APPEARANCE", "CeilingScene", "SceneTruth", "iter_frames"]

#: Laser appearance per colour: (core amplitude B, G, R), (glow amplitude B, G, R), in grey
#: levels on a tile of the nominal albedo. The core saturates all channels (a laser dot looks
#: white in its centre); the glow carries the laser's colour.
LASER_APPEARANCE = {
    "red": ((160.0, 170.0, 500.0), (6.0, 8.0, 120.0)),
    "green": ((200.0, 500.0, 150.0), (40.0, 130.0, 15.0)),
}

_NOMINAL_TILE_ALBEDO = NOMINAL_TILE_ALBEDO
_EXPOSURE_LEVEL = 205.0            # grey level of albedo 1 at gain 1
_CEILING_TINT_BGR = (0.95, 1.0, 1.03)
_SUPERSAMPLE = 4
_SPRITE_HALF_PX = 10               # half-size of the window a dot sprite is drawn in
_BLUR_SUBSAMPLES = 5

# --- the ceiling ------------------------------------------------------------------------------

def _background(config: SceneConfig) -> np.ndarray:
    """Linear radiance of the ceiling at gain 1, shape (H, W, 3) float32, grey levels (BGR)."""
    return _background_cached(replace(config, **_NOT_BACKGROUND))


#: Fields that do not change the background (reset so that such configs share one rendering).
_NOT_BACKGROUND = dict(seed=0, duration_s=0.0, fps=15.0, dots=("red",), laser_gain=1.0, noise_std=0.0,
                       stray_light_xy_mm=(),
                       motion_blur=False, path_phase_s=0.0, drift_gain=0.0, drift_offset=0.0, gradient=0.0,
                       bloom=0.0, exposure_step_s=0.0, occluders=0, shadows=0, stray_lights=0, blinking_lights=0,
                       reflections=0, codec="mjpg", line_pattern="solid")


@functools.lru_cache(maxsize=8)
def _background_cached(config: SceneConfig) -> np.ndarray:
    H_world_image = np.linalg.inv(true_homography(config))
    h, w = config.height_px, config.width_px
    p, holes, seed = albedo_params(config)
    K, _, _ = _camera(config)
    albedo = render_albedo(H_world_image, h, w, _SUPERSAMPLE, p, holes, seed, K, np.asarray(config.dist, float))
    vv, uu = np.mgrid[0:h, 0:w]
    r2 = ((uu - (w - 1) / 2) ** 2 + (vv - (h - 1) / 2) ** 2) / (((w - 1) / 2) ** 2 + ((h - 1) / 2) ** 2)
    radiance = albedo * (1.0 - config.vignetting * r2) * _EXPOSURE_LEVEL
    bg = (radiance[:, :, None] * np.asarray(_CEILING_TINT_BGR)[None, None, :]).astype(np.float32)
    bg.setflags(write=False)
    return bg


@dataclass(frozen=True)
class SceneTruth:
    """Ground truth per frame. Arrays have a leading frame axis of length N.

    ``xy_red`` and ``xy_green`` are in W, mm (``xy_green`` is the second laser, whatever its
    colour; NaN with one dot); ``uv_*`` their projections in px (pixel-centre convention);
    ``heading_rad`` the robot's heading (direction from the first to the second dot), wrapped
    to (-π, π]; ``visible`` (N, 2) bool (column 1 False with one dot).
    """

    frame: np.ndarray
    time_s: np.ndarray
    xy_red: np.ndarray
    xy_green: np.ndarray
    uv_red: np.ndarray
    uv_green: np.ndarray
    heading_rad: np.ndarray
    visible: np.ndarray


class CeilingScene:
    """A rendered ceiling: precomputed background, truth, and frames on demand.

    Frame k is rendered from its own generator ``np.random.default_rng([seed, k])``, so any
    frame can be rendered alone and the same config always gives the same pixels.
    """

    def __init__(self, config: SceneConfig):
        self.config = config
        self.H_image_world = true_homography(config)
        self.H_world_image = np.linalg.inv(self.H_image_world)
        self.camera = lens_camera(config)
        self._bg = _background(config)
        h, w = config.height_px, config.width_px
        self._xn = ((np.arange(w) - (w - 1) / 2) / ((w - 1) / 2)).astype(np.float32)
        self._yn = ((np.arange(h) - (h - 1) / 2) / ((h - 1) / 2)).astype(np.float32)
        lap = np.linspace(0.0, 600.0, 6001)                           # the path, densely (every 0.1 s)
        self.lights = stray_lights(config, self.project, robot_path(replace(config, path_phase_s=0.0), lap)[0])
        self.occluders = occluders(config)
        self.shadows = shadows(config)
        self._exposure = exposure_levels(config)

    def exposure(self, t: float) -> float:
        """Auto-exposure level at time ``t`` s (1 without exposure steps)."""
        return exposure_at(*self._exposure, t)

    def occluded(self, t: float, uv) -> bool:
        """Whether image point ``uv`` (2,) px is hidden by an occluder at time ``t``."""
        return any(o.covers(t, uv) for o in self.occluders)

    @property
    def n_frames(self) -> int:
        return self.config.n_frames

    def project(self, xy) -> np.ndarray:
        """Image positions (..., 2) in px of ceiling points ``xy`` (..., 2) in mm, in the real
        (distorted) image."""
        uv = _apply_h(self.H_image_world, xy)
        if not self.camera.is_distorted:
            return uv
        shape = uv.shape
        return self.camera.distort_points(uv.reshape(-1, 2)).reshape(shape)

    def reference_image(self) -> np.ndarray:
        """The ceiling without dots at nominal illumination, noiseless, uint8 (H, W, 3) BGR."""
        return np.clip(np.rint(self._bg), 0, 255).astype(np.uint8)

    def calibration_points(self, margin_px: float = 10.0) -> np.ndarray:
        """Grid corners (T-bar crossings) in view, shape (n, 4): ``X, Y`` in mm, ``u, v`` in px."""
        c = self.config
        xs = np.arange(0.0, c.ceiling_size_mm[0] + 1e-6, c.tile_size_mm[0])
        ys = np.arange(0.0, c.ceiling_size_mm[1] + 1e-6, c.tile_size_mm[1])
        XY = np.stack(np.meshgrid(xs, ys), -1).reshape(-1, 2)
        uv = self.project(XY)
        ok = ((uv[:, 0] >= margin_px) & (uv[:, 0] <= c.width_px - 1 - margin_px)
              & (uv[:, 1] >= margin_px) & (uv[:, 1] <= c.height_px - 1 - margin_px))
        return np.column_stack([XY[ok], uv[ok]])

    def truth(self) -> SceneTruth:
        c = self.config
        n = c.n_frames
        t = np.arange(n) / c.fps
        xy, heading = robot_path(c, t)
        two = len(c.dots) == 2
        xy2 = xy + c.dot_spacing_mm * np.column_stack([np.cos(heading), np.sin(heading)])
        if not two:
            xy2 = np.full_like(xy, np.nan)
        vis = np.column_stack([self._visible(xy), self._visible(xy2) if two else np.zeros(n, bool)])
        uv, uv2 = self.project(xy), self.project(xy2)
        if self.occluders:
            for k in range(n):
                vis[k, 0] &= not self.occluded(t[k], uv[k])
                vis[k, 1] &= not self.occluded(t[k], uv2[k])
        return SceneTruth(frame=np.arange(n), time_s=t, xy_red=xy, xy_green=xy2, uv_red=uv,
                          uv_green=uv2, heading_rad=np.angle(np.exp(1j * heading)), visible=vis)

    def _visible(self, xy: np.ndarray) -> np.ndarray:
        _, reflects, _ = _ceiling_albedo(self.config, xy[:, 0], xy[:, 1], texture=False)
        uv = self.project(xy)
        c = self.config
        in_view = (uv[:, 0] >= 0) & (uv[:, 0] <= c.width_px - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= c.height_px - 1)
        return reflects & in_view

    # -- frames --
    def render_frame(self, k: int) -> np.ndarray:
        """Frame ``k`` (time k / fps), uint8 (H, W, 3) BGR."""
        c = self.config
        t = k / c.fps
        rng = np.random.default_rng([c.seed, k])
        e = self.exposure(t)
        g = e * (1.0 + c.drift_gain * math.sin(2 * math.pi * t / c.drift_period_s))
        off = c.drift_offset * math.sin(2 * math.pi * t / (0.7 * c.drift_period_s) + 1.0)
        th = 2 * math.pi * t / c.gradient_period_s
        gain_rows = (g * c.gradient * math.sin(th)) * self._yn
        gain_cols = g + (g * c.gradient * math.cos(th)) * self._xn
        n = self._bg.size
        bits = rng.bit_generator.random_raw((n + 3) // 4).view(np.uint16)[:n] if c.noise_std > 0 \
            else np.full(n, 1 << (NOISE_LUT_BITS - 1), np.uint16)
        sigma = np.float32(c.noise_std)
        out = np.empty(self._bg.shape, np.uint8)
        shade = self._shade(t)
        if shade is None:
            compose(self._bg, gain_rows.astype(np.float32), gain_cols.astype(np.float32), np.float32(off),
                    bits, noise_lut(), sigma, out)
        else:
            compose_shaded(self._bg, shade, gain_rows.astype(np.float32), gain_cols.astype(np.float32),
                           np.float32(off), bits, noise_lut(), sigma, out)
        sprites = self._sprites(t) + self._light_sprites(t)
        if sprites:
            bits3 = bits.reshape(self._bg.shape)
            for (r0, r1, c0, c1), add in sprites:
                gain = (gain_rows[r0:r1, None] + gain_cols[None, c0:c1])[..., None]
                if shade is not None:
                    gain = gain * shade[r0:r1, c0:c1, None]
                noise = sigma * noise_lut()[bits3[r0:r1, c0:c1]]
                val = self._bg[r0:r1, c0:c1] * gain + off + noise + add * e
                # sprites may overlap (two dots, a lamp): add this one to what is there
                prev = out[r0:r1, c0:c1].astype(np.float32) - (self._bg[r0:r1, c0:c1] * gain + off + noise)
                val = val + np.maximum(prev, 0.0) * (prev > 1.0)
                out[r0:r1, c0:c1] = np.clip(np.rint(val), 0, 255).astype(np.uint8)
        self._occlude(t, out, rng)
        return out

    def _shade(self, t: float) -> np.ndarray | None:
        """Light factor (H, W) float32 of the shadows at time ``t``, or None without shadows."""
        if not self.shadows:
            return None
        c = self.config
        rows, cols = np.arange(c.height_px, dtype=np.float32), np.arange(c.width_px, dtype=np.float32)
        shade = np.ones((c.height_px, c.width_px), np.float32)
        for s in self.shadows:
            shade *= s.factor(t, rows, cols)
        return shade

    def _occlude(self, t: float, out: np.ndarray, rng) -> None:
        """Draw the occluders in view at time ``t`` over ``out`` (in place)."""
        c = self.config
        for o in self.occluders:
            cen = o.centre(t)
            if cen is None:
                continue
            a, b = o.axes_px
            r0, r1 = max(int(cen[1] - 1.1 * b), 0), min(int(cen[1] + 1.1 * b) + 1, c.height_px)
            c0, c1 = max(int(cen[0] - 1.1 * a), 0), min(int(cen[0] + 1.1 * a) + 1, c.width_px)
            if r0 >= r1 or c0 >= c1:
                continue
            alpha = o.alpha(t, np.arange(r0, r1), np.arange(c0, c1))[..., None]
            dark = o.grey * self.exposure(t) + c.noise_std * rng.standard_normal((r1 - r0, c1 - c0, 1))
            win = out[r0:r1, c0:c1].astype(np.float32)
            out[r0:r1, c0:c1] = np.clip(np.rint(win * (1 - alpha) + dark * alpha), 0, 255).astype(np.uint8)

    def _light_sprites(self, t: float) -> list:
        """Windows and added radiance of the stray lights on at time ``t``."""
        out = []
        c = self.config
        for light in self.lights:
            f = light.intensity(t)
            if f <= 0:
                continue
            core, s_core, glow, s_glow = LIGHT_APPEARANCE[light.kind]
            half = int(math.ceil(3.5 * s_glow))
            u, v = light.uv
            r0, c0 = int(round(v)) - half, int(round(u)) - half
            r0c, c0c = max(r0, 0), max(c0, 0)
            r1c, c1c = min(r0 + 2 * half + 1, c.height_px), min(c0 + 2 * half + 1, c.width_px)
            if r0c >= r1c or c0c >= c1c:
                continue
            rows, cols = np.arange(r0c, r1c), np.arange(c0c, c1c)
            add = np.zeros((r1c - r0c, c1c - c0c, 3))
            for sigma, amp in ((s_core, core), (s_glow, glow)):
                prof = np.outer(_pixel_gauss(rows, v, sigma), _pixel_gauss(cols, u, sigma)) * 2 * math.pi * sigma ** 2
                add += prof[..., None] * np.asarray(amp)
            out.append(((r0c, r1c, c0c, c1c), (f * add).astype(np.float32)))
        return out

    def frames(self, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
        """Frames ``start .. stop - 1`` (default: the whole video), uint8 (H, W, 3) BGR."""
        stop = self.n_frames if stop is None else stop
        for k in range(start, stop):
            yield self.render_frame(k)

    def _laser_points(self, t: np.ndarray) -> list[tuple[str, np.ndarray]]:
        """(colour, world points (len(t), 2)) of each laser at times t; for a line, its end points."""
        c = self.config
        xy, heading = robot_path(c, t)
        d = np.column_stack([np.cos(heading), np.sin(heading)])
        if c.dots == ("line",):
            if c.line_pattern == "dotted":                 # §III-C's dot line: line_dots dots over the length
                offsets = np.linspace(-0.5, 0.5, c.line_dots) * c.line_length_mm
                return [("red", xy + s * d) for s in offsets]
            half = 0.5 * c.line_length_mm * d
            return [("line", np.stack([xy - half, xy + half], 1))]
        pts = [(c.dots[0], xy)]
        if len(c.dots) == 2:
            pts.append((c.dots[1], xy + c.dot_spacing_mm * d))
        return pts

    def _sprites(self, t: float) -> list[tuple[tuple[int, int, int, int], np.ndarray]]:
        c = self.config
        m = _BLUR_SUBSAMPLES if (c.motion_blur and c.exposure_s > 0) else 1
        ts = t + (np.linspace(-0.5, 0.5, m) * c.exposure_s if m > 1 else np.zeros(1))
        out = []
        for color, pts in self._laser_points(ts):
            if color == "line":
                out += self._line_sprite(pts)
                continue
            mid = pts[m // 2]
            albedo, reflects, _ = _ceiling_albedo(c, mid[:1], mid[1:])
            if not reflects[0]:
                continue
            uv = self.project(pts)                                   # (m, 2)
            uc = uv[m // 2]
            half = max(_SPRITE_HALF_PX, int(math.ceil(3.5 * c.bloom_sigma_px))) if c.bloom > 0 else _SPRITE_HALF_PX
            r0, c0 = int(round(uc[1])) - half, int(round(uc[0])) - half
            r1, c1 = r0 + 2 * half + 1, c0 + 2 * half + 1
            r0c, c0c, r1c, c1c = max(r0, 0), max(c0, 0), min(r1, c.height_px), min(c1, c.width_px)
            if r0c >= r1c or c0c >= c1c:
                continue
            core, glow = LASER_APPEARANCE[color]
            add = np.zeros((r1c - r0c, c1c - c0c, 3))
            rows, cols = np.arange(r0c, r1c), np.arange(c0c, c1c)
            layers = [(c.core_sigma_px, core), (c.glow_sigma_px, glow)]
            if c.bloom > 0:
                # blooming: the saturated core spreads (a wider white disc) and bleeds into a halo of
                # the laser's colour; the same energy scale as the glow
                layers = [(c.core_sigma_px * (1.0 + 0.35 * c.bloom), tuple(a * (1.0 + 0.5 * c.bloom) for a in core)),
                          (c.glow_sigma_px * (1.0 + 0.2 * c.bloom), glow),
                          (c.bloom_sigma_px, tuple(0.35 * c.bloom * a for a in glow))]
            for sigma, amp in layers:
                prof = np.zeros(add.shape[:2])
                for u, v in uv:
                    prof += np.outer(_pixel_gauss(rows, v, sigma), _pixel_gauss(cols, u, sigma))
                add += (prof / m * 2 * math.pi * sigma ** 2)[..., None] * np.asarray(amp)
            add *= c.laser_gain * albedo[0] / _NOMINAL_TILE_ALBEDO
            out.append(((r0c, r1c, c0c, c1c), add.astype(np.float32)))
        return out

    def _line_sprite(self, ends: np.ndarray) -> list:
        """A laser line segment (case C): Gaussian cross-section about the projected segment."""
        c = self.config
        mid = ends[len(ends) // 2]                                    # (2 ends, 2)
        uv = self.project(mid)
        lo = np.floor(uv.min(0)).astype(int) - _SPRITE_HALF_PX
        hi = np.ceil(uv.max(0)).astype(int) + _SPRITE_HALF_PX + 1
        c0, r0 = max(lo[0], 0), max(lo[1], 0)
        c1, r1 = min(hi[0], c.width_px), min(hi[1], c.height_px)
        if r0 >= r1 or c0 >= c1:
            return []
        vv, uu = np.mgrid[r0:r1, c0:c1].astype(float)
        # sample the segment densely in the world so the part inside a vent goes dark
        s = np.linspace(0.0, 1.0, 64)
        wp = mid[0] + s[:, None] * (mid[1] - mid[0])
        albedo, reflects, _ = _ceiling_albedo(c, wp[:, 0], wp[:, 1], texture=False)
        a, b = uv
        ab = b - a
        proj = np.clip(((uu - a[0]) * ab[0] + (vv - a[1]) * ab[1]) / max(ab @ ab, 1e-9), 0, 1)
        dist2 = (uu - a[0] - proj * ab[0]) ** 2 + (vv - a[1] - proj * ab[1]) ** 2
        lit = np.interp(proj, s, np.where(reflects, albedo, 0.0)) / _NOMINAL_TILE_ALBEDO
        core, glow = LASER_APPEARANCE["red"]
        add = np.zeros((r1 - r0, c1 - c0, 3))
        for sigma, amp in ((c.core_sigma_px, core), (c.glow_sigma_px, glow)):
            add += (0.6 * np.exp(-0.5 * dist2 / sigma ** 2) * lit)[..., None] * np.asarray(amp)
        return [((r0, r1, c0, c1), (add * c.laser_gain).astype(np.float32))]


def _pixel_gauss(centres: np.ndarray, mu: float, sigma: float) -> np.ndarray:
    """Integral of N(mu, sigma²) over the pixels [k - 0.5, k + 0.5] for k in ``centres``."""
    from scipy.special import erf  # here, not at import (see noise_lut)

    s = sigma * math.sqrt(2.0)
    return 0.5 * (erf((centres + 0.5 - mu) / s) - erf((centres - 0.5 - mu) / s))


def iter_frames(config: SceneConfig, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
    """Frames of the video in memory: uint8 arrays (H, W, 3) BGR, one per 1 / fps."""
    return CeilingScene(config).frames(start, stop)
