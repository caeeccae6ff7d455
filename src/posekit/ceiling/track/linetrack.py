"""Pose from one laser *line* on the ceiling (the paper's case C).

A segment on the ceiling gives the robot's position (its centre) and its heading up to
180° (a line has no sense). Per frame the two end points of the detected segment
(:meth:`~posekit.ceiling.detect.Line.endpoints`) are mapped to the world plane through the
calibration; their world midpoint is the position measurement, fed to the ordinary dot
:class:`~posekit.ceiling.track.Tracker` as its primary ('red') dot, and the world direction
``φ`` of the segment, mod 180°, is the heading measurement.

Heading: a circular constant-turn-rate filter ``[θ, ω]`` (θ unwrapped). Each frame the
branch ``φ`` or ``φ + 180°`` closest to the predicted θ is used (the innovation is wrapped
to (-90°, 90°]), so the heading stays continuous through any angle, ±90° included. The
branch itself — which end is the front — is resolved from the motion of the robot (a ground
robot drives forward along its heading):

* initialisation: the heading is reported as unknown (NaN, an empty CSV field) until the
  robot has moved ``init_motion_mm`` along a straight stretch (its axis turned by less than
  ``straight_tol_deg``); then θ is put on the branch within 90° of the direction of motion;
* re-check: whenever the robot drives straight over at least ``init_motion_mm`` within
  ``window_s``, a direction of motion more than 90° from θ on ``flip_after`` consecutive
  frames flips θ by 180°.

A robot that drives *backwards* for ``flip_after`` frames therefore flips the heading:
the motion is the only cue of the sense of a line.

Statuses are those of :class:`~posekit.ceiling.track.Tracker` (``ok`` only with a segment
measured and accepted this frame). When the segment is shorter than the expected length
(part of it hidden by a vent or out of the image) the midpoint is not the centre: the
centre is measured half a length from the intact end (the end that agrees with the
prediction); if neither does, the frame updates only the heading and the position is
predicted. (Without ``line_length_mm`` the expected length is learnt from the segments
seen, so a track that *starts* with a cut segment has a biased centre for a few frames.) The heading is forgotten (and
must be re-initialised from the motion) when no segment was seen for ``max_predict_s``.
"""

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from ...errors import ConfigError, GeometryError, TrajectoryError
from .tracker import HeadingState, Tracker, TrackerConfig, TrackRow, cv_predict, kf_update

__all__ = ["LineTracker", "LineTrackerConfig", "DottedLineDetector", "dots_to_line", "line_world_measurement",
           "pick_line", "wrap_half"]


def _wrap(a: float) -> float:
    """Angle wrapped to (-π, π]."""
    return float(np.pi - np.mod(np.pi - a, 2.0 * np.pi))


def wrap_half(a):
    """Angle(s) wrapped to (-π/2, π/2] (the difference of two axes, which have no sense)."""
    return np.pi / 2 - np.mod(np.pi / 2 - np.asarray(a, dtype=float), np.pi)


@dataclass(frozen=True)
class LineTrackerConfig:
    """Tuning of :class:`LineTracker` (mm, s, degrees).

    Attributes
    ----------
    tracker : TrackerConfig
        Position filter (its ``dots`` are replaced by ``("red",)``: the segment's midpoint
        is the primary dot, and ``min_move_mm`` by 0: a segment needs no motion to be
        believed); its ``max_predict_s``, ``heading_psd_rad2_s3`` and
        ``init_rate_std_rad_s`` also tune the heading filter.
    init_motion_mm : float
        Straight travel that resolves (or re-checks) the forward/backward branch.
    window_s : float
        The straight travel is measured over at most this long.
    straight_tol_deg : float
        A stretch is straight while the line's axis turns by less than this.
    flip_after : int
        Consecutive straight frames whose direction of motion is more than 90° from the
        heading before the heading is flipped by 180°.
    min_angle_std_deg : float
        Floor of the std of the measured line direction.
    line_length_mm : float or None
        Length of the line on the ceiling; None: the median of the lengths measured so far.
    length_tol : float
        A segment shorter than ``(1 - length_tol)`` times the expected length is cut (vent,
        image border): its midpoint is not the centre; the centre is taken half a length
        from the intact end (the one agreeing with the prediction), or not measured.
    """

    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    init_motion_mm: float = 30.0
    window_s: float = 1.0
    straight_tol_deg: float = 10.0
    flip_after: int = 5
    min_angle_std_deg: float = 0.05
    line_length_mm: float | None = None
    length_tol: float = 0.04

    def __post_init__(self):
        if not isinstance(self.tracker, TrackerConfig):
            raise ConfigError(f"LineTrackerConfig.tracker: expected a TrackerConfig, got {self.tracker!r}")
        # a segment is verified by its shape (a lamp is no line): it starts a track at once, even while
        # the robot turns on the spot, where the dot tracker would wait for motion (min_move_mm)
        no_wait = {"min_move_mm": 0.0} if hasattr(self.tracker, "min_move_mm") else {}
        object.__setattr__(self, "tracker", replace(self.tracker, dots=("red",), **no_wait))
        for name in ("init_motion_mm", "window_s", "straight_tol_deg", "min_angle_std_deg"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"LineTrackerConfig.{name}: expected a positive number, got {v!r}")
        if int(self.flip_after) != self.flip_after or self.flip_after < 1:
            raise ConfigError(f"LineTrackerConfig.flip_after: expected an integer >= 1, got {self.flip_after!r}")
        if self.line_length_mm is not None and not (np.isfinite(self.line_length_mm) and self.line_length_mm > 0):
            raise ConfigError(f"LineTrackerConfig.line_length_mm: expected a positive number or None, "
                              f"got {self.line_length_mm!r}")
        if not (0 <= self.length_tol < 1):
            raise ConfigError(f"LineTrackerConfig.length_tol: expected a number in [0, 1), got {self.length_tol!r}")


