"""Time for hand-eye: pose interpolation and a clock-offset estimate that does not depend on the
unknown camera mount.

``association.estimate_time_offset`` aligns positions, which a camera off the tool point does not
share with the tool (a 240 mm lever arm biased it by 61 ms). The angle a body turns in a time
step is the same for every point and frame of a rigid body (``A_ij = X B_ij X^-1``), so the
offset is found here by matching the angular-speed profiles of the two trajectories.

Clock convention as in :mod:`.association`: ``t_kinematic ≈ t_camera + offset_s``.
"""

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.spatial.transform import Rotation

from posekit.errors import TrajectoryError

from .alignment import thin_indices

__all__ = ["PoseInterpolator", "angular_speed", "estimate_offset_by_rotation"]

#: Camera samples the offset search evaluates (evenly thinned beyond).
_OFFSET_SAMPLES = 800
#: Most offsets of the grid search (a step coarser than a tenth of the window may miss the optimum:
#: the CLI bounds the search to +-100 s, 20,000 steps of 10 ms).
_MAX_GRID = 20_000
#: Fewest overlapping samples an offset needs to be scored.
_MIN_OVERLAP = 10


class PoseInterpolator:
    """Poses of a trajectory at arbitrary times: positions linear, rotations along the geodesic.

    Parameters
    ----------
    t_s : ndarray, shape (N,)
        Sample times, s, non-decreasing, N >= 2.
    T : ndarray, shape (N, 4, 4)
        Poses ``T_world_body``, mm.
    """

    def __init__(self, t_s, T):
        self.t_s = np.asarray(t_s, dtype=np.float64)
        self.T = np.asarray(T, dtype=np.float64)
        R = Rotation.from_matrix(self.T[:, :3, :3])
        self._R = R
        self._seg = (R[:-1].inv() * R[1:]).as_rotvec()          # body-frame step of each segment
        self._dt = np.diff(self.t_s)

    def segment(self, t_query):
        """Index k of the segment ``[t_k, t_k+1]`` holding each query, the fraction along it, and
        the distance in time to the nearer sample, s (0 inside the span)."""
        tq = np.asarray(t_query, dtype=np.float64)
        k = np.clip(np.searchsorted(self.t_s, tq, side="right") - 1, 0, self.t_s.size - 2)
        dt = self._dt[k]
        f = np.where(dt > 0, (tq - self.t_s[k]) / np.where(dt > 0, dt, 1.0), 0.0)
        outside = np.maximum(self.t_s[0] - tq, tq - self.t_s[-1]).clip(min=0)
        return k, np.clip(f, 0.0, 1.0), outside

    def __call__(self, t_query) -> np.ndarray:
        """Poses at ``t_query`` (shape (M,)), shape (M, 4, 4), mm; clamped at the ends."""
        k, f, _ = self.segment(t_query)
        T = np.zeros((k.size, 4, 4))
        T[:, :3, :3] = self.T[k, :3, :3] @ Rotation.from_rotvec(self._seg[k] * f[:, None]).as_matrix()
        T[:, :3, 3] = (1 - f)[:, None] * self.T[k, :3, 3] + f[:, None] * self.T[k + 1, :3, 3]
        T[:, 3, 3] = 1.0
        return T

    def rotations(self, t_query) -> Rotation:
        """Orientations at ``t_query`` as a scipy Rotation (clamped at the ends)."""
        k, f, _ = self.segment(t_query)
        return self._R[k] * Rotation.from_rotvec(self._seg[k] * f[:, None])


def angular_speed(interp: PoseInterpolator, t_s, h_s: float) -> np.ndarray:
    """Mean angular speed over ``[t, t + h_s]`` at each ``t_s``, rad/s (frame-independent)."""
    t_s = np.asarray(t_s, dtype=np.float64)
    R0, R1 = interp.rotations(t_s), interp.rotations(t_s + h_s)
    return (R0.inv() * R1).magnitude() / h_s


def _speed_grid(t_kin, h: float, step: float):
    """Grid times over the stretches of continuous data of a log, and each stretch's ``[lo, hi]``.

    A stretch ends where two samples are further apart than ``max(5 x the median step, 2 h)``;
    the grid covers ``[start, end - h]`` of each stretch (the speed over ``[t, t + h]`` needs data
    up to ``t + h``).
    """
    d = np.diff(t_kin)
    med = float(np.median(d[d > 0])) if np.any(d > 0) else 0.0
    cut = np.flatnonzero(d > max(5.0 * med, 2.0 * h)) + 1
    starts, ends = t_kin[np.r_[0, cut]], t_kin[np.r_[cut - 1, t_kin.size - 1]]
    keep = ends - h > starts
    lo, hi = starts[keep], ends[keep] - h
    if lo.size == 0:
        return np.zeros(0), np.zeros(1), np.zeros(1) - 1.0
    grid = np.concatenate([np.arange(a, b, step) for a, b in zip(lo, hi)])
    return grid, lo, hi


