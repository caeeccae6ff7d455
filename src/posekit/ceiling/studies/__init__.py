"""Ceiling experiments: the paper's accuracy assessment and heading simulation, the demo run."""

from .accuracy import heading_std_closed_form, known_points_assessment, simulate_heading_error
from .demo import run_demo
from .demo_command import check_demo_lens

__all__ = ["heading_std_closed_form", "known_points_assessment", "simulate_heading_error", "run_demo", "check_demo_lens"]
