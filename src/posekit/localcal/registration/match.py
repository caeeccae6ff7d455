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
  nearest-neighbour re-fit against every pose. The CPD's matrix-Fisher
  orientation term (hybrid-mixture style) is available in :func:`.cpd.rigid_cpd` but not used
  here: on synthetic paths it did not improve accuracy, it doubled the run time, and on the real
  TUM fr1/xyz pair it moved the result away from the timestamped reference (0.47 deg vs 0.24 deg).

The model is ``p_dst ≈ s R p_src + t`` for the positions of the two bodies. The bodies may have
different axes (a camera and a flange): orientations are only compared up to one constant rotation.
A lever arm between the two body origins is absorbed in ``t`` when the orientation is constant
along the path (the paper's planar calibration path); it is not modelled otherwise.
"""

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from posekit.errors import ConfigError, TrajectoryError
from posekit.geometry import nearest_rotation, rotation_angle_between
from posekit.localcal.registration.alignment import (
    _CHI3_MEDIAN,
    INLIER_SIGMAS,
    MIN_POSES,
    body_rotation_spread,
    check_path_shape,
    robust_umeyama,
    thin_indices,
    umeyama,
)
from posekit.localcal.registration.association import associate, estimate_time_offset
from posekit.localcal.registration.coarse import coarse_align
from posekit.localcal.registration.cpd import rigid_cpd
from posekit.localcal.registration.tum import Trajectory

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
            "scale": float(self.scale),
            "time_offset_s": float(self.time_offset_s),
            "n_pairs": int(self.n_pairs),
            "n_inliers": int(self.inliers.sum()),
            "orientation_spread_deg": (float(self.orientation_spread_deg)
                                       if np.isfinite(self.orientation_spread_deg) else None),
            "mode": self.mode,
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
                       names: tuple[str, str] = ("src", "dst")) -> Registration:
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
    names : (str, str)
        Names of src and dst for messages (e.g. file names).

    Returns
    -------
    Registration
        ``R`` is ``R_dst_src``, ``t_mm`` is ``t_dst_src`` (mm), with the residual statistics of
        the inlier pairs (mm) and the clock offset used (s).

    Raises
    ------
    TrajectoryError
        Too few poses, a path that does not move or is a straight line, no overlapping
        timestamps, an ambiguous clock offset (a path that maps onto itself under a time
        shift), or without timestamps a symmetric path whose orientations do not vary (unless
        ``use_orientations=False``, which keeps the best-scoring candidate).
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
    check_path_shape(src.positions, names[0])
    check_path_shape(dst.positions, names[1])
    if use_timestamps:
        return _match_timed(src, dst, max_dt_s, time_offset_s, max_offset_s, with_scale,
                            outlier_fraction, names)
    return _match_free(src, dst, with_scale, outlier_fraction, use_orientations, names)


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
    spread = np.rad2deg(body_rotation_spread(src.rotations[i_s][inl], dst.rotations[i_d][inl], R))
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
        inl = dist <= INLIER_SIGMAS * max(np.median(dist) / _CHI3_MEDIAN, 1e-9)
        if inl.sum() < 3:
            break
        R_new, t_new, s_new = umeyama(ps[inl], pd[j[inl]], with_scale=with_scale)
        step = np.linalg.norm(R_new - R) * 1e3 + np.linalg.norm(t_new - t)
        R, t, s = R_new, t_new, s_new
        if step < 1e-4:
            break
    dist, j = tree.query(s * ps @ R.T + t)
    inl = dist <= INLIER_SIGMAS * max(np.median(dist) / _CHI3_MEDIAN, 1e-9)
    return R, t, s, inl, j


def _match_free(src, dst, with_scale, outlier_fraction, use_orientations, names):
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
    ks, kd = thin_indices(len(ps), CPD_MAX_POINTS), thin_indices(len(pd), CPD_MAX_POINTS)
    fine = rigid_cpd(pd[kd], ps[ks], R0=coarse.R, t0=coarse.t, s0=coarse.s, w=w, with_scale=with_scale,
                     sigma2=coarse.sigma2)
    R, t, s, inl, j = _polish(ps, cKDTree(pd), pd, fine.R, fine.t, fine.s, with_scale)
    rmse, mean_e, max_e = _errors(ps, pd[j], R, t, s, inl)
    spread = np.rad2deg(body_rotation_spread(src.rotations[inl], dst.rotations[j][inl], R))
    return Registration(R, t, rmse, mean_e, max_e, len(ps), inl, s, 0.0,
                        np.column_stack([np.arange(len(ps)), j]), spread, "no-timestamps")
