"""posekit: precise robot pose from laser and vision sensors."""

__version__ = "0.1.0"

__all__ = ["__version__"]
