"""The estimator part of localcal: the paper's local-calibration methods, pure on their inputs.

:mod:`.orientation`
    Orientation adjustment (eq. 7–8).
:mod:`.line_method`
    Line-equation range adjustment on the circular path (eq. 10–16).
:mod:`.trajectory_method`
    Trajectory-matching range adjustment (eq. 17–22).

They read measurements (marker poses, trajectories) and never import the simulator
(:mod:`posekit.localcal.sim`) or the studies (:mod:`posekit.localcal.studies`).
"""

__all__ = ["line_method", "orientation", "trajectory_method"]
