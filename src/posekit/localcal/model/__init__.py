"""The model of localcal: what the world is, as plain data (no estimator, no simulator).

:mod:`.trajectory`
    :class:`~posekit.localcal.model.trajectory.Trajectory`, a timed sequence of rigid poses
    (s, mm), exchanged by the registration, the methods, the simulator and the studies.
:mod:`.camera`
    :class:`~posekit.localcal.model.camera.CameraIntrinsics`, the eye-in-hand camera's pinhole
    intrinsics with OpenCV lens distortion, and the ZED 2 at 720p (:func:`~.camera.zed2_720p`).
"""

__all__ = ["camera", "trajectory"]
