"""The verdict on a trajectory match: checks that say whether to believe a registration.

Every check looks at something the fit itself does not optimise, so a wrong transform cannot hide
from all of them at once:

* **sample count** — correspondence-free matching of a handful of poses always "fits";
* **units** — the two paths differ in size by ~1000 (a file in mm read as m), checked before
  any fit by :func:`check_units` (an error, since no rigid transform exists then);
* **coverage** — the matched part against both paths (a short camera file matched to a long log
  without timestamps lands on whatever part of the log looks alike);
* **orientation consistency** — after alignment the body-to-body rotation
  ``X_i = R_src_i^T R^T R_dst_i`` of two rigidly attached bodies is one constant rotation; a wrong
  ``R`` (mirror, inverted poses, a wrong clock offset, a partial match) makes it vary with the
  orientation. Positions-only matches are checked with it too;
* **lever arm** — residuals that follow the tool's orientation (``e_i ≈ R_dst_i y + c``) mean the
  camera is not at the tool point: the hand-eye problem (``posekit localcal handeye``);
* **degeneracy** — the spread of the matched positions across their main axis (a nearly straight
  path leaves the rotation about it weakly determined);
* **residual vs path extent** — residuals comparable to the size of the path (random data);
* **clock offset** — an estimate at the edge of the search, or a given ``--time-offset`` that the
  data contradict (e.g. the wrong sign);
* **mirror / inverse diagnosis** — when a check failed, a mirrored or inverted camera file is
  named if it explains the data much better.

The thresholds were set on the good and bad cases of ``tests/localcal/test_localcal_verdict.py``
(real TUM pairs and synthetic paths); the numbers quoted there.
"""

import numpy as np
from scipy.spatial import cKDTree

from posekit.errors import TrajectoryError
from posekit.localcal.registration.alignment import robust_principal_axes, thin_indices, umeyama
from posekit.localcal.registration.uncertainty import path_tangents

__all__ = [
    "COVERAGE_MIN",
    "DEGENERATE_RATIO",
    "LEVER_MIN_MM",
    "MIN_FREE_POSES",
    "ORIENTATION_MAX_DEG",
    "RESIDUAL_MAX_FRACTION",
    "check_units",
    "lever_arm_fit",
    "verdict",
]

#: Fewest poses on either side for correspondence-free matching (7 poses fit anything).
MIN_FREE_POSES = 30
#: Largest median body-to-body rotation spread after alignment, deg (good data: <= 0.9 deg on the
#: real TUM pairs and synthetic paths with 0.1 deg noise; wrong transforms: 4-126 deg).
ORIENTATION_MAX_DEG = 2.5
#: Largest RMSE as a fraction of the matched path's extent (std along its main axis); the real
#: TUM fr1/xyz SLAM pair has 0.11.
RESIDUAL_MAX_FRACTION = 0.25
#: Smallest spread across the main axis as a fraction of the spread along it (the paper's planar
#: path: ~0.1; a straight line is refused outright below 0.01).
DEGENERATE_RATIO = 0.05
#: Smallest share of inlier pairs, and (without timestamps) of each path covered by the match.
COVERAGE_MIN = 0.5
#: A fitted lever arm is reported when it is at least this long, mm, ...
LEVER_MIN_MM = 10.0
#: ... and removes at least this share of the residual variance.
LEVER_MIN_GAIN = 0.5
#: Longest pair list the checks look at (evenly subsampled beyond).
VERDICT_MAX_PAIRS = 20_000
#: Path extents differing by more than this factor cannot be the same motion in the same unit.
UNIT_RATIO_MAX = 20.0
#: A free-running clock-offset estimate within this share of the search edge is suspect.
OFFSET_EDGE_FRACTION = 0.95


def _extent(p) -> float:
    """Std along the main axis of a point set, mm (robust to gross outliers)."""
    return float(robust_principal_axes(p)[2][0])


