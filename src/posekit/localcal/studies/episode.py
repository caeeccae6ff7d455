"""One look-then-move episode on the simulated long-reach arm (Sec. 3 and 5 of the paper).

An episode:

1. **look** at the tool marker and the OOI (camera image → ``T_C_M``, ``T_C_O``);
2. **orientation adjustment** (eq. 7–8) and a move;
3. **range adjustment**, either

   * ``'line'``: the circular path (eq. 10–12) observed by the camera, the line equation
     (eq. 13–16) and a move; every further update is the paper's servo variant: the
     currently measured planar distance along the same direction,
     ``p_ref = p_now + p_u d_ε,now``;
   * ``'trajectory'``: the asymmetric planar path (eq. 17–19) tracked by a simulated stereo
     VO (W = the first camera frame; errors growing with the depth of the wall), matched to
     the encoder TCP trajectory with timestamps or correspondence-free
     (:func:`~posekit.localcal.registration.match.match_trajectories`) — or, on a path that
     tilts, registered together with the camera's mount by hand-eye calibration
     (:func:`~posekit.localcal.registration.handeye.calibrate_handeye`) — then ``updates``
     times: look, eq. (20)–(22), move (VO keeps running for ``R_W_C``);

4. after each update a final look gives the image-based errors (the paper's tables) and the
   simulator gives the true ones.

The camera (lens distortion rendered, undistorted in the detection; ~0.47 m off the tool
point) is sampled along every motion at ``camera_hz`` for the line method's distance errors
and for the error-over-time plots (Fig. 5, 7, 9).
"""

from dataclasses import dataclass, field

import numpy as np

from posekit.errors import ConfigError, EstimationError
from posekit.geometry import invert_transform
from posekit.localcal.methods.line_method import (
    circle_path,
    line_range_adjustment,
)
from posekit.localcal.methods.orientation import orientation_reference, rotation_errors_deg
from posekit.localcal.methods.trajectory_method import (
    asymmetric_path,
    calibrate_trajectories,
    trajectory_reference,
)
from posekit.localcal.sim.vo import depth_along_axis, simulate_vo
from posekit.localcal.studies.episode_config import METHODS, START_Q, EpisodeConfig
from posekit.verdict import Verdict

__all__ = ["LocalcalEpisode", "run_localcal_episode"]

@dataclass
class LocalcalEpisode:
    """Outcome of one episode.

    Attributes
    ----------
    method : str
        ``'line'`` or ``'trajectory'``.
    config : EpisodeConfig
    rotation_before_deg, rotation_after_deg : ndarray, shape (3,)
        Image-based absolute rotation errors (XYZ Euler, deg) between the tool marker and the
        OOI before and after the orientation adjustment.
    true_rotation_after_deg : ndarray, shape (3,)
        The same from the simulator's truth.
    errors_mm : ndarray, shape (updates, 3)
        Image-based position error ``^O p - ^T p`` in the camera frame after each update, mm
        (signed; the tables show absolute values; z includes the offset b).
    true_errors_mm : ndarray, shape (updates, 3)
        The true error of the tool marker vs the OOI in the camera frame, mm.
    matching : dict or None
        Trajectory method: ``Registration.to_json()`` (Table 3's errors, the verdict), or with
        hand-eye ``HandEyeResult.to_json()`` plus ``mode='handeye'`` and Table 3's
        ``mean_abs_err_mm``/``max_abs_err_mm`` (VO's TCP positions vs the encoder TCP).
    timeline : dict
        ``t_s`` (K,), ``e_C_mm`` (K, 3) image-based position errors along the episode (NaN
        unseen), ``rot_deg`` (K, 3) the signed XYZ Euler rotation errors (deg, Fig. 5),
        ``events``: list of (t_s, label).
    logs : dict
        Paths for the figures (base-frame positions, mm; see :mod:`posekit.localcal.studies.plots`).
    images : list of (str, ndarray of shape (720, 1280), uint8)
        The label and camera image of every labelled look (only with ``config.keep_images``).
    """

    method: str
    config: EpisodeConfig
    rotation_before_deg: np.ndarray
    rotation_after_deg: np.ndarray
    true_rotation_after_deg: np.ndarray
    errors_mm: np.ndarray
    true_errors_mm: np.ndarray
    matching: dict | None
    timeline: dict
    logs: dict = field(default_factory=dict)
    images: list = field(default_factory=list)

    @property
    def verdict(self) -> Verdict:
        """``suspect`` with the registration's reasons when the trajectory registration (match or
        hand-eye) was, else ``ok`` (an episode that could not run raises instead)."""
        if self.matching and self.matching.get("status") not in (None, "ok"):
            return Verdict("suspect", tuple(self.matching.get("reasons", ())))
        return Verdict("ok")