def line_world_measurement(ends_world, ends_cov=None):
    """Midpoint, axis angle and their uncertainty of a segment given by its world end points.

    Parameters
    ----------
    ends_world : array_like, shape (2, 2)
        The two end points, mm.
    ends_cov : array_like, shape (2, 2, 2), optional
        Covariance of each end point, mm² (default: 1 mm² isotropic).

    Returns
    -------
    mid : ndarray, shape (2,)
        World midpoint, mm.
    mid_cov : ndarray, shape (2, 2)
        Its covariance, mm².
    phi : float
        Direction of the segment, rad in [0, π).
    phi_var : float
        Variance of ``phi``, rad² (perpendicular scatter of the ends over the length²).
    length : float
        World length, mm.
    """
    e = np.asarray(ends_world, dtype=float).reshape(2, 2)
    R = np.broadcast_to(np.eye(2), (2, 2, 2)) if ends_cov is None else np.asarray(ends_cov, dtype=float).reshape(2, 2, 2)
    d = e[1] - e[0]
    length = float(np.hypot(*d))
    if not np.all(np.isfinite(e)) or length <= 0:
        raise GeometryError(f"line_world_measurement: expected two distinct finite end points, got {e.tolist()}")
    n = np.array([-d[1], d[0]]) / length
    phi = float(np.mod(np.arctan2(d[1], d[0]), np.pi))
    return 0.5 * (e[0] + e[1]), 0.25 * (R[0] + R[1]), phi, float(n @ (R[0] + R[1]) @ n) / length ** 2, length


