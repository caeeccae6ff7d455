"""Hand-eye calibration of a camera that is not at the tool point: the camera mount
``X = T_tool_camera`` and the VO world frame ``Z = T_base_world`` together from the same pose pairs
(``A_k X = Z B_k``), with a clock offset, a verdict and an uncertainty.

Pipeline: the clock offset from the angular-speed profiles (independent of ``X``, see
:mod:`.handeye_time`), timestamp association as in ``match``, the closed-form start of Park &
Martin (:mod:`.handeye_closed`), a joint robust least-squares refinement of ``X``, ``Z`` and the
offset (:mod:`.handeye_refine`), then the verdict.

Examples
--------
>>> from posekit.localcal.registration.handeye import calibrate_handeye
>>> res = calibrate_handeye(camera_traj, kinematic_traj)          # doctest: +SKIP
>>> res.T_tool_camera, res.T_base_world, res.status, res.reasons  # doctest: +SKIP
"""

from dataclasses import dataclass, field, replace

import numpy as np

from posekit.errors import CalibrationError, TrajectoryError
from posekit.geometry import rotation_vector_from_matrix
from posekit.localcal.model.trajectory import Trajectory
from posekit.verdict import Verdict

from .association import associate
from .handeye_closed import park_martin, solve_world
from .handeye_refine import JointFit, pose_residuals, refine_joint
from .handeye_time import PoseInterpolator, estimate_offset_by_rotation

__all__ = ["HandEyeResult", "calibrate_handeye", "MIN_PAIRS", "EXCITATION_MIN_DEG", "RESIDUAL_FACTOR",
           "MAX_STD_ROT_DEG", "MAX_STD_T_MM", "UNIT_GAIN"]

#: Fewest associated pose pairs for an ``ok`` verdict (3 is the least that gives an answer).
MIN_PAIRS = 20
#: Least rotation spread (1 sigma) of the tool about its second principal rotation axis, deg:
#: rotations about one axis only leave the camera offset along that axis undetermined.
EXCITATION_MIN_DEG = 2.0
#: ``suspect`` when the residual rms exceeds this many times the stated noise.
RESIDUAL_FACTOR = 3.0
#: ``suspect`` when the camera mount is this uncertain (1 sigma), deg and mm (defaults of the
#: ``max_std_*`` arguments).
MAX_STD_ROT_DEG = 0.5
MAX_STD_T_MM = 5.0
#: ``suspect`` when the estimated clock offset is this uncertain (1 sigma), s.
MAX_STD_OFFSET_S = 0.02
#: ``suspect`` (mm vs m) when scaling the camera positions by 1e-3 or 1e3 fits this many times better.
UNIT_GAIN = 10.0
#: ``suspect`` when fewer than this fraction of the pairs are inliers.
MIN_INLIER_FRACTION = 0.5
#: ``suspect`` when the mounts fitted on the two halves of the run differ by more than this many
#: standard deviations (of their difference) in any component.
SPLIT_SIGMAS = 5.0
#: Blocks of consecutive pairs whose mean residuals bound the world frame's std from below (drift).
DRIFT_BLOCKS = 8
#: Most pairs the refinement uses (evenly thinned beyond; the uncertainty accounts for it).
MAX_PAIRS = 4000
#: A kinematic log with at most this many samples per camera pose (and one within the pairing
#: window of each) holds one pose per capture: stop-and-go pose pairs, not a trajectory.
CAPTURE_RATIO = 1.5


