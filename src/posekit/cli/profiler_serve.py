"""``posekit profiler serve``: the real-time pose server on the command line.

Wired into ``posekit profiler`` by :func:`add_serve_parser` (called from
:mod:`posekit.cli.profiler`). Besides the robot link it can run the PD compensation of the
closed loop (``--controller pd`` with ``--kp``, ``--kd``, ``--limit-mm`` and the target
pose), a pose filter for the weakly observable y / rx (``--filter cv|window``), and record
every record to ``--out FILE.jsonl|FILE.csv`` (renamed into place at the end) and
``--jsonl FILE|-`` (flushed per record).
"""

import logging
import signal
import sys
import threading

from .._numbers import parse_number
from ._common import add_deprecated
from ._config import add_config_arguments
from ._flags import bounded_float, bounded_int, check_flags

__all__ = ["add_serve_parser", "run_serve"]

_STATUS_RANGE = (0.1, 86_400.0)        # --status-every, s
_TIMEOUT_RANGE = (0.05, 86_400.0)      # --idle-timeout-s, --read-timeout-s, s (PoseServer's range)
_CONTROL_FLAGS = ("kp", "kd", "limit_mm", "derivative_filter_hz")
_TARGET_FLAGS = ("target_mm", "target_q_wxyz")
_FILTER_FLAGS = {"filter_accel_mm_s2": "cv", "filter_angular_accel_rad_s2": "cv", "filter_window": "window"}


