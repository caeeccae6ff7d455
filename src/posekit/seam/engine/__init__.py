"""The particle-filter engine: particles, robot and laser densities, the filter step, the seam
line and the trend filter. Compiled kernels live in ``_kernels`` (the densities), ``_cloud_kernels`` (the
particle cloud's statistics) and ``_linear``.

It imports no front end (tests/seam/test_seam_layout.py). The public names are exported by
:mod:`posekit.seam`; the sub-package lists its modules only.
"""

__all__ = ["densities", "ekf", "filter", "integrity", "particles", "seamline", "spread_bound", "step", "trend"]