def check_units(p_src, p_dst, names=("src", "dst")) -> None:
    """Raise TrajectoryError if the two paths cannot be the same motion in the same unit.

    Parameters
    ----------
    p_src, p_dst : ndarray, shape (N, 3)
        Positions of the two trajectories, mm (as read).
    names : (str, str)
        File names for the message.
    """
    a, b = _extent(p_src), _extent(p_dst)
    if a <= 0 or b <= 0:
        return
    ratio = a / b
    if 1.0 / UNIT_RATIO_MAX <= ratio <= UNIT_RATIO_MAX:
        return
    big, small = (names[0], names[1]) if ratio > 1 else (names[1], names[0])
    r = max(ratio, 1.0 / ratio)
    hint = ""
    if 300.0 <= r <= 3000.0:
        hint = "; is it in millimetres? trajectory files are in metres"
    elif 30.0 <= r < 300.0:
        hint = "; is it in centimetres? trajectory files are in metres"
    raise TrajectoryError(
        f"{big} moves {r:.0f}x as far as {small} ({max(a, b) / 1000:.3g} m vs {min(a, b) / 1000:.3g} m along "
        f"the main axis), not the same motion in one unit{hint}; unknown scale: --with-scale")


def lever_arm_fit(p_src, p_dst, R_dst, *, with_scale: bool = False, tangents=None, R=None, t=None, s=1.0,
                  n_iter: int = 8):
    """Fit ``p_dst_i = s R p_src_i + t + R_dst_i y``: a camera at ``-y`` from the tool point.

    Alternates a Umeyama fit and the linear least-squares lever ``y`` (tool frame).

    Parameters
    ----------
    p_src : ndarray, shape (K, 3)
        Paired src positions, mm.
    p_dst : ndarray, shape (K, 3)
        Paired dst positions, mm.
    R_dst : ndarray, shape (K, 3, 3)
        Paired dst orientations ``R_dstworld_tool``.
    with_scale : bool
        Similarity instead of rigid.
    tangents : ndarray, shape (K, 3), optional
        Unit dst path directions at the pairs, for nearest-neighbour pairs (no timestamps): their
        along-path residual is meaningless, so the model ``P_i e_i = P_i (R_dst_i y + c)`` is fitted
        to the residuals of the given ``R``, ``t``, ``s`` projected across the path (one linear
        least-squares solve).
    R, t, s : ndarray (3, 3), ndarray (3,), float
        The fitted transform, with ``tangents``.

    Returns
    -------
    y : ndarray, shape (3,)
        Lever in the dst body (tool) frame, mm.
    rmse : float
        RMSE of the model with the lever, mm.
    """
    if tangents is not None:
        P = np.eye(3) - tangents[:, :, None] * tangents[:, None, :]
        e = (P @ (p_dst - (s * p_src @ R.T + t))[:, :, None])[:, :, 0]
        A = np.concatenate([P @ R_dst, P], axis=2).reshape(-1, 6)
        x = np.linalg.lstsq(A, e.reshape(-1), rcond=None)[0]
        res = e.reshape(-1) - A @ x
        return x[:3], float(np.sqrt((res ** 2).sum() / len(e)))
    y = np.zeros(3)
    R, t, s = umeyama(p_src, p_dst, with_scale=with_scale)
    for _ in range(n_iter):
        R, t, s = umeyama(p_src, p_dst - R_dst @ y, with_scale=with_scale)
        e = p_dst - (s * p_src @ R.T + t)                    # = R_dst_i y + (c)
        A = R_dst - R_dst.mean(0)                            # remove the constant part
        y = np.linalg.lstsq(A.reshape(-1, 3), (e - e.mean(0)).reshape(-1), rcond=None)[0]
    R, t, s = umeyama(p_src, p_dst - R_dst @ y, with_scale=with_scale)
    e = p_dst - R_dst @ y - (s * p_src @ R.T + t)
    return y, float(np.sqrt((e ** 2).sum(1).mean()))


