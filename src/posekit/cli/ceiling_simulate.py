"""``posekit ceiling simulate``: render a synthetic ceiling video with its truth."""

import sys
from pathlib import Path

from ..errors import ConfigError
from ._common import add_overwrite, out_folder, staged
from ._flags import bounded_float, check_flags, seed

__all__ = ["add_simulate_parser", "run_simulate"]

DOT_CHOICES = {"red": ("red",), "red,green": ("red", "green"), "red,red": ("red", "red"), "line": ("line",)}
#: Longest video, s, and its most frames (--duration-s × --fps: one hour at 15 fps, ~1.5 GB of MJPG).
MAX_DURATION_S, MAX_FRAMES = 3600.0, 54_000


def add_simulate_parser(verbs):
    """Add ``simulate`` to the ``posekit ceiling`` verbs (an argparse sub-parsers object)."""
    s = verbs.add_parser(
        "simulate", help="render a synthetic ceiling video (laser dots of a robot driving a rectangle)",
        description="Render a 4 m x 6 m tiled ceiling seen by a fixed 864x480 camera while a robot with "
                    "laser pointers drives the paper's 2.4 m x 4.4 m rectangle. Writes video.avi (MJPG), "
                    "truth.csv, calibration_points.csv (X,Y,u,v of grid corners), reference.png.")
    s.add_argument("--out", required=True, help="output folder")
    add_overwrite(s)
    s.add_argument("--seed", type=seed, default=0, help="random seed (same seed, same video; default 0)")
    s.add_argument("--dots", default="red", help="lasers: red (case A), red,green or red,red (case B, "
                                                 "40 cm apart), line (case C); default red")
    s.add_argument("--duration-s", type=bounded_float(0.0, MAX_DURATION_S, "s", lo_open=True), default=60.0,
                   help="video length, (0, 3600] s, at most 54,000 frames (default 60)")
    s.add_argument("--fps", type=bounded_float(1.0, 120.0, "Hz"), default=15.0, help="frame rate, 1..120 Hz (default 15)")
    s.add_argument("--holes", action="store_true", default=True,
                   help="air-conditioning vents where a dot vanishes (default)")
    s.add_argument("--no-holes", dest="holes", action="store_false", help="a ceiling without vents")
    s.add_argument("--noise-std", type=bounded_float(0.0, 255.0, "grey levels"), default=2.0,
                   help="sensor noise, 0..255 grey levels (default 2)")
    s.add_argument("--frames-png", action="store_true", help="also write every frame as frames/NNNNNN.png")
    s.set_defaults(func=run_simulate)
    return s


def _progress(iterable, total=None):
    if not sys.stderr.isatty():
        return iterable
    from tqdm import tqdm
    return tqdm(iterable, total=total, desc="render", unit="frame", leave=False)


def _moved(paths, old: Path, new: Path):
    """The ``paths`` record with every path under ``old`` re-rooted under ``new``."""
    import dataclasses

    def move(v):
        return new / Path(v).relative_to(old) if isinstance(v, Path) and Path(v).is_relative_to(old) else v

    if dataclasses.is_dataclass(paths):
        return dataclasses.replace(paths, **{f.name: move(getattr(paths, f.name)) for f in dataclasses.fields(paths)})
    return paths._replace(**{k: move(v) for k, v in paths._asdict().items()})


def run_simulate(args) -> int:
    from ..ceiling.render import SceneConfig, render_video

    dots = DOT_CHOICES.get(args.dots.replace(" ", "").lower())
    if dots is None:
        raise ConfigError(f"--dots: expected one of {' | '.join(DOT_CHOICES)}, got '{args.dots}'")
    if not args.duration_s > 0:
        raise ConfigError(f"--duration-s: expected a positive number of seconds, got {args.duration_s}")
    check_flags(args)
    if args.duration_s * args.fps > MAX_FRAMES:
        raise ConfigError(f"--duration-s {args.duration_s:g} × --fps {args.fps:g} = {args.duration_s * args.fps:.0f} "
                          f"frames; expected at most {MAX_FRAMES}")
    config = SceneConfig(seed=args.seed, dots=dots, duration_s=args.duration_s, fps=args.fps, holes=args.holes,
                         noise_std=args.noise_std)
    out_folder(args)
    with staged(args) as tmp:
        paths = render_video(config, tmp, frames_png=args.frames_png, progress=_progress)
    paths = _moved(paths, tmp, Path(args.out))
    print(f"wrote {paths.n_frames} frames ({config.width_px}x{config.height_px}, {config.fps:g} fps) to "
          f"{paths.video}; truth {paths.truth.name}, calibration {paths.calibration_points.name}, "
          f"reference {paths.reference.name}" + (f", frames in {paths.frames_dir}" if paths.frames_dir else ""))
    return 0