# --------------------------------------------------------------------------- simulator glue

class _Camera:
    """The eye-in-hand camera of an episode: looks, and samples along motions."""

    def __init__(self, cell, detector, rng, config):
        self.cell, self.detector, self.rng = cell, detector, rng
        self.keep_images = config.keep_images
        self.hide_ooi = config.occlude_ooi == "always"
        self.t, self.e, self.rot = [], [], []
        self.events = []
        self.images = []

    def _observe(self, T_B_F_true):
        from posekit.localcal.sim.scene import observe
        obs = observe(self.cell, T_B_F_true, self.detector, self.rng, keep_image=self.keep_images)
        if self.hide_ooi:
            seen = tuple(i for i in obs.seen if i not in self.cell.ooi_marker_ids)
            obs = obs._replace(T_C_O=None, seen=seen)
        return obs

    def _record(self, t, obs):
        if obs.T_C_O is not None and obs.T_C_M is not None:
            self.e.append(obs.T_C_O[:3, 3] - obs.T_C_M[:3, 3])
            self.rot.append(rotation_errors_deg(obs.T_C_O, obs.T_C_M, signed=True))
        else:
            self.e.append(np.full(3, np.nan))
            self.rot.append(np.full(3, np.nan))
        self.t.append(float(t))

    def look(self, arm, label=None):
        """One image at the arm's current (settled) pose."""
        obs = self._observe(arm.true_pose())
        self._record(arm.t_s, obs)
        if label:
            self.events.append((float(arm.t_s), label))
        if self.keep_images and obs.image is not None:
            self.images.append((label or "", obs.image))
        return obs

    def along(self, log, hz):
        """Images along a motion log at ``hz`` (none for 0); returns (indices, observations)."""
        if hz <= 0 or len(log.t_s) == 0:
            return np.zeros(0, int), []
        dt = float(np.median(np.diff(log.t_s))) if len(log.t_s) > 1 else 1.0
        step = max(1, round(1.0 / (hz * dt)))
        idx = np.arange(0, len(log.t_s), step)
        obs = []
        for i in idx:
            o = self._observe(log.T_B_F_true[i])
            self._record(log.t_s[i], o)
            obs.append(o)
        return idx, obs

    def hidden(self, flag: bool):
        """Hide the OOI (occlusion) from now on, or show it again."""
        self.hide_ooi = flag

    def timeline(self):
        return {"t_s": np.asarray(self.t), "e_C_mm": np.asarray(self.e).reshape(-1, 3),
                "rot_deg": np.asarray(self.rot).reshape(-1, 3), "events": list(self.events)}


def _require(obs, what: str):
    """The OOI and the tool marker must both be seen; a one-line EstimationError otherwise."""
    missing = []
    if obs.T_C_M is None:
        missing.append("the tool marker (id 0)")
    if obs.T_C_O is None:
        missing.append("the OOI (markers 1, 2, 3)")
    if missing:
        raise EstimationError(f"{' and '.join(missing)} not seen by the camera {what}")


def _positions(obs_list, attr):
    return np.array([getattr(o, attr)[:3, 3] if getattr(o, attr) is not None else np.full(3, np.nan)
                     for o in obs_list]).reshape(-1, 3)


