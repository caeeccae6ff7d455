"""The simulator part of localcal: the world the methods are tried on, each part seeded.

:mod:`.arm`, :mod:`.arm_errors`
    The hydraulic long-reach arm (and its compiled kernel) and its non-kinematic errors.
:mod:`.camera`, :mod:`.marker_detector`
    OpenCV ArUco rendering and detection for the eye-in-hand camera of the model
    (:mod:`posekit.localcal.model.camera`: ZED2-like, with lens distortion).
:mod:`.scene`
    The work cell (markers, object of interest) and what the camera observes in it.
:mod:`.vo`
    Stereo visual odometry whose noise and drift grow with depth.

The simulator may use the model (:mod:`posekit.localcal.model`) and never the estimator
(:mod:`posekit.localcal.registration`, :mod:`posekit.localcal.methods`): running a method on
simulated data is a study (:mod:`posekit.localcal.studies.episode`).
"""

__all__ = ["arm", "arm_errors", "camera", "marker_detector", "scene", "vo"]
