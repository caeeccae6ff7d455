"""Trajectory matching: the transform that maps a camera (VO/SLAM) trajectory into the robot base.

:func:`match_trajectories` aligns a source trajectory (e.g. the camera poses in the VO world frame
W) with a destination trajectory (e.g. the TCP poses in the base frame B from the kinematic model)
and returns ``T_dst_src`` (``T_B_W``). Two modes:

* with timestamps: an unknown constant clock offset is estimated (:mod:`.association`), poses are
  paired by nearest timestamp within ``max_dt_s``, and a robust (trimmed) Umeyama fit on the
  paired positions rejects gross outliers;
* without timestamps (correspondence-free): a coarse alignment that can never be mirrored
  (:mod:`.coarse`; orientations break ties between candidates on symmetric paths), then rigid CPD
  with a uniform outlier component on the positions (:mod:`.cpd`), polished by a trimmed
  nearest-neighbour re-fit against every pose and a point-to-line Gauss-Newton refinement
  (``matcher='cpd'``, the default); or (``matcher='hybrid'``) the hybrid-mixture style matcher of
  :mod:`.hybrid` that uses the orientations as well as the positions in the CPD and the polish
  (when the orientations turn; with constant ones it is the positional matcher). On the real TUM
  fr1/xyz pair both land 0.65 deg / 15-20 mm from the timestamped match, inside 3 sigma of the
  reported uncertainty (a 125 mm path with 13 mm SLAM residuals); on fr2/desk 0.04-0.05 deg / <1 mm.

Every result carries a verdict (:mod:`.quality`: ``status`` ok|suspect and ``reasons``) and a
1-sigma uncertainty about the base axes (:mod:`.uncertainty`: Gauss-Newton with the residual
variance, corrected for time-correlated residuals).

The model is ``p_dst ≈ s R p_src + t`` for the positions of the two bodies. The bodies may have
different axes (a camera and a flange): orientations are only compared up to one constant rotation.
A lever arm between the two body origins is absorbed in ``t`` when the orientation is constant
along the path (the paper's planar calibration path); it is not modelled otherwise, and the
verdict flags it (``posekit localcal handeye`` solves that case).
"""

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from posekit.errors import ConfigError, TrajectoryError
from posekit.geometry import nearest_rotation, rotation_angle_between
from posekit.localcal.registration.alignment import (
    MIN_POSES,
    body_rotation_spread,
    check_path_shape,
    robust_inliers,
    robust_umeyama,
    thin_indices,
    umeyama,
)
from posekit.localcal.registration.association import associate, estimate_time_offset
from posekit.localcal.registration.coarse import coarse_align
from posekit.localcal.registration.cpd import rigid_cpd
from posekit.localcal.registration.hybrid import hybrid_refine
from posekit.localcal.registration.quality import check_units, verdict
from posekit.localcal.registration.tum import Trajectory
from posekit.localcal.registration.uncertainty import path_tangents, path_velocity, registration_covariance

__all__ = ["Registration", "associate", "match_trajectories", "umeyama"]

#: Each set is thinned evenly to at most this many points for the fine CPD.
CPD_MAX_POINTS = 400
#: Orientations that all stay within this angle of their mean carry no information on R
#: (the orientation term would be the same for every pair); the CPD then runs on positions only.
ORIENTATION_STILL_DEG = 2.0
#: Nearest-neighbour re-fits after the CPD, at most.
POLISH_ITERS = 30
#: Coarse candidates that tie on the positions but rotate further apart than this make a match
#: without timestamps ambiguous, deg (tied candidates on asymmetric paths: < 0.03 deg; on a circle
#: or an ellipse: 180 deg).
SYMMETRY_DEG = 2.0
#: Pairs the orientation spread (a median) is computed on, at most (evenly subsampled).
SPREAD_MAX_PAIRS = 50_000
#: Point-to-line Gauss-Newton steps after the polish, at most.
LINE_ITERS = 10
#: Correspondence-free fine matchers.
MATCHERS = ("cpd", "hybrid")


