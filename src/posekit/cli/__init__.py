"""The ``posekit`` command: one sub-command group per system."""