class LineTracker:
    """Position and heading (180° ambiguity resolved by the motion) from a laser line.

    Examples
    --------
    >>> lt = LineTracker()
    >>> rows = [lt.step(k / 15, [[20.0 * k - 150, 0.0], [20.0 * k + 150, 0.0]]) for k in range(5)]
    >>> [r.status for r in rows], round(rows[-1].heading_deg, 3)
    (['ok', 'ok', 'ok', 'ok', 'ok'], 0.0)
    >>> import math; math.isnan(rows[0].heading_deg)      # not moved yet: sense unknown
    True
    """

    def __init__(self, config: LineTrackerConfig | None = None):
        self.config = LineTrackerConfig() if config is None else config
        self.tracker = Tracker(self.config.tracker)
        self.reset()

    def reset(self) -> None:
        """Forget position, heading and branch."""
        self.tracker.reset()
        self.heading = HeadingState()
        self.branch_known = False
        self.n_disagree = 0
        self.n_flips = 0
        self._history: deque = deque()          # (t, x, y, θ) of ok frames on the current straight stretch
        self._lengths: deque = deque(maxlen=31)
        self.t_s = float("nan")

    # -- helpers -----------------------------------------------------------------------------
    def _expected_length(self) -> float:
        """The configured length, else the 90th percentile of the last 31 measured lengths
        (a segment cut by a vent shrinks for a few frames only)."""
        if self.config.line_length_mm is not None:
            return float(self.config.line_length_mm)
        return float(np.percentile(self._lengths, 90)) if self._lengths else float("nan")

    def _centre_from_one_end(self, t_s: float, ends: np.ndarray, ends_cov: np.ndarray, length: float):
        """Centre of a cut segment from its intact end: ``end ± length/2`` along the axis, the
        end whose centre lies closest to the predicted one (within ``gate_floor_mm``);
        (None, None) without a prediction or when neither end fits."""
        pred = self.tracker.predict(t_s).get("red")
        if pred is None:
            return None, None
        d = ends[1] - ends[0]
        u = d / np.hypot(*d)
        cands = np.stack([ends[0] + 0.5 * length * u, ends[1] - 0.5 * length * u])
        dist = np.hypot(*(cands - pred[0]).T)
        k = int(np.argmin(dist))
        if dist[k] > self.config.tracker.gate_floor_mm:
            return None, None
        return cands[k], ends_cov[k]

    def _update_heading(self, t_s: float, phi: float | None, var: float) -> None:
        cfg, tc = self.config, self.config.tracker
        h = self.heading
        if h.x is not None and t_s - h.t_meas_s > tc.max_predict_s + 1e-9:
            h.x = h.P = None                        # not seen for too long: the robot may have turned
            self.branch_known = False
            self._history.clear()
            self.n_disagree = 0
        if h.x is not None:
            h.x, h.P = cv_predict(h.x, h.P, max(t_s - h.t_s, 0.0), tc.heading_psd_rad2_s3)
        h.t_s = t_s
        if phi is None:
            return
        var = max(var, np.radians(cfg.min_angle_std_deg) ** 2)
        if h.x is None:
            h.x = np.array([phi, 0.0])
            h.P = np.diag([var, tc.init_rate_std_rad_s ** 2])
        else:
            nu = float(wrap_half(phi - h.x[0]))     # the branch φ or φ + π closest to the prediction
            h.x, h.P = kf_update(h.x, h.P, np.array([h.x[0] + nu]), np.array([[var]]), innovation=np.array([nu]))
        h.t_meas_s = t_s

    def _check_branch(self, t_s: float, row: TrackRow) -> None:
        """Resolve / re-check the sense of the heading from the direction of straight motion."""
        cfg = self.config
        h = self.heading
        if h.x is None or row.status != "ok":
            return
        theta = float(h.x[0])
        hist = self._history
        tol = np.radians(cfg.straight_tol_deg)
        hist.append((t_s, row.x, row.y, theta))
        while hist and (t_s - hist[0][0] > cfg.window_s + 1e-9 or abs(float(wrap_half(theta - hist[0][3]))) > tol):
            hist.popleft()
        if len(hist) < 2:
            return
        dx, dy = row.x - hist[0][1], row.y - hist[0][2]
        if np.hypot(dx, dy) < cfg.init_motion_mm:
            return
        motion = float(np.arctan2(dy, dx))
        off = abs(_wrap(motion - theta)) > np.pi / 2
        if not self.branch_known:
            if off:
                h.x = h.x.copy()
                h.x[0] += np.pi
            self.branch_known = True
            self.n_disagree = 0
            return
        self.n_disagree = self.n_disagree + 1 if off else 0
        if self.n_disagree >= cfg.flip_after:
            h.x = h.x.copy()
            h.x[0] += np.pi
            self.n_disagree = 0
            self.n_flips += 1
            hist.clear()

    # -- one frame ---------------------------------------------------------------------------
    def step(self, t_s: float, ends_world=None, ends_cov=None, *, frame: int | None = None,
             camera: int = -1) -> TrackRow:
        """Advance to ``t_s`` with this frame's segment (or None).

        Parameters
        ----------
        t_s : float
            Frame time, s (non-decreasing).
        ends_world : array_like, shape (2, 2), or None
            World end points of the detected segment, mm; None: no segment this frame.
        ends_cov : array_like, shape (2, 2, 2), optional
            Covariance of each end point, mm² (default ``meas_std_mm²·I``).
        frame : int, optional
        camera : int

        Returns
        -------
        TrackRow
            ``x, y``: centre of the line; ``heading_deg`` in (-180, 180], NaN while the
            sense of the line is unknown or the heading is lost; ``status`` as the
            :class:`~posekit.ceiling.track.Tracker` (``ok`` only with a segment measured).
        """
        t_s = float(t_s)
        if not np.isfinite(t_s):
            raise TrajectoryError(f"LineTracker.step: frame time must be finite, got {t_s}")
        if np.isfinite(self.t_s) and t_s < self.t_s:
            raise TrajectoryError(f"LineTracker.step: frame time went back from {self.t_s:.6f} s to {t_s:.6f} s")
        self.t_s = t_s
        tc = self.config.tracker
        phi, var, pos, pos_cov = None, 0.0, None, None
        if ends_world is not None:
            if ends_cov is None:
                ends_cov = np.broadcast_to(tc.meas_std_mm ** 2 * np.eye(2), (2, 2, 2))
            ends_world = np.asarray(ends_world, dtype=float).reshape(2, 2)
            ends_cov = np.asarray(ends_cov, dtype=float).reshape(2, 2, 2)
            mid, mid_cov, phi, var, length = line_world_measurement(ends_world, ends_cov)
            expected = self._expected_length()
            if self.config.line_length_mm is None:
                self._lengths.append(length)
            if np.isfinite(expected) and length < (1.0 - self.config.length_tol) * expected:
                pos, pos_cov = self._centre_from_one_end(t_s, ends_world, ends_cov, expected)
            else:
                pos, pos_cov = mid, mid_cov
        row = self.tracker.step(t_s, None if pos is None else {"red": pos},
                                None if pos is None else {"red": pos_cov}, frame=frame, camera=camera)
        # a segment gated out of the position filter is not trusted for the heading either
        self._update_heading(t_s, phi if (phi is not None and (pos is None or row.status == "ok")) else None, var)
        self._check_branch(t_s, row)
        h = self.heading
        heading = float("nan")
        if self.branch_known and h.x is not None and row.status != "lost":
            heading = float(np.degrees(_wrap(float(h.x[0]))))
            heading = 180.0 if heading == -180.0 else heading
        row.heading_deg = heading
        return row


