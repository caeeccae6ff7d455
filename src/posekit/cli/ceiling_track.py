"""``posekit ceiling track`` (wired into ``cli/ceiling.py``)."""

import sys
from pathlib import Path

from ._flags import bounded_float, bounded_int, check_flags

__all__ = ["add_track_parser", "run_track"]

#: ``--duration-s`` of the demo: at most an hour (54,000 frames at 15 fps); > 0 is checked by
#: ``posekit.ceiling.studies.demo.run_demo`` with its own message.
_DURATION = bounded_float(None, 3600.0, "s", flag="--duration-s")


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
    t.add_argument("--fps", type=bounded_float(0.01, 1e4, "Hz"), default=None,
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
    t.set_defaults(func=run_track)


def run_track(args) -> int:
    import signal

    from ..ceiling.track.outputs import ReaderGone, TrackOutputs
    from ..ceiling.track.pipeline import parse_dots, track_video
    from ..ceiling.track.sources import DEFAULT_FPS, is_live_source
    from ..ceiling.track.types import TrackerConfig
    from ..errors import ConfigError
    from ..verdict import track_exit_code

    inputs = [args.input, *args.input2]
    if len(args.calibration) != len(inputs):
        raise ConfigError(f"--calibration given {len(args.calibration)} time(s) for {len(inputs)} input(s); "
                          "give one calibration per camera, in the order INPUT, --input2 ...")
    check_flags(args)
    robots = args.robots
    if args.dots.replace(" ", "") == "red,red":
        if robots not in (None, 2):
            raise ConfigError(f"--dots red,red means two robots; got --robots {robots}")
        robots, dots = 2, ("red",)
    else:
        dots = parse_dots(args.dots)
    robots = 1 if robots is None else robots
    if robots > 1 and (dots != ("red",) or args.input2):
        raise ConfigError("--robots: several robots are tracked with one red dot each (--dots red) and one camera")
    try:
        config = TrackerConfig(dots=dots, max_predict_s=args.max_predict_s)
    except ConfigError:
        raise ConfigError(f"--max-predict-s must be a number >= 0, got {args.max_predict_s:g}") from None
    if args.out is None and args.jsonl is None and args.udp is None:
        raise ConfigError("no output: give --out TRACK.csv, --jsonl FILE|- or --udp HOST:PORT")
    out = None if args.out is None else Path(args.out)
    if out is not None and out.is_dir():
        raise ConfigError(f"--out {out}: is a folder; expected a CSV file name")
    if args.scene is not None and len(args.scene) not in (1, len(inputs)):
        raise ConfigError(f"--scene given {len(args.scene)} time(s) for {len(inputs)} input(s); give it once for "
                          "all inputs or once per input")
    if args.camera is not None and len(args.camera) not in (1, len(inputs)):
        raise ConfigError(f"--camera given {len(args.camera)} time(s) for {len(inputs)} input(s); give it once for "
                          "all inputs or once per input")
    lenses = None if args.camera is None else (args.camera if len(args.camera) > 1 else args.camera[0])
    live = args.live or any(is_live_source(s) for s in inputs)
    options = {"method": args.line_method} if dots == ("line",) and args.line_method != "moments" else None
    outputs = TrackOutputs(out, args.jsonl, args.udp, allow_remote=args.allow_remote, robots=robots)
    say = sys.stderr if outputs.to_stdout else sys.stdout
    interrupted, gone, result = False, None, None
    old_term = None
    try:
        old_term = signal.signal(signal.SIGTERM, _raise_interrupt)
    except ValueError:                       # not the main thread (tests): Ctrl-C only
        pass
    try:
        common = dict(fps=args.fps, camera=lenses, loop=args.loop, max_frames=args.max_frames, live=args.live,
                      progress=None if live else _frame_progress())
        if robots > 1:
            from ..ceiling.track.multitrack import track_robots_video
            result = track_robots_video(inputs[0], args.calibration[0], robots, config=config,
                                        on_row=outputs.write, **common)
        else:
            scenes = None if args.scene is None else (args.scene if len(args.scene) > 1 else args.scene[0])
            result = track_video(inputs, args.calibration, dots, config=config, detector_options=options,
                                 on_row=outputs.write, scene=scenes, **common)
    except KeyboardInterrupt:
        interrupted = True
    except ReaderGone as exc:
        gone = str(exc)
        _silence_stdout()
    except BaseException:
        outputs.close(discard=True)
        raise
    finally:
        if old_term is not None:
            signal.signal(signal.SIGTERM, old_term)
    outputs.close()                          # the CSV is renamed into place, complete, even after Ctrl-C
    c = outputs.counts
    if result is not None:
        for w in result.warnings:
            print(f"posekit: warning: {w}", file=sys.stderr)
        if result.fps_source == "default":
            print(f"posekit: note: no frame rate in the input; timestamps assume {DEFAULT_FPS:g} fps "
                  "(pass --fps)", file=sys.stderr)
    where = ", ".join(x for x in (str(out) if out else "", "stdout" if outputs.to_stdout else
                                  (args.jsonl or ""), f"udp {args.udp}" if args.udp else "") if x)
    speed = "" if result is None else (f"; {result.fps:.0f} frames/s end to end ({result.processing_ms:.2f} ms/frame "
                                      "without decoding)")
    what = f"{outputs.frames} frames" if robots == 1 else f"{outputs.frames // robots} frames x {robots} robots"
    stop = "interrupted after " if interrupted else ""
    if gone:
        print(f"posekit: stopped: {gone}", file=sys.stderr)
        return track_exit_code(False)        # the input was not read whole
    print(f"{stop}{what}: {c['ok']} ok, {c['suspect']} suspect, {c['predicted']} predicted, {c['lost']} lost{speed}; "
          f"wrote {where}", file=say)
    if result is not None and getattr(result, "stats", None):
        s = result.stats
        print(f"background: {s.get('rebuilds', 0)} rebuild(s), {s.get('relights', 0)} exposure step(s); static lights: "
              f"{s.get('static_lights', 0)} held, {s.get('scene', 'learned online')}", file=say)
    if interrupted and not live:
        return 130                           # a file not read whole
    return 0


def _silence_stdout() -> None:
    """Point stdout at /dev/null once its reader is gone, so that the interpreter's last flush
    does not print "Broken pipe" (stderr stays)."""
    import os
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


def _raise_interrupt(signum, frame):
    raise KeyboardInterrupt
