"""Several robots, one red dot each (the paper's §III-B with more than one robot).

Every robot has its own constant-velocity :class:`~posekit.ceiling.track.Tracker`; the
dots of a frame are shared out by a global nearest-neighbour assignment
(``scipy.optimize.linear_sum_assignment`` on the squared Mahalanobis distances of each dot
to each robot's prediction, pairs outside the χ² gate or beyond physical reach excluded).
Identity is carried by the motion model: when two robots pass close (a few dot diameters)
each keeps the dot its prediction explains; when their dots merge into one blob (the blob
lies in the gates of both and one robot has no other dot) neither takes it and both coast
(``predicted``) until the dots separate. A lost robot is re-acquired only on a
verified dot that no live robot claims, and only when the choice is unambiguous (as many
free dots as lost robots, taken in order of image column so the first fix is repeatable).

Each robot's tracker sees every dot of the frame, the other robots' dots marked ``claimed``
(never associated, never rivals), so the verdict rules of the single tracker
(:mod:`~posekit.ceiling.track.verdicts`) hold per robot: a robot whose dot was gated out for
``reinit_after`` frames re-acquires only a lone free dot found moving, far from every robot's
gate, and its rows are then ``suspect`` (probation, the previous track kept as the other
hypothesis in ``std_mm``); another free moving laser-like dot outside its gate makes its rows
``suspect``; a lost robot starts only on a dot found moving (``moving``), never on a static
one.

Output: one :class:`~posekit.ceiling.track.TrackRow` per robot per frame with ``robot``
0..n-1; the CSV is the single-robot one plus a last column ``robot``
(``frame,time_s,x,y,heading_deg,status,std_mm,robot``), rows of a frame in robot order.
"""

from __future__ import annotations

import time
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field, replace

import numpy as np

from ...errors import ConfigError
from ._kalman import _mahalanobis2
from .cameras import Camera
from .results import _TimedRows
from .tracker import Tracker, TrackerConfig, TrackRow

__all__ = ["MultiRobotTracker", "RobotsResult", "iter_track_robots", "track_robots_frames", "track_robots_video"]


