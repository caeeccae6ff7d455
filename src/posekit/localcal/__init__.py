"""Look-then-move positioning of a long-reach manipulator with motion-based local calibration."""
