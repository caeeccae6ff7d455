"""``posekit ceiling track`` (wired into ``cli/ceiling.py``)."""

import sys
from pathlib import Path

from ._flags import bounded_float, check_flags

__all__ = ["add_track_parser", "run_track"]

#: ``--duration-s`` of the demo: at most an hour (54,000 frames at 15 fps); > 0 is checked by
#: ``posekit.ceiling.demo.run_demo`` with its own message.
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
    t = verbs.add_parser("track", help="track the laser dot(s) in a video or a folder of images")
    t.add_argument("input", help="video file, or folder of images sorted by name")
    t.add_argument("--calibration", action="append", required=True, metavar="CAL.json",
                   help="calibration JSON of INPUT (`posekit ceiling calibrate`); repeat it once per "
                        "--input2 for several cameras, in the same order")
    t.add_argument("--input2", action="append", default=[], metavar="INPUT",
                   help="video or image folder of a further camera covering another part of the ceiling "
                        "(case D; synchronised frame by frame with INPUT); may be repeated")
    t.add_argument("--dots", default="red", help="'red' (position), 'red,green' (position and heading) or 'line' "
                        "(one laser line: position and heading, its sense from the motion)")
    t.add_argument("--line-method", choices=["moments", "hough"], default="moments",
                   help="with --dots line: measure the segment by its principal axis (default, most precise) "
                        "or by a Hough transform of its centre line")
    t.add_argument("--fps", type=bounded_float(0.01, 1e4, "Hz"), default=None,
                   help="frame rate for the timestamps, 0.01..10000 Hz (default: the video's, or 15 for an image "
                        "folder)")
    t.add_argument("--max-predict-s", type=bounded_float(0.0, 3600.0, "s"), default=1.0,
                   help="predict through a dropout for at most this long, then 'lost', 0..3600 s (default 1 s)")
    t.add_argument("--out", required=True, metavar="TRACK.csv",
                   help="output CSV frame,time_s,x,y,heading_deg,status (mm, s, degrees)")
    t.set_defaults(func=run_track)


def run_track(args) -> int:
    from ..ceiling.pipeline import parse_dots, track_video, write_track_csv
    from ..ceiling.track import TrackerConfig
    from ..ceiling.video_io import DEFAULT_FPS
    from ..errors import ConfigError

    inputs = [args.input, *args.input2]
    if len(args.calibration) != len(inputs):
        raise ConfigError(f"--calibration given {len(args.calibration)} time(s) for {len(inputs)} input(s); "
                          "give one calibration per camera, in the order INPUT, --input2 ...")
    dots = parse_dots(args.dots)
    try:
        config = TrackerConfig(dots=dots, max_predict_s=args.max_predict_s)
    except ConfigError:
        raise ConfigError(f"--max-predict-s must be a number >= 0, got {args.max_predict_s:g}") from None
    check_flags(args)
    out = Path(args.out)
    if out.is_dir():
        raise ConfigError(f"--out {out}: is a folder; expected a CSV file name")
    options = {"method": args.line_method} if dots == ("line",) and args.line_method != "moments" else None
    result = track_video(inputs, args.calibration, dots, fps=args.fps, config=config,
                         detector_options=options, progress=_frame_progress())
    try:
        write_track_csv(result.rows, out)
    except OSError as exc:
        raise ConfigError(f"--out {out}: cannot write ({exc.strerror or exc})") from None
    c = result.counts()
    if result.fps_source == "default":
        print(f"posekit: note: no frame rate in the input; timestamps assume {DEFAULT_FPS:g} fps "
              "(pass --fps)", file=sys.stderr)
    print(f"{len(result)} frames: {c['ok']} ok, {c['predicted']} predicted, {c['lost']} lost; "
          f"{result.fps:.0f} frames/s end to end ({result.processing_ms:.2f} ms/frame without decoding); "
          f"wrote {out}")
    return 0
