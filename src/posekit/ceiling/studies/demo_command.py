"""The ``posekit ceiling demo`` verb as one library call (:func:`demo`)."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from ...errors import ConfigError
from ..camera.lens import load_camera
from ..sim.config import SceneConfig
from ..track.pipeline import parse_dots
from .demo import run_demo
from .demo_report import DemoReport

__all__ = ["check_demo_lens", "demo"]


def check_demo_lens(camera: str | Path, realistic: bool = False):
    """The lens model file ``camera`` (``--camera``), read and checked against the demo's frame size
    before anything is rendered; a one-line ConfigError for another size."""
    lens = load_camera(camera)
    cfg = SceneConfig.realistic() if realistic else SceneConfig()
    if tuple(lens.image_size) != (cfg.width_px, cfg.height_px):
        raise ConfigError(f"--camera {camera}: the model is for {lens.image_size[0]}x{lens.image_size[1]} px "
                          f"images; the demo renders {cfg.width_px}x{cfg.height_px}")
    return lens


def demo(out: str | Path, *, dots: str | tuple = "red,green", duration_s: float | None = None, seed: int = 0,
         camera: str | Path | None = None, realistic: bool = False, line_pattern: str = "dotted",
         progress: Callable | None = None) -> DemoReport:
    """``posekit ceiling demo``: render, calibrate, track and compare with the truth, into the folder ``out``.

    Parameters are the command's flags by the same names (``dots``: ``'red'``, ``'red,green'`` or
    ``'line'``; ``duration_s``: video length, s, default the renderer's; ``camera``: a lens model
    file to calibrate and track with). Returns the :class:`~posekit.ceiling.studies.demo_report.DemoReport`
    whose ``summary()`` the command prints; the files are :func:`run_demo`'s.
    """
    dots = parse_dots(dots) if isinstance(dots, str) else tuple(dots)
    if camera is not None:
        check_demo_lens(camera, realistic)   # a bad CAMERA.json fails before the render, not after it
    return run_demo(out, dots=dots, seconds=duration_s, seed=seed, progress=progress, camera=camera,
                    realistic=realistic, line_pattern=line_pattern)
