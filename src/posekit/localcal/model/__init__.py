"""The model of localcal: what the world is, as plain data (no estimator, no simulator).

:mod:`.trajectory`
    :class:`~posekit.localcal.model.trajectory.Trajectory`, a timed sequence of rigid poses
    (s, mm), exchanged by the registration, the methods, the simulator and the studies.
"""

__all__ = ["trajectory"]
