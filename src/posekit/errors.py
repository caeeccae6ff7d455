"""The one exception tree of posekit.

Every error that bad input can cause is a :class:`PosekitError`; the CLI prints its
message on one line and exits 1. Errors about wrong input are also ``ValueError``.
"""

__all__ = [
    "PosekitError",
    "GaugeError",
    "ProfileError",
    "EstimationError",
    "ConfigError",
    "MissingExtraError",
    "InputFileError",
    "CalibrationError",
    "TrajectoryError",
    "GeometryError",
]


class PosekitError(Exception):
    """Root of all posekit errors; ``str(err)`` is a one-line message for the user."""


class GaugeError(PosekitError, ValueError):
    """A gauge file or gauge geometry is invalid (too few ridges, parallel faces, ...)."""


class ProfileError(PosekitError, ValueError):
    """A laser profile cannot be used: no points, missing or extra corners, ..."""


class EstimationError(PosekitError):
    """A pose could not be estimated from otherwise valid input (degenerate geometry)."""


class ConfigError(PosekitError, ValueError):
    """A configuration file or option has an unknown, missing or impossible value."""


class MissingExtraError(ConfigError):
    """An optional dependency is not installed; the message names the extra that brings it."""


class InputFileError(PosekitError, ValueError):
    """An input file is missing, unreadable or malformed."""


class CalibrationError(PosekitError, ValueError):
    """A calibration cannot be computed from the given correspondences."""


class TrajectoryError(PosekitError, ValueError):
    """A trajectory file or trajectory is malformed or degenerate."""


class GeometryError(PosekitError, ValueError):
    """Geometric input is malformed: wrong shape, non-finite, not a rotation or rigid transform."""