@dataclass(frozen=True)
class Registration:
    """Result of a trajectory match: ``p_dst = scale * R @ p_src + t_mm``.

    Attributes
    ----------
    R : ndarray, shape (3, 3)
        Rotation ``R_dst_src`` (det +1).
    t_mm : ndarray, shape (3,)
        Translation ``t_dst_src``, mm.
    rmse_mm : float
        Root-mean-square position residual over the inlier pairs, mm.
    mean_abs_err_mm, max_abs_err_mm : ndarray, shape (3,)
        Mean and largest absolute residual per dst axis over the inlier pairs, mm (Table 3 of
        the paper). Without timestamps the pairs are nearest neighbours, so the residuals only
        measure the distance across the path (a slip along it is invisible) and the inlier gate
        (``INLIER_SIGMAS`` robust sigmas of those distances) also flags src poses where dst has
        no data (e.g. a gap in the recording).
    n_pairs : int
        Number of pairs: timestamp-associated pairs, or (without timestamps) src poses each
        paired with its nearest dst pose after alignment.
    inliers : ndarray, shape (n_pairs,), bool
        Pairs kept by the outlier gate.
    scale : float
        Similarity scale (1.0 for a rigid match).
    time_offset_s : float
        Clock offset used, s (``t_dst ≈ t_src + time_offset_s``; 0 without timestamps).
    pairs : ndarray, shape (n_pairs, 2), int
        Indices ``(i_src, i_dst)`` of the pairs.
    orientation_spread_deg : float
        Median angle between each inlier pair's body-to-body rotation and their mean, deg: small
        when the orientations agree with ``R`` (a check, not used in the fit with timestamps).
    mode : {'timestamps', 'no-timestamps'}
        How the poses were paired.
    status : {'ok', 'suspect'}
        Verdict of :func:`.quality.verdict`.
    reasons : tuple of str
        Why the result is suspect (empty when ``ok``).
    std_rot_deg : ndarray, shape (3,)
        1-sigma uncertainty of the rotation about the base frame's x, y, z axes, deg.
    std_t_mm : ndarray, shape (3,)
        1-sigma uncertainty of ``t_mm`` along the base frame's axes, mm.
    matcher : str
        Fine matcher used without timestamps ('cpd' or 'hybrid'; '' with timestamps).
    """

    R: np.ndarray
    t_mm: np.ndarray
    rmse_mm: float
    mean_abs_err_mm: np.ndarray
    max_abs_err_mm: np.ndarray
    n_pairs: int
    inliers: np.ndarray
    scale: float = 1.0
    time_offset_s: float = 0.0
    pairs: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=int))
    orientation_spread_deg: float = float("nan")
    mode: str = "timestamps"
    status: str = "ok"
    reasons: tuple = ()
    std_rot_deg: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    std_t_mm: np.ndarray = field(default_factory=lambda: np.full(3, np.nan))
    matcher: str = ""

    @property
    def T(self) -> np.ndarray:
        """``T_dst_src``, shape (4, 4), mm (the scale is folded into the rotation block)."""
        T = np.eye(4)
        T[:3, :3] = self.scale * self.R
        T[:3, 3] = self.t_mm
        return T

    def to_json(self) -> dict:
        """The record of ``posekit localcal match``: ``R, t_mm, rmse_mm, mean_abs_err_mm, max_abs_err_mm`` first."""
        return {
            "R": self.R.tolist(),
            "t_mm": self.t_mm.tolist(),
            "rmse_mm": float(self.rmse_mm),
            "mean_abs_err_mm": self.mean_abs_err_mm.tolist(),
            "max_abs_err_mm": self.max_abs_err_mm.tolist(),
            "status": self.status,
            "reasons": list(self.reasons),
            "std_rot_deg": [float(v) if np.isfinite(v) else None for v in self.std_rot_deg],
            "std_t_mm": [float(v) if np.isfinite(v) else None for v in self.std_t_mm],
            "scale": float(self.scale),
            "time_offset_s": float(self.time_offset_s),
            "n_pairs": int(self.n_pairs),
            "n_inliers": int(self.inliers.sum()),
            "orientation_spread_deg": (float(self.orientation_spread_deg)
                                       if np.isfinite(self.orientation_spread_deg) else None),
            "mode": self.mode,
            **({"matcher": self.matcher} if self.matcher else {}),
        }


def _errors(p_src, p_dst, R, t, s, inl):
    e = p_dst - (s * p_src @ R.T + t)
    ei = e[inl]
    rmse = float(np.sqrt((ei ** 2).sum(1).mean()))
    return rmse, np.abs(ei).mean(0), np.abs(ei).max(0)