def _setup(seed, config):
    from posekit.localcal.model.camera import zed2_720p
    from posekit.localcal.sim.arm import LongReachArm
    from posekit.localcal.sim.arm_errors import sample_nonkinematic_errors
    from posekit.localcal.sim.marker_detector import MarkerDetector
    from posekit.localcal.sim.scene import default_workcell

    ss = seed if isinstance(seed, np.random.SeedSequence) else np.random.SeedSequence(seed)
    s_err, s_arm, s_cell, s_cam, s_vo = ss.spawn(5)
    model, q0 = _robot(config)
    errors = sample_nonkinematic_errors(np.random.default_rng(s_err), scale=config.error_scale,
                                        n_joints=model.n_joints)
    arm = LongReachArm(model, errors, q0=q0, seed=np.random.default_rng(s_arm))
    cell = default_workcell(arm, np.random.default_rng(s_cell), distance_mm=config.ooi_distance_mm)
    detector = MarkerDetector(zed2_720p(distorted=config.lens_distortion), cell.sizes_mm)
    camera = _Camera(cell, detector, np.random.default_rng(s_cam), config)
    vo_seed = int(np.random.default_rng(s_vo).integers(2**63 - 1))
    return arm, cell, camera, vo_seed


def _robot(config):
    """The nominal model and the start configuration of ``config.robot``."""
    from posekit.robots import load_robot

    model = load_robot(config.robot, config.base_link, config.tip_link)
    if config.start_q is not None:
        return model, np.asarray(config.start_q, dtype=np.float64)
    if config.robot == "hiab033":
        return model, np.array(START_Q)
    raise ConfigError(f"start_q: required for robot {config.robot!r} (the crane's start pose fits only the "
                      "crane); give its joint values (--start-q-deg)")


def _truth(cell, arm):
    """True position error (3,) mm and absolute XYZ rotation errors (3,) deg of the tool marker vs the OOI."""
    from posekit.localcal.sim.scene import ground_truth_errors
    gt = ground_truth_errors(cell, arm.true_pose())
    return np.asarray(gt.e_C_mm, float), rotation_errors_deg(gt.T_C_O, gt.T_C_M)


# --------------------------------------------------------------------------- the episode

def run_localcal_episode(method: str, seed=0, *, updates: int = 2,
                         config: EpisodeConfig | None = None) -> LocalcalEpisode:
    """Run one look-then-move episode of a range adjustment method on the simulator.

    Parameters
    ----------
    method : {'line', 'trajectory'}
        Range adjustment method.
    seed : int or numpy.random.SeedSequence
        Seeds the arm's errors, the scene, the camera noise and the VO; same seed, same numbers.
    updates : int
        Look-then-move updates of the range adjustment (>= 1).
    config : EpisodeConfig, optional

    Returns
    -------
    LocalcalEpisode

    Raises
    ------
    ConfigError
        Unknown method, ``updates < 1`` or a negative seed.
    EstimationError
        The OOI or the tool marker is not seen when it must be (at a look, or never along
        the circular path).
    TrajectoryError
        The calibration path or the trajectories are degenerate.
    """
    from posekit.localcal.sim.scene import R_F_C_NOMINAL

    if method not in METHODS:
        raise ConfigError(f"method: expected one of {' | '.join(METHODS)}, got {method!r}")
    if int(updates) != updates or updates < 1:
        raise ConfigError(f"updates must be an integer >= 1, got {updates!r}")
    if not (isinstance(seed, np.random.SeedSequence) or (isinstance(seed, (int, np.integer)) and seed >= 0)):
        raise ConfigError(f"seed: expected an integer >= 0 or a numpy SeedSequence, got {seed!r}")
    config = config or EpisodeConfig()
    arm, cell, camera, vo_seed = _setup(seed, config)

    obs = camera.look(arm, "start")
    _require(obs, "at the start pose")
    rot_before = rotation_errors_deg(obs.T_C_O, obs.T_C_M)
    # eq. (8) with the designed camera mount as the 'uniformity' of the camera and TCP frames
    T_ref = orientation_reference(arm.nominal_pose(), obs.T_C_O, obs.T_C_M, R_F_C=R_F_C_NOMINAL)
    camera.along(arm.move_to(T_ref), config.plot_hz)
    obs = camera.look(arm, "orientation adjusted")
    _require(obs, "after the orientation adjustment")
    rot_after = rotation_errors_deg(obs.T_C_O, obs.T_C_M)
    true_rot_after = _truth(cell, arm)[1]

    if method == "line":
        errors, true_errors, matching, logs = _line(arm, cell, camera, config, updates)
    else:
        errors, true_errors, matching, logs = _trajectory(arm, cell, camera, config, updates, vo_seed)
    return LocalcalEpisode(method, config, rot_before, rot_after, true_rot_after, np.asarray(errors),
                           np.asarray(true_errors), matching, camera.timeline(), logs, camera.images)


