"""The settings of a look-then-move episode (:class:`EpisodeConfig`) and their vocabularies.

Defaults are the paper's values where it gives them; what it does not give (the crane's start
pose, the VO's error model) is an assumption of this simulation, named as such.
"""

from dataclasses import dataclass

import numpy as np

from posekit.errors import ConfigError
from posekit.localcal.methods.line_method import CIRCLE_POINTS, CIRCLE_RADIUS_MM
from posekit.localcal.methods.trajectory_method import PATH_LENGTHS_MM, STANDOFF_MM
from posekit.localcal.sim.vo import StereoNoise, VONoise

__all__ = ["MATCHERS", "METHODS", "OCCLUSIONS", "REGISTRATIONS", "START_Q", "EpisodeConfig"]

#: Range adjustment methods.
METHODS = ("line", "trajectory")
#: Start configuration of the crane (rad): booms pulled in from the arm's default pose (TCP
#: ~4.6 m from the slewing axis, camera looking ~50° below the horizon) and the wrist pitched
#: 20° away from its singularity (wrist 2 = 0), so that driving the tool marker to an OOI about
#: 1 m in front of the camera stays inside the ~5.25 m reach and the wrist never flips
#: (an assumption of this simulation; the paper does not give its start pose).
START_Q = (0.0, 0.55, -1.1, 0.0, 0.35, 0.0)
#: When the OOI can be hidden from the camera (:attr:`EpisodeConfig.occlude_ooi`).
OCCLUSIONS = ("never", "calibration", "always")
#: How the trajectory method registers VO to the robot (:attr:`EpisodeConfig.registration`).
REGISTRATIONS = ("auto", "match", "handeye")
#: Fine matchers without timestamps (:attr:`EpisodeConfig.matcher`).
MATCHERS = ("cpd", "hybrid")


