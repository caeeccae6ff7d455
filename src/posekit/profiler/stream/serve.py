"""Run the pose server until told to stop: the library behind ``posekit profiler serve``.

:func:`serve` builds a :class:`~posekit.profiler.stream.server.PoseServer` from the command's
arguments (by the same names: the controller of :func:`~posekit.profiler.loop.control.make_compensator`,
the pose filter of :func:`~posekit.profiler.stream.pose_filter.make_filter`, the record outputs of
:class:`~posekit.profiler.stream.server_records.RecordSink`), serves until ``duration_s``,
``count`` processed frames or Ctrl-C, and returns what happened (:class:`ServeReport`).
``on_start`` and ``on_status`` let a caller print while it runs.
"""

import time
from collections.abc import Callable
from dataclasses import dataclass, field

from ...errors import ConfigError
from ..gauge.model import resolve_gauge
from ..loop.control import make_compensator
from .pose_filter import make_filter
from .server import PoseServer
from .server_records import RecordOutput, RecordSink, output_format
from .server_support import parse_address, read_token_file

__all__ = ["serve", "ServeReport", "FILTER_DEFAULTS"]

#: The pose filters' parameters unless told (``--filter-accel-mm-s2``, ``--filter-angular-accel-rad-s2``,
#: ``--filter-window``): a robot at rest.
FILTER_DEFAULTS = {"accel_mm_s2": 10.0, "angular_accel_rad_s2": 0.025, "window": 10}


@dataclass
class ServeReport:
    """What :func:`serve` did.

    Attributes
    ----------
    elapsed_s : float
        Time served, s.
    stats : dict
        :meth:`PoseServer.stats <posekit.profiler.stream.server.PoseServer.stats>` at the end.
    timings : dict
        :meth:`PoseServer.timings <posekit.profiler.stream.server.PoseServer.timings>` (ms per frame).
    interrupted : bool
        Stopped by Ctrl-C (or SIGTERM turned into it).
    records_written, records_unwritten : int
        Records written to the outputs, and those the outputs fell behind on.
    targets : list of str
        Where the records went.
    errors : list of str
        The record outputs' errors (the first one is raised after the summary).
    """

    elapsed_s: float
    stats: dict
    timings: dict
    interrupted: bool = False
    records_written: int = 0
    records_unwritten: int = 0
    targets: list = field(default_factory=list)
    errors: list = field(default_factory=list)