def match_trajectories(src: Trajectory, dst: Trajectory, *, use_timestamps: bool = True,
                       max_dt_s: float = 0.02, time_offset_s: float | None = None,
                       max_offset_s: float = 1.0, with_scale: bool = False,
                       outlier_fraction: float = 0.05, use_orientations: bool = True,
                       matcher: str = "cpd", names: tuple[str, str] = ("src", "dst")) -> Registration:
    """Transform that maps the src trajectory's world frame into dst's (``T_dst_src``).

    Parameters
    ----------
    src : Trajectory
        Source poses ``T_Wsrc_body`` (e.g. VO/SLAM camera poses in W), mm.
    dst : Trajectory
        Destination poses ``T_Wdst_body`` (e.g. encoder-based TCP poses in the base B), mm.
    use_timestamps : bool
        Pair poses by time (default) or match the point sets without correspondences.
    max_dt_s : float
        Largest time difference of an associated pair, s.
    time_offset_s : float or None
        Known clock offset (``t_dst ≈ t_src + offset``), s; None estimates it within
        ``±max_offset_s``.
    max_offset_s : float
        Half-width of the offset search, s.
    with_scale : bool
        Estimate a similarity (Sim(3)): for a monocular VO trajectory of unknown scale.
    outlier_fraction : float
        Expected fraction of gross outliers (trimmed start; CPD's uniform weight).
    use_orientations : bool
        Without timestamps: let orientations break ties between coarse candidates that fit the
        positions equally well (used only when the orientations vary by more than
        ``ORIENTATION_STILL_DEG``).
    matcher : {'cpd', 'hybrid'}
        Without timestamps: positional rigid CPD (default) or the hybrid-mixture style matcher
        that uses orientations too (:mod:`.hybrid`).
    names : (str, str)
        Names of src and dst for messages (e.g. file names).

    Returns
    -------
    Registration
        ``R`` is ``R_dst_src``, ``t_mm`` is ``t_dst_src`` (mm), with the residual statistics of
        the inlier pairs (mm), the clock offset used (s), the verdict (``status``, ``reasons``)
        and the 1-sigma uncertainty (``std_rot_deg``, ``std_t_mm``).

    Raises
    ------
    TrajectoryError
        Too few poses, a path that does not move or is a straight line, no overlapping
        timestamps, an ambiguous clock offset (a path that maps onto itself under a time
        shift), or without timestamps a symmetric path whose orientations do not vary (unless
        ``use_orientations=False``, which keeps the best-scoring candidate); two paths whose sizes
        differ by more than 20x without ``with_scale`` (a file in mm instead of m).
    ConfigError
        An option out of range.
    """
    for traj, name in ((src, names[0]), (dst, names[1])):
        if not isinstance(traj, Trajectory):
            raise TrajectoryError(f"{name}: expected a Trajectory, got {type(traj).__name__}")
    if not (np.isfinite(max_dt_s) and max_dt_s > 0):
        raise ConfigError(f"max_dt_s must be a number > 0, got {max_dt_s:g}")
    if not (np.isfinite(max_offset_s) and max_offset_s >= 0):
        raise ConfigError(f"max_offset_s must be a number >= 0, got {max_offset_s:g}")
    if time_offset_s is not None and not np.isfinite(time_offset_s):
        raise ConfigError(f"time_offset_s must be a finite number of seconds, got {time_offset_s:g}")
    if not 0.0 <= outlier_fraction < 0.5:
        raise ConfigError(f"outlier_fraction must be in [0, 0.5), got {outlier_fraction:g}")
    if matcher not in MATCHERS:
        raise ConfigError(f"matcher must be one of {', '.join(MATCHERS)}, got {matcher!r}")
    check_path_shape(src.positions, names[0])
    check_path_shape(dst.positions, names[1])
    if not with_scale:
        check_units(src.positions, dst.positions, names)

    def run(a):
        if use_timestamps:
            return _match_timed(a, dst, max_dt_s, time_offset_s, max_offset_s, with_scale,
                                outlier_fraction, names)
        return _match_free(a, dst, with_scale, outlier_fraction, use_orientations, names, matcher)

    reg = run(src)
    reg = _with_uncertainty(reg, src, dst, offset_estimated=use_timestamps and time_offset_s is None)

    def offset_check():
        try:
            off = estimate_time_offset(src.t_s, src.positions, dst.t_s, dst.positions,
                                       max_offset_s=max(max_offset_s, 2 * abs(time_offset_s)),
                                       with_scale=with_scale, names=names)
            alt = _match_timed(src, dst, max_dt_s, off, max_offset_s, with_scale, outlier_fraction, names)
        except TrajectoryError:
            return None
        return off, alt.rmse_mm

    status, reasons = verdict(src, dst, reg, mode=reg.mode, with_scale=with_scale, names=names,
                              offset_given=time_offset_s is not None, max_offset_s=max_offset_s,
                              rematch=run, offset_check=offset_check)
    return replace(reg, status=status, reasons=tuple(reasons))


