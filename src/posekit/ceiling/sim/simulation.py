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
           "dump_scene_config", "scene_effects", "simulate"]

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


def scene_config(*, seed: int | None = None, dots=None, duration_s: float | None = None, fps: float | None = None,
                 holes: bool | None = None, noise_grey: float | None = None, realistic: bool = False,
                 config: str | Path | None = None, distortion=None, **effects) -> SceneConfig:
    """The scene of ``posekit ceiling simulate``: :class:`SceneConfig`'s defaults, then ``realistic``, then
    the ``config`` file (a YAML mapping of :class:`SceneConfig` keys, as :func:`dump_scene_config` writes
    it), then the options given. An option left at None is not given: the file's value, else the default.

    Parameters
    ----------
    seed : int, optional
        Seed of the render (default 0).
    dots : str or tuple of str, optional
        One of :data:`DOT_CHOICES` (default ``'red'``).
    duration_s, fps : float, optional
        Video length (s, > 0; default 60) and frame rate (Hz; default 15); at most :data:`MAX_FRAMES` frames.
    holes : bool, optional
        Air-conditioning vents where a dot vanishes (default True).
    noise_grey : float, optional
        Sensor noise, grey levels (default the scene's: 2, or 3 when realistic).
    distortion : sequence of 4 or 5 float, optional
        Lens distortion k1, k2, p1, p2[, k3] (OpenCV model about the image centre).
    **effects
        ``bloom``, ``exposure_step_s``, ``occluders``, ``shadows``, ``stray_lights``, ``blinking_lights``,
        ``reflections``, ``codec``, ``line_pattern``: None leaves the scene's value.

    Raises
    ------
    ConfigError
        A bad option (naming its flag), an unreadable or malformed file, an unknown key or a value of the
        wrong kind (naming the file), more than :data:`MAX_FRAMES` frames.
    """
    from ...io import load_yaml

    unknown = set(effects) - set(_EFFECT_KEYS)
    if unknown:
        raise TypeError(f"scene_config: unknown option(s) {', '.join(sorted(unknown))}")
    if dots is not None:
        dots = simulation_dots(dots)
    if duration_s is not None and not duration_s > 0:
        raise ConfigError(f"--duration-s: expected a positive number of seconds, got {duration_s}")
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
        if isinstance(values.get("dots"), str):                  # 'red,green' as on the command line
            values["dots"] = tuple(v.strip() for v in values["dots"].split(","))
    given = dict(seed=seed, dots=dots, duration_s=duration_s, fps=fps, holes=holes)
    values.update({k: v for k, v in given.items() if v is not None})
    if noise_grey is not None:
        values["noise_std"] = noise_grey
    if distortion is not None:
        values["dist"] = _check_distortion(distortion)
    values.update({k: v for k, v in effects.items() if v is not None})
    try:
        scene = SceneConfig(**values)
    except (TypeError, ValueError, OverflowError) as exc:   # a setting of the wrong kind (text for a number, ...)
        if isinstance(exc, ConfigError):
            raise ConfigError(f"{config}: {exc}" if config else str(exc)) from None
        raise ConfigError(f"{config or '--config'}: {str(exc)[:120]}; expected each setting as in "
                          "SceneConfig (numbers, lists of numbers, names)") from None
    if not scene.duration_s > 0:                              # only a file's value can be 0 here
        raise ConfigError(f"{config}: duration_s: expected a positive number of seconds, got {scene.duration_s}")
    if scene.duration_s * scene.fps > MAX_FRAMES:
        raise ConfigError(f"--duration-s {scene.duration_s:g} × --frame-rate-hz {scene.fps:g} = "
                          f"{scene.duration_s * scene.fps:.0f} frames; expected at most {MAX_FRAMES}")
    return scene


def _plain(value):
    """Tuples (nested) → lists: YAML without Python tags."""
    return [_plain(v) for v in value] if isinstance(value, (tuple, list)) else value


def dump_scene_config(config: SceneConfig) -> str:
    """``posekit ceiling simulate --dump-config``: every field of the scene ``config`` as YAML, in
    :class:`SceneConfig`'s order (lengths mm, times s, angles degrees, grey levels). Read back by
    :func:`scene_config` (``config=``, or ``simulate --config``) it gives the same scene."""
    import yaml

    data = {f.name: _plain(getattr(config, f.name)) for f in dataclasses.fields(SceneConfig)}
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True, default_flow_style=None)


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