def add_serve_parser(verbs):
    """Add the ``serve`` verb to the ``posekit profiler`` sub-parsers ``verbs``."""
    p = verbs.add_parser(
        "serve", help="real-time pose server: profile frames in over TCP, pose records out to a robot",
        description="Accept sensors on --listen (binary frames, see posekit.profiler.stream.protocol; each connection "
                    "is served on its own, with idle and read timeouts), estimate the pose of every frame and "
                    "send one JSON line per frame to the robot interface at --robot. Runs until Ctrl-C or "
                    "--duration.")
    p.add_argument("--gauge", required=True, help="gauge YAML file (or a bundled name: demo-4/5/7/10)")
    p.add_argument("--listen", required=True, metavar="HOST:PORT",
                   help="address to accept the sensor on, e.g. 127.0.0.1:5020 (port 0: any free port)")
    p.add_argument("--robot", metavar="HOST:PORT",
                   help="robot interface to send JSON records to (TCP); omit to only estimate")
    p.add_argument("--queue", type=int, default=4, metavar="N",
                   help="frames buffered for the worker; when full the oldest is dropped (default 4)")
    p.add_argument("--method", choices=["cf", "mle"], default="mle",
                   help="cf: closed form eq. (9)-(14); mle: refined (default)")
    p.add_argument("--mounting", choices=["auto", "normal", "reversed"], default="auto",
                   help="scan order of the corners vs the ridges (default: auto-detect)")
    add_deprecated(p, "--duration", "--duration-s", "duration", float)
    p.add_argument("--duration-s", dest="duration", type=float, default=None, metavar="S",
                   help="stop after S seconds (default: run until Ctrl-C)")
    add_deprecated(p, "--status-every", "--status-every-s", "status_every", float)
    p.add_argument("--status-every-s", dest="status_every", type=float, default=5.0, metavar="S",
                   help=f"seconds between status lines, {_STATUS_RANGE[0]:g} to {_STATUS_RANGE[1]:g} (default 5)")
    p.add_argument("--idle-timeout-s", type=float, default=30.0, metavar="S",
                   help="close a sensor connection that sends no complete frame for S seconds (default 30)")
    p.add_argument("--read-timeout-s", type=float, default=2.0, metavar="S",
                   help="close a sensor connection whose frame (or hello) is not complete S seconds after "
                        "its first byte (default 2)")
    p.add_argument("--allow-remote", action="store_true",
                   help="allow non-loopback --listen/--robot addresses (default: loopback only); "
                        "needs --token-file")
    p.add_argument("--token-file", metavar="FILE",
                   help="file holding a shared secret (one line of text) that every sensor must send first "
                        "(protocol hello); required with --allow-remote. Not encryption: use a firewall/VPN")
    p.add_argument("--count", type=bounded_int(1, 10**9, "frames"), default=None, metavar="N",
                   help="stop after N processed frames (default: run until Ctrl-C or --duration-s)")
    rec = p.add_argument_group("records")
    rec.add_argument("--out", metavar="FILE.jsonl|FILE.csv",
                     help="write every record to FILE (JSON lines, or CSV by the suffix); written under a "
                          "temporary name and renamed into place when the server stops")
    rec.add_argument("--jsonl", metavar="FILE|-",
                     help="write every record as a JSON line to FILE ('-': stdout, the status lines then go to "
                          "stderr), flushed as it is produced")
    ctl = p.add_argument_group("controller (the PD compensation of the closed loop, posekit.profiler.loop.control)")
    ctl.add_argument("--controller", choices=["none", "open", "pd"], default="none",
                     help="pd: PD compensation towards the target pose, one command per pose in the record's "
                          "'command' (command_mm, measured_mm; mm in G); open: command 0 (the open-loop "
                          "baseline); none: command null (default)")
    ctl.add_argument("--kp", metavar="X,Y,Z", help="proportional gains on x, y, z (one value: all axes); "
                     "default the loop's tuned -0.275,-0.6,-0.325 (negative on purpose: see control.py)")
    ctl.add_argument("--kd", metavar="X,Y,Z", help="derivative gains on x, y, z, s (default 0,-0.001,0)")
    ctl.add_argument("--limit-mm", type=bounded_float(0.0, 100.0, "mm", lo_open=True), default=None, metavar="L",
                     help="largest correction per axis, mm (default 2)")
    ctl.add_argument("--derivative-filter-hz", type=bounded_float(0.0, 1e4, "Hz", lo_open=True), default=None,
                     metavar="F", help="low-pass cut-off of the derivative, Hz (default: none)")
    ctl.add_argument("--target-mm", metavar="X,Y,Z",
                     help="target position of the sensor frame F in the gauge frame G, mm (default: the "
                          "nominal pose above the gauge's centre)")
    ctl.add_argument("--target-q-wxyz", metavar="W,X,Y,Z",
                     help="target orientation of F in G, unit quaternion (default: the nominal, F's z down)")
    ctl.add_argument("--standoff-mm", type=bounded_float(1.0, 1e4, "mm"), default=None, metavar="D",
                     help="depth of the laser spot on F's z axis that the controller holds, and of the default "
                          "target above the gauge, mm (default: mid-range, as the loop)")
    flt = p.add_argument_group("pose filter (y and the tilt about x are weakly observable from one profile)")
    flt.add_argument("--filter", choices=["none", "cv", "window"], default="none",
                     help="cv: constant-velocity Kalman filter on the 6-DoF pose with each estimate's "
                          "covariance; window: information-weighted fusion of the last K estimates (a robot at "
                          "rest); the result, with its covariance, is the record's 'filter' (default none)")
    flt.add_argument("--filter-accel-mm-s2", type=bounded_float(0.0, 1e7, "mm/s²", lo_open=True), default=None,
                     metavar="A", help="cv: typical acceleration of the flange, mm/s² (default 10: a robot at "
                                       "rest; raise it for a moving one)")
    flt.add_argument("--filter-angular-accel-rad-s2", type=bounded_float(0.0, 1e5, "rad/s²", lo_open=True),
                     default=None, metavar="B", help="cv: the same for the rotation, rad/s² (default 0.025)")
    flt.add_argument("--filter-window", type=bounded_int(1, 10_000, "estimates"), default=None, metavar="K",
                     help="window: estimates fused (default 10)")
    add_config_arguments(p)
    p.set_defaults(func=run_serve)
    return p


def _numbers(text: str, flag: str, sizes: tuple[int, ...], what: str) -> list[float]:
    import math

    from ..errors import ConfigError
    try:
        vals = [parse_number(v) for v in str(text).split(",")]
    except ValueError:
        vals = []
    if len(vals) not in sizes or not all(math.isfinite(v) for v in vals):
        raise ConfigError(f"{flag}: expected {what}, got '{str(text)[:80]}'")
    return vals


