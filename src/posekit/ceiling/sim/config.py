"""Configuration of a synthetic ceiling video (:class:`SceneConfig`): the room, the camera and its
lens, the robot's lasers and the realistic effects (:data:`REALISTIC`); every field is documented
in :mod:`posekit.ceiling.sim.render`."""

from __future__ import annotations

import math
from dataclasses import dataclass

from ...errors import ConfigError

__all__ = ["SceneConfig", "REALISTIC", "CODECS", "DEFAULT_HOLES_MM", "NOMINAL_TILE_ALBEDO"]

#: Albedo of a ceiling tile (the renderer scales the laser's brightness by the albedo against it).
NOMINAL_TILE_ALBEDO = 0.80

#: Air-conditioning vents (openings), ``(x0, y0, x1, y1)`` in mm on the ceiling: three on the
#: default robot path (the dot vanishes while crossing them) and one off it.
DEFAULT_HOLES_MM = (
    (1500.0, 700.0, 2100.0, 1100.0),
    (300.0, 1900.0, 900.0, 2300.0),
    (3900.0, 3100.0, 4500.0, 3500.0),
    (2700.0, 1900.0, 3300.0, 2300.0),
)

#: Video codecs the renderer can write: name -> (fourcc, file suffix). H.264 needs an encoder
#: OpenCV's FFmpeg build here does not have (``avc1``/``H264`` writers do not open); ``mp4v``
#: (MPEG-4 Part 2) and ``xvid`` are the block-DCT compressions with motion prediction it can write.
CODECS = {"mjpg": ("MJPG", ".avi"), "mp4v": ("mp4v", ".mp4"), "xvid": ("XVID", ".avi"), "h264": ("avc1", ".mp4")}