class MultiRobotTracker:
    """Tracks ``n_robots`` single-dot robots in the world plane (mm, s).

    Parameters
    ----------
    n_robots : int
        Number of robots (>= 1).
    config : TrackerConfig, optional
        Tuning of each robot's filter (``dots`` is forced to ``("red",)``).
    """

    def __init__(self, n_robots: int, config: TrackerConfig | None = None):
        if int(n_robots) != n_robots or n_robots < 1:
            raise ConfigError(f"n_robots: expected an integer >= 1, got {n_robots!r}")
        cfg = replace(TrackerConfig() if config is None else config, dots=("red",))
        self.config = cfg
        self.trackers = [Tracker(cfg) for _ in range(int(n_robots))]

    def predict(self, t_s: float) -> list[tuple[np.ndarray, np.ndarray] | None]:
        """Per robot the predicted position (2,) mm and covariance (2, 2) mm² at ``t_s`` (None if lost)."""
        return [tr.predict(t_s).get("red") for tr in self.trackers]

    def step(self, t_s: float, dots_world, meas_cov=None, *, frame: int | None = None,
             eligible=None, moving=None) -> list[TrackRow]:
        """Share this frame's dots out among the robots and advance every filter.

        Parameters
        ----------
        t_s : float
            Frame time, s (non-decreasing).
        dots_world : ndarray, shape (K, 2), or None
            Red dots of the frame in the world plane, mm.
        meas_cov : ndarray, shape (K, 2, 2), optional
            Their covariances, mm² (default ``config.meas_std_mm²·I``).
        eligible : ndarray of bool, shape (K,), optional
            Verified dots (see :meth:`Tracker.step`); default all.
        moving : ndarray of bool, shape (K,), optional
            Dots found moving by a test over several frames (see :meth:`Tracker.step`); default:
            each tracker's own test.

        Returns
        -------
        list of TrackRow
            One per robot, ``robot`` set.
        """
        from scipy.optimize import linear_sum_assignment

        cfg = self.config
        z = np.zeros((0, 2)) if dots_world is None else np.asarray(dots_world, dtype=float).reshape(-1, 2)
        k = len(z)
        R = (np.broadcast_to(cfg.meas_std_mm ** 2 * np.eye(2), (k, 2, 2)) if meas_cov is None
             else np.asarray(meas_cov, dtype=float).reshape(k, 2, 2)) + cfg.min_meas_std_mm ** 2 * np.eye(2)
        el = np.ones(k, bool) if eligible is None else np.asarray(eligible, bool).reshape(k)
        mv = None if moving is None else np.asarray(moving, bool).reshape(k)
        n = len(self.trackers)
        assign: list[int | None] = [None] * n
        pred = self.predict(t_s)
        live = [i for i in range(n) if pred[i] is not None]
        gated = np.zeros(k, bool)                  # inside some live robot's gate
        contested = set()                          # live robots with a dot in their gate
        if k and live:
            big = 1e9
            cost = np.full((len(live), k), big)
            for row, i in enumerate(live):
                st = self.trackers[i].states["red"]
                p, P = pred[i]
                d2 = _mahalanobis2(z - p, P + R * st.noise_scale)
                since = t_s - st.t_meas_s
                reach = cfg.gate_floor_mm + cfg.max_speed_mm_s * since
                dist_last = np.hypot(*(z - st.z_meas).T) if st.z_meas is not None else np.zeros(k)
                dist_pred = np.hypot(*(z - p).T)
                ok = ((d2 <= cfg.gate_chi2) | (el & (dist_pred <= cfg.gate_floor_mm))) & (dist_last <= reach)
                cost[row, ok] = d2[ok]
                gated |= ok
                if ok.any():
                    contested.add(i)
            rows, cols = linear_sum_assignment(cost)
            for r, c in zip(rows, cols):
                if cost[r, c] < big:
                    assign[live[r]] = int(c)
            # a dot inside the gate of a robot left without one may be both dots merged (they
            # overlap as the robots pass): it goes to neither, both coast for that frame
            for r, i in enumerate(live):
                if assign[i] is None:
                    for r2, i2 in enumerate(live):
                        c = assign[i2]
                        if c is not None and i2 != i and cost[r, c] < big:
                            assign[i2] = None
        taken = {c for c in assign if c is not None}
        lost = [i for i in range(n) if pred[i] is None]
        free = [c for c in range(k) if c not in taken and el[c]]
        # a dot near a live robot (within its reach) may be that robot's after a sharp turn: not free
        if lost and free and len(free) <= len(lost):
            free.sort(key=lambda c: (z[c, 0], z[c, 1]))
            if len(free) == len(lost):
                for i, c in zip(lost, free):
                    assign[i] = c
        taken = {c for c in assign if c is not None}
        far = np.array([c not in taken and not gated[c] for c in range(k)], bool)
        out = []
        for i, tr in enumerate(self.trackers):
            c = assign[i]
            if c is None and (pred[i] is None or i in contested) or k == 0:
                row = tr.step(t_s, None, frame=frame)       # lost without a clear dot, or its dot merged
            else:
                claimed = np.array([j in taken and j != c for j in range(k)], bool)
                assoc = np.arange(k) == c if c is not None else far     # unassigned: only far, free dots
                row = tr.step(t_s, {"red": z}, {"red": R}, frame=frame, eligible={"red": el},
                              moving=None if mv is None else {"red": mv}, associable={"red": assoc},
                              claimed={"red": claimed})
            row.robot = i
            out.append(row)
        return out


@dataclass
class RobotsResult(_TimedRows):
    """Track of several robots: ``rows`` per frame per robot (robot order within a frame)."""

    rows: list[TrackRow]
    n_robots: int
    seconds_total: float
    seconds_processing: np.ndarray
    fps_source: str = ""
    warnings: list = field(default_factory=list)

    def _n_frames(self) -> int:
        return len(self.rows) // max(self.n_robots, 1)

    def robot(self, i: int) -> list[TrackRow]:
        """The rows of robot ``i``."""
        return [r for r in self.rows if r.robot == i]

    def xy(self, i: int) -> np.ndarray:
        """(N, 2) track of robot ``i``, mm (NaN where lost)."""
        return np.array([[r.x, r.y] for r in self.robot(i)], dtype=float).reshape(-1, 2)

    def status(self, i: int) -> np.ndarray:
        return np.array([r.status for r in self.robot(i)])


