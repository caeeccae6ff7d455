"""``posekit ceiling track`` (wired into ``cli/ceiling.py``)."""

import sys
from pathlib import Path

from ._common import add_deprecated
from ._config import add_config_arguments
from ._flags import bounded_float, bounded_int, check_flags

__all__ = ["add_track_parser", "run_track"]

#: ``--duration-s`` of the demo: at most an hour (54,000 frames at 15 fps); > 0 is checked by
#: ``posekit.ceiling.studies.demo.run_demo`` with its own message.
_DURATION = bounded_float(None, 3600.0, "s", flag="--duration-s")
#: ``--frame-rate-hz`` of a file or image folder (was ``--fps``).
_FPS = bounded_float(0.01, 1e4, "Hz", flag="--frame-rate-hz")


def _frame_progress(total=None, desc="track"):
    """A tqdm bar over frames on a terminal (stderr); None (no bar) otherwise."""
    if not sys.stderr.isatty():
        return None

    def wrap(iterable, total=total, **_):
        from tqdm import tqdm
        return tqdm(iterable, total=total, desc=desc, unit="frame", leave=False)
    return wrap


def add_track_parser(verbs):
    t = verbs.add_parser("track", help="track the laser dot(s) in a video, a folder of images, a camera or a stream")
    t.add_argument("input", help="video file, folder of images sorted by name, camera index (0), /dev/videoN, or a "
                                 "stream URL (rtsp://, http://)")
    t.add_argument("--calibration", action="append", required=True, metavar="CAL.json",
                   help="calibration JSON of INPUT (`posekit ceiling calibrate`); repeat it once per "
                        "--input2 for several cameras, in the same order")
    t.add_argument("--camera", action="append", default=None, metavar="CAMERA.json",
                   help="lens model of the camera (`posekit ceiling camera`): dot centroids are undistorted "
                        "before the homography (calibrate with the same --camera); once for all inputs or once per "
                        "input")
    t.add_argument("--input2", action="append", default=[], metavar="INPUT",
                   help="video or image folder of a further camera covering another part of the ceiling "
                        "(case D; synchronised frame by frame with INPUT); may be repeated")
    t.add_argument("--dots", default="red", help="'red' (position), 'red,green' (position and heading), 'line' "
                        "(one laser line: position and heading, its sense from the motion) or 'red,red' (two robots "
                        "with one red dot each, as --robots 2)")
    t.add_argument("--robots", type=bounded_int(1, 8), default=None,
                   help="robots with one red dot each, 1..8 (default 1): one track per robot, column 'robot'")
    t.add_argument("--line-method", choices=["moments", "hough", "dotted"], default="moments",
                   help="with --dots line: measure a solid segment by its principal axis (default, most precise) "
                        "or by a Hough transform of its centre line; 'dotted' for the paper's §III-C dotted line "
                        "(a row of dots, as `ceiling simulate --dots line --line-pattern dotted` renders)")
    add_deprecated(t, "--fps", "--frame-rate-hz", "fps", _FPS)
    t.add_argument("--frame-rate-hz", dest="fps", type=_FPS, default=None,
                   help="frame rate for the timestamps of a file, 0.01..10000 Hz (default: the video's, or 15 for an "
                        "image folder); live input is stamped with the capture clock")
    t.add_argument("--max-predict-s", type=bounded_float(0.0, 3600.0, "s"), default=1.0,
                   help="predict through a dropout for at most this long, then 'lost', 0..3600 s (default 1 s)")
    t.add_argument("--out", default=None, metavar="TRACK.csv",
                   help="output CSV frame,time_s,x,y,heading_deg,status,std_mm,std_heading_deg,reason (mm, s, "
                        "degrees), written row by row and renamed into place at the end or on Ctrl-C; required unless "
                        "--jsonl or --udp")
    t.add_argument("--jsonl", default=None, metavar="FILE|-",
                   help="also write one JSON object per frame {frame,time_s,x,y,heading_deg,status,std_mm,"
                        "std_heading_deg,reason}, flushed as soon as the frame is done ('-': stdout; the run stops "
                        "when its reader closes)")
    t.add_argument("--udp", default=None, metavar="HOST:PORT",
                   help="also send each frame's JSON object as a UDP datagram (loopback only unless --allow-remote)")
    t.add_argument("--allow-remote", action="store_true", help="allow a --udp host that is not this machine")
    t.add_argument("--live", action="store_true",
                   help="read INPUT through the live path even if it is a video file (capture-clock timestamps)")
    t.add_argument("--loop", type=bounded_int(1, 1_000_000), default=1,
                   help="with --live and a video file: play it this many times (default 1)")
    t.add_argument("--max-frames", type=bounded_int(1, 10**9), default=None,
                   help="stop after this many frames, for every kind of input (a camera never ends by itself; "
                        "Ctrl-C stops too)")
    t.add_argument("--scene", action="append", default=None, metavar="SCENE.json",
                   help="static lights of the empty scene (`posekit ceiling learn-scene`): never taken for the laser "
                        "from the first frame on; once for all inputs or once per input (default: learned online)")
    add_config_arguments(t)
    t.set_defaults(func=run_track)


