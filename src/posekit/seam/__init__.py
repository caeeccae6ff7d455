"""Particle-filter 6-DoF tool pose relative to a weld seam from 2D laser seam trackers."""