def _with_uncertainty(reg, src, dst, offset_estimated=False):
    """``reg`` with ``std_rot_deg``, ``std_t_mm`` from :func:`.uncertainty.registration_covariance`."""
    inl = reg.inliers
    i_s, i_d = reg.pairs[inl, 0], reg.pairs[inl, 1]
    if i_s.size < 4:
        return reg
    pd, tangents, vel = dst.positions[i_d], None, None
    if offset_estimated:
        vel = path_velocity(dst.t_s, dst.positions, at=i_d)
    if reg.mode != "timestamps":
        tg, smooth = path_tangents(dst.positions, smoothed=True)
        pd, tangents = smooth[i_d], tg[i_d]
    cov, _ = registration_covariance(src.positions[i_s], pd, reg.R, reg.t_mm, reg.scale, tangents=tangents,
                                     velocities=vel)
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return replace(reg, std_rot_deg=np.rad2deg(sd[:3]), std_t_mm=sd[3:])


def _match_timed(src, dst, max_dt_s, offset, max_offset_s, with_scale, outlier_fraction, names):
    if offset is None:
        offset = estimate_time_offset(src.t_s, src.positions, dst.t_s, dst.positions,
                                      max_offset_s=max_offset_s, with_scale=with_scale, names=names)
    i_s, i_d = associate(src.t_s, dst.t_s, max_dt_s=max_dt_s, offset_s=offset)
    if i_s.size < MIN_POSES:
        raise TrajectoryError(
            f"no overlapping timestamps: only {i_s.size} pose pairs of {names[0]} "
            f"({src.t_s[0]:.3f}-{src.t_s[-1]:.3f} s) and {names[1]} ({dst.t_s[0]:.3f}-{dst.t_s[-1]:.3f} s) "
            f"lie within {max_dt_s:g} s of each other at a clock offset of {offset:+.3f} s, "
            f"at least {MIN_POSES} are needed")
    ps, pd = src.positions[i_s], dst.positions[i_d]
    check_path_shape(ps, f"{names[0]} (poses paired with {names[1]})")
    R, t, s, inl, _ = robust_umeyama(ps, pd, with_scale=with_scale, outlier_fraction=outlier_fraction)
    rmse, mean_e, max_e = _errors(ps, pd, R, t, s, inl)
    k = thin_indices(int(inl.sum()), SPREAD_MAX_PAIRS)       # a median: a subsample of a long log will do
    spread = np.rad2deg(body_rotation_spread(src.rotations[i_s[inl][k]], dst.rotations[i_d[inl][k]], R))
    return Registration(R, t, rmse, mean_e, max_e, int(i_s.size), inl, s, float(offset),
                        np.column_stack([i_s, i_d]), spread, "timestamps")


def _turns(R) -> bool:
    """True if the orientations along a path vary by more than ORIENTATION_STILL_DEG."""
    angles = rotation_angle_between(R, nearest_rotation(R.sum(0)), check=False)
    return bool(np.rad2deg(angles.max()) > ORIENTATION_STILL_DEG)


def _polish(ps, tree, pd, R, t, s, with_scale, max_iter=POLISH_ITERS):
    """Trimmed nearest-neighbour refinement of the CPD result against every dst pose.

    The CPD runs on thinned sets (``CPD_MAX_POINTS``), and the sample spacing on a fast path
    biases it (seen up to 0.6 deg on random smooth paths); this polish pairs every src pose with
    its nearest dst pose and re-fits (Umeyama) on the pairs within ``INLIER_SIGMAS`` robust sigmas
    until the pairing settles. A second CPD level on 1000 points was as accurate but 5x slower.
    """
    for _ in range(max_iter):
        dist, j = tree.query(s * ps @ R.T + t)
        inl = robust_inliers(dist)
        if inl.sum() < 3:
            break
        R_new, t_new, s_new = umeyama(ps[inl], pd[j[inl]], with_scale=with_scale)
        step = np.linalg.norm(R_new - R) * 1e3 + np.linalg.norm(t_new - t)
        R, t, s = R_new, t_new, s_new
        if step < 1e-4:
            break
    dist, j = tree.query(s * ps @ R.T + t)
    inl = robust_inliers(dist)
    return R, t, s, inl, j


