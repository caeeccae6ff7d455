"""The worker half of :class:`~posekit.profiler.stream.server.PoseServer`: one frame at a time,
corners, pose and verdict (the estimator's own unchecked path), the NaN-storm check, the pose
filter, the controller, the record to the robot and to the record sink.

:class:`PoseWorker` is a mixin that uses the server's state (``gauge``, ``params``, ``noise``,
``significance``, the method/mounting codes, ``_last_T``, ``_counts``, ...); the record and the
timing are documented on :mod:`~posekit.profiler.stream.server`.
"""

import logging
import math
import time

from ...errors import ConfigError
from ...geometry import quaternion_from_matrix
from ..estimate.fast import estimate_profile_unchecked
from .lines import encode_command
from .protocol import Frame
from .reading import units_hint
from .server_receiver import _POLL_S
from .server_support import RobotLink

__all__ = ["PoseWorker", "NAN_STORM"]

#: Rejection reason of a frame whose points are (almost) all NaN.
NAN_STORM = "nan_storm"


def _error_record(frame, error):
    """The robot record of a frame without a pose (its fields are filled in on success)."""
    return {"seq": frame.seq, "t_sensor_ns": frame.t_sensor_ns, "status": "error", "t_mm": None, "q_wxyz": None,
            "std_t_um": None, "std_rot_deg": None, "reprojection_um": None, "reversed": None,
            "chi2": None, "dof": None, "reason": None, "command": None, "filter": None, "timing_ms": None, "error": error}


class PoseWorker:
    """The worker thread's methods of :class:`~posekit.profiler.stream.server.PoseServer`."""

    def _work_loop(self) -> None:
        link = None if self._robot is None else RobotLink(*self._robot, self._counts, self._stats_lock, self._limiter)
        try:
            while True:
                with self._cond:
                    while not self._ready and not self._stop.is_set():
                        self._cond.wait(_POLL_S)
                    if self._stop.is_set():
                        break
                    frame, dt_ns = self._next_frame()      # the sensors' queues in turn
                try:
                    record = self._process(frame, dt_ns)
                except Exception as exc:  # a bug, never bad input: report it and go on
                    self.log.exception("worker: internal error on frame seq %d", frame.seq)
                    with self._stats_lock:
                        self._counts.processed += 1
                        self._counts.errors += 1
                    record = _error_record(frame, f"seq {frame.seq}: internal error: {type(exc).__name__}: {exc}")
                if self.record_sink is not None:
                    self.record_sink.put(record)
                if link is None:
                    continue
                sent = link.send(encode_command(record))
                with self._stats_lock:
                    if sent:
                        self._counts.sent += 1
                    else:
                        self._counts.unsent += 1
        finally:
            if link is not None:
                link.close()

    def _estimate(self, pts, last=None):
        """Corners, pose and verdict of one profile; warm start from ``last = (T_G_F, reversed)``."""
        T_init, rev_init = (None, False) if last is None or self._method_code != 1 else last
        return estimate_profile_unchecked(pts, self.gauge, self.params, self._turns, self._method_code,
                                          self._mounting_code, T_init, rev_init, noise=self.noise,
                                          significance=self.significance, gate=self._chi2_gate)

    def _process(self, frame: Frame, dt_ns: int | None = None) -> dict:
        t0 = time.perf_counter_ns()
        seq = frame.seq
        dt_ms = None if dt_ns is None else dt_ns * 1e-6
        qw_ms = (t0 - frame.t_recv_ns) * 1e-6
        rec = _error_record(frame, None)
        pts = frame.points
        n_pts = pts.shape[0]
        res = None if n_pts == 0 else self._estimate(pts, None if self._last_T is None else (self._last_T,
                                                                                             self._last_rev))
        n_nan = 0 if res is None else n_pts - res.n_valid      # (an empty frame costs no estimate)
        if n_pts == 0 or n_nan > self.nan_storm_fraction * n_pts:
            detail = (f"seq {seq}: {n_nan} of {n_pts} points have no return "
                      f"(more than {100 * self.nan_storm_fraction:.0f} % NaN)")
            self._reject(NAN_STORM, detail)
            rec["error"] = f"rejected frame (nan_storm): {detail}"
            return rec
        if res.cold_restart:
            with self._stats_lock:
                self._counts.cold_restarts += 1
        error = None
        T = res.T_G_F
        if T is None:
            error = f"seq {seq}: {res.error}"
            if res.corners is None:
                hint = units_hint(pts)         # only on failure: free on the good path
                if hint is not None:
                    error += f"; the profile {hint}"
        else:
            cov = res.cov
            self._last_T = T
            self._last_rev = bool(res.reversed)
            var = cov.diagonal().tolist()
            finite = all(map(math.isfinite, var))
            rec.update(status=res.status, t_mm=T[:3, 3].tolist(),
                       q_wxyz=quaternion_from_matrix(T[:3, :3], check=False).tolist(),
                       std_t_um=[1e3 * math.sqrt(abs(v)) for v in var[:3]] if finite else None,
                       std_rot_deg=[math.degrees(math.sqrt(abs(v))) for v in var[3:]] if finite else None,
                       reprojection_um=float(res.reprojection_um), reversed=bool(res.reversed),
                       chi2=float(res.chi2), dof=int(res.dof), reason=res.reason)
            if self.pose_filter is not None and finite:
                try:
                    rec["filter"] = self.pose_filter.update(frame.t_sensor_ns * 1e-9, T, cov).to_record()
                except ConfigError:         # a covariance the filter cannot use: no filtered pose
                    rec["filter"] = None
            if self.controller is not None:
                try:
                    command = self.controller(seq, frame.t_sensor_ns * 1e-9, T, cov)
                    if command is not None:
                        encode_command(command)     # a dict JSON can carry, or ConfigError
                    rec["command"] = command
                except Exception as exc:   # user code: report, never kill the worker
                    error = f"seq {seq}: controller failed: {type(exc).__name__}: {exc}"
        t2 = time.perf_counter_ns()
        cd_ms = res.detect_ns * 1e-6
        pc_ms = (t2 - t0 - res.detect_ns) * 1e-6
        rec["timing_ms"] = {"DT": dt_ms, "QW": qw_ms, "CD": cd_ms, "PC": pc_ms}
        with self._stats_lock:
            c = self._counts
            c.processed += 1
            if error is not None:
                c.errors += 1
            elif rec["status"] == "ok":
                c.ok += 1
            else:
                self._n_suspect += 1
            row = self._tim[self._tim_n % self._tim.shape[0]]
            row[0] = math.nan if dt_ms is None else dt_ms
            row[1] = qw_ms
            row[2] = cd_ms
            row[3] = pc_ms
            self._tim_n += 1
        if error is not None:
            rec["status"] = "error"
            rec["error"] = error
            self._limiter.event("profile_error", logging.WARNING, f"profile failed: {error}")
        return rec
