"""``posekit ceiling demo`` (wired into ``cli/ceiling.py``)."""

from ._common import add_deprecated, add_overwrite, out_folder, staged
from ._config import add_config_arguments
from ._flags import check_flags, seed
from .ceiling_track import _DURATION, _frame_progress

__all__ = ["add_demo_parser", "run_demo"]


def add_demo_parser(verbs):
    d = verbs.add_parser("demo", help="render a ceiling video, calibrate, track, and compare with the truth "
                                      "(the paper's §V: Fig. 8/9, accuracy, speed)")
    d.add_argument("--out", default="posekit-ceiling-demo",
                   help="output folder (default posekit-ceiling-demo, replaced on each run while it holds only posekit's files)")
    add_overwrite(d, "posekit-ceiling-demo")
    d.add_argument("--dots", default="red,green",
                   help="'red', 'red,green' (default: both, for the heading) or 'line' (case C, §III-C)")
    d.add_argument("--line-pattern", choices=("dotted", "solid"), default="dotted",
                   help="with --dots line: the paper's dotted line (default) or a solid line")
    d.add_argument("--realistic", action="store_true",
                   help="render what a real camera sees (lens distortion, bloom, exposure steps, MPEG-4, a person, "
                        "shadows, stray red lights, reflections: see 'posekit ceiling simulate --help'); the lens "
                        "is then calibrated from rendered chessboard views unless --camera is given")
    d.add_argument("--camera", metavar="CAMERA.json",
                   help="lens model (posekit ceiling camera) to calibrate and track with, instead of the demo's own")
    add_deprecated(d, "--seconds", "--duration-s", "seconds", _DURATION)
    d.add_argument("--duration-s", dest="seconds", type=_DURATION, default=None,
                   help="length of the rendered video, (0, 3600] s (default: the renderer's)")
    d.add_argument("--seed", type=seed, default=0, help="random seed of the render (default 0)")
    add_config_arguments(d)
    d.set_defaults(func=run_demo)


def run_demo(args) -> int:
    from ..ceiling.studies.demo_command import check_demo_lens, demo
    from ..ceiling.track.pipeline import parse_dots

    parse_dots(args.dots)
    check_flags(args)
    out_folder(args)
    if args.camera is not None:
        check_demo_lens(args.camera, args.realistic)     # before the staged folder is made
    with staged(args) as tmp:
        report = demo(tmp, dots=args.dots, duration_s=args.seconds, seed=args.seed,
                      progress=_frame_progress(desc="demo"), camera=args.camera, realistic=args.realistic,
                      line_pattern=args.line_pattern)
        summary = report.summary().replace(str(tmp), str(args.out))
    print(summary)
    return 0
