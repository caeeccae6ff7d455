"""Pose pairs of two timed trajectories: duplicate stamps, the clock offset, and the association.

:func:`pair_by_time` is the timestamped front half of ``match``:

1. **duplicate stamps** — of every run of equal timestamps in a file the last pose is kept (a pose
   re-published at the same stamp supersedes the earlier one; evo's nearest-stamp match also picks
   the last); how many were dropped is reported;
2. **the clock offset** — given, or estimated (:func:`.association.estimate_time_offset`) with its
   1σ (:func:`.association.offset_std`). An estimate that does not differ from 0 at the
   significance level :data:`.association.OFFSET_ALPHA` is not a measured clock offset: the clocks
   are taken as synchronised (0) and a note says so. On KITTI 00 S-PTAM (3.7 m of drift) the data
   put the offset at +132 ± 149 ms: sampled at 10 Hz, that estimate paired no frame within
   0.02 s and ``match`` failed; 0 pairs every frame, as evo does;
3. **the association** — nearest timestamps within ``max_dt_s``, one to one
   (:func:`.association.associate`). When that pairs fewer than half of the src poses that fall
   inside the dst recording (two streams sampled at the same rate with a genuine offset between
   their clocks), the dst poses are interpolated at the src stamps instead (positions linearly,
   rotations along the geodesic: evo's ``SyncMethod.interpolation``), and a note says so.

A file pair whose time spans overlap by at least ``MIN_POSES`` poses therefore always gives pairs.
"""

from dataclasses import dataclass, field

import numpy as np

from posekit.errors import TrajectoryError
from posekit.localcal.model.trajectory import Trajectory

from .alignment import MIN_POSES
from .association import (
    associate,
    dedupe_stamps,
    edge_message,
    estimate_time_offset,
    offset_is_determined,
    offset_std,
    typical_gap,
)
from .handeye_time import PoseInterpolator

__all__ = ["INTERPOLATE_BELOW", "Pairing", "pair_by_time", "without_duplicates"]

#: Interpolate the dst poses when nearest-stamp pairs cover less than this share of the src poses
#: inside the dst recording.
INTERPOLATE_BELOW = 0.5


@dataclass(frozen=True)
class Pairing:
    """How two timed trajectories were paired.

    Attributes
    ----------
    src, dst : Trajectory
        The trajectories the pairs index: duplicate stamps removed; with interpolated pairing
        ``dst`` holds the interpolated dst poses (one per pair, at ``t_src + offset_s``).
    i_src, i_dst : ndarray of int, shape (K,)
        Paired indices into ``src`` and ``dst``.
    src_index, dst_index : ndarray of int
        Index of each pose of ``src`` / ``dst`` in the input file's trajectory (to report pairs
        in the user's numbering).
    offset_s : float
        Clock offset used, s (``t_dst ≈ t_src + offset_s``).
    offset_estimate_s, offset_std_s : float
        The data's estimate and its 1σ, s (NaN when the offset was given).
    offset_source : {'given', 'estimated', 'zero'}
        ``zero``: estimated, but not different from 0 at the significance level; 0 used.
    duplicate_stamps : int
        Poses dropped because their stamp repeated the next one's (both files).
    mode : {'nearest', 'interpolated'}
    notes : tuple of str
        What was decided and why, in words for the user.
    """

    src: Trajectory
    dst: Trajectory
    i_src: np.ndarray
    i_dst: np.ndarray
    src_index: np.ndarray
    dst_index: np.ndarray
    offset_s: float
    offset_estimate_s: float = float("nan")
    offset_std_s: float = float("nan")
    offset_source: str = "given"
    duplicate_stamps: int = 0
    mode: str = "nearest"
    notes: tuple = field(default_factory=tuple)


def without_duplicates(traj: Trajectory, name: str):
    """``(traj without repeated stamps, kept indices, note or None)``: the last of each run is kept."""
    keep = dedupe_stamps(traj.t_s)
    if keep.size == len(traj):
        return traj, keep, None
    n = len(traj) - keep.size
    note = (f"{name}: {n} pose{'s' if n > 1 else ''} with a repeated timestamp dropped "
            f"(the last pose of each stamp kept)")
    return Trajectory(traj.t_s[keep], traj.T[keep]), keep, note