def _goal_B(cell, arm):
    """Base-frame TCP position (nominal model) that would put the tool marker on the OOI's axis
    b in front of it — for the plots only (truth, mapped through the current model error), mm."""
    delta_C = _truth(cell, arm)[0]                  # true t_C_O - t_C_M
    R_B_C = (arm.true_pose() @ cell.T_F_C)[:3, :3]
    return arm.nominal_pose()[:3, 3] + R_B_C @ delta_C


def _line(arm, cell, camera, config, updates):
    T_centre = arm.nominal_pose()
    path = circle_path(T_centre, radius_mm=config.radius_mm, n_points=config.circle_points)
    camera.events.append((float(arm.t_s), "circle"))
    camera.hidden(config.occlude_ooi in ("calibration", "always"))
    log = arm.follow(path)
    idx, obs_path = camera.along(log, config.camera_hz)
    camera.hidden(config.occlude_ooi == "always")
    adj = line_range_adjustment(T_centre, log.T_B_F_nominal[idx, :3, 3], _positions(obs_path, "T_C_O"),
                                _positions(obs_path, "T_C_M"), radius_mm=config.radius_mm)
    goal = _goal_B(cell, arm)
    references, approach, errors, true_errors = [adj.T_B_ref[:3, 3]], [], [], []
    T_ref = adj.T_B_ref
    for k in range(updates):
        move = arm.move_to(T_ref)
        approach.append(move.T_B_F_true[:, :3, 3])
        camera.along(move, config.plot_hz)
        obs = camera.look(arm, f"update {k + 1}")
        _require(obs, f"after update {k + 1}")
        delta = obs.T_C_O[:3, 3] - obs.T_C_M[:3, 3]
        errors.append(delta)
        true_errors.append(_truth(cell, arm)[0])
        if k + 1 < updates:     # the paper's servo variant: same direction, the distance measured now
            T_ref = arm.nominal_pose()
            T_ref[:3, 3] = T_ref[:3, 3] + adj.p_u * float(np.hypot(delta[0], delta[1]))
            references.append(T_ref[:3, 3])
    logs = {
        "T_B_F_centre": T_centre,
        "reference_path_B": path[:, :3, 3],
        "path_nominal_B": log.T_B_F_nominal[:, :3, 3],
        "path_true_B": log.T_B_F_true[:, :3, 3],
        "approach_true_B": np.concatenate(approach),
        "references_B": np.asarray(references),
        "ooi_target_B": goal,
        "d_eps_mm": adj.d_eps_mm,
        "d_eps_min_mm": adj.d_eps_min_mm,
    }
    return errors, true_errors, None, logs


def _handeye_record(he, t_vo, p_B_vo, kinematic) -> dict:
    """Table 3's errors for a hand-eye calibration: VO's TCP positions in B vs the encoder TCP
    at the same times (nearest kinematic sample after the clock offset), with the hand-eye JSON."""
    t = np.asarray(t_vo) + he.time_offset_s
    j = np.clip(np.searchsorted(kinematic.t_s, t), 1, len(kinematic.t_s) - 1)
    j -= (t - kinematic.t_s[j - 1]) < (kinematic.t_s[j] - t)
    e = np.abs(p_B_vo - kinematic.T[j, :3, 3])
    return {**he.to_json(), "mode": "handeye", "mean_abs_err_mm": e.mean(axis=0).tolist(),
            "max_abs_err_mm": e.max(axis=0).tolist()}


