"""Small builders for the seam tests: a configuration with a profile's values replaced, and the engine's three
inputs (cell, filter settings, fitted profile) from it."""

import numpy as np

from posekit.seam.engine.filter import SeamParticleFilter
from posekit.seam.frontend.config import apply_overrides, cell_from_config, config_from_dict


def config(data: dict | None = None, **overrides):
    """``config_from_dict(data)`` with dotted ``overrides`` (``**{"profile.walk.z_mm": 0.1}``)."""
    cfg = config_from_dict(data or {})
    return apply_overrides(cfg, overrides) if overrides else cfg


def make_filter(cfg, seam_polyline, seed=0, **kw) -> SeamParticleFilter:
    """The engine's particle filter of a configuration."""
    return SeamParticleFilter(cell_from_config(cfg.cell), cfg.filter.settings(), cfg.profile_model(),
                              np.asarray(seam_polyline, dtype=np.float64), seed, **kw)