def _inside(t_dst: np.ndarray, t_query: np.ndarray) -> np.ndarray:
    """Where dst has data around each query time: inside its span, between two samples no further
    apart than :func:`.association.typical_gap`, shape (M,) bool."""
    if t_dst.size < 2:
        return np.zeros(t_query.size, dtype=bool)
    k = np.clip(np.searchsorted(t_dst, t_query, side="right") - 1, 0, t_dst.size - 2)
    return (t_query >= t_dst[0]) & (t_query <= t_dst[-1]) & (t_dst[k + 1] - t_dst[k] <= typical_gap(t_dst))


def pair_by_time(src: Trajectory, dst: Trajectory, *, max_dt_s: float, time_offset_s: float | None,
                 max_offset_s: float, with_scale: bool, names=("src", "dst")) -> Pairing:
    """Pose pairs of two timed trajectories (the module docstring gives the steps).

    Parameters
    ----------
    src, dst : Trajectory
        Timestamps in s, poses in mm.
    max_dt_s : float
        Largest time difference of a nearest-stamp pair, s.
    time_offset_s : float or None
        Known clock offset, s; None estimates it within ``±max_offset_s``.
    max_offset_s : float
        Half-width of the offset search, s.
    with_scale : bool
        The match is a similarity (the offset is estimated with a scale).
    names : (str, str)
        Names for messages.

    Returns
    -------
    Pairing

    Raises
    ------
    TrajectoryError
        Fewer than ``MIN_POSES`` pairs (the spans do not overlap at the offset used); an
        estimated offset at the edge of the search that the data determine; the errors of
        :func:`.association.estimate_time_offset`.
    """
    notes = []
    n_in = len(src) + len(dst)
    src, keep_s, note = without_duplicates(src, names[0])
    notes += [note] if note else []
    dst, keep_d, note = without_duplicates(dst, names[1])
    notes += [note] if note else []
    dups = n_in - len(src) - len(dst)
    est, std, source = float("nan"), float("nan"), "given"
    if time_offset_s is None:
        est, at_edge = estimate_time_offset(src.t_s, src.positions, dst.t_s, dst.positions,
                                            max_offset_s=max_offset_s, with_scale=with_scale, names=names,
                                            edge="return")
        std = offset_std(est, src.t_s, src.positions, dst.t_s, dst.positions, with_scale=with_scale)
        if offset_is_determined(est, std):
            if at_edge:
                raise TrajectoryError(edge_message(names, est, max_offset_s))
            offset, source = est, "estimated"
        else:
            offset, source = 0.0, "zero"
            shown = "undetermined" if not np.isfinite(std) else f"{std * 1000:.1f} ms"
            notes.append(f"clock offset {est * 1000:+.1f} ms (1 sigma {shown}) does not differ from 0 at the "
                         "1% level: the clocks are taken as synchronised (give --time-offset to set one)")
    else:
        offset = float(time_offset_s)
    i_s, i_d = associate(src.t_s, dst.t_s, max_dt_s=max_dt_s, offset_s=offset)
    mode = "nearest"
    inside = _inside(dst.t_s, src.t_s + offset)
    if i_s.size < max(MIN_POSES, INTERPOLATE_BELOW * int(inside.sum())):
        if inside.sum() >= MIN_POSES:
            notes.append(f"only {i_s.size} of the {int(inside.sum())} {names[0]} poses inside {names[1]}'s recording "
                         f"have a {names[1]} pose within {max_dt_s:g} s at a clock offset of {offset:+.3f} s: "
                         f"{names[1]} poses interpolated at the {names[0]} stamps instead")
            i_s = np.flatnonzero(inside)
            T_interp = PoseInterpolator(dst.t_s, dst.T)(src.t_s[i_s] + offset)
            dst = Trajectory(src.t_s[i_s] + offset, T_interp)
            i_d, keep_d, mode = np.arange(i_s.size), np.full(i_s.size, -1), "interpolated"
        else:
            raise TrajectoryError(
                f"no overlapping timestamps: only {i_s.size} pose pairs of {names[0]} "
                f"({src.t_s[0]:.3f}-{src.t_s[-1]:.3f} s) and {names[1]} ({dst.t_s[0]:.3f}-{dst.t_s[-1]:.3f} s) "
                f"lie within {max_dt_s:g} s of each other at a clock offset of {offset:+.3f} s, "
                f"at least {MIN_POSES} are needed")
    return Pairing(src, dst, i_s, i_d, keep_s, keep_d, offset, est, std, source,
                   dups, mode, tuple(notes))
