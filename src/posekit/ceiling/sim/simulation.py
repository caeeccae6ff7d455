"""The ``posekit ceiling simulate`` verb as one library call: the scene of the options, rendered.

:func:`simulate` is the command without its parsing and printing: the same arguments by the same
names (a flag ``--noise-grey`` is ``noise_grey``), the same files, the same one-line errors.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

from ...errors import ConfigError
from .config import REALISTIC, SceneConfig
from .video import RenderedVideo, render_video

__all__ = ["DOT_CHOICES", "MAX_DURATION_S", "MAX_FRAMES", "CeilingSimulation", "simulation_dots", "scene_config",
           "scene_effects", "simulate"]

#: The lasers of ``--dots``: red (case A), red,green or red,red (case B), line (case C).
DOT_CHOICES = {"red": ("red",), "red,green": ("red", "green"), "red,red": ("red", "red"), "line": ("line",)}
#: Longest video, s, and its most frames (duration × frame rate: one hour at 15 fps, ~1.5 GB of MJPG).
MAX_DURATION_S, MAX_FRAMES = 3600.0, 54_000
#: The realism options that set the SceneConfig field of the same name when given.
_EFFECT_KEYS = ("bloom", "exposure_step_s", "occluders", "shadows", "stray_lights", "blinking_lights",
                "reflections", "codec", "line_pattern")


class CeilingSimulation(NamedTuple):
    """What :func:`simulate` made: the scene it rendered and the files it wrote."""

    config: SceneConfig
    paths: RenderedVideo


def simulation_dots(dots: str | tuple) -> tuple[str, ...]:
    """``'red,green'`` (or a tuple of colours) → ``('red', 'green')``; a one-line ConfigError naming --dots."""
    text = ",".join(dots) if isinstance(dots, (tuple, list)) else str(dots)
    found = DOT_CHOICES.get(text.replace(" ", "").lower())
    if found is None:
        raise ConfigError(f"--dots: expected one of {' | '.join(DOT_CHOICES)}, got '{dots}'")
    return found


def _check_distortion(dist) -> tuple:
    """4 or 5 lens coefficients k1,k2,p1,p2[,k3] within ±10 → 5 floats."""
    vals = tuple(dist)
    if len(vals) not in (4, 5) or not all(isinstance(v, (int, float)) and math.isfinite(v) and abs(v) <= 10
                                          for v in vals):
        raise ConfigError(f"--distortion: expected 5 comma-separated numbers k1,k2,p1,p2,k3 within ±10, "
                          f"got '{','.join(map(str, vals))[:80]}'")
    return tuple(float(v) for v in vals) + (0.0,) * (5 - len(vals))


def scene_config(*, seed: int = 0, dots="red", duration_s: float = 60.0, fps: float = 15.0, holes: bool = True,
                 noise_grey: float | None = None, realistic: bool = False, config: str | Path | None = None,
                 distortion=None, **effects) -> SceneConfig:
    """The scene of ``posekit ceiling simulate``: defaults, then ``realistic``, then the ``config`` file
    (a YAML mapping of :class:`SceneConfig` keys), then the options given.

    Parameters
    ----------
    seed : int
        Seed of the render.
    dots : str or tuple of str
        One of :data:`DOT_CHOICES`.
    duration_s, fps : float
        Video length (s, > 0) and frame rate (Hz); at most :data:`MAX_FRAMES` frames.
    holes : bool
        Air-conditioning vents where a dot vanishes.
    noise_grey : float, optional
        Sensor noise, grey levels (default the scene's: 2, or 3 when realistic).
    distortion : sequence of 4 or 5 float, optional
        Lens distortion k1, k2, p1, p2[, k3] (OpenCV model about the image centre).
    **effects
        ``bloom``, ``exposure_step_s``, ``occluders``, ``shadows``, ``stray_lights``, ``blinking_lights``,
        ``reflections``, ``codec``, ``line_pattern``: None leaves the scene's value.
    """
    from ...io import load_yaml

    unknown = set(effects) - set(_EFFECT_KEYS)
    if unknown:
        raise TypeError(f"scene_config: unknown option(s) {', '.join(sorted(unknown))}")
    dots = simulation_dots(dots)
    if not duration_s > 0:
        raise ConfigError(f"--duration-s: expected a positive number of seconds, got {duration_s}")
    if duration_s * fps > MAX_FRAMES:
        raise ConfigError(f"--duration-s {duration_s:g} × --frame-rate-hz {fps:g} = {duration_s * fps:.0f} "
                          f"frames; expected at most {MAX_FRAMES}")
    values = dict(REALISTIC) if realistic else {}
    if config:
        data = load_yaml(config, expected="a YAML mapping of scene settings", error=ConfigError)
        if not isinstance(data, dict):
            raise ConfigError(f"{config}: expected a mapping of scene settings (e.g. 'bloom: 1')")
        known = {f.name for f in dataclasses.fields(SceneConfig)}
        for key in data:
            if key not in known:
                raise ConfigError(f"{config}: unknown setting '{str(key)[:40]}'; expected keys of "
                                  "SceneConfig (e.g. dist, bloom, occluders, stray_lights, codec, focal_px)")
        values.update(data)
    values.update(seed=seed, dots=dots, duration_s=duration_s, fps=fps, holes=holes)
    if noise_grey is not None:
        values["noise_std"] = noise_grey
    if distortion is not None:
        values["dist"] = _check_distortion(distortion)
    values.update({k: v for k, v in effects.items() if v is not None})
    try:
        return SceneConfig(**values)
    except (TypeError, ValueError, OverflowError) as exc:   # a setting of the wrong kind (text for a number, ...)
        if isinstance(exc, ConfigError):
            raise ConfigError(f"{config}: {exc}" if config else str(exc)) from None
        raise ConfigError(f"{config or '--config'}: {str(exc)[:120]}; expected each setting as in "
                          "SceneConfig (numbers, lists of numbers, names)") from None


def scene_effects(config: SceneConfig) -> list[str]:
    """The realism effects a scene has on, as the command prints them (``'bloom 1'``, ``'codec mjpg'``)."""
    return [name for name, on in (
        (f"distortion k1={config.dist[0]:g}", any(config.dist)), (f"bloom {config.bloom:g}", config.bloom > 0),
        (f"exposure steps every ~{config.exposure_step_s:g} s", config.exposure_step_s > 0),
        (f"{config.occluders} occluder(s)", config.occluders), (f"{config.shadows} shadow(s)", config.shadows),
        (f"{config.stray_lights} steady + {config.blinking_lights} blinking red light(s)",
         config.stray_lights + config.blinking_lights),
        (f"{config.reflections} reflection(s)", config.reflections), (f"codec {config.codec}", True)) if on]


def simulate(out: str | Path, *, frames_png: bool = False, progress: Callable | None = None,
             **options) -> CeilingSimulation:
    """Render the video of ``posekit ceiling simulate`` into the folder ``out`` (created if needed).

    ``options`` are :func:`scene_config`'s (``seed``, ``dots``, ``duration_s``, ``fps``, ``holes``,
    ``noise_grey``, ``realistic``, ``config``, ``distortion`` and the effects). Writes what
    :func:`~posekit.ceiling.sim.video.render_video` writes (video, truth.csv, calibration_points.csv,
    reference.png, camera.json, stray_lights.csv; frames/ with ``frames_png``).
    """
    config = scene_config(**options)
    return CeilingSimulation(config, render_video(config, out, frames_png=frames_png, progress=progress))