@dataclass(frozen=True)
class HandEyeResult:
    """Camera mount and VO world frame from ``A_k X = Z B_k``.

    Attributes
    ----------
    T_tool_camera : ndarray, shape (4, 4)
        ``X``: camera frame into the tool frame, mm.
    T_base_world : ndarray, shape (4, 4)
        ``Z``: the camera trajectory's world frame into the robot base frame, mm
        (``p_base = R p_world + t``, as ``match``'s ``R``, ``t_mm``).
    rmse_mm : float
        RMS of the inlier camera-position residuals ``|p(A X) - p(Z B)|``, mm.
    rms_rot_deg : float
        RMS of the inlier camera-rotation residuals, deg.
    n_pairs : int
        Associated pose pairs used.
    inliers : ndarray of bool, shape (n_pairs,)
    time_offset_s : float
        Clock offset ``t_kinematic - t_camera``, s.
    status : str
        ``ok`` or ``suspect``.
    reasons : list of str
        Why ``suspect`` (empty when ``ok``).
    std_rot_deg, std_t_mm : ndarray, shape (3,)
        1 sigma of ``X``: rotation about the tool axes, deg; translation in the tool frame, mm;
        from the normal matrix (raised to a time-block sandwich estimate when larger), multiplied
        by the disagreement (in sigmas, when > 1) of the mounts fitted on the two halves of the run.
    std_world_rot_deg, std_world_t_mm : ndarray, shape (3,)
        1 sigma of ``Z``: rotation about the base axes, deg; translation in the base frame, mm;
        at least the spread of the residuals' block means (VO drift moves the world frame), and
        multiplied like the mount's by the disagreement of the two halves of the run.
    std_time_offset_s : float
        1 sigma of the clock offset, s (0 when it was given; NaN when the data do not determine it).
    excitation_deg : ndarray, shape (3,)
        Rotation spread of the tool about its principal rotation axes (1 sigma, largest first), deg.
    time_offset_source : {'estimated', 'given', 'undetermined'}
        ``undetermined``: the data cannot measure the clock offset (one kinematic pose per capture,
        or a tool at rest at every capture); the poses were paired at 0 (``time_offset_s`` NaN).
    notes : list of str
        What was decided and why.
    """

    T_tool_camera: np.ndarray
    T_base_world: np.ndarray
    rmse_mm: float
    rms_rot_deg: float
    n_pairs: int
    inliers: np.ndarray
    time_offset_s: float
    status: str
    reasons: list = field(default_factory=list)
    std_rot_deg: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    std_t_mm: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    std_world_rot_deg: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    std_world_t_mm: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    std_time_offset_s: float = 0.0
    excitation_deg: np.ndarray = field(default_factory=lambda: np.zeros(3))
    time_offset_source: str = "estimated"
    notes: list = field(default_factory=list)

    @property
    def verdict(self):
        """The result's :class:`posekit.verdict.Verdict` (1σ of the camera mount)."""
        std = {**{f"r{a}_deg": v for a, v in zip("xyz", self.std_rot_deg)},
               **{f"t{a}_mm": v for a, v in zip("xyz", self.std_t_mm)}}
        return Verdict(self.status, tuple(self.reasons), std)

    def to_json(self) -> dict:
        """The DESIGN.md contract ``{R_tool_camera, t_tool_camera_mm, R, t_mm, rmse_mm, status,
        reasons, std_rot_deg, std_t_mm}`` (std of the camera mount) and extra keys."""
        def f(v):
            v = float(v)
            return v if np.isfinite(v) else None
        return {
            "R_tool_camera": self.T_tool_camera[:3, :3].tolist(),
            "t_tool_camera_mm": self.T_tool_camera[:3, 3].tolist(),
            "R": self.T_base_world[:3, :3].tolist(),
            "t_mm": self.T_base_world[:3, 3].tolist(),
            "rmse_mm": f(self.rmse_mm),
            "status": self.status,
            "reasons": list(self.reasons),
            "std_rot_deg": [f(v) for v in self.std_rot_deg],
            "std_t_mm": [f(v) for v in self.std_t_mm],
            "std_world_rot_deg": [f(v) for v in self.std_world_rot_deg],
            "std_world_t_mm": [f(v) for v in self.std_world_t_mm],
            "rms_rot_deg": f(self.rms_rot_deg),
            "n_pairs": int(self.n_pairs),
            "n_inliers": int(np.sum(self.inliers)),
            "time_offset_s": f(self.time_offset_s),
            "std_time_offset_s": f(self.std_time_offset_s),
            "time_offset_source": self.time_offset_source,
            "excitation_deg": [f(v) for v in self.excitation_deg],
            "notes": list(self.notes),
        }


