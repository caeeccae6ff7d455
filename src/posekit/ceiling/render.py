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
"""

from __future__ import annotations

import csv
import functools
import math
from collections.abc import Callable, Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
from scipy.special import erf

from .._extras import require
from ..errors import ConfigError, InputFileError
from ._render_kernels import (
    NOISE_LUT_BITS,
    albedo_params,
    compose,
    noise_lut,
    render_albedo,
)
from ._render_kernels import ceiling_albedo as _ceiling_albedo

__all__ = [
    "SceneConfig",
    "CeilingScene",
    "SceneTruth",
    "RenderedVideo",
    "true_homography",
    "robot_path",
    "iter_frames",
    "render_video",
    "DEFAULT_HOLES_MM",
    "TRUTH_HEADER",
]

#: Air-conditioning vents (openings), ``(x0, y0, x1, y1)`` in mm on the ceiling: three on the
#: default robot path (the dot vanishes while crossing them) and one off it.
DEFAULT_HOLES_MM = (
    (1500.0, 700.0, 2100.0, 1100.0),
    (300.0, 1900.0, 900.0, 2300.0),
    (3900.0, 3100.0, 4500.0, 3500.0),
    (2700.0, 1900.0, 3300.0, 2300.0),
)

#: Laser appearance per colour: (core amplitude B, G, R), (glow amplitude B, G, R), in grey
#: levels on a tile of the nominal albedo. The core saturates all channels (a laser dot looks
#: white in its centre); the glow carries the laser's colour.
LASER_APPEARANCE = {
    "red": ((160.0, 170.0, 500.0), (6.0, 8.0, 120.0)),
    "green": ((200.0, 500.0, 150.0), (40.0, 130.0, 15.0)),
}

TRUTH_HEADER = ("frame", "time_s", "x", "y", "heading_deg", "red_visible", "green_visible",
                "red_u", "red_v", "green_x", "green_y", "green_u", "green_v")

_NOMINAL_TILE_ALBEDO = 0.80
_EXPOSURE_LEVEL = 205.0            # grey level of albedo 1 at gain 1
_CEILING_TINT_BGR = (0.95, 1.0, 1.03)
_SUPERSAMPLE = 4
_SPRITE_HALF_PX = 10               # half-size of the window a dot sprite is drawn in
_BLUR_SUBSAMPLES = 5


@dataclass(frozen=True)
class SceneConfig:
    """Every parameter of a synthetic ceiling video (same config and seed, same video).

    Lengths in mm in the world frame W (ceiling plane Z = 0, Z up), times in s, angles in
    degrees (a user-facing configuration), grey levels on the 0-255 scale. ``seed`` draws the
    sensor noise; ``ceiling_seed`` the tiles' texture (the room stays the same across runs).
    """

    seed: int = 0
    ceiling_seed: int = 0
    fps: float = 15.0
    duration_s: float = 60.0
    width_px: int = 864
    height_px: int = 480
    # ceiling
    ceiling_size_mm: tuple[float, float] = (6000.0, 4000.0)
    tile_size_mm: tuple[float, float] = (1200.0, 600.0)
    tbar_width_mm: float = 15.0
    tile_albedo: float = _NOMINAL_TILE_ALBEDO
    tile_albedo_spread: float = 0.02
    tbar_albedo: float = 0.55
    holes: bool = True
    hole_rects_mm: tuple[tuple[float, float, float, float], ...] = DEFAULT_HOLES_MM
    # camera: pinhole, no distortion; x axis of the image horizontal before the roll
    camera_position_mm: tuple[float, float, float] = (3000.0, 400.0, -2300.0)
    camera_target_mm: tuple[float, float] = (3000.0, 1700.0)
    focal_px: float = 370.0
    camera_roll_deg: float = -1.5
    vignetting: float = 0.2
    # robot and lasers
    dots: tuple[str, ...] = ("red",)
    dot_spacing_mm: float = 400.0
    line_length_mm: float = 300.0
    path_rect_mm: tuple[float, float, float, float] = (800.0, 800.0, 5200.0, 3200.0)
    speed_mm_s: float = 300.0
    turn_rate_deg_s: float = 45.0
    path_phase_s: float = 0.0
    core_sigma_px: float = 0.9
    glow_sigma_px: float = 2.4
    laser_gain: float = 1.0
    # camera effects
    motion_blur: bool = True
    exposure_s: float = 1.0 / 60.0
    noise_std: float = 2.0
    drift_gain: float = 0.10
    drift_period_s: float = 90.0
    drift_offset: float = 4.0
    gradient: float = 0.06
    gradient_period_s: float = 120.0

    def __post_init__(self):
        allowed = {("red",), ("red", "green"), ("red", "red"), ("line",)}
        dots = tuple(self.dots)
        if dots not in allowed:
            raise ConfigError(f"dots: expected one of red | red,green | red,red | line, got {','.join(dots)!r}")
        object.__setattr__(self, "dots", dots)
        for name, size in (("ceiling_size_mm", 2), ("tile_size_mm", 2), ("camera_position_mm", 3),
                           ("camera_target_mm", 2), ("path_rect_mm", 4)):
            value = tuple(float(v) for v in getattr(self, name))          # lists (YAML) -> hashable tuples
            if len(value) != size:
                raise ConfigError(f"{name}: expected {size} numbers, got {len(value)}")
            object.__setattr__(self, name, value)
        holes = tuple(tuple(float(v) for v in rect) for rect in self.hole_rects_mm)
        if any(len(rect) != 4 or not (rect[2] > rect[0] and rect[3] > rect[1]) for rect in holes):
            raise ConfigError(f"hole_rects_mm: expected rectangles (x0, y0, x1, y1) with x1 > x0 and y1 > y0, got {holes}")
        object.__setattr__(self, "hole_rects_mm", holes)
        positive = {"fps": self.fps, "focal_px": self.focal_px, "speed_mm_s": self.speed_mm_s,
                    "turn_rate_deg_s": self.turn_rate_deg_s, "core_sigma_px": self.core_sigma_px,
                    "glow_sigma_px": self.glow_sigma_px, "tbar_width_mm": self.tbar_width_mm}
        for name, value in positive.items():
            if not (math.isfinite(value) and value > 0):
                raise ConfigError(f"{name}: expected a positive number, got {value}")
        if not (self.duration_s >= 0 and math.isfinite(self.duration_s)):
            raise ConfigError(f"duration_s: expected a non-negative number, got {self.duration_s}")
        if self.width_px < 32 or self.height_px < 32:
            raise ConfigError(f"image size: expected at least 32×32 px, got {self.width_px}×{self.height_px}")
        if self.noise_std < 0 or self.exposure_s < 0:
            raise ConfigError("noise_std and exposure_s must be >= 0")
        if self.camera_position_mm[2] >= 0:
            raise ConfigError(f"camera_position_mm: the camera must be below the ceiling (Z < 0), "
                              f"got Z = {self.camera_position_mm[2]}")
        x0, y0, x1, y1 = self.path_rect_mm
        if not (x1 > x0 and y1 > y0):
            raise ConfigError(f"path_rect_mm: expected (x0, y0, x1, y1) with x1 > x0 and y1 > y0, got {self.path_rect_mm}")

    @property
    def n_frames(self) -> int:
        return int(round(self.duration_s * self.fps))

    @property
    def shape(self) -> tuple[int, int, int]:
        return (self.height_px, self.width_px, 3)


# --- geometry ---------------------------------------------------------------------------------

def _camera(config: SceneConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """K (3, 3) in px, R_cam_world (3, 3), t_cam_world (3,) in mm (camera: x right, y down, z forward)."""
    C = np.asarray(config.camera_position_mm, float)
    forward = np.array([*config.camera_target_mm, 0.0]) - C
    forward /= np.linalg.norm(forward)
    x = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-9:                       # looking straight up: image x along world X
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(forward, x)
    R = np.stack([x, y, forward])
    r = math.radians(config.camera_roll_deg)
    R = np.array([[math.cos(r), -math.sin(r), 0.0], [math.sin(r), math.cos(r), 0.0], [0.0, 0.0, 1.0]]) @ R
    K = np.array([[config.focal_px, 0.0, (config.width_px - 1) / 2.0],
                  [0.0, config.focal_px, (config.height_px - 1) / 2.0],
                  [0.0, 0.0, 1.0]])
    return K, R, -R @ C


def true_homography(config: SceneConfig) -> np.ndarray:
    """H_image_world, shape (3, 3): ceiling point ``(X, Y, 1)`` in mm → image ``(u, v, 1)`` in px
    (pixel-centre convention), normalised so that ``H[2, 2] == 1``."""
    K, R, t = _camera(config)
    H = K @ np.column_stack([R[:, 0], R[:, 1], t])
    return H / H[2, 2]


def _apply_h(H: np.ndarray, p: np.ndarray) -> np.ndarray:
    p = np.asarray(p, float)
    q = p @ H[:, :2].T + H[:, 2]
    return q[..., :2] / q[..., 2:3]


def robot_path(config: SceneConfig, t_s) -> tuple[np.ndarray, np.ndarray]:
    """Pose of the robot at times ``t_s`` (shape (N,), s) on the rectangle, counter-clockwise.

    The robot drives each side at ``speed_mm_s`` and turns on the spot by +90° at each corner
    at ``turn_rate_deg_s``, starting at corner (x0, y0) heading +X (at ``path_phase_s``).

    Returns
    -------
    xy : ndarray, shape (N, 2)
        Position of the robot's reference point (the red laser) in W, mm.
    heading : ndarray, shape (N,)
        Heading in rad, counter-clockwise from +X seen from above, unwrapped (continuous).
    """
    t = np.asarray(t_s, float) + config.path_phase_s
    x0, y0, x1, y1 = config.path_rect_mm
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)
    lengths = np.array([x1 - x0, y1 - y0, x1 - x0, y1 - y0])
    t_drive = lengths / config.speed_mm_s
    t_turn = (math.pi / 2) / math.radians(config.turn_rate_deg_s)
    durations = np.ravel(np.column_stack([t_drive, np.full(4, t_turn)]))    # drive, turn, ...
    starts = np.concatenate([[0.0], np.cumsum(durations)])
    lap = starts[-1]
    laps, tau = np.divmod(t, lap)
    phase = np.clip(np.searchsorted(starts, tau, side="right") - 1, 0, 7)
    side = phase // 2
    frac = np.clip((tau - starts[phase]) / durations[phase], 0.0, 1.0)
    driving = phase % 2 == 0
    a, b = corners[side], corners[(side + 1) % 4]
    xy = np.where(driving[:, None], a + (b - a) * frac[:, None], b)
    heading = (laps * 4 + side + np.where(driving, 0.0, frac)) * (math.pi / 2)
    return xy, heading


def _background(config: SceneConfig) -> np.ndarray:
    """Linear radiance of the ceiling at gain 1, shape (H, W, 3) float32, grey levels (BGR)."""
    return _background_cached(replace(config, **_NOT_BACKGROUND))


#: Fields that do not change the background (reset so that such configs share one rendering).
_NOT_BACKGROUND = dict(seed=0, duration_s=0.0, fps=15.0, dots=("red",), laser_gain=1.0, noise_std=0.0,
                       motion_blur=False, path_phase_s=0.0, drift_gain=0.0, drift_offset=0.0, gradient=0.0)


@functools.lru_cache(maxsize=8)
def _background_cached(config: SceneConfig) -> np.ndarray:
    H_world_image = np.linalg.inv(true_homography(config))
    h, w = config.height_px, config.width_px
    p, holes, seed = albedo_params(config)
    albedo = render_albedo(H_world_image, h, w, _SUPERSAMPLE, p, holes, seed)
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


@dataclass(frozen=True)
class RenderedVideo:
    """Paths written by :func:`render_video`."""

    video: Path
    truth: Path
    calibration_points: Path
    reference: Path
    frames_dir: Path | None
    n_frames: int


class CeilingScene:
    """A rendered ceiling: precomputed background, truth, and frames on demand.

    Frame k is rendered from its own generator ``np.random.default_rng([seed, k])``, so any
    frame can be rendered alone and the same config always gives the same pixels.
    """

    def __init__(self, config: SceneConfig):
        self.config = config
        self.H_image_world = true_homography(config)
        self.H_world_image = np.linalg.inv(self.H_image_world)
        self._bg = _background(config)
        h, w = config.height_px, config.width_px
        self._xn = ((np.arange(w) - (w - 1) / 2) / ((w - 1) / 2)).astype(np.float32)
        self._yn = ((np.arange(h) - (h - 1) / 2) / ((h - 1) / 2)).astype(np.float32)

    @property
    def n_frames(self) -> int:
        return self.config.n_frames

    def project(self, xy) -> np.ndarray:
        """Image positions (..., 2) in px of ceiling points ``xy`` (..., 2) in mm."""
        return _apply_h(self.H_image_world, xy)

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
        return SceneTruth(frame=np.arange(n), time_s=t, xy_red=xy, xy_green=xy2, uv_red=self.project(xy),
                          uv_green=self.project(xy2), heading_rad=np.angle(np.exp(1j * heading)), visible=vis)

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
        g = 1.0 + c.drift_gain * math.sin(2 * math.pi * t / c.drift_period_s)
        off = c.drift_offset * math.sin(2 * math.pi * t / (0.7 * c.drift_period_s) + 1.0)
        th = 2 * math.pi * t / c.gradient_period_s
        gain_rows = (g * c.gradient * math.sin(th)) * self._yn
        gain_cols = g + (g * c.gradient * math.cos(th)) * self._xn
        n = self._bg.size
        bits = rng.bit_generator.random_raw((n + 3) // 4).view(np.uint16)[:n] if c.noise_std > 0 \
            else np.full(n, 1 << (NOISE_LUT_BITS - 1), np.uint16)
        sigma = np.float32(c.noise_std)
        out = np.empty(self._bg.shape, np.uint8)
        compose(self._bg, gain_rows.astype(np.float32), gain_cols.astype(np.float32), np.float32(off),
                 bits, noise_lut(), sigma, out)
        sprites = self._sprites(t)
        if sprites:
            bits3 = bits.reshape(self._bg.shape)
            for (r0, r1, c0, c1), add in sprites:
                gain = (gain_rows[r0:r1, None] + gain_cols[None, c0:c1])[..., None]
                noise = sigma * noise_lut()[bits3[r0:r1, c0:c1]]
                val = self._bg[r0:r1, c0:c1] * gain + off + noise + add
                out[r0:r1, c0:c1] = np.clip(np.rint(val), 0, 255).astype(np.uint8)
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
            r0, c0 = int(round(uc[1])) - _SPRITE_HALF_PX, int(round(uc[0])) - _SPRITE_HALF_PX
            r1, c1 = r0 + 2 * _SPRITE_HALF_PX + 1, c0 + 2 * _SPRITE_HALF_PX + 1
            r0c, c0c, r1c, c1c = max(r0, 0), max(c0, 0), min(r1, c.height_px), min(c1, c.width_px)
            if r0c >= r1c or c0c >= c1c:
                continue
            core, glow = LASER_APPEARANCE[color]
            add = np.zeros((r1c - r0c, c1c - c0c, 3))
            rows, cols = np.arange(r0c, r1c), np.arange(c0c, c1c)
            for sigma, amp in ((c.core_sigma_px, core), (c.glow_sigma_px, glow)):
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
    s = sigma * math.sqrt(2.0)
    return 0.5 * (erf((centres + 0.5 - mu) / s) - erf((centres - 0.5 - mu) / s))


def iter_frames(config: SceneConfig, start: int = 0, stop: int | None = None) -> Iterator[np.ndarray]:
    """Frames of the video in memory: uint8 arrays (H, W, 3) BGR, one per 1 / fps."""
    return CeilingScene(config).frames(start, stop)


# --- files ------------------------------------------------------------------------------------

def write_truth_csv(path: Path, truth: SceneTruth) -> None:
    """``truth.csv``: the columns of :data:`TRUTH_HEADER`; x, y, green_x, green_y in mm,
    heading_deg from the first to the second dot (the robot's heading with one dot), u, v in px;
    ``green_*`` empty when there is no second dot."""
    two = not np.all(np.isnan(truth.xy_green))

    def fmt(value, spec):
        return "" if not np.isfinite(value) else format(value, spec)

    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(TRUTH_HEADER)
        for k in range(len(truth.frame)):
            x, y = truth.xy_red[k]
            gx, gy = truth.xy_green[k]
            w.writerow([int(truth.frame[k]), f"{truth.time_s[k]:.6f}", f"{x:.3f}", f"{y:.3f}",
                        f"{math.degrees(truth.heading_rad[k]):.4f}", int(truth.visible[k, 0]),
                        int(truth.visible[k, 1]) if two else "",
                        f"{truth.uv_red[k, 0]:.4f}", f"{truth.uv_red[k, 1]:.4f}",
                        fmt(gx, ".3f"), fmt(gy, ".3f"), fmt(truth.uv_green[k, 0], ".4f"),
                        fmt(truth.uv_green[k, 1], ".4f")])


def write_calibration_csv(path: Path, points: np.ndarray) -> None:
    """``X,Y,u,v`` per line (the calibration-points CSV of :mod:`posekit.ceiling.calibration`), mm and px."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["X", "Y", "u", "v"])
        for X, Y, u, v in points:
            w.writerow([f"{X:.3f}", f"{Y:.3f}", f"{u:.4f}", f"{v:.4f}"])


def render_video(config: SceneConfig, out_dir, *, frames_png: bool = False,
                 progress: Callable | None = None) -> RenderedVideo:
    """Render the video of ``config`` into ``out_dir`` (created if needed).

    Writes ``video.avi`` (Motion-JPEG, ``fps`` frames per second), ``truth.csv``,
    ``calibration_points.csv`` (every grid corner in view, at least 18), ``reference.png``
    (the ceiling without dots) and, with ``frames_png``, ``frames/000000.png`` ... (lossless).
    ``progress`` wraps the frame iterator (a progress bar), if given.
    """
    cv2 = require("cv2", "vision", "the ceiling video renderer")

    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputFileError(f"{out}: cannot create the output folder ({exc.strerror})") from None
    scene = CeilingScene(config)
    points = scene.calibration_points()
    if len(points) < 18:
        raise ConfigError(f"camera sees only {len(points)} grid corners (calibration needs at least 18): "
                          "widen the view (focal_px) or move the camera")
    paths = RenderedVideo(video=out / "video.avi", truth=out / "truth.csv",
                          calibration_points=out / "calibration_points.csv", reference=out / "reference.png",
                          frames_dir=(out / "frames") if frames_png else None, n_frames=scene.n_frames)
    write_calibration_csv(paths.calibration_points, points)
    write_truth_csv(paths.truth, scene.truth())
    cv2.imwrite(str(paths.reference), scene.reference_image())
    if paths.frames_dir is not None:
        paths.frames_dir.mkdir(exist_ok=True)
    writer = cv2.VideoWriter(str(paths.video), cv2.VideoWriter_fourcc(*"MJPG"), config.fps,
                             (config.width_px, config.height_px))
    if not writer.isOpened():
        raise InputFileError(f"{paths.video}: OpenCV cannot open a Motion-JPEG writer here")
    writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
    try:
        frames = scene.frames()
        for k, frame in enumerate(progress(frames, total=scene.n_frames) if progress else frames):
            writer.write(frame)
            if paths.frames_dir is not None:
                cv2.imwrite(str(paths.frames_dir / f"{k:06d}.png"), frame)
    finally:
        writer.release()
    return paths