@dataclass(frozen=True)
class EpisodeConfig:
    """Settings of an episode (defaults: the paper's values where it gives them).

    Parameters
    ----------
    radius_mm, circle_points : float, int
        Circular path of the line method (Sec. 5.2.1: 20 cm, 18 points).
    path_lengths_mm : tuple of float
        Segment lengths of the trajectory method's calibration path (eq. 17–19), mm.
    b_mm : float
        Depth offset b of eq. (21) (Sec. 5.2.2: 10 cm), mm.
    camera_hz : float
        Camera samples per second along the circular path (the line method's distance errors).
    plot_hz : float
        Camera samples per second along the other motions (only for the error plots; 0 = none).
    vo_stereo : StereoNoise or None
        The stereo VO's depth-dependent noise and drift (ZED2-like baseline 120 mm, focal of
        the camera; :class:`~posekit.localcal.sim.vo.StereoNoise`), with the scene depth of
        every pose measured to the wall the OOI is on; None for the isotropic model only.
    vo_noise_mm, vo_noise_rad, vo_drift_mm_per_sqrt_m, vo_drift_rad_per_sqrt_m, vo_stride,
    vo_time_offset_s, vo_outlier_fraction :
        Isotropic VO errors added to the stereo ones (a floor; see
        :func:`posekit.localcal.sim.vo.simulate_vo`), the VO rate and clock, outliers.
    lens_distortion : bool
        The camera's images have lens distortion (:data:`~posekit.localcal.model.camera.ZED2_720P_DISTORTION`,
        rendered distorted, undistorted in the detection with the known intrinsics); False gives
        rectified images.
    use_timestamps : bool
        Match the trajectories with timestamps (default) or correspondence-free (the paper's
        coarse alignment + point-set matching: ``match_trajectories(..., use_timestamps=False)``).
    matcher : {'cpd', 'hybrid'}
        The fine matcher without timestamps: rigid CPD on the positions, or the hybrid-mixture
        style matcher that also uses the orientations (the paper's [31]); see
        :func:`~posekit.localcal.registration.match.match_trajectories`.
    calibration_tilt_deg : float
        Tilt of the trajectory method's calibration path at its inner waypoints, deg (0: the
        paper's orientation-holding path; see
        :func:`~posekit.localcal.methods.trajectory_method.asymmetric_path`).
    registration : {'auto', 'match', 'handeye'}
        How the trajectory method gets ``R_B_W``: ``'match'`` the paper's trajectory matching of
        the positions; ``'handeye'`` the hand-eye calibration
        (:func:`posekit.localcal.registration.handeye.calibrate_handeye`: the camera mount and
        ``T_B_W`` together, for a camera that is not at the tool point — the simulated camera
        is ~0.47 m from it — on a path that rotates); ``'auto'`` hand-eye when the path
        rotates (``calibration_tilt_deg > 0``), matching otherwise.
    error_scale : float
        Scales the arm's sampled non-kinematic errors (1 = ~2–6 cm at the tip).
    ooi_distance_mm : float
        Distance of the OOI in front of the camera at the start pose, mm (the scene puts it
        ~0.36 m off the tool marker laterally, outside the circle, as the line method needs).
        Default 760 mm: the tool marker is 420 mm in front of the camera, so the depth between
        the tool marker and the OOI is the paper's (Table 2, last column: 338 mm on average).
    occlude_ooi : {'never', 'calibration', 'always'}
        Hide the OOI from the camera never, during the calibration path (circle or planar
        path), or always (to exercise the errors of a marker that is never seen).
    keep_images : bool
        Keep the camera image of every 'look' (for inspection; large).
    robot : str
        The arm: a bundled model name (``posekit.robots.MODEL_NAMES``; the HIAB033-like crane
        ``'hiab033'`` by default) or the path of the user's URDF file.
    base_link, tip_link : str, optional
        The URDF chain's ends (the tip is the TCP frame F the camera is mounted on).
    start_q : tuple of float, optional
        Start configuration (rad, mm for prismatic joints); :data:`START_Q` for the crane,
        required for any other arm (its TCP must be able to move ~1 m along the camera's
        viewing axis from there). The non-kinematic errors treat joints 1–3 as the slewing,
        lift and tilt joints and 2 and 3 as the drooping booms.
    """

    radius_mm: float = CIRCLE_RADIUS_MM
    circle_points: int = CIRCLE_POINTS
    path_lengths_mm: tuple = PATH_LENGTHS_MM
    b_mm: float = STANDOFF_MM
    camera_hz: float = 10.0
    plot_hz: float = 2.0
    vo_stereo: StereoNoise | None = StereoNoise()
    vo_noise_mm: float = 0.2
    vo_noise_rad: float = float(np.deg2rad(0.02))
    vo_drift_mm_per_sqrt_m: float = 0.0
    vo_drift_rad_per_sqrt_m: float = 0.0
    vo_stride: int = VONoise.stride
    vo_time_offset_s: float = 0.0
    vo_outlier_fraction: float = VONoise.outlier_fraction
    lens_distortion: bool = True
    use_timestamps: bool = True
    matcher: str = "cpd"
    calibration_tilt_deg: float = 0.0
    registration: str = "auto"
    error_scale: float = 1.0
    ooi_distance_mm: float = 760.0
    occlude_ooi: str = "never"
    keep_images: bool = False
    robot: str = "hiab033"
    base_link: str | None = None
    tip_link: str | None = None
    start_q: tuple | None = None

    def __post_init__(self):
        if not self.camera_hz > 0:
            raise ConfigError(f"camera_hz must be > 0, got {self.camera_hz!r}")
        if not self.plot_hz >= 0:
            raise ConfigError(f"plot_hz must be >= 0, got {self.plot_hz!r}")
        if self.vo_stereo is not None and not isinstance(self.vo_stereo, StereoNoise):
            raise ConfigError(f"vo_stereo: expected a StereoNoise or None, got {type(self.vo_stereo).__name__}")
        if self.matcher not in MATCHERS:
            raise ConfigError(f"matcher: expected one of {' | '.join(MATCHERS)}, got {self.matcher!r}")
        if self.registration not in REGISTRATIONS:
            raise ConfigError(f"registration: expected one of {' | '.join(REGISTRATIONS)}, got {self.registration!r}")
        if not (np.ndim(self.calibration_tilt_deg) == 0 and 0.0 <= self.calibration_tilt_deg <= 45.0):
            raise ConfigError(f"calibration_tilt_deg: expected 0 to 45 deg, got {self.calibration_tilt_deg!r}")
        if self.uses_handeye and not self.use_timestamps:
            raise ConfigError("registration: hand-eye calibration needs timestamps (use_timestamps=True)")
        if self.occlude_ooi not in OCCLUSIONS:
            raise ConfigError(f"occlude_ooi: expected one of {' | '.join(OCCLUSIONS)}, got {self.occlude_ooi!r}")

    @property
    def uses_handeye(self) -> bool:
        """The trajectory method calibrates with hand-eye (see ``registration``)."""
        return self.registration == "handeye" or (self.registration == "auto" and self.calibration_tilt_deg > 0)