def estimate_offset_by_rotation(t_cam, T_cam, t_kin, T_kin, *, max_offset_s: float = 1.0,
                                names=("camera", "kinematic")) -> tuple[float, bool]:
    """Clock offset that best matches the angular-speed profiles of two trajectories of one body.

    Parameters
    ----------
    t_cam, t_kin : ndarray, shape (M,), (N,)
        Camera and kinematic timestamps, s.
    T_cam, T_kin : ndarray, shape (M, 4, 4), (N, 4, 4)
        ``T_world_camera`` and ``T_base_tool``, mm (only the rotations are used).
    max_offset_s : float
        Half-width of the search, s.
    names : (str, str)
        Input names for messages.

    Returns
    -------
    offset_s : float
        ``t_kin ≈ t_cam + offset_s``, s.
    at_edge : bool
        The best offset lies at the edge of the search (the true one may be beyond it).

    Raises
    ------
    TrajectoryError
        If no offset in the range overlaps a third of the camera samples (at least 3, and 10 when
        there are that many) with the kinematic span.
    """
    t_cam = np.asarray(t_cam, dtype=np.float64)
    t_kin = np.asarray(t_kin, dtype=np.float64)
    cam, kin = PoseInterpolator(t_cam, T_cam), PoseInterpolator(t_kin, T_kin)
    dt_cam = float(np.median(np.diff(t_cam))) if t_cam.size > 1 else 0.0
    h = max(0.1, 3.0 * dt_cam)
    tc = t_cam[thin_indices(t_cam.size, _OFFSET_SAMPLES)]
    tc = tc[tc + h <= t_cam[-1]]
    w_cam = angular_speed(cam, tc, h)
    # kinematic speed on a grid fine enough to interpolate (a tenth of the window), built only over
    # the stretches where the log has data: memory follows the samples, not the time span (a log
    # with one 1e6 s jump in its stamps would otherwise need a grid of 1e8 points)
    step = h / 10.0
    grid, lo, hi = _speed_grid(t_kin, h, step)
    if grid.size < 2:
        raise TrajectoryError(f"{names[1]}: spans {t_kin[-1] - t_kin[0]:.3g} s; too short to estimate "
                              f"a clock offset (needs > {2 * h:.3g} s)")
    w_kin = angular_speed(kin, grid, h)

    def inside(tq):
        b = np.clip(np.searchsorted(lo, tq, side="right") - 1, 0, lo.size - 1)
        return (tq >= lo[b]) & (tq <= hi[b])

    def cost(offset):
        tq = tc + offset
        ok = inside(tq)
        if ok.sum() < max(min(_MIN_OVERLAP, tc.size), 3, tc.size // 3):
            return np.inf
        return float(np.mean(np.abs(w_cam[ok] - np.interp(tq[ok], grid, w_kin))))

    span = max(max_offset_s, 0.0)
    coarse = max(min(step, span / 20.0), 1e-4, span / _MAX_GRID) if span > 0 else 1.0
    offsets = np.arange(-span, span + coarse / 2, coarse) if span > 0 else np.zeros(1)
    costs = np.array([cost(o) for o in offsets])
    if not np.isfinite(costs).any():
        raise TrajectoryError(f"{names[0]} and {names[1]} do not overlap in time within a clock offset of "
                              f"+-{max_offset_s:g} s (camera {t_cam[0]:.3f}..{t_cam[-1]:.3f} s, kinematic "
                              f"{t_kin[0]:.3f}..{t_kin[-1]:.3f} s); give --time-offset or --max-offset")
    b = int(np.argmin(costs))
    best = float(offsets[b])
    if span > 0:
        r = minimize_scalar(cost, bounds=(max(best - coarse, -span), min(best + coarse, span)), method="bounded",
                            options={"xatol": 1e-5})
        if np.isfinite(r.fun) and r.fun <= costs[b]:
            best = float(r.x)
    at_edge = span > 0 and abs(best) > span - 1.5 * coarse
    return best, at_edge
