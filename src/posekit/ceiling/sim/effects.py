"""What a real ceiling camera sees besides the laser: stray lights, reflections, people, shadows,
auto-exposure — the "realistic" effects of :mod:`posekit.ceiling.sim.render`.

Every effect is drawn from the scene's seed (``np.random.default_rng([seed, tag])``), so the same
:class:`~posekit.ceiling.sim.config.SceneConfig` gives the same video.

* **Stray lights** (:class:`StrayLight`): red indicator LEDs (also at chosen points:
  ``stray_light_xy_mm``) (smoke detectors, exit signs, a
  projector's standby light) fixed on the ceiling, ``steady`` or ``blinking`` (square wave of
  ``blink_period_s``, half on), and ``reflection`` — specular glints of the room lamps on glossy
  fittings, white with a warm tint and saturated, slowly flickering. Positions are on the ceiling
  in view, at least :data:`MIN_PATH_DISTANCE_MM` from the robot's path (a lamp does not sit on
  the laser dot), written to ``stray_lights.csv`` by the renderer.
* **Occluders** (:class:`Occluder`): dark soft ellipses (a person's head and shoulders, a ladder)
  crossing the image along straight lines, each once per ``occluder_period_s``; a laser dot
  behind one is invisible (the truth's ``red_visible`` is 0).
* **Shadows**: large soft multiplicative darkenings of the ceiling (down to 55 % of the light)
  drifting across the view; they dim the room light on the ceiling, not the laser.
* **Auto-exposure steps**: the exposure (it scales every light the sensor collects, the laser
  included) jumps to a new level at seeded times about every ``exposure_step_s`` s, by up to
  ``±exposure_step_gain``.

Pixels are those of the real (distorted) image, px, pixel-centre convention; world points mm.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["StrayLight", "Occluder", "Shadow", "MIN_PATH_DISTANCE_MM", "stray_lights", "occluders", "shadows",
           "exposure_levels", "exposure_at", "LIGHT_APPEARANCE"]

#: A stray light is at least this far from the robot's path (its laser dot), mm.
MIN_PATH_DISTANCE_MM = 250.0

#: Appearance of each kind of light: (core amplitude B, G, R), core sigma px, (glow B, G, R), glow sigma px.
#: An LED is red and bright but, unlike the laser, not white-saturated in all channels; a
#: specular reflection is white and saturated.
LIGHT_APPEARANCE = {
    "steady": ((70.0, 60.0, 420.0), 1.3, (8.0, 6.0, 110.0), 3.2),
    "blinking": ((70.0, 60.0, 420.0), 1.3, (8.0, 6.0, 110.0), 3.2),
    "reflection": ((330.0, 340.0, 380.0), 1.6, (25.0, 30.0, 45.0), 3.5),
}


@dataclass(frozen=True)
class StrayLight:
    """A light fixed on the ceiling that is not the laser.

    Attributes
    ----------
    kind : str
        ``steady``, ``blinking`` or ``reflection``.
    xy : ndarray, shape (2,)
        Position on the ceiling (world frame W), mm.
    uv : ndarray, shape (2,)
        Where the camera shows it (distorted image), px.
    period_s : float
        Blinking period, s (0: steady).
    phase_s : float
        Time of its first switch-on, s.
    """

    kind: str
    xy: np.ndarray
    uv: np.ndarray
    period_s: float
    phase_s: float

    def intensity(self, t: float) -> float:
        """Brightness factor at time ``t`` (0 off, ~1 on)."""
        if self.kind == "blinking":
            return 1.0 if ((t - self.phase_s) % self.period_s) < 0.5 * self.period_s else 0.0
        if self.kind == "reflection":                     # glints flicker a little
            return 0.85 + 0.15 * math.sin(2 * math.pi * (t / 3.7 + self.phase_s))
        return 1.0


@dataclass(frozen=True)
class Occluder:
    """A dark soft ellipse crossing the image along a line, once per period.

    Attributes
    ----------
    start_uv, end_uv : ndarray, shape (2,)
        Where its centre enters and leaves (outside the image), px.
    axes_px : tuple of float
        Semi-axes (along u, along v), px.
    period_s, offset_s : float
        It crosses during ``[offset_s + k·period_s, offset_s + k·period_s + crossing_s]``.
    crossing_s : float
        Duration of one crossing, s.
    grey : float
        Its grey level.
    """

    start_uv: np.ndarray
    end_uv: np.ndarray
    axes_px: tuple
    period_s: float
    offset_s: float
    crossing_s: float
    grey: float

    def centre(self, t: float):
        """Centre (u, v) px at time ``t``, or None when it is not in view."""
        tau = (t - self.offset_s) % self.period_s
        if tau > self.crossing_s:
            return None
        f = tau / self.crossing_s
        return self.start_uv + f * (self.end_uv - self.start_uv)

    def alpha(self, t: float, rows: np.ndarray, cols: np.ndarray) -> np.ndarray | None:
        """Opacity (len(rows), len(cols)) in [0, 1] at time ``t``; None when out of view."""
        c = self.centre(t)
        if c is None:
            return None
        a, b = self.axes_px
        d = np.sqrt(((cols[None, :] - c[0]) / a) ** 2 + ((rows[:, None] - c[1]) / b) ** 2)
        return np.clip((1.08 - d) / 0.16, 0.0, 1.0)            # a soft edge of ~8 % of the size

    def covers(self, t: float, uv) -> bool:
        """Whether the image point ``uv`` (2,) px is hidden at time ``t`` (opacity > 0.5)."""
        c = self.centre(t)
        if c is None or not np.all(np.isfinite(uv)):
            return False
        a, b = self.axes_px
        return math.hypot((uv[0] - c[0]) / a, (uv[1] - c[1]) / b) < 1.0


@dataclass(frozen=True)
class Shadow:
    """A large soft shadow drifting across the view (a Gaussian dip of the room light)."""

    start_uv: np.ndarray
    velocity_px_s: np.ndarray
    sigma_px: float
    depth: float
    width: int
    height: int

    def factor(self, t: float, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Light factor (len(rows), len(cols)) in [1 - depth, 1] at time ``t``."""
        span = np.array([self.width + 6 * self.sigma_px, self.height + 6 * self.sigma_px])
        c = (self.start_uv + self.velocity_px_s * t + 3 * self.sigma_px) % span - 3 * self.sigma_px
        g = np.exp(-0.5 * (((cols - c[0]) / self.sigma_px) ** 2))[None, :] * \
            np.exp(-0.5 * (((rows - c[1]) / self.sigma_px) ** 2))[:, None]
        return (1.0 - self.depth * g).astype(np.float32)