def pick_line(lines: Sequence, camera) -> tuple[np.ndarray, np.ndarray] | None:
    """World end points (2, 2) and their covariances (2, 2, 2) of the longest segment seen
    by ``camera`` (a :class:`~posekit.ceiling.track.Camera`), or None."""
    if not lines:
        return None
    ends_uv = lines[0].endpoints()
    xy, cov = camera.measurement(ends_uv)
    if not np.all(np.isfinite(xy)):
        return None
    return xy, cov


# --- the dotted line of §III-C ------------------------------------------------------------------

def dots_to_line(uv, *, tol_px: float = 2.0, min_dots: int = 3, max_gap_ratio: float = 2.6):
    """The largest set of collinear, evenly spaced dots among ``uv`` as a segment.

    A laser dot-line generator (the paper's Fig. 3, left) projects a row of equally spaced dots;
    the row's end dots are the ends of the segment, so a dotted line feeds
    :class:`LineTracker` like a solid one (a row cut by a vent is shorter: the tracker takes the
    centre from the intact end). Every pair of dots proposes a line; the one with the most dots
    within ``tol_px`` wins (ties: the smaller spread about it). Dots missing inside the row are
    allowed up to ``max_gap_ratio`` times the smallest gap (a dot lost in a vent).

    Parameters
    ----------
    uv : array_like, shape (N, 2)
        Dot centres in the image, px.

    Returns
    -------
    tuple (ends, members) or None
        ``ends`` (2, 2) px, the outermost dots along the fitted axis, projected onto it;
        ``members`` the indices of the dots used. None with fewer than ``min_dots`` in a row.
    """
    pts = np.asarray(uv, dtype=float).reshape(-1, 2)
    pts_ok = np.flatnonzero(np.all(np.isfinite(pts), axis=1))
    best = None
    for a_i in range(len(pts_ok)):
        for b_i in range(a_i + 1, len(pts_ok)):
            a, b = pts[pts_ok[a_i]], pts[pts_ok[b_i]]
            d = b - a
            n = np.hypot(*d)
            if n < 1e-6:
                continue
            u = d / n
            perp = np.abs((pts[pts_ok] - a) @ np.array([-u[1], u[0]]))
            members = pts_ok[perp <= tol_px]
            if len(members) < min_dots:
                continue
            s_along = np.sort((pts[members] - a) @ u)
            gaps = np.diff(s_along)
            if gaps.min() <= 1e-6 or gaps.max() > max_gap_ratio * gaps.min() * 1.0001:
                continue
            score = (len(members), -float(np.sum(perp[perp <= tol_px] ** 2)))
            if best is None or score > best[0]:
                best = (score, members)
    if best is None:
        return None
    members = best[1]
    p = pts[members]
    c = p.mean(axis=0)
    _, _, vt = np.linalg.svd(p - c)
    axis = vt[0]
    s_along = (p - c) @ axis
    ends = c + np.outer([s_along.min(), s_along.max()], axis)
    return ends, np.sort(members)