def serve(gauge, listen, *, robot=None, queue: int = 4, method: str = "mle", mounting: str = "auto",
          duration_s: float | None = None, count: int | None = None, status_every_s: float = 5.0,
          idle_timeout_s: float = 30.0, read_timeout_s: float = 2.0, allow_remote: bool = False,
          token_file=None, out=None, jsonl=None, controller: str = "none", kp=None, kd=None,
          limit_mm: float | None = None, derivative_filter_hz: float | None = None, target_mm=None,
          target_q_wxyz=None, standoff_mm: float | None = None, filter: str = "none",
          filter_accel_mm_s2: float | None = None, filter_angular_accel_rad_s2: float | None = None,
          filter_window: int | None = None, log=None, on_start: Callable | None = None,
          on_status: Callable | None = None) -> ServeReport:
    """Serve poses of the frames that arrive on ``listen`` until stopped.

    Parameters
    ----------
    gauge : Gauge or str or Path
    listen, robot : str ``HOST:PORT`` or (host, port)
        Where sensors connect; the robot interface the records go to (None: not sent).
    queue, method, mounting, idle_timeout_s, read_timeout_s, allow_remote
        As :class:`~posekit.profiler.stream.server.PoseServer` (``queue`` its ``queue_size``).
    duration_s, count : optional
        Stop after this long, s, or this many processed frames (default: until Ctrl-C).
    status_every_s : float
        Seconds between ``on_status`` calls.
    token_file : str or Path, optional
        The shared secret every sensor must present (required with ``allow_remote``).
    out : str or Path, optional
        ``FILE.jsonl`` or ``FILE.csv`` of every record, renamed into place when the server stops.
    jsonl : str or Path, optional
        JSON lines of every record, flushed as produced (``'-'``: stdout).
    controller, kp, kd, limit_mm, derivative_filter_hz, target_mm, target_q_wxyz, standoff_mm
        As :func:`~posekit.profiler.loop.control.make_compensator` (``controller`` its ``kind``).
    filter, filter_accel_mm_s2, filter_angular_accel_rad_s2, filter_window
        The pose filter: ``'none'``, ``'cv'`` or ``'window'`` (:func:`~posekit.profiler.stream.pose_filter.make_filter`,
        defaults :data:`FILTER_DEFAULTS`); needs ``method='mle'``.
    log : logging.Logger, optional
    on_start : callable, optional
        ``on_start(server, host, port)`` once listening.
    on_status : callable, optional
        ``on_status(elapsed_s, stats, recent_timings, rate_hz)`` every ``status_every_s``.

    Returns
    -------
    ServeReport
    """
    listen = parse_address(listen, "listen") if isinstance(listen, str) else tuple(listen)
    if robot is not None:
        robot = parse_address(robot, "robot") if isinstance(robot, str) else tuple(robot)
    if allow_remote and not token_file:
        raise ConfigError("allow_remote needs a token_file (a shared secret every sensor must present); "
                          "refusing to accept remote sensors without one")
    if filter != "none" and method == "cf":
        raise ConfigError(f"filter '{filter}' needs method 'mle' (the closed form 'cf' gives no covariance to "
                          "filter with)")
    if out is not None:
        output_format(out, "out")
    token = read_token_file(token_file) if token_file else None
    gauge = resolve_gauge(gauge)
    compensator = make_compensator(controller, gauge, kp=kp, kd=kd, limit_mm=limit_mm,
                                   derivative_filter_hz=derivative_filter_hz, target_mm=target_mm,
                                   target_q_wxyz=target_q_wxyz, standoff_mm=standoff_mm)
    pose_filter = None if filter == "none" else make_filter(
        filter,
        accel_mm_s2=FILTER_DEFAULTS["accel_mm_s2"] if filter_accel_mm_s2 is None else filter_accel_mm_s2,
        angular_accel_rad_s2=(FILTER_DEFAULTS["angular_accel_rad_s2"] if filter_angular_accel_rad_s2 is None
                              else filter_angular_accel_rad_s2),
        window=FILTER_DEFAULTS["window"] if filter_window is None else filter_window)
    outputs = []
    if out is not None:
        outputs.append(RecordOutput(out, output_format(out, "--out"), stream=False, flag="--out"))
    if jsonl is not None:
        outputs.append(RecordOutput(jsonl, "jsonl", stream=True, flag="--jsonl"))
    sink = RecordSink(outputs) if outputs else None    # opens the outputs: a bad one fails before serving
    server = None
    served = False
    interrupted = False
    elapsed = 0.0
    try:
        server = PoseServer(gauge, listen=listen, robot=robot, queue_size=queue, method=method, mounting=mounting,
                            allow_remote=allow_remote, log=log, token=token, idle_timeout_s=idle_timeout_s,
                            read_timeout_s=read_timeout_s, controller=compensator, pose_filter=pose_filter,
                            record_sink=sink)
        host, port = server.start()
        if on_start is not None:
            on_start(server, host, port)
        t0 = time.monotonic()
        next_status = t0 + status_every_s
        last_processed, last_t = 0, t0
        nap = 0.2 if count is None else 0.02
        try:
            while True:
                now = time.monotonic()
                if duration_s is not None and now - t0 >= duration_s:
                    break
                if count is not None and server.stats()["processed"] >= count:
                    break
                if now >= next_status:
                    st, tim = server.stats(), server.timings()
                    new = st["processed"] - last_processed          # medians over this interval only
                    recent = {k: (v[-new:] if new else v[:0]) for k, v in tim.items()}
                    if on_status is not None:
                        on_status(now - t0, st, recent, new / max(now - last_t, 1e-9))
                    last_processed, last_t = st["processed"], now
                    next_status += status_every_s
                wake = next_status if duration_s is None else min(next_status, t0 + duration_s)
                time.sleep(max(0.0, min(nap, wake - time.monotonic())))
        except KeyboardInterrupt:
            interrupted = True
        elapsed = time.monotonic() - t0
        served = True
    finally:
        if server is not None:
            server.stop()
        if sink is not None:
            sink.close(discard=not served)     # after the worker: every record is in; out renamed into place
    report = ServeReport(elapsed_s=elapsed, stats=server.stats(), timings=server.timings(), interrupted=interrupted)
    if sink is not None:
        report.records_written, report.records_unwritten = sink.written, sink.unwritten
        report.targets, report.errors = list(sink.targets), list(sink.errors)
    return report
