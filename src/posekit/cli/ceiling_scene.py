"""``posekit ceiling learn-scene``: the static lights of the empty scene (wired into ``cli/ceiling.py``)."""

import sys

from ._common import add_deprecated
from ._config import add_config_arguments
from ._flags import bounded_float, bounded_int, check_flags

_FPS = bounded_float(0.01, 1e4, "Hz", flag="--frame-rate-hz")

__all__ = ["add_learn_scene_parser", "run_learn_scene"]


def add_learn_scene_parser(verbs):
    s = verbs.add_parser(
        "learn-scene", help="static lights of the empty ceiling (laser off) for `track --scene`",
        description="Record the ceiling with the laser off (or the robot still) for a few seconds and learn its "
                    "static lights: lamps, exit signs, LEDs, glints, steady or blinking. Each is written with its "
                    "image and ceiling position, colour and centroid jitter; `ceiling track --scene SCENE.json` "
                    "never takes them for the laser, from the first frame on.")
    s.add_argument("input", help="video file, folder of images, camera index or stream URL")
    s.add_argument("--calibration", required=True, metavar="CAL.json", help="calibration of this camera")
    s.add_argument("--camera", default=None, metavar="CAMERA.json", help="lens model (posekit ceiling camera)")
    s.add_argument("--out", required=True, metavar="SCENE.json", help="scene file to write")
    add_deprecated(s, "--fps", "--frame-rate-hz", "fps", _FPS)
    s.add_argument("--frame-rate-hz", dest="fps", type=_FPS, default=None,
                   help="frame rate for an image folder (default: the video's, or 15)")
    s.add_argument("--max-frames", type=bounded_int(1, 10**7), default=None,
                   help="read at most this many frames (needed for a camera)")
    add_config_arguments(s)
    s.set_defaults(func=run_learn_scene)
    return s


def run_learn_scene(args) -> int:
    from ..ceiling.track.scene_learning import learn_scene

    check_flags(args)
    res = learn_scene(args.input, args.calibration, camera=args.camera, out=args.out, fps=args.fps,
                      max_frames=args.max_frames)
    for w in res.warnings:
        print(f"posekit: warning: {w}", file=sys.stderr)
    print(f"learned {len(res.lights)} static light(s) from {res.frames} frames ({res.image_size[0]}x"
          f"{res.image_size[1]} px; scene jitter {res.jitter_px:.2f} px):")
    for lt in res.lights:
        print(f"  {lt.colour} at u={lt.u:.1f} v={lt.v:.1f} px, x={lt.x_mm:.0f} y={lt.y_mm:.0f} mm, jitter "
              f"{lt.jitter_px:.2f} px, seen in {lt.seen} frames")
    print(f"wrote {args.out}")
    return 0
