"""Finding the laser on ceiling images: dots (paper §IV-B), lines (case C)."""

from .dots import DotDetector
from .lines import Line, LineDetector
from .signature import DotSignature
from .spots import LASER_COLORS, Dot, LaserColor

__all__ = ["LASER_COLORS", "LaserColor", "Dot", "DotDetector", "DotSignature", "Line", "LineDetector"]