def _excitation_deg(R_tool) -> np.ndarray:
    """Principal rotation spreads (1 sigma, deg) of tool orientations about their mean."""
    from scipy.spatial.transform import Rotation

    rot = Rotation.from_matrix(R_tool)
    mean = rot.mean()
    v = (mean.inv() * rot).as_rotvec()
    ev = np.linalg.eigvalsh(np.cov(v.T) if len(v) > 1 else np.zeros((3, 3)))[::-1]
    return np.rad2deg(np.sqrt(np.clip(ev, 0, None)))


def _wander(r) -> np.ndarray:
    """Per-axis spread (std) of the means of ``DRIFT_BLOCKS`` consecutive blocks of residuals
    ``r`` (K, 3): about sigma / sqrt(K / DRIFT_BLOCKS) for white noise, the drift when it drifts."""
    if len(r) < 2 * DRIFT_BLOCKS:
        return np.zeros(3)
    means = np.stack([b.mean(axis=0) for b in np.array_split(r, DRIFT_BLOCKS)])
    return means.std(axis=0, ddof=1)


def _extent_mm(p) -> float:
    """RMS distance of points from their centroid, mm."""
    return float(np.sqrt(np.mean(np.sum((p - p.mean(axis=0)) ** 2, axis=1)))) if len(p) else 0.0


def _closed_form_rms(A, B) -> float:
    """Median camera-position residual of the closed-form fit, mm (inf when it fails)."""
    try:
        X = park_martin(A, B)
        Z = solve_world(A, X, B)
    except CalibrationError:
        return np.inf
    r = (A @ X)[:, :3, 3] - (B[:, :3, 3] @ Z[:3, :3].T + Z[:3, 3])
    return float(np.median(np.linalg.norm(r, axis=1)))


def _unit_hint(A, B, rmse_mm: float, names) -> str | None:
    """A reason when the camera positions fit far better scaled by 1e-3 or 1e3 (a file in mm
    instead of m, or the other way round), else None."""
    ext_kin, ext_cam = _extent_mm(A[:, :3, 3]), _extent_mm(B[:, :3, 3])
    here = _closed_form_rms(A, B) / max(ext_kin + ext_cam, 1e-9)
    for scale, who in ((1e-3, names[0]), (1e3, names[1])):
        Bs = B.copy()
        Bs[:, :3, 3] *= scale
        rel = _closed_form_rms(A, Bs) / max(ext_kin + scale * ext_cam, 1e-9)
        if rel * UNIT_GAIN < here:
            return (f"the camera positions fit {here / rel:.0f}x better scaled by {scale:g} (rmse {rmse_mm:.3g} mm "
                    f"as read): is {who} in mm instead of m?")
    return None


def _split_check(t_c, B, kin, fit: JointFit, n: int) -> tuple[str | None, np.ndarray]:
    """The mount fitted on each half of the run: a reason when they differ by more than
    ``SPLIT_SIGMAS`` (a camera that moved on its mount) or None, and their difference per
    component ``[X rot x3, X t x3, Z rot x3, Z t x3]`` in standard deviations of the difference (ones when not
    computed): about |N(0, 1)| for white noise, larger when the residuals drift."""
    none = (None, np.ones(12))
    if n < 2 * MIN_PAIRS:
        return none
    order = np.argsort(t_c, kind="stable")
    halves = []
    for sel in np.array_split(order, 2):
        try:                                    # a weakly excited half has a large std: no false alarm
            halves.append(refine_joint(t_c[sel], B[sel], kin, fit.X, fit.Z, fit.offset_s, fit_offset=False))
        except (CalibrationError, np.linalg.LinAlgError):
            return none
    (a, b) = halves
    d_rot = np.rad2deg(rotation_vector_from_matrix(a.X[:3, :3] @ b.X[:3, :3].T, check=False))
    d_t = a.X[:3, 3] - b.X[:3, 3]
    d_zrot = rotation_vector_from_matrix(a.Z[:3, :3] @ b.Z[:3, :3].T, check=False)
    d_zt = a.Z[:3, 3] - b.Z[:3, 3]
    var = np.diag(a.cov)[:12] + np.diag(b.cov)[:12]
    if not np.isfinite(var).all():
        return none
    z = np.abs(np.r_[np.deg2rad(d_rot), d_t, d_zrot, d_zt]) / np.sqrt(var)
    if z[:6].max() > SPLIT_SIGMAS:
        return (f"the camera mount fitted on the first half of the run differs from the second half's by "
                f"{np.linalg.norm(d_t):.3g} mm and {np.linalg.norm(d_rot):.3g} deg ({z[:6].max():.1f} sigma): did the "
                "camera move on its mount, or the VO drift?"), z
    return None, z