def _line_refine(ps, tree, pd, tangents, R, t, s, inl, j, max_iter=LINE_ITERS):
    """Point-to-line Gauss-Newton refinement of a nearest-neighbour match.

    A nearest-neighbour pair measures the distance to a dst *sample*, not to the path: with dst
    samples a few mm apart that pulls the fit along the path by up to a sample spacing (seen as
    0.2-0.4 deg on the thin planar paths of the verdict tests). Here each pair's residual and
    Jacobian are projected across the local dst path direction (point-to-line), and ``R``, ``t``
    take Gauss-Newton steps on the inlier pairs until the step is below 1e-6 rad / 1e-4 mm.
    """
    for _ in range(max_iter):
        if inl.sum() < 6:
            break
        q = s * ps[inl] @ R.T
        e = pd[j[inl]] - q - t
        tg = tangents[j[inl]]
        J = np.zeros((len(q), 3, 6))
        J[:, 0, 1], J[:, 0, 2] = q[:, 2], -q[:, 1]          # d(exp([δ]x) q)/dδ = -[q]x
        J[:, 1, 0], J[:, 1, 2] = -q[:, 2], q[:, 0]
        J[:, 2, 0], J[:, 2, 1] = q[:, 1], -q[:, 0]
        J[:, :, 3:] = np.eye(3)
        J = J - tg[:, :, None] * np.einsum("ni,nij->nj", tg, J)[:, None, :]
        e = e - tg * np.einsum("ni,ni->n", tg, e)[:, None]
        H = np.einsum("nij,nik->jk", J, J)
        try:
            x = np.linalg.solve(H, np.einsum("nij,ni->j", J, e))
        except np.linalg.LinAlgError:
            break
        R = Rotation.from_rotvec(x[:3]).as_matrix() @ R
        t = t + x[3:]
        dist, j = tree.query(s * ps @ R.T + t)
        inl = robust_inliers(dist)
        if np.linalg.norm(x[:3]) < 1e-6 and np.linalg.norm(x[3:]) < 1e-4:
            break
    return R, t, inl, j


def _match_free(src, dst, with_scale, outlier_fraction, use_orientations, names, matcher="cpd"):
    ps, pd = src.positions, dst.positions
    turns = use_orientations and (_turns(src.rotations) or _turns(dst.rotations))
    Rsrc = src.rotations if turns else None
    Rdst = dst.rotations if turns else None
    w = max(outlier_fraction, 1e-3)
    coarse = coarse_align(ps, pd, w=w, with_scale=with_scale, R_src=Rsrc, R_dst=Rdst)
    if use_orientations and np.rad2deg(coarse.unresolved_rad) > SYMMETRY_DEG:
        raise TrajectoryError(
            f"{names[0]} and {names[1]}: the path is symmetric: rotations {np.rad2deg(coarse.unresolved_rad):.0f} deg "
            f"apart fit the positions equally well, and the orientations (constant along the path) cannot tell them "
            f"apart; match with timestamps, or record a path without symmetry (e.g. the asymmetric planar path "
            f"of eq. 17-19)")
    if matcher == "hybrid" and turns:
        R, t, s, inl, j = hybrid_refine(ps, src.rotations, pd, dst.rotations, coarse, w=w, with_scale=with_scale,
                                        max_points=CPD_MAX_POINTS)
    else:                     # (with constant orientations the hybrid mixture is the positional one)
        ks, kd = thin_indices(len(ps), CPD_MAX_POINTS), thin_indices(len(pd), CPD_MAX_POINTS)
        fine = rigid_cpd(pd[kd], ps[ks], R0=coarse.R, t0=coarse.t, s0=coarse.s, w=w, with_scale=with_scale,
                         sigma2=coarse.sigma2)
        tree = cKDTree(pd)
        R, t, s, inl, j = _polish(ps, tree, pd, fine.R, fine.t, fine.s, with_scale)
        tg, smooth = path_tangents(pd, smoothed=True)
        R, t, inl, j = _line_refine(ps, tree, smooth, tg, R, t, s, inl, j)
    rmse, mean_e, max_e = _errors(ps, pd[j], R, t, s, inl)
    spread = np.rad2deg(body_rotation_spread(src.rotations[inl], dst.rotations[j][inl], R))
    return Registration(R, t, rmse, mean_e, max_e, len(ps), inl, s, 0.0,
                        np.column_stack([np.arange(len(ps)), j]), spread, "no-timestamps", matcher=matcher)