def _controller_flags(args) -> dict:
    """The controller's arguments of :func:`~posekit.profiler.stream.serve.serve` from the flags (checked)."""
    import numpy as np

    from ..errors import ConfigError

    given = [f for f in _CONTROL_FLAGS if getattr(args, f) is not None]
    if given and args.controller != "pd":
        raise ConfigError(f"--{given[0].replace('_', '-')} needs --controller pd")
    given = [f for f in (*_TARGET_FLAGS, "standoff_mm") if getattr(args, f) is not None]
    if given and args.controller == "none":
        raise ConfigError(f"--{given[0].replace('_', '-')} needs --controller pd (or open)")
    gains = "one number or three comma-separated numbers X,Y,Z"
    kw = {"controller": args.controller, "limit_mm": args.limit_mm, "derivative_filter_hz": args.derivative_filter_hz,
          "standoff_mm": args.standoff_mm,
          "kp": None if args.kp is None else _numbers(args.kp, "--kp", (1, 3), gains),
          "kd": None if args.kd is None else _numbers(args.kd, "--kd", (1, 3), gains),
          "target_mm": None if args.target_mm is None else _numbers(args.target_mm, "--target-mm", (3,),
                                                                       "three comma-separated numbers X,Y,Z in mm"),
          "target_q_wxyz": None}
    if args.target_q_wxyz is not None:
        q = np.array(_numbers(args.target_q_wxyz, "--target-q-wxyz", (4,), "a unit quaternion W,X,Y,Z"))
        norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > 1e-3:
            raise ConfigError(f"--target-q-wxyz: expected a unit quaternion W,X,Y,Z, got '{args.target_q_wxyz}' "
                              f"(norm {norm:.6g})")
        kw["target_q_wxyz"] = q
    return kw


def _filter_flags(args) -> dict:
    """The pose filter's arguments of :func:`~posekit.profiler.stream.serve.serve` from the flags (checked)."""
    from ..errors import ConfigError

    for flag, kind in _FILTER_FLAGS.items():
        if getattr(args, flag) is not None and args.filter != kind:
            raise ConfigError(f"--{flag.replace('_', '-')} needs --filter {kind}")
    if args.filter != "none" and args.method == "cf":
        raise ConfigError(f"--filter {args.filter} needs --method mle (the closed form 'cf' gives no covariance "
                          "to filter with)")
    return {"filter": args.filter, "filter_accel_mm_s2": args.filter_accel_mm_s2,
            "filter_angular_accel_rad_s2": args.filter_angular_accel_rad_s2, "filter_window": args.filter_window}


def _check_seconds(value: float, flag: str, bounds: tuple[float, float]) -> None:
    from ..errors import ConfigError
    lo, hi = bounds
    if not lo <= value <= hi:            # NaN fails too
        raise ConfigError(f"{flag} must be between {lo:g} and {hi:g} seconds, got {value:g}")


def _median(values) -> str:
    import numpy as np
    values = values[np.isfinite(values)]
    return f"{np.median(values):.3f}" if len(values) else "-"


def _status_line(elapsed: float, st: dict, tim: dict, rate: float) -> str:
    return (f"[{elapsed:7.1f} s] received {st['received']}  processed {st['processed']} ({rate:.0f}/s)  "
            f"dropped {st['dropped']}  rejected {st['rejected']}  errors {st['errors']}  "
            f"sensors {st['connected']}  |  median ms "
            f"DT {_median(tim['DT'])}  CD {_median(tim['CD'])}  PC {_median(tim['PC'])}")


def _summary(elapsed: float, st: dict, tim: dict) -> str:
    import numpy as np
    lines = [(f"summary after {elapsed:.1f} s: received {st['received']}, processed {st['processed']} "
             f"(ok {st['ok']}, errors {st['errors']}), dropped {st['dropped']}, rejected {st['rejected']}, "
             f"connections {st['connections']} (disconnects {st['disconnects']}: timeouts "
             f"{st['timeouts']}, refused {st['auth_failures']}, shed {st['shed']}, evicted {st['evictions']}), "
             f"records sent {st['sent']} (unsent {st['unsent']})")]
    if st["reasons"]:
        lines.append("  rejected by reason: " + ", ".join(f"{k} {v}" for k, v in sorted(st["reasons"].items())))
    for key, what in (("DT", "data transmission"), ("CD", "corner detection"), ("PC", "pose computation")):
        v = tim[key][np.isfinite(tim[key])]
        if len(v):
            lines.append(f"  {key} ({what}) ms: median {np.median(v):.3f}  mean {v.mean():.3f}  "
                         f"p99 {np.percentile(v, 99):.3f}  max {v.max():.3f}")
    if st["bad_stamps"]:
        lines.append(f"  DT unknown for {st['bad_stamps']} frames: sensor stamp not believed (ahead of the "
                     "server's clock, too old, or going backwards)")
    return "\n".join(lines)


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt


def _describe(args, controller, pose_filter) -> str:
    parts = []
    if controller is not None:
        t = ", ".join(f"{v:.3f}" for v in controller.T_target[:3, 3])
        parts.append(f"controller {args.controller} ({controller.controller!r}) holding t = [{t}] mm")
    if pose_filter is not None:
        parts.append(f"filter {pose_filter!r}")
    return "; ".join(parts)


def run_serve(args) -> int:
    from ..errors import ConfigError
    from ..profiler.stream.serve import serve
    from ..profiler.stream.server_support import parse_address

    check_flags(args)
    listen = parse_address(args.listen, "--listen")
    robot = parse_address(args.robot, "--robot") if args.robot else None
    if args.queue < 1:
        raise ConfigError(f"--queue must be >= 1, got {args.queue}")
    if args.duration is not None and not args.duration > 0:
        raise ConfigError(f"--duration-s must be > 0 seconds, got {args.duration:g}")
    _check_seconds(args.status_every, "--status-every-s", _STATUS_RANGE)
    _check_seconds(args.idle_timeout_s, "--idle-timeout-s", _TIMEOUT_RANGE)
    _check_seconds(args.read_timeout_s, "--read-timeout-s", _TIMEOUT_RANGE)
    if args.allow_remote and not args.token_file:
        raise ConfigError("--allow-remote needs --token-file FILE (a shared secret every sensor must present); "
                          "refusing to accept remote sensors without one")
    if args.out is not None:
        from ..profiler.stream.server_records import output_format
        output_format(args.out, "--out")
    controller, pose_filter = _controller_flags(args), _filter_flags(args)
    say = sys.stderr if args.jsonl == "-" else sys.stdout      # stdout carries the records then

    log = logging.getLogger("posekit.server")
    handler = None
    if not log.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("posekit: %(levelname)s: %(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)

    def started(server, host, port):
        target = f"robot interface {robot[0]}:{robot[1]}" if robot else "no robot (records are not sent)"
        auth = "sensors must present the token" if args.token_file else "no token"
        print(f"posekit profiler serve: gauge '{server.gauge.name}', method {args.method}, listening on "
              f"{host}:{port} ({auth}), sending to {target}; Ctrl-C stops", file=say, flush=True)
        extra = _describe(args, server.controller, server.pose_filter)
        if extra:
            print(f"posekit profiler serve: {extra}", file=say, flush=True)

    def status(elapsed, st, recent, rate):
        print(_status_line(elapsed, st, recent, rate), file=say, flush=True)

    old_term = None
    try:
        if threading.current_thread() is threading.main_thread():     # SIGTERM stops like Ctrl-C
            old_term = signal.signal(signal.SIGTERM, _raise_interrupt)
        report = serve(args.gauge, listen, robot=robot, queue=args.queue, method=args.method, mounting=args.mounting,
                       duration_s=args.duration, count=args.count, status_every_s=args.status_every,
                       idle_timeout_s=args.idle_timeout_s, read_timeout_s=args.read_timeout_s,
                       allow_remote=args.allow_remote, token_file=args.token_file, out=args.out, jsonl=args.jsonl,
                       log=log, on_start=started, on_status=status, **controller, **pose_filter)
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        if handler is not None:
            log.removeHandler(handler)
    if report.interrupted:
        print("posekit profiler serve: interrupted, stopping", file=sys.stderr, flush=True)
    print(_summary(report.elapsed_s, report.stats, report.timings), file=say, flush=True)
    if report.targets:
        lost = (f" ({report.records_unwritten} not written: the outputs fell behind)" if report.records_unwritten
                else "")
        print(f"  records: {report.records_written} written to {', '.join(report.targets)}{lost}", file=say,
              flush=True)
        if report.errors:
            raise ConfigError(report.errors[0])
    return 0