def _pose_pairs_only(t_cam, t_kin, max_dt_s: float) -> bool:
    """True when the kinematic log holds one pose per camera pose (stop-and-go captures): at most
    ``CAPTURE_RATIO`` samples per camera pose over the camera's span, and a kinematic stamp within
    ``max_dt_s`` of at least 90 % of the camera stamps."""
    if t_cam.size < 2 or t_kin.size < 2:
        return False
    span = (t_kin >= t_cam[0] - max_dt_s) & (t_kin <= t_cam[-1] + max_dt_s)
    if span.sum() > CAPTURE_RATIO * t_cam.size:
        return False
    i, _ = associate(t_cam, t_kin, max_dt_s=max_dt_s)
    return i.size >= 0.9 * t_cam.size


def calibrate_handeye(camera: Trajectory, kinematic: Trajectory, *, max_dt_s: float = 0.02,
                      time_offset_s: float | None = None, max_offset_s: float = 1.0,
                      noise_mm: float = 2.0, noise_deg: float = 0.5, max_std_t_mm: float = MAX_STD_T_MM,
                      max_std_rot_deg: float = MAX_STD_ROT_DEG,
                      names: tuple[str, str] = ("camera", "kinematic")) -> HandEyeResult:
    """Camera mount ``T_tool_camera`` and VO world ``T_base_world`` from a camera and a kinematic
    trajectory of the same motion (``T_base_tool(t) T_tool_camera = T_base_world T_world_camera(t)``).

    Parameters
    ----------
    camera : Trajectory
        ``T_world_camera`` from VO/SLAM (world = the VO's frame), s and mm.
    kinematic : Trajectory
        ``T_base_tool`` from the robot's kinematics, s and mm; sampled at least as densely as the
        camera (poses are interpolated between samples).
    max_dt_s : float
        Largest time difference of an associated pair, s.
    time_offset_s : float, optional
        Known clock offset ``t_kinematic - t_camera``, s; estimated within ``±max_offset_s`` (from
        the angular-speed profiles, then jointly with the transforms) when None.
    max_offset_s : float
        Half-width of the offset search, s.
    noise_mm, noise_deg : float
        Expected per-pose noise of the camera poses (with the kinematics'), mm and deg; the
        residual test compares against them.
    max_std_t_mm, max_std_rot_deg : float
        ``suspect`` when the camera mount's std (1 sigma, any axis) exceeds these, mm and deg.
    names : (str, str)
        Input names for messages.

    Returns
    -------
    HandEyeResult
        When the data cannot measure the clock offset — one kinematic pose per capture (stop-and-go
        pose pairs), or a tool at rest at every capture (the offset's 1σ beyond ``max_offset_s``) —
        the poses are paired at offset 0, ``time_offset_source`` is ``undetermined`` and a note
        says so, instead of a number.
        With ``status`` ``ok`` or ``suspect`` and ``reasons``: too few pairs, rotations about one
        axis only (the camera offset along it is undetermined), residuals above
        ``RESIDUAL_FACTOR`` times the stated noise, camera positions that fit far better scaled by
        1e-3 or 1e3 (a file in mm instead of m), few inliers, a clock offset at the edge of the search,
        a weakly determined mount (std above ``MAX_STD_ROT_DEG`` / ``MAX_STD_T_MM``), mounts fitted
        on the two halves of the run that differ by more than ``SPLIT_SIGMAS`` (a camera that moved).

    Raises
    ------
    TrajectoryError
        Fewer than 3 associated pairs, or trajectories that never overlap in time.
    CalibrationError
        No relative motion rotates the tool (no closed-form start).
    """
    if len(camera) < 3 or len(kinematic) < 2:
        raise TrajectoryError(f"hand-eye needs >= 3 camera poses and >= 2 kinematic poses, got {len(camera)} "
                              f"({names[0]}) and {len(kinematic)} ({names[1]})")
    kw = dict(max_dt_s=max_dt_s, max_offset_s=max_offset_s, noise_mm=noise_mm, noise_deg=noise_deg,
              max_std_t_mm=max_std_t_mm, max_std_rot_deg=max_std_rot_deg, names=names)
    if time_offset_s is None and _pose_pairs_only(camera.t_s, kinematic.t_s, max_dt_s):
        res = calibrate_handeye(camera, kinematic, time_offset_s=0.0, **kw)
        return replace(res, time_offset_s=float("nan"), std_time_offset_s=float("nan"),
                       time_offset_source="undetermined",
                       notes=[f"{names[1]} holds one pose per {names[0]} pose (stop-and-go captures): the clock "
                              "offset cannot be measured from them; the poses are paired by their stamps "
                              f"within {max_dt_s:g} s (give --time-offset to shift them)"])
    reasons = []
    fit_offset = time_offset_s is None
    if fit_offset:
        offset, at_edge = estimate_offset_by_rotation(camera.t_s, camera.T, kinematic.t_s, kinematic.T,
                                                      max_offset_s=max_offset_s, names=names)
        if at_edge:
            reasons.append(f"clock offset {offset * 1000:+.1f} ms is at the edge of the search (+-{max_offset_s:g} s): "
                           "the true one may lie beyond; widen --max-offset or give --time-offset")
    else:
        offset = float(time_offset_s)
    i_cam, _ = associate(camera.t_s, kinematic.t_s, max_dt_s=max_dt_s, offset_s=offset)
    if i_cam.size > MAX_PAIRS:
        i_cam = i_cam[np.linspace(0, i_cam.size - 1, MAX_PAIRS).round().astype(int)]
    n = int(i_cam.size)
    if n < 3:
        raise TrajectoryError(f"{names[0]} and {names[1]}: {n} pose pairs within {max_dt_s:g} s at a clock offset "
                              f"of {offset * 1000:+.1f} ms; hand-eye needs >= 3 (expected >= {MIN_PAIRS})")
    # times relative to the first camera stamp: at 1.3e9 s (Unix time) a float64 resolves 2.4e-7 s,
    # coarser than the refinement's finite-difference step on the offset (which then saw no motion)
    t_ref = float(camera.t_s[0])
    kin = PoseInterpolator(kinematic.t_s - t_ref, kinematic.T)
    t_c = camera.t_s[i_cam] - t_ref
    B = camera.T[i_cam]
    A = kin(t_c + offset)
    excitation = _excitation_deg(A[:, :3, :3])
    if excitation[1] < EXCITATION_MIN_DEG:
        # the closed form still runs when rotations exist at all; the verdict says why it is weak
        reasons.append(f"the tool rotates about one axis only ({excitation[0]:.2f} deg spread about it, "
                       f"{excitation[1]:.2f} deg about any other; needs >= {EXCITATION_MIN_DEG:g} deg about a "
                       "second axis): the camera offset along that axis is undetermined; rotate about >= 2 "
                       "non-parallel axes")
    X0 = park_martin(A, B)
    Z0 = solve_world(A, X0, B)
    fit: JointFit = refine_joint(t_c, B, kin, X0, Z0, offset, fit_offset=fit_offset)
    inl = fit.inliers
    C = kin(t_c + fit.offset_s) @ fit.X
    r_mm = C[:, :3, 3] - (B[:, :3, 3] @ fit.Z[:3, :3].T + fit.Z[:3, 3])
    rmse = float(np.sqrt(np.mean(np.sum(r_mm[inl] ** 2, axis=1))))
    rms_rot = float(np.rad2deg(np.sqrt(np.mean(fit.res_rad[inl] ** 2))))
    std = np.sqrt(np.clip(np.diag(fit.cov), 0, None))
    std[~np.isfinite(std)] = np.inf
    split, z_split = _split_check(t_c, B, kin, fit, n)
    std[0:12] *= np.maximum(z_split, 1.0)          # halves that disagree beyond their std: inflate by as much
    # VO drift: the world frame is known no better than the residuals wander over the run
    r_p, r_r = pose_residuals(kin(t_c + fit.offset_s), fit.X, fit.Z, B)
    r_r = np.einsum("kab,kb->ka", C[:, :3, :3], r_r)                     # camera frame -> base axes
    order = np.argsort(t_c[inl], kind="stable")
    std[6:9] = np.maximum(std[6:9], _wander(r_r[inl][order]))
    std[9:12] = np.maximum(std[9:12], _wander(r_p[inl][order]))
    std_rot, std_t = np.rad2deg(std[0:3]), std[3:6]
    # ---- verdict
    if split:
        reasons.append(split)
    if not fit.converged:
        reasons.append("the joint refinement did not converge (iteration limit): the poses do not fit one model")
    if n < MIN_PAIRS:
        reasons.append(f"only {n} pose pairs (expected >= {MIN_PAIRS})")
    hint = _unit_hint(A, B, rmse, names)
    if hint:
        reasons.append(hint)
    per_mm = rmse / np.sqrt(3.0)
    per_deg = rms_rot / np.sqrt(3.0)
    if per_mm > RESIDUAL_FACTOR * noise_mm:
        reasons.append(f"position residuals {per_mm:.3g} mm rms per axis, above {RESIDUAL_FACTOR:g} x the stated "
                       f"noise {noise_mm:g} mm (--noise-mm): the poses do not fit one rigid mount")
    if per_deg > RESIDUAL_FACTOR * noise_deg:
        reasons.append(f"rotation residuals {per_deg:.3g} deg rms per axis, above {RESIDUAL_FACTOR:g} x the stated "
                       f"noise {noise_deg:g} deg (--noise-deg): the poses do not fit one rigid mount")
    if inl.mean() < MIN_INLIER_FRACTION:
        reasons.append(f"only {int(inl.sum())} of {n} pose pairs are inliers")
    if std_rot.max() > max_std_rot_deg or std_t.max() > max_std_t_mm:
        reasons.append(f"camera mount weakly determined: std {std_rot.max():.3g} deg, {std_t.max():.3g} mm "
                       f"(limits {max_std_rot_deg:g} deg, {max_std_t_mm:g} mm: --max-std-deg, --max-std-mm)")
    std_off = float(std[12]) if fit_offset else 0.0
    if fit_offset and std_off > max(max_offset_s, MAX_STD_OFFSET_S):
        # the data leave the offset where the prior put it: the tool is (nearly) at rest at the captures
        res = calibrate_handeye(camera, kinematic, time_offset_s=0.0, **kw)
        return replace(res, time_offset_s=float("nan"), std_time_offset_s=float("nan"),
                       time_offset_source="undetermined",
                       notes=[f"the clock offset is not determined by the data (1 sigma {std_off:.3g} s, beyond the "
                              f"±{max_offset_s:g} s search): the tool is at rest or nearly at the {names[0]} poses; "
                              "paired at offset 0 (give --time-offset to shift them)"])
    if std_off > MAX_STD_OFFSET_S:
        reasons.append(f"clock offset weakly determined: std {std_off * 1000:.3g} ms (limit "
                       f"{MAX_STD_OFFSET_S * 1000:g} ms): the angular speed varies too little; give --time-offset")
    return HandEyeResult(
        T_tool_camera=fit.X, T_base_world=fit.Z, rmse_mm=rmse, rms_rot_deg=rms_rot, n_pairs=n, inliers=inl,
        time_offset_s=fit.offset_s, status=Verdict("suspect" if reasons else "ok", tuple(reasons)).status,
        reasons=reasons,
        time_offset_source="estimated" if fit_offset else "given",
        std_rot_deg=std_rot, std_t_mm=std_t, std_world_rot_deg=np.rad2deg(std[6:9]), std_world_t_mm=std[9:12],
        std_time_offset_s=std_off, excitation_deg=excitation)


