"""The front end: configuration and the cell, the fitted profile and its tuner, the robot program,
simulated and recorded episodes, the online tracker, studies, sensor design, report and plots.

The public names are exported by :mod:`posekit.seam`; the sub-package lists its modules only.
"""

__all__ = ["commands", "compare", "config", "config_cell", "config_legacy", "config_messages", "config_types", "design", "logs",
           "logs_setup", "plots", "profile", "report", "simulate", "study", "tracker", "trajectories", "tune",
           "tune_fit", "tune_intervals", "tune_nis", "tune_truth"]