#: The realistic defaults (``posekit ceiling simulate --realistic``, :meth:`SceneConfig.realistic`):
#: a wide-angle lens (k1 = -0.2 at 864×480, as in issue 13), a blooming saturated dot,
#: auto-exposure steps about every 8 s, MPEG-4 compression, one person and two shadows crossing
#: the view, one steady and one blinking red LED, two specular reflections, more sensor noise.
REALISTIC = dict(dist=(-0.2, 0.04, 0.0008, -0.0006, 0.0), bloom=1.0, exposure_step_s=8.0, exposure_step_gain=0.3,
                 occluders=1, shadows=2, stray_lights=1, blinking_lights=1, reflections=2, codec="mp4v",
                 noise_std=3.0)


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
    tile_albedo: float = NOMINAL_TILE_ALBEDO
    tile_albedo_spread: float = 0.02
    tbar_albedo: float = 0.55
    holes: bool = True
    hole_rects_mm: tuple[tuple[float, float, float, float], ...] = DEFAULT_HOLES_MM
    # camera: pinhole; x axis of the image horizontal before the roll; lens distortion
    # [k1, k2, p1, p2, k3] of OpenCV's model (all zero: none) about the image centre, with K of focal_px
    camera_position_mm: tuple[float, float, float] = (3000.0, 400.0, -2300.0)
    camera_target_mm: tuple[float, float] = (3000.0, 1700.0)
    focal_px: float = 370.0
    camera_roll_deg: float = -1.5
    vignetting: float = 0.2
    dist: tuple[float, ...] = (0.0, 0.0, 0.0, 0.0, 0.0)
    # robot and lasers
    dots: tuple[str, ...] = ("red",)
    dot_spacing_mm: float = 400.0
    line_length_mm: float = 300.0
    line_pattern: str = "solid"          # case C: "solid" line or "dotted" (line_dots dots over line_length_mm)
    line_dots: int = 5
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
    # realism (all off by default; REALISTIC turns them on)
    bloom: float = 0.0                   # 0 none; 1 a saturated dot bleeding into a coloured halo
    bloom_sigma_px: float = 4.0
    exposure_step_s: float = 0.0         # mean interval of auto-exposure steps, s; 0 none
    exposure_step_gain: float = 0.3      # each step changes the exposure by 40-100 % of this
    occluders: int = 0                   # people crossing the view (hide the dot)
    occluder_period_s: float = 15.0
    shadows: int = 0                     # soft shadows drifting over the ceiling
    stray_lights: int = 0                # steady red LEDs on the ceiling
    blinking_lights: int = 0             # blinking red LEDs
    blink_period_s: float = 1.0
    reflections: int = 0                 # specular glints of lamps (white, saturated)
    stray_light_xy_mm: tuple = ()        # extra steady red LEDs at these ceiling points ((x, y), ...), mm
    codec: str = "mjpg"                  # video file: mjpg | mp4v | xvid | h264 (see CODECS)

    @classmethod
    def realistic(cls, **overrides) -> "SceneConfig":
        """A config with the :data:`REALISTIC` effects on (``overrides`` win)."""
        return cls(**{**REALISTIC, **overrides})

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
        try:
            xy = tuple((float(a), float(b)) for a, b in self.stray_light_xy_mm)
        except (TypeError, ValueError):
            raise ConfigError(f"stray_light_xy_mm: expected a list of (x, y) points in mm, got "
                              f"{self.stray_light_xy_mm!r}") from None
        if len(xy) > 20 or not all(math.isfinite(v) for pt in xy for v in pt):
            raise ConfigError(f"stray_light_xy_mm: expected at most 20 finite (x, y) points, got {len(xy)}")
        object.__setattr__(self, "stray_light_xy_mm", xy)
        dist = tuple(float(v) for v in self.dist)
        if len(dist) == 4:
            dist += (0.0,)
        if len(dist) != 5 or not all(math.isfinite(v) and abs(v) <= 10 for v in dist):
            raise ConfigError(f"dist: expected 5 finite coefficients k1,k2,p1,p2,k3 within ±10, got {self.dist}")
        object.__setattr__(self, "dist", dist)
        if self.codec not in CODECS:
            raise ConfigError(f"codec: expected one of {' | '.join(CODECS)}, got {self.codec!r}")
        if self.line_pattern not in ("solid", "dotted"):
            raise ConfigError(f"line_pattern: expected solid | dotted, got {self.line_pattern!r}")
        counts = {"occluders": self.occluders, "shadows": self.shadows, "stray_lights": self.stray_lights,
                  "blinking_lights": self.blinking_lights, "reflections": self.reflections}
        for name, value in counts.items():
            if isinstance(value, bool) or int(value) != value or not 0 <= value <= 20:
                raise ConfigError(f"{name}: expected a whole number 0..20, got {value!r}")
        if isinstance(self.line_dots, bool) or int(self.line_dots) != self.line_dots or not 2 <= self.line_dots <= 20:
            raise ConfigError(f"line_dots: expected a whole number 2..20, got {self.line_dots!r}")
        nonneg = {"bloom": self.bloom, "exposure_step_s": self.exposure_step_s}
        for name, value in nonneg.items():
            if not (math.isfinite(value) and 0 <= value <= 1e4):
                raise ConfigError(f"{name}: expected a number >= 0, got {value}")
        if not (math.isfinite(self.exposure_step_gain) and 0 <= self.exposure_step_gain < 1):
            raise ConfigError(f"exposure_step_gain: expected a number in [0, 1), got {self.exposure_step_gain}")
        positive = {"fps": self.fps, "focal_px": self.focal_px, "speed_mm_s": self.speed_mm_s,
                    "turn_rate_deg_s": self.turn_rate_deg_s, "core_sigma_px": self.core_sigma_px,
                    "glow_sigma_px": self.glow_sigma_px, "tbar_width_mm": self.tbar_width_mm,
                    "bloom_sigma_px": self.bloom_sigma_px, "occluder_period_s": self.occluder_period_s,
                    "blink_period_s": self.blink_period_s}
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