def iter_track_robots(frames: Iterable, camera: Camera, n_robots: int, *, config: TrackerConfig | None = None,
                      detector=None, timings: list | None = None) -> Iterator[list[TrackRow]]:
    """Track ``n_robots`` red dots in one camera's frames, yielding each frame's rows when done.

    ``frames`` yields ``(index, time_s, image)`` (image BGR (H, W, 3), or None when the
    frame could not be decoded: every robot's row is then ``lost``). Every frame is searched
    whole (several dots); every dot goes through the laser tests of the single-robot pipeline
    (:func:`~posekit.ceiling.track.verify.verify_candidates`: static lights, the ring test, the
    colour, the signature of the robots' dots), and only one found moving starts a robot's track.
    """
    from ..detect.scene import StaticLights
    from ..detect.signature import DotSignature
    from .verify import verify_candidates

    if detector is None:
        from ..detect.dots import DotDetector
        detector = DotDetector(("red",))
    lights = StaticLights(jitter_floor_px=camera.detection_std_px)
    signatures = {"red": DotSignature()}
    followed: set = set()                      # image-track identities of the robots' dots
    mrt = MultiRobotTracker(n_robots, config)
    for item in frames:
        index, t_s, image = item[:3]
        if isinstance(image, (list, tuple)):
            image = image[0]
        t0 = time.perf_counter()
        ds = [] if image is None else [d for d in detector.detect(image) if d.color == "red"]
        cand = verify_candidates(index, ds, lights, signatures, camera.detection_std_px, followed={"red": followed})
        mv = None
        if cand.dots:
            uv = cand.uv["red"]
            xy, R = camera.measurement(uv, cand.std_px["red"])
            el, mv = cand.eligible["red"], cand.moving["red"]
        else:
            xy, R, el = np.zeros((0, 2)), np.zeros((0, 2, 2)), np.zeros(0, bool)
        rows = mrt.step(t_s, xy, R, frame=index, eligible=el, moving=mv)
        followed = set()
        for r in rows:
            if r.status in ("ok", "suspect") and "red" in r.measured:
                p = camera.to_image(np.asarray(r.measured["red"], float).reshape(1, 2))[0]
                ident = cand.identity("red", p)
                if ident is not None:
                    followed.add(ident)
                    best = min(cand.dots, key=lambda d: (d.u - p[0]) ** 2 + (d.v - p[1]) ** 2)
                    signatures["red"].update(best)
        rows = mrt.step(t_s, xy, R, frame=index, eligible=el)
        if image is None:
            rows = [replace(r, x=float("nan"), y=float("nan"), status="lost", std_mm=float("nan"), measured={},
                            reasons=("the frame could not be decoded",)) for r in rows]
        if timings is not None:
            timings.append(time.perf_counter() - t0)
        yield rows


def track_robots_frames(frames: Iterable, camera: Camera, n_robots: int, *, config: TrackerConfig | None = None,
                        detector=None, on_row=None) -> RobotsResult:
    """:func:`iter_track_robots` collected into a :class:`RobotsResult`; ``on_row(row, robot)``
    is called for every row as soon as its frame is done."""
    rows, proc = [], []
    t_start = time.perf_counter()
    for frame_rows in iter_track_robots(frames, camera, n_robots, config=config, detector=detector, timings=proc):
        for r in frame_rows:
            rows.append(r)
            if on_row is not None:
                on_row(r, r.robot)
    return RobotsResult(rows, int(n_robots), time.perf_counter() - t_start, np.array(proc))


def track_robots_video(source, calibration, n_robots: int, *, config: TrackerConfig | None = None,
                       fps: float | None = None, camera=None, on_row=None, loop: int = 1,
                       max_frames: int | None = None, live: bool = False, progress=None) -> RobotsResult:
    """Track ``n_robots`` one-dot robots in a video, image folder, camera or stream (one camera).

    Parameters are those of :func:`~posekit.ceiling.track.pipeline.track_video` (one source, one
    calibration, ``camera`` the lens model); ``on_row(row, robot)`` as in
    :func:`track_robots_frames`.
    """
    from .setup import frame_groups, make_cameras, open_sources

    streams = open_sources([source], fps, loop=loop, max_frames=max_frames, live=live)
    cams = make_cameras(streams, [calibration], camera)
    frames = frame_groups(streams)
    if progress is not None:
        frames = progress(frames)
    res = track_robots_frames(frames, cams[0], n_robots, config=config, on_row=on_row)
    res.fps_source = streams[0].fps_source
    res.warnings = [w for st in streams for w in st.warnings]
    return res
