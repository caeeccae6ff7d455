"""The estimator part of localcal: trajectory registration, pure on its inputs.

Trajectory files (:mod:`.formats`), timestamp association (:mod:`.association`, :mod:`.pairing`),
robust Umeyama alignment (:mod:`.alignment`), correspondence-free coarse alignment and rigid CPD
(:mod:`.coarse`, :mod:`.cpd`, :mod:`.hybrid`, :mod:`.match_free`), the verdict on a match
(:mod:`.quality`), its uncertainty and scale drift (:mod:`.uncertainty`, :mod:`.scale`), and on top
of them :func:`.match.match_trajectories` (``posekit localcal match``) and
:func:`.handeye.calibrate_handeye` (``posekit localcal handeye``) with their closed form, time
offset and joint refinement (:mod:`.handeye_closed`, :mod:`.handeye_time`, :mod:`.handeye_refine`).

Nothing here imports the simulator (:mod:`posekit.localcal.sim`) or the studies
(:mod:`posekit.localcal.studies`); the trajectory type is the model's
(:class:`posekit.localcal.model.trajectory.Trajectory`).
"""

__all__ = [
    "alignment",
    "association",
    "coarse",
    "cpd",
    "formats",
    "handeye",
    "handeye_closed",
    "handeye_refine",
    "handeye_time",
    "hybrid",
    "match",
    "match_free",
    "pairing",
    "quality",
    "scale",
    "uncertainty",
]
