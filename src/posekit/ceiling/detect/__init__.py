"""Finding the laser on ceiling images: dots (paper §IV-B), lines (case C)."""

from .dots import LASER_COLORS, Dot, DotDetector, DotSignature, LaserColor
from .lines import Line, LineDetector

__all__ = ["LASER_COLORS", "LaserColor", "Dot", "DotDetector", "DotSignature", "Line", "LineDetector"]
