"""The particle-filter engine: particles, robot and laser densities, the filter step, the seam
line and the trend filter. Compiled kernels live in ``_kernels``."""
