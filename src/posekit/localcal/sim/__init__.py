"""The simulator part of localcal: the world the methods are tried on, each part seeded.

:mod:`.arm`
    The hydraulic long-reach arm with non-kinematic errors (and its compiled kernel).
:mod:`.camera`, :mod:`.marker_detector`
    The ZED2-like eye-in-hand camera with lens distortion, OpenCV ArUco rendering and detection.
:mod:`.scene`
    The work cell (markers, object of interest) and what the camera observes in it.
:mod:`.vo`
    Stereo visual odometry whose noise and drift grow with depth.

The simulator may use the model (:mod:`posekit.localcal.model`) and never the estimator
(:mod:`posekit.localcal.registration`, :mod:`posekit.localcal.methods`): running a method on
simulated data is a study (:mod:`posekit.localcal.studies.episode`).
"""

__all__ = ["arm", "camera", "marker_detector", "scene", "vo"]
