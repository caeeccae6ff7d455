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

Every result carries a verdict (:mod:`.quality`: ``status`` ok|suspect and ``reasons``, a
:class:`posekit.verdict.Verdict`) and a 1-sigma uncertainty about the base axes
(:mod:`.uncertainty`: Gauss-Newton with the residual variance, corrected for time-correlated
residuals; with a scale, its uncertainty and correlation are in it). With timestamps the pairing
(:mod:`.pairing`) drops repeated stamps, tests the clock offset against 0, and interpolates the dst
poses when nearest stamps pair too few; with a scale, :mod:`.scale` tests whether it drifts along
the path. The result says what was decided (``notes``), how many pairs were kept and dropped, and
the RMSE over all pairs (what evo reports) beside the one over the kept pairs.

The model is ``p_dst ≈ s R p_src + t`` for the positions of the two bodies. The bodies may have
different axes (a camera and a flange): orientations are only compared up to one constant rotation.
A lever arm between the two body origins is absorbed in ``t`` when the orientation is constant
along the path (the paper's planar calibration path); it is not modelled otherwise, and the
verdict flags it (``posekit localcal handeye`` solves that case).
"""

from dataclasses import dataclass, field, replace

import numpy as np

from posekit.errors import ConfigError, TrajectoryError
from posekit.localcal.model.trajectory import Trajectory
from posekit.localcal.registration.alignment import (
    body_rotation_spread,
    check_path_shape,
    robust_umeyama,
    thin_indices,
)
from posekit.localcal.registration.association import associate, estimate_time_offset
from posekit.localcal.registration.match_free import match_free
from posekit.localcal.registration.pairing import pair_by_time, without_duplicates
from posekit.localcal.registration.quality import check_units, verdict
from posekit.localcal.registration.scale import ScaleDrift, scale_drift
from posekit.localcal.registration.uncertainty import path_tangents, path_velocity, registration_covariance
from posekit.verdict import Verdict

__all__ = ["Registration", "match_trajectories"]

#: Pairs the orientation spread (a median) is computed on, at most (evenly subsampled).
SPREAD_MAX_PAIRS = 50_000
#: Correspondence-free fine matchers.
MATCHERS = ("cpd", "hybrid")
#: Dropped pairs listed in the JSON record, at most (``--residuals`` writes every pair).
DROPPED_LISTED = 100


def _f(v):
    """A JSON number, or None for NaN/inf."""
    v = float(v)
    return v if np.isfinite(v) else None


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
        Root-mean-square position residual over the kept (inlier) pairs, mm.
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
        Indices ``(i_src, i_dst)`` of the pairs in the input trajectories; ``i_dst`` is -1 for a
        dst pose interpolated at the src stamp (``pairing == 'interpolated'``).
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
        1-sigma uncertainty of ``t_mm`` along the base frame's axes, mm (with a scale, its
        uncertainty included).
    matcher : str
        Fine matcher used without timestamps ('cpd' or 'hybrid'; '' with timestamps).
    rmse_all_mm : float
        RMSE over every pair, the outliers included (what evo reports), mm.
    residuals_mm : ndarray, shape (n_pairs, 3)
        ``p_dst - (s R p_src + t)`` of every pair, mm.
    pair_t_s : ndarray, shape (n_pairs, 2)
        Timestamps ``(t_src, t_dst)`` of every pair, s.
    duplicate_stamps : int
        Poses dropped because their timestamp repeated (both inputs; the last of each stamp kept).
    pairing : {'nearest', 'interpolated', 'nearest-neighbour'}
        Nearest timestamps, dst poses interpolated at the src stamps, or (no timestamps) nearest
        positions.
    time_offset_std_s, time_offset_estimate_s : float
        1σ and value of the data's offset estimate, s (NaN when given).
    time_offset_source : {'given', 'estimated', 'zero', 'none'}
        ``zero``: estimated, but not different from 0 at the 1 % level, so 0 was used.
    notes : tuple of str
        What was decided and why (duplicates dropped, the offset taken as 0, interpolation).
    std_scale : float
        1σ of ``scale`` (NaN for a rigid match).
    scale_drift : ScaleDrift or None
        The per-segment scale test (with ``with_scale`` and timestamps).
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
    rmse_all_mm: float = float("nan")
    residuals_mm: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    pair_t_s: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    duplicate_stamps: int = 0
    pairing: str = "nearest"
    time_offset_std_s: float = float("nan")
    time_offset_estimate_s: float = float("nan")
    time_offset_source: str = "given"
    notes: tuple = ()
    std_scale: float = float("nan")
    scale_drift: ScaleDrift | None = None

    @property
    def T(self) -> np.ndarray:
        """``T_dst_src``, shape (4, 4), mm (the scale is folded into the rotation block)."""
        T = np.eye(4)
        T[:3, :3] = self.scale * self.R
        T[:3, 3] = self.t_mm
        return T

    @property
    def pairs_used(self) -> int:
        """Pairs kept by the outlier gate (the fit's pairs)."""
        return int(self.inliers.sum())

    @property
    def pairs_dropped(self) -> int:
        """Pairs dropped as outliers."""
        return int(self.n_pairs - self.inliers.sum())

    @property
    def verdict(self) -> Verdict:
        """The result's :class:`posekit.verdict.Verdict` (status, reasons, 1σ per component)."""
        std = {**{f"r{a}_deg": v for a, v in zip("xyz", self.std_rot_deg)},
               **{f"t{a}_mm": v for a, v in zip("xyz", self.std_t_mm)}}
        if np.isfinite(self.std_scale):
            std["scale"] = self.std_scale
        return Verdict(self.status, self.reasons, std)

    def to_json(self) -> dict:
        """The record of ``posekit localcal match``: ``R, t_mm, rmse_mm, mean_abs_err_mm, max_abs_err_mm`` first."""
        dropped = np.flatnonzero(~self.inliers)[:DROPPED_LISTED]
        out = {
            "R": self.R.tolist(),
            "t_mm": self.t_mm.tolist(),
            "rmse_mm": float(self.rmse_mm),
            "mean_abs_err_mm": self.mean_abs_err_mm.tolist(),
            "max_abs_err_mm": self.max_abs_err_mm.tolist(),
            "status": self.status,
            "reasons": list(self.reasons),
            "std_rot_deg": [_f(v) for v in self.std_rot_deg],
            "std_t_mm": [_f(v) for v in self.std_t_mm],
            "scale": float(self.scale),
            "time_offset_s": float(self.time_offset_s),
            "time_offset_std_s": _f(self.time_offset_std_s),
            "time_offset_source": self.time_offset_source,
            "n_pairs": int(self.n_pairs),
            "n_inliers": self.pairs_used,
            "pairs_used": self.pairs_used,
            "pairs_dropped": self.pairs_dropped,
            "rmse_all_mm": _f(self.rmse_all_mm),
            "rmse_kept_mm": _f(self.rmse_mm),
            "duplicate_stamps": int(self.duplicate_stamps),
            "pairing": self.pairing,
            "dropped": [{"t_src_s": float(self.pair_t_s[k, 0]), "error_mm": float(np.linalg.norm(self.residuals_mm[k]))}
                        for k in dropped] if len(self.pair_t_s) == self.n_pairs else [],
            "notes": list(self.notes),
            "orientation_spread_deg": _f(self.orientation_spread_deg),
            "mode": self.mode,
            **({"matcher": self.matcher} if self.matcher else {}),
        }
        if np.isfinite(self.std_scale) or self.scale_drift is not None:
            out["std_scale"] = _f(self.std_scale)
            out["scale_drift"] = None if self.scale_drift is None else self.scale_drift.to_json()
        return out


def _errors(p_src, p_dst, R, t, s, inl):
    """``(rmse over inliers, mean |e|, max |e|, rmse over all, residuals)`` of a fit, mm."""
    e = p_dst - (s * p_src @ R.T + t)
    ei = e[inl]
    rmse = float(np.sqrt((ei ** 2).sum(1).mean()))
    return rmse, np.abs(ei).mean(0), np.abs(ei).max(0), float(np.sqrt((e ** 2).sum(1).mean())), e


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
        ``±max_offset_s`` (and uses 0 when the estimate does not differ from 0 at the 1 % level).
    max_offset_s : float
        Half-width of the offset search, s.
    with_scale : bool
        Estimate a similarity (Sim(3)): for a monocular VO trajectory of unknown scale. The
        scale's std and the per-segment drift test are reported.
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
        and the 1-sigma uncertainty (``std_rot_deg``, ``std_t_mm``, ``std_scale``).

    Raises
    ------
    TrajectoryError
        Too few poses, a path that does not move or is a straight line, time spans that do not
        overlap, an ambiguous clock offset (a path that maps onto itself under a time
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

    if use_timestamps:
        pairing = pair_by_time(src, dst, max_dt_s=max_dt_s, time_offset_s=time_offset_s,
                               max_offset_s=max_offset_s, with_scale=with_scale, names=names)
        su, du = pairing.src, pairing.dst

        def run(a):
            if a is su:
                return _fit_pairs(a, du, pairing.i_src, pairing.i_dst, pairing.offset_s, with_scale,
                                  outlier_fraction, names)
            # another reading of src (the mirror/inverse diagnosis): paired afresh, its own clock offset
            alt = pair_by_time(a, dst, max_dt_s=max_dt_s, time_offset_s=time_offset_s, max_offset_s=max_offset_s,
                               with_scale=with_scale, names=names)
            return _fit_pairs(alt.src, alt.dst, alt.i_src, alt.i_dst, alt.offset_s, with_scale, outlier_fraction,
                              names)
        src_index, dst_index = pairing.src_index, pairing.dst_index
        extra = dict(duplicate_stamps=pairing.duplicate_stamps, pairing=pairing.mode, notes=pairing.notes,
                     time_offset_std_s=pairing.offset_std_s, time_offset_estimate_s=pairing.offset_estimate_s,
                     time_offset_source=pairing.offset_source)
        offset_nuisance = time_offset_s is None
    else:
        su, src_index, note_s = without_duplicates(src, names[0])
        du, dst_index, note_d = without_duplicates(dst, names[1])

        def run(a):
            R, t, s, inl, j, spread = match_free(a, du, with_scale, outlier_fraction, use_orientations, names, matcher)
            return _registration(a, du, np.arange(len(a)), j, R, t, s, inl, spread, 0.0, "no-timestamps", matcher)
        extra = dict(duplicate_stamps=len(src) + len(dst) - len(su) - len(du), pairing="nearest-neighbour",
                     notes=tuple(n for n in (note_s, note_d) if n), time_offset_source="none")
        offset_nuisance = False

    reg = replace(run(su), **extra)
    reg = _with_uncertainty(reg, su, du, offset_estimated=offset_nuisance, with_scale=with_scale)

    def offset_check():
        try:
            off = estimate_time_offset(su.t_s, su.positions, du.t_s, du.positions,
                                       max_offset_s=max(max_offset_s, 2 * abs(time_offset_s)),
                                       with_scale=with_scale, names=names)
            i_s, i_d = associate(su.t_s, du.t_s, max_dt_s=max_dt_s, offset_s=off)
            alt = _fit_pairs(su, du, i_s, i_d, off, with_scale, outlier_fraction, names)
        except TrajectoryError:
            return None
        return off, alt.rmse_mm

    status, reasons = verdict(su, du, reg, mode=reg.mode, with_scale=with_scale, names=names,
                              offset_given=time_offset_s is not None, max_offset_s=max_offset_s,
                              rematch=run, offset_check=offset_check)
    if reg.scale_drift is not None and reg.scale_drift.significant:
        d = reg.scale_drift
        reasons.append(f"the scale drifts along the path: {d.relative:+.2%} from start to end ({d.std:.2%} 1 sigma, "
                       f"{d.segments} segments): one similarity cannot fit a monocular trajectory whose scale drifts")
    v = Verdict("suspect" if reasons else "ok", tuple(reasons))
    # report the pairs in the inputs' numbering (duplicates dropped, -1 for an interpolated dst pose)
    pairs = reg.pairs.copy()
    if len(pairs):
        pairs[:, 0] = src_index[pairs[:, 0]]
        pairs[:, 1] = -1 if reg.pairing == "interpolated" else dst_index[pairs[:, 1]]
    return replace(reg, status=v.status, reasons=v.reasons, pairs=pairs)


def _with_uncertainty(reg, src, dst, offset_estimated=False, with_scale=False):
    """``reg`` with ``std_rot_deg``, ``std_t_mm`` (``std_scale``, ``scale_drift``) from
    :func:`.uncertainty.registration_covariance` and :func:`.scale.scale_drift`."""
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
                                     velocities=vel, fit_scale=with_scale)
    extra = {}
    if with_scale and reg.mode == "timestamps":
        drift = scale_drift(src.positions[i_s], dst.positions[i_d], reg.R)
        extra["scale_drift"] = drift
        if drift is not None:
            # one scale holds only on average along a drifting path: the scale at either end differs
            # from it by half the drift. Its (log) variance, drift measured or not, widens the scale's
            # and, through t = mean_dst - s R mean_src, the translation's covariance
            v = (drift.relative ** 2 + drift.std ** 2) / 4.0
            g = reg.scale * reg.R @ src.positions[i_s].mean(0)
            cov = cov.copy()
            cov[3:6, 3:6] += v * np.outer(g, g)
            cov[6, 6] += v
    sd = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    if with_scale:
        extra["std_scale"] = float(reg.scale * sd[6])
    return replace(reg, std_rot_deg=np.rad2deg(sd[:3]), std_t_mm=sd[3:6], **extra)


def _registration(src, dst, i_s, i_d, R, t, s, inl, spread, offset, mode, matcher=""):
    ps, pd = src.positions[i_s], dst.positions[i_d]
    rmse, mean_e, max_e, rmse_all, e = _errors(ps, pd, R, t, s, inl)
    return Registration(R, t, rmse, mean_e, max_e, int(i_s.size), inl, s, float(offset),
                        np.column_stack([i_s, i_d]), spread, mode, matcher=matcher, rmse_all_mm=rmse_all,
                        residuals_mm=e, pair_t_s=np.column_stack([src.t_s[i_s], dst.t_s[i_d]]))


def _fit_pairs(src, dst, i_s, i_d, offset, with_scale, outlier_fraction, names):
    """The robust Umeyama fit of timestamp pairs ``(i_s, i_d)``."""
    ps, pd = src.positions[i_s], dst.positions[i_d]
    check_path_shape(ps, f"{names[0]} (poses paired with {names[1]})")
    R, t, s, inl, _ = robust_umeyama(ps, pd, with_scale=with_scale, outlier_fraction=outlier_fraction)
    k = thin_indices(int(inl.sum()), SPREAD_MAX_PAIRS)       # a median: a subsample of a long log will do
    spread = np.rad2deg(body_rotation_spread(src.rotations[i_s[inl][k]], dst.rotations[i_d[inl][k]], R))
    return _registration(src, dst, i_s, i_d, R, t, s, inl, spread, offset, "timestamps")