def run_track(args) -> int:
    import signal

    from ..ceiling.track.command import plan_track, track_input
    from ..ceiling.track.sources import DEFAULT_FPS

    check_flags(args)
    options = dict(input2=args.input2, dots=args.dots, robots=args.robots, line_method=args.line_method,
                   max_predict_s=args.max_predict_s, camera=args.camera, scene=args.scene, live=args.live,
                   out=args.out, jsonl=args.jsonl, udp=args.udp)
    plan = plan_track(args.input, args.calibration, **options)
    old_term = None
    try:
        old_term = signal.signal(signal.SIGTERM, _raise_interrupt)
    except ValueError:                       # not the main thread (tests): Ctrl-C only
        pass
    try:
        run = track_input(args.input, args.calibration, fps=args.fps, allow_remote=args.allow_remote, loop=args.loop,
                    max_frames=args.max_frames, progress=None if plan.live else _frame_progress(), **options)
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
    say = sys.stderr if run.to_stdout else sys.stdout
    c, result, out = run.counts, run.result, args.out
    if result is not None:
        for w in result.warnings:
            print(f"posekit: warning: {w}", file=sys.stderr)
        if result.fps_source == "default":
            print(f"posekit: note: no frame rate in the input; timestamps assume {DEFAULT_FPS:g} fps "
                  "(pass --frame-rate-hz)", file=sys.stderr)
    where = ", ".join(x for x in (str(Path(out)) if out else "", "stdout" if run.to_stdout else
                                  (args.jsonl or ""), f"udp {args.udp}" if args.udp else "") if x)
    speed = "" if result is None else (f"; {result.fps:.0f} frames/s end to end ({result.processing_ms:.2f} ms/frame "
                                      "without decoding)")
    robots = plan.robots
    what = f"{run.rows} frames" if robots == 1 else f"{run.rows // robots} frames x {robots} robots"
    stop = "interrupted after " if run.interrupted else ""
    if run.gone:
        print(f"posekit: stopped: {run.gone}", file=sys.stderr)
        return run.exit_code                 # the input was not read whole
    print(f"{stop}{what}: {c['ok']} ok, {c['suspect']} suspect, {c['predicted']} predicted, {c['lost']} lost{speed}; "
          f"wrote {where}", file=say)
    if result is not None and getattr(result, "stats", None):
        s = result.stats
        print(f"background: {s.get('rebuilds', 0)} rebuild(s), {s.get('relights', 0)} exposure step(s); static lights: "
              f"{s.get('static_lights', 0)} held, {s.get('scene', 'learned online')}", file=say)
    return run.exit_code


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt
