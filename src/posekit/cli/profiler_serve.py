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
import time

from ..io._numbers import parse_number
from ._common import add_deprecated, resolve_gauge
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
    p.add_argument("--status-every", type=float, default=5.0, metavar="S",
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


def _controller(args, gauge):
    """The server's controller from the flags (None for --controller none)."""
    import numpy as np

    from ..errors import ConfigError
    from ..geometry import matrix_from_quaternion
    from ..profiler.estimate.sensor import LJ_X8400, nominal_pose
    from ..profiler.loop.control import DEFAULT_KD, DEFAULT_KP, OpenLoop, PDController, TargetCompensator

    given = [f for f in _CONTROL_FLAGS if getattr(args, f) is not None]
    if given and args.controller != "pd":
        raise ConfigError(f"--{given[0].replace('_', '-')} needs --controller pd")
    given = [f for f in (*_TARGET_FLAGS, "standoff_mm") if getattr(args, f) is not None]
    if given and args.controller == "none":
        raise ConfigError(f"--{given[0].replace('_', '-')} needs --controller pd (or open)")
    if args.controller == "none":
        return None
    gains = "one number or three comma-separated numbers X,Y,Z"
    kp = DEFAULT_KP if args.kp is None else _numbers(args.kp, "--kp", (1, 3), gains)
    kd = DEFAULT_KD if args.kd is None else _numbers(args.kd, "--kd", (1, 3), gains)
    standoff = LJ_X8400.z_mid if args.standoff_mm is None else float(args.standoff_mm)
    T = nominal_pose(gauge, standoff_mm=standoff)
    if args.target_mm is not None:
        T[:3, 3] = _numbers(args.target_mm, "--target-mm", (3,), "three comma-separated numbers X,Y,Z in mm")
    if args.target_q_wxyz is not None:
        q = np.array(_numbers(args.target_q_wxyz, "--target-q-wxyz", (4,), "a unit quaternion W,X,Y,Z"))
        norm = float(np.linalg.norm(q))
        if abs(norm - 1.0) > 1e-3:
            raise ConfigError(f"--target-q-wxyz: expected a unit quaternion W,X,Y,Z, got '{args.target_q_wxyz}' "
                              f"(norm {norm:.6g})")
        T[:3, :3] = matrix_from_quaternion(q / norm)
    if args.controller == "open":
        law = OpenLoop()
    else:
        law = PDController(kp=kp, kd=kd, limit_mm=2.0 if args.limit_mm is None else args.limit_mm,
                           derivative_filter_hz=args.derivative_filter_hz)
    return TargetCompensator(law, T, standoff)


def _pose_filter(args):
    """The server's pose filter from the flags (None for --filter none)."""
    from ..errors import ConfigError
    from ..profiler.stream.pose_filter import ConstantVelocityFilter, WindowFusion

    for flag, kind in _FILTER_FLAGS.items():
        if getattr(args, flag) is not None and args.filter != kind:
            raise ConfigError(f"--{flag.replace('_', '-')} needs --filter {kind}")
    if args.filter != "none" and args.method == "cf":
        raise ConfigError(f"--filter {args.filter} needs --method mle (the closed form 'cf' gives no covariance "
                          "to filter with)")
    if args.filter == "cv":
        return ConstantVelocityFilter(10.0 if args.filter_accel_mm_s2 is None else args.filter_accel_mm_s2,
                                      0.025 if args.filter_angular_accel_rad_s2 is None
                                      else args.filter_angular_accel_rad_s2)
    if args.filter == "window":
        return WindowFusion(10 if args.filter_window is None else args.filter_window)
    return None


def _record_sink(args):
    """The record outputs of --out / --jsonl (None without either); files are opened here."""
    from ..profiler.stream.server_records import RecordOutput, RecordSink, output_format

    outputs = []
    if args.out is not None:
        outputs.append(RecordOutput(args.out, output_format(args.out, "--out"), stream=False, flag="--out"))
    if args.jsonl is not None:
        outputs.append(RecordOutput(args.jsonl, "jsonl", stream=True, flag="--jsonl"))
    return RecordSink(outputs) if outputs else None


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
    from ..profiler.stream.server import PoseServer, parse_address, read_token_file

    check_flags(args)
    listen = parse_address(args.listen, "--listen")
    robot = parse_address(args.robot, "--robot") if args.robot else None
    if args.queue < 1:
        raise ConfigError(f"--queue must be >= 1, got {args.queue}")
    if args.duration is not None and not args.duration > 0:
        raise ConfigError(f"--duration-s must be > 0 seconds, got {args.duration:g}")
    _check_seconds(args.status_every, "--status-every", _STATUS_RANGE)
    _check_seconds(args.idle_timeout_s, "--idle-timeout-s", _TIMEOUT_RANGE)
    _check_seconds(args.read_timeout_s, "--read-timeout-s", _TIMEOUT_RANGE)
    if args.allow_remote and not args.token_file:
        raise ConfigError("--allow-remote needs --token-file FILE (a shared secret every sensor must present); "
                          "refusing to accept remote sensors without one")
    if args.out is not None:
        from ..profiler.stream.server_records import output_format
        output_format(args.out, "--out")
    token = read_token_file(args.token_file) if args.token_file else None
    gauge = resolve_gauge(args.gauge)
    controller = _controller(args, gauge)
    pose_filter = _pose_filter(args)
    say = sys.stderr if args.jsonl == "-" else sys.stdout      # stdout carries the records then

    log = logging.getLogger("posekit.server")
    handler = None
    if not log.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("posekit: %(levelname)s: %(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)
    sink = _record_sink(args)                  # opens the outputs: a bad --out/--jsonl fails before serving
    server = None
    old_term = None
    served = False
    try:
        server = PoseServer(gauge, listen=listen, robot=robot, queue_size=args.queue, method=args.method,
                            mounting=args.mounting, allow_remote=args.allow_remote, log=log, token=token,
                            idle_timeout_s=args.idle_timeout_s, read_timeout_s=args.read_timeout_s,
                            controller=controller, pose_filter=pose_filter, record_sink=sink)
        if threading.current_thread() is threading.main_thread():     # SIGTERM stops like Ctrl-C
            old_term = signal.signal(signal.SIGTERM, _raise_interrupt)
        host, port = server.start()
        target = f"robot interface {robot[0]}:{robot[1]}" if robot else "no robot (records are not sent)"
        auth = "sensors must present the token" if token is not None else "no token"
        print(f"posekit profiler serve: gauge '{gauge.name}', method {args.method}, listening on "
              f"{host}:{port} ({auth}), sending to {target}; Ctrl-C stops", file=say, flush=True)
        extra = _describe(args, controller, pose_filter)
        if extra:
            print(f"posekit profiler serve: {extra}", file=say, flush=True)
        t0 = time.monotonic()
        next_status = t0 + args.status_every
        last_processed, last_t = 0, t0
        nap = 0.2 if args.count is None else 0.02
        try:
            while True:
                now = time.monotonic()
                if args.duration is not None and now - t0 >= args.duration:
                    break
                if args.count is not None and server.stats()["processed"] >= args.count:
                    break
                if now >= next_status:
                    st, tim = server.stats(), server.timings()
                    new = st["processed"] - last_processed          # medians over this interval only
                    recent = {k: (v[-new:] if new else v[:0]) for k, v in tim.items()}
                    rate = new / max(now - last_t, 1e-9)
                    print(_status_line(now - t0, st, recent, rate), file=say, flush=True)
                    last_processed, last_t = st["processed"], now
                    next_status += args.status_every
                wake = next_status if args.duration is None else min(next_status, t0 + args.duration)
                time.sleep(max(0.0, min(nap, wake - time.monotonic())))
        except KeyboardInterrupt:
            print("posekit profiler serve: interrupted, stopping", file=sys.stderr, flush=True)
        elapsed = time.monotonic() - t0
        served = True
    finally:
        if server is not None:
            server.stop()
        if sink is not None:
            sink.close(discard=not served)     # after the worker: every record is in; --out renamed into place
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        if handler is not None:
            log.removeHandler(handler)
    print(_summary(elapsed, server.stats(), server.timings()), file=say, flush=True)
    if sink is not None:
        lost = f" ({sink.unwritten} not written: the outputs fell behind)" if sink.unwritten else ""
        print(f"  records: {sink.written} written to {', '.join(sink.targets)}{lost}", file=say, flush=True)
        if sink.errors:
            raise ConfigError(sink.errors[0])
    return 0