def stray_lights(config, project, path_xy: np.ndarray) -> list[StrayLight]:
    """The stray lights of ``config`` (``stray_lights`` steady, ``blinking_lights``, ``reflections``).

    Parameters
    ----------
    config : SceneConfig
    project : callable
        World points (N, 2) mm → distorted image points (N, 2) px.
    path_xy : ndarray, shape (M, 2)
        Dense samples of the robot's path (its laser dot), mm.
    """
    kinds = (["steady"] * int(config.stray_lights) + ["blinking"] * int(config.blinking_lights)
             + ["reflection"] * int(config.reflections))
    placed = []
    for x, y in getattr(config, "stray_light_xy_mm", ()):       # where the user put them, path or not
        uv = project(np.array([[x, y]], float))[0]
        if np.all(np.isfinite(uv)):
            placed.append(StrayLight("steady", np.array([x, y], float), uv, 0.0, 0.0))
    if not kinds:
        return placed
    rng = np.random.default_rng([int(config.seed), 0x57A7])
    sx, sy = config.ceiling_size_mm
    out = []
    for kind in kinds:
        for _ in range(2000):
            xy = rng.uniform([100.0, 100.0], [sx - 100.0, sy - 100.0])
            uv = project(xy[None])[0]
            inside = (np.all(np.isfinite(uv)) and 15 <= uv[0] <= config.width_px - 16
                      and 15 <= uv[1] <= config.height_px - 16)
            far = np.min(np.hypot(*(path_xy - xy).T)) >= MIN_PATH_DISTANCE_MM
            if inside and far and all(np.hypot(*(xy - s.xy)) > 300.0 for s in out):
                break
        else:
            continue
        period = float(config.blink_period_s) if kind == "blinking" else 0.0
        out.append(StrayLight(kind, xy, uv, period, float(rng.uniform(0.0, max(period, 1.0)))))
    return out + placed


def occluders(config) -> list[Occluder]:
    """``config.occluders`` people crossing the view, each once per ``occluder_period_s``."""
    rng = np.random.default_rng([int(config.seed), 0x0CC1])
    w, h = config.width_px, config.height_px
    out = []
    for k in range(int(config.occluders)):
        a = float(rng.uniform(0.12, 0.2) * h)
        b = float(a * rng.uniform(0.7, 1.3))
        if rng.uniform() < 0.5:                            # left to right or right to left
            v0, v1 = rng.uniform(0.15 * h, 0.85 * h, 2)
            s, e = np.array([-a - 5, v0]), np.array([w + a + 5, v1])
        else:
            u0, u1 = rng.uniform(0.15 * w, 0.85 * w, 2)
            s, e = np.array([u0, -b - 5]), np.array([u1, h + b + 5])
        if rng.uniform() < 0.5:
            s, e = e, s
        crossing = float(np.hypot(*(e - s)) / rng.uniform(150.0, 260.0))       # px/s
        period = max(float(config.occluder_period_s), crossing * 1.2)
        out.append(Occluder(s, e, (a, b), period, float(rng.uniform(0.2, 0.6) * period + k * period / 3),
                            crossing, float(rng.uniform(25.0, 60.0))))
    return out


def shadows(config) -> list[Shadow]:
    """``config.shadows`` soft shadows drifting across the view."""
    rng = np.random.default_rng([int(config.seed), 0x5AD0])
    w, h = config.width_px, config.height_px
    out = []
    for _ in range(int(config.shadows)):
        ang = rng.uniform(0, 2 * np.pi)
        out.append(Shadow(rng.uniform([0, 0], [w, h]), 60.0 * np.array([np.cos(ang), np.sin(ang)]),
                          float(rng.uniform(0.15, 0.25) * h), float(rng.uniform(0.3, 0.45)), w, h))
    return out


def exposure_levels(config) -> tuple[np.ndarray, np.ndarray]:
    """Times (s) of the auto-exposure steps and the exposure level after each (first: 1 at t=0)."""
    if not config.exposure_step_s > 0:
        return np.zeros(1), np.ones(1)
    rng = np.random.default_rng([int(config.seed), 0xAE])
    n = int(config.duration_s / config.exposure_step_s) + 2
    times = np.concatenate([[0.0], np.cumsum(config.exposure_step_s * rng.uniform(0.6, 1.4, n))])
    a = float(config.exposure_step_gain)
    steps = rng.uniform(0.4 * a, a, n) * rng.choice([-1.0, 1.0], n)
    levels = np.concatenate([[1.0], np.clip(1.0 + steps, 0.3, 3.0)])
    return times, levels


def exposure_at(times: np.ndarray, levels: np.ndarray, t: float) -> float:
    """The exposure level at time ``t`` (piecewise constant: AE jumps by whole steps)."""
    return float(levels[max(int(np.searchsorted(times, t, side="right")) - 1, 0)])
