"""Ceiling system: x, y and heading of a ground robot from laser dots on the ceiling seen by a
fixed camera (homography calibration, dot detection, tracking, synthetic ceiling videos)."""