def _trajectory(arm, cell, camera, config, updates, vo_seed):
    from posekit.localcal.model.trajectory import Trajectory

    T_start = arm.nominal_pose()
    path = asymmetric_path(T_start, config.path_lengths_mm, tilt_rad=np.deg2rad(config.calibration_tilt_deg))
    camera.events.append((float(arm.t_s), "calibration path"))
    camera.hidden(config.occlude_ooi in ("calibration", "always"))
    log = arm.follow(path)
    camera.along(log, config.plot_hz)
    camera.hidden(config.occlude_ooi == "always")
    T_F_C = cell.T_F_C
    history = [(log.t_s, log.T_B_F_true @ T_F_C)]

    def vo():
        """The VO estimate of every camera pose since the calibration path began."""
        t = np.concatenate([h[0] for h in history])
        T = np.concatenate([h[1] for h in history])
        keep = np.r_[True, np.diff(t) > 0]                 # consecutive logs share a sample
        depth = depth_along_axis(T[keep], cell.T_B_O) if config.vo_stereo is not None else None
        return simulate_vo(T[keep], t[keep], vo_seed, noise_mm=config.vo_noise_mm, noise_rad=config.vo_noise_rad,
                           stereo=config.vo_stereo, depth_mm=depth,
                           drift_mm_per_sqrt_m=config.vo_drift_mm_per_sqrt_m,
                           drift_rad_per_sqrt_m=config.vo_drift_rad_per_sqrt_m, stride=config.vo_stride,
                           time_offset_s=config.vo_time_offset_s, outlier_fraction=config.vo_outlier_fraction)

    vo_calib = vo()
    kinematic = Trajectory(t_s=log.t_s, T=log.T_B_F_nominal)
    if config.uses_handeye:
        from posekit.localcal.registration.handeye import calibrate_handeye

        he = calibrate_handeye(vo_calib, kinematic, names=("VO camera", "encoder TCP"))
        R_B_W = he.T_base_world[:3, :3]
        # VO's TCP positions in B: Z T_W_C X^-1 (the camera's lever arm removed)
        T_B_F_vo = he.T_base_world @ vo_calib.T @ invert_transform(he.T_tool_camera, check=False)
        matching = _handeye_record(he, vo_calib.t_s, T_B_F_vo[:, :3, 3], kinematic)
        vo_tcp_B = T_B_F_vo[:, :3, 3]
    else:
        free = {} if config.use_timestamps else {"matcher": config.matcher}
        reg = calibrate_trajectories(vo_calib, kinematic, use_timestamps=config.use_timestamps,
                                     names=("VO camera", "encoder TCP"), **free)
        R_B_W = reg.R
        matching = reg.to_json()
        vo_tcp_B = reg.scale * vo_calib.T[:, :3, 3] @ reg.R.T + reg.t_mm
    camera.events.append((float(arm.t_s), "matched"))
    errors, true_errors, references = [], [], []
    obs = camera.look(arm, None)
    for k in range(updates):
        _require(obs, f"before update {k + 1}")
        delta = obs.T_C_O[:3, 3] - obs.T_C_M[:3, 3]
        R_W_C = vo().T[-1, :3, :3]                          # VO keeps tracking the camera
        T_ref = trajectory_reference(arm.nominal_pose(), R_B_W, R_W_C, delta, b_mm=config.b_mm)
        references.append(T_ref[:3, 3])
        move = arm.move_to(T_ref)
        history.append((move.t_s, move.T_B_F_true @ T_F_C))
        camera.along(move, config.plot_hz)
        obs = camera.look(arm, f"update {k + 1}")
        _require(obs, f"after update {k + 1}")
        errors.append(obs.T_C_O[:3, 3] - obs.T_C_M[:3, 3])
        true_errors.append(_truth(cell, arm)[0])
    logs = {
        "T_B_F_start": T_start,
        "reference_path_B": path[:, :3, 3],
        "path_nominal_B": log.T_B_F_nominal[:, :3, 3],
        "path_true_B": log.T_B_F_true[:, :3, 3],
        "vo_calibrated_B": vo_tcp_B,
        "references_B": np.asarray(references),
    }
    return errors, true_errors, matching, logs
