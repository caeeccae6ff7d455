"""Ceiling experiments: the paper's accuracy assessment and heading simulation, the demo run.

Modules: ``accuracy`` (§V-B), ``figures`` (Fig. 5-9), ``truth`` (a track against the render's truth),
``rendered_calibration`` (a rendered camera calibrated as a user would), ``demo`` (``run_demo``),
``demo_report`` (its summary, JSON and HTML), ``demo_command`` (the ``demo`` verb), ``render_study``."""

from .accuracy import heading_std_closed_form, known_points_assessment, simulate_heading_error
from .demo import run_demo
from .demo_command import check_demo_lens

__all__ = ["heading_std_closed_form", "known_points_assessment", "simulate_heading_error", "run_demo", "check_demo_lens"]