class DottedLineDetector:
    """Finds the dotted laser line of §III-C: the red dots of a frame
    (:class:`~posekit.ceiling.detect.DotDetector`, which learns static lights), grouped by
    :func:`dots_to_line` into one segment, reported as a :class:`~posekit.ceiling.detect.Line`
    so that the line pipeline (:func:`~posekit.ceiling.track.pipeline.track_frames` with
    ``dots=("line",)``) and :class:`LineTracker` take it like a solid line.

    Parameters
    ----------
    color : str
        Laser colour.
    tol_px, min_dots : as :func:`dots_to_line` (default 3: two red things are always
        collinear). A row cut by a vent down to two dots is taken only if their distance is a
        whole number (1-4) of the dot gap learnt from full rows, within 15 %, and it lies within
        two row lengths of the last row seen.
    contrast : int
        Threshold above the background, grey levels: 60 (the dot detector's default is 25) so
        the glows of dots about 10 px apart do not merge into one elongated blob, which the dot
        detector would refuse as not round.
    **kwargs
        Any other :class:`~posekit.ceiling.detect.DotDetector` parameter.

    Where the row is seen end-on (far away, along the view) its dots merge into one streak: a
    :class:`~posekit.ceiling.detect.LineDetector` running beside the dot detector measures that
    streak as a solid segment, used when fewer than three dots form a row and it is longer. Its
    length from the second moments (``sqrt(12 λ)``, exact for a uniform bar) is scaled by
    ``sqrt((n - 1) / (n + 1))`` for ``n_dots`` point-like dots spanning the row (their variance
    is ``L² (n + 1) / (12 (n - 1))``), so that a streak and a resolved row give the same length.
    """

    def __init__(self, color: str = "red", *, tol_px: float = 2.0, min_dots: int = 3, contrast: int = 60,
                 n_dots: int = 5, **kwargs):
        from ..detect.dots import DotDetector
        from ..detect.lines import LineDetector
        self._dots = DotDetector(colors=(color,), contrast=contrast, **kwargs)
        self._lines = LineDetector(color)
        self.colors = (color,)
        self.tol_px, self.min_dots = float(tol_px), int(min_dots)
        self._streak_scale = float(np.sqrt((n_dots - 1) / (n_dots + 1)))
        self.last_dots: list = []
        self._gap_px = float("nan")              # dot gap of the last full row, px
        self._last: tuple | None = None          # (centre (2,), length px) of the last row

    def detect(self, frame_bgr: np.ndarray, predicted_uv=None) -> list:
        """The dotted segment of this frame as a one-element list of ``Line`` (or empty).
        The whole frame is searched (a row of dots is wider than the dot detector's window)."""
        from ..detect.lines import Line
        dots = [d for d in self._dots.detect(frame_bgr) if d.color == self.colors[0] and not d.stray]
        streaks = self._lines.detect(frame_bgr)
        self.last_dots = dots
        found = None
        if len(dots) >= 2:
            uv = np.array([(d.u, d.v) for d in dots])
            found = dots_to_line(uv, tol_px=self.tol_px, min_dots=self.min_dots) if len(dots) >= self.min_dots else None
            if found is not None:
                self._gap_px = float(np.hypot(*(found[0][1] - found[0][0]))) / max(len(found[1]) - 1, 1)
            else:
                found = self._pair(uv)
        if streaks and (found is None or (len(found[1]) < 3
                                          and streaks[0].length_px > np.hypot(*(found[0][1] - found[0][0])))):
            return [replace(streaks[0], length_px=streaks[0].length_px * self._streak_scale)]
        if found is None:
            return []
        ends, members = found
        d = ends[1] - ends[0]
        c = ends.mean(axis=0)
        self._last = (c, float(np.hypot(*d)))
        angle = float(np.degrees(np.arctan2(d[1], d[0])) % 180.0)
        return [Line(self.colors[0], float(c[0]), float(c[1]), angle, float(np.hypot(*d)),
                     int(sum(dots[k].area_px for k in members)), float(max(dots[k].peak for k in members)))]

    def _pair(self, uv: np.ndarray):
        """Two dots of a row cut by a vent: ``(ends, members)`` if their distance is 1-4 learnt gaps
        (within 15 %) and they lie within two row lengths of the last row; else None."""
        if not np.isfinite(self._gap_px) or self._last is None:
            return None
        centre, length = self._last
        best = None
        for i in range(len(uv)):
            for j in range(i + 1, len(uv)):
                dist = float(np.hypot(*(uv[j] - uv[i])))
                m = round(dist / self._gap_px)
                if not 1 <= m <= 4 or abs(dist - m * self._gap_px) > 0.15 * m * self._gap_px:
                    continue
                off = float(np.hypot(*(0.5 * (uv[i] + uv[j]) - centre)))
                if off <= 2.0 * max(length, self._gap_px) and (best is None or off < best[0]):
                    best = (off, i, j)
        if best is None:
            return None
        return uv[[best[1], best[2]]], np.array([best[1], best[2]])
