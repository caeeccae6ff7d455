"""``posekit profiler serve``: the real-time pose server on the command line.

Wired into ``posekit profiler`` by :func:`add_serve_parser` (called from
:mod:`posekit.cli.profiler`).
"""

import logging
import signal
import sys
import threading
import time

from ._common import add_deprecated, resolve_gauge

__all__ = ["add_serve_parser", "run_serve"]

_STATUS_RANGE = (0.1, 86_400.0)        # --status-every, s
_TIMEOUT_RANGE = (0.05, 86_400.0)      # --idle-timeout-s, --read-timeout-s, s (PoseServer's range)


def add_serve_parser(verbs):
    """Add the ``serve`` verb to the ``posekit profiler`` sub-parsers ``verbs``."""
    p = verbs.add_parser(
        "serve", help="real-time pose server: profile frames in over TCP, pose records out to a robot",
        description="Accept sensors on --listen (binary frames, see posekit.profiler.protocol; each connection "
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
    p.set_defaults(func=run_serve)
    return p


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
             f"sensor connections {st['connections']} (disconnects {st['disconnects']}: timeouts "
             f"{st['timeouts']}, refused {st['auth_failures']}, evicted {st['evictions']}), "
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


def run_serve(args) -> int:
    from ..errors import ConfigError
    from ..profiler.server import PoseServer, parse_address, read_token_file

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
    token = read_token_file(args.token_file) if args.token_file else None
    gauge = resolve_gauge(args.gauge)

    log = logging.getLogger("posekit.server")
    handler = None
    if not log.handlers:
        handler = logging.StreamHandler(sys.stderr)
        handler.setFormatter(logging.Formatter("posekit: %(levelname)s: %(message)s"))
        log.addHandler(handler)
        log.setLevel(logging.INFO)
    server = PoseServer(gauge, listen=listen, robot=robot, queue_size=args.queue, method=args.method,
                        mounting=args.mounting, allow_remote=args.allow_remote, log=log, token=token,
                        idle_timeout_s=args.idle_timeout_s, read_timeout_s=args.read_timeout_s)
    old_term = None
    if threading.current_thread() is threading.main_thread():     # SIGTERM stops like Ctrl-C
        old_term = signal.signal(signal.SIGTERM, _raise_interrupt)
    try:
        host, port = server.start()
        target = f"robot interface {robot[0]}:{robot[1]}" if robot else "no robot (records are not sent)"
        auth = "sensors must present the token" if token is not None else "no token"
        print(f"posekit profiler serve: gauge '{gauge.name}', method {args.method}, listening on "
              f"{host}:{port} ({auth}), sending to {target}; Ctrl-C stops", flush=True)
        t0 = time.monotonic()
        next_status = t0 + args.status_every
        last_processed, last_t = 0, t0
        try:
            while True:
                now = time.monotonic()
                if args.duration is not None and now - t0 >= args.duration:
                    break
                if now >= next_status:
                    st, tim = server.stats(), server.timings()
                    new = st["processed"] - last_processed          # medians over this interval only
                    recent = {k: (v[-new:] if new else v[:0]) for k, v in tim.items()}
                    rate = new / max(now - last_t, 1e-9)
                    print(_status_line(now - t0, st, recent, rate), flush=True)
                    last_processed, last_t = st["processed"], now
                    next_status += args.status_every
                wake = next_status if args.duration is None else min(next_status, t0 + args.duration)
                time.sleep(max(0.0, min(0.2, wake - time.monotonic())))
        except KeyboardInterrupt:
            print("posekit profiler serve: interrupted, stopping", file=sys.stderr, flush=True)
        elapsed = time.monotonic() - t0
    finally:
        server.stop()
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
        if handler is not None:
            log.removeHandler(handler)
    print(_summary(elapsed, server.stats(), server.timings()), flush=True)
    return 0