def _mirror_or_inverse(src, dst, reg, match, names):
    """Name a mirrored or inverted src file when it explains the data much better, else ''."""
    rmse = reg.rmse_mm
    found = []
    M = np.diag([1.0, 1.0, -1.0])
    Tm = src.T.copy()
    Tm[:, :3, 3] = Tm[:, :3, 3] @ M
    Tm[:, :3, :3] = M @ Tm[:, :3, :3] @ M
    for label, T in (("mirrored (a left-handed frame, one axis flipped)", Tm),
                     ("inverted (T_C_W, world in camera, written instead of T_W_C)", np.linalg.inv(src.T))):
        try:
            alt = match(type(src)(src.t_s, T))
        except Exception:                                   # noqa: BLE001 - a diagnosis only
            continue
        if (alt.rmse_mm < 0.5 * rmse and np.isfinite(alt.orientation_spread_deg)
                and alt.orientation_spread_deg < ORIENTATION_MAX_DEG):
            found.append(f"{names[0]} looks {label}: that reading fits with rmse {alt.rmse_mm:.1f} mm "
                         f"and orientation spread {alt.orientation_spread_deg:.2f} deg")
    return found


def verdict(src, dst, reg, *, mode: str, with_scale: bool = False, names=("src", "dst"),
            offset_given: bool = False, max_offset_s: float = 1.0, rematch=None, offset_check=None):
    """Status and reasons for a registration.

    Parameters
    ----------
    src, dst : Trajectory
        The matched trajectories (mm).
    reg : Registration
        The result (its ``pairs``, ``inliers``, ``R``, ``t_mm``, ``scale``).
    mode : {'timestamps', 'no-timestamps'}
        How the poses were paired.
    with_scale : bool
        Whether a scale was estimated.
    names : (str, str)
        File names for messages.
    offset_given : bool
        True when the clock offset was given rather than estimated.
    max_offset_s : float
        Half-width of the offset search, s.
    rematch : callable, optional
        ``rematch(src_like) -> Registration`` with the same options, for the mirror/inverse diagnosis.
    offset_check : callable, optional
        ``offset_check() -> (offset_s, rmse_mm) or None``: the offset the data prefer and the RMSE
        it gives, for a given ``--time-offset``.

    Returns
    -------
    status : {'ok', 'suspect'}
    reasons : list of str
        Empty when ``ok``.
    """
    reasons = []
    i_s, i_d = reg.pairs[:, 0], reg.pairs[:, 1]
    inl = reg.inliers
    if len(i_s) > VERDICT_MAX_PAIRS:                # statistics of shape: an even subsample suffices
        k = thin_indices(len(i_s), VERDICT_MAX_PAIRS)
        i_s, i_d, inl = i_s[k], i_d[k], inl[k]
    ps, pd = src.positions[i_s][inl], dst.positions[i_d][inl]
    Rd = dst.rotations[i_d][inl]
    free = mode != "timestamps"
    if free and min(len(src), len(dst)) < MIN_FREE_POSES:
        reasons.append(f"only {min(len(src), len(dst))} poses in {names[0] if len(src) < len(dst) else names[1]}: "
                       f"correspondence-free matching needs at least {MIN_FREE_POSES}; match with timestamps")
    # coverage of the matched part
    share = float(inl.mean()) if inl.size else 0.0
    if share < COVERAGE_MIN:
        reasons.append(f"only {share:.0%} of the pose pairs are inliers (at least {COVERAGE_MIN:.0%} expected)")
    if free and len(pd) >= 3:
        q = reg.scale * ps @ reg.R.T + reg.t_mm
        step = float(np.median(np.linalg.norm(np.diff(q, axis=0), axis=1)))     # thinned src: its spacing
        gate = max(4.0 * reg.rmse_mm, 2.0 * step, 1e-6)
        dist, _ = cKDTree(q).query(dst.positions)
        cov_dst = float((dist <= gate).mean())
        if cov_dst < COVERAGE_MIN:
            reasons.append(f"the matched part covers only {cov_dst:.0%} of {names[1]}'s poses: without "
                           f"timestamps both files must record the same path; match with timestamps, or "
                           f"crop {names[1]} to the camera's part")
    # degeneracy of the matched positions
    if len(pd) >= 3:
        sd = robust_principal_axes(pd)[2]
        if sd[1] < DEGENERATE_RATIO * sd[0]:
            reasons.append(f"the matched path is nearly straight ({sd[1]:.1f} mm across vs {sd[0]:.1f} mm along "
                           f"it, ratio {sd[1] / sd[0]:.3f} < {DEGENERATE_RATIO}): the rotation about it is weakly "
                           f"determined; record a planar or 3D path")
        extent = float(sd[0])
        if reg.rmse_mm > RESIDUAL_MAX_FRACTION * extent:
            reasons.append(f"rmse {reg.rmse_mm:.1f} mm is {reg.rmse_mm / extent:.0%} of the path's extent "
                           f"({extent:.1f} mm std along its main axis): the two paths do not have the same shape")
    # orientation consistency
    spread = reg.orientation_spread_deg
    if np.isfinite(spread) and spread > ORIENTATION_MAX_DEG:
        reasons.append(f"the orientations disagree with the fitted rotation: the camera-to-tool rotation varies "
                       f"by a median {spread:.1f} deg along the path (at most {ORIENTATION_MAX_DEG} deg expected)")
    # lever arm (hand-eye)
    if len(pd) >= 10 and reg.rmse_mm > 0:
        if free:
            tg = path_tangents(dst.positions)[i_d][inl]
            y, rmse_lever = lever_arm_fit(ps, pd, Rd, tangents=tg, R=reg.R, t=reg.t_mm, s=reg.scale)
            e = pd - (reg.scale * ps @ reg.R.T + reg.t_mm)
            e -= tg * np.einsum("ni,ni->n", tg, e)[:, None]
            rmse0 = float(np.sqrt((e ** 2).sum(1).mean()))
        else:
            y, rmse_lever = lever_arm_fit(ps, pd, Rd, with_scale=with_scale)
            rmse0 = reg.rmse_mm
        gain = 1.0 - (rmse_lever / max(rmse0, 1e-12)) ** 2
        if np.linalg.norm(y) >= LEVER_MIN_MM and gain >= LEVER_MIN_GAIN:
            reasons.append(f"the residuals follow the tool's orientation: the camera looks {np.linalg.norm(y):.0f} mm "
                           f"from the tool point (a lever arm removes {gain:.0%} of the residual variance, rmse "
                           f"{rmse0:.1f} -> {rmse_lever:.1f} mm); use `posekit localcal handeye`")
    # clock offset
    if not free:
        if not offset_given and max_offset_s > 0 and abs(reg.time_offset_s) >= OFFSET_EDGE_FRACTION * max_offset_s:
            reasons.append(f"the clock offset {reg.time_offset_s:+.3f} s lies at the edge of the search (±{max_offset_s:g} s): "
                           f"the true one may lie beyond; widen --max-offset or give --time-offset")
        if offset_given and offset_check is not None:
            got = offset_check()
            if got is not None:
                off, rmse_off = got
                if rmse_off < 0.7 * reg.rmse_mm and abs(off - reg.time_offset_s) > 0.01:
                    reasons.append(f"the data fit a clock offset of {off:+.3f} s (rmse {rmse_off:.1f} mm) better than "
                                   f"the given {reg.time_offset_s:+.3f} s: check the sign of --time-offset "
                                   f"(t_kinematic - t_camera)")
    if reasons and rematch is not None:
        reasons.extend(_mirror_or_inverse(src, dst, reg, rematch, names))
    return ("suspect" if reasons else "ok"), reasons
