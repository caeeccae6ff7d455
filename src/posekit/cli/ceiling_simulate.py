"""``posekit ceiling simulate``: render a synthetic ceiling video with its truth."""

import sys
from pathlib import Path

from .._numbers import parse_number
from ..errors import ConfigError
from ._common import add_deprecated, add_overwrite, out_folder, staged
from ._flags import bounded_float, bounded_int, check_flags, seed

__all__ = ["add_simulate_parser", "run_simulate"]

#: ``posekit.ceiling.sim.simulation.MAX_DURATION_S`` (not imported: the parser stays light; a test keeps them equal).
MAX_DURATION_S = 3600.0


_FPS = bounded_float(1.0, 120.0, "Hz", flag="--frame-rate-hz")
_NOISE = bounded_float(0.0, 255.0, "grey levels", flag="--noise-grey")


def add_simulate_parser(verbs):
    """Add ``simulate`` to the ``posekit ceiling`` verbs (an argparse sub-parsers object)."""
    s = verbs.add_parser(
        "simulate", help="render a synthetic ceiling video (laser dots of a robot driving a rectangle)",
        description="Render a 4 m x 6 m tiled ceiling seen by a fixed 864x480 camera while a robot with "
                    "laser pointers drives the paper's 2.4 m x 4.4 m rectangle. Writes video.avi (MJPG; "
                    "video.mp4 with --codec mp4v), truth.csv, calibration_points.csv (X,Y,u,v of grid "
                    "corners where the lens shows them), reference.png, camera.json (the simulated lens: "
                    "K, dist) and stray_lights.csv. --realistic turns on what a real camera sees: lens "
                    "distortion k1=-0.2, a blooming dot, auto-exposure steps, MPEG-4 compression, a person "
                    "and shadows crossing the view, a steady and a blinking red LED, two reflections; each "
                    "flag below overrides one effect (0 turns it off). Precedence: defaults < --realistic < "
                    "--config SCENE.yaml < flags; --dump-config prints the effective scene.")
    s.add_argument("--out", default=None, help="output folder (required unless --dump-config)")
    add_overwrite(s)
    s.add_argument("--seed", type=seed, default=None, help="random seed (same seed, same video; default 0)")
    s.add_argument("--dots", default=None, help="lasers: red (case A), red,green or red,red (case B, "
                                                "40 cm apart), line (case C); default red")
    s.add_argument("--duration-s", type=bounded_float(0.0, MAX_DURATION_S, "s", lo_open=True), default=None,
                   help="video length, (0, 3600] s, at most 54,000 frames (default 60)")
    add_deprecated(s, "--fps", "--frame-rate-hz", "fps", _FPS)
    s.add_argument("--frame-rate-hz", dest="fps", type=_FPS, default=None, help="frame rate, 1..120 Hz (default 15)")
    s.add_argument("--holes", action="store_true", default=None,
                   help="air-conditioning vents where a dot vanishes (default)")
    s.add_argument("--no-holes", dest="holes", action="store_false", default=None, help="a ceiling without vents")
    add_deprecated(s, "--noise-std", "--noise-grey", "noise_grey", _NOISE)
    s.add_argument("--noise-grey", type=_NOISE, default=None,
                   help="sensor noise, 0..255 grey levels (default 2; 3 with --realistic)")
    s.add_argument("--frames-png", action="store_true", help="also write every frame as frames/NNNNNN.png")
    r = s.add_argument_group("realism (default: off; --realistic: the values in brackets)")
    r.add_argument("--realistic", action="store_true", help="turn on the realistic set of effects below")
    r.add_argument("--config", metavar="SCENE.yaml",
                   help="YAML mapping of scene settings (keys of SceneConfig, e.g. dist, bloom, occluders, "
                        "stray_lights, codec, focal_px, seed, duration_s, fps); flags given on the command line "
                        "win, a flag not given keeps the file's value")
    r.add_argument("--dump-config", action="store_true",
                   help="print the effective scene as YAML (every SceneConfig key; loadable by --config) and exit")
    r.add_argument("--distortion", metavar="K1,K2,P1,P2,K3",
                   help="lens distortion (OpenCV model, about the image centre) [-0.2,0.04,0.0008,-0.0006,0]")
    r.add_argument("--bloom", type=bounded_float(0.0, 5.0), help="blooming of the saturated dot, 0..5 [1]")
    r.add_argument("--exposure-step-s", type=bounded_float(0.0, 3600.0, "s"),
                   help="mean interval of auto-exposure steps, 0 (none)..3600 s [8]")
    r.add_argument("--occluders", type=bounded_int(0, 20), help="people crossing the view, hiding the dot [1]")
    r.add_argument("--shadows", type=bounded_int(0, 20), help="soft shadows drifting over the ceiling [2]")
    r.add_argument("--stray-lights", type=bounded_int(0, 20), help="steady red LEDs on the ceiling [1]")
    r.add_argument("--blinking-lights", type=bounded_int(0, 20), help="blinking red LEDs [1]")
    r.add_argument("--reflections", type=bounded_int(0, 20), help="specular glints of lamps [2]")
    r.add_argument("--codec", choices=("mjpg", "mp4v", "xvid", "h264"),
                   help="video compression [mp4v]; h264 only where OpenCV has an encoder (not here)")
    r.add_argument("--line-pattern", choices=("solid", "dotted"),
                   help="with --dots line: a solid line or the paper's dotted line (5 dots) (default solid)")
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


_EFFECTS = ("bloom", "exposure_step_s", "occluders", "shadows", "stray_lights", "blinking_lights", "reflections",
            "codec", "line_pattern")


def parse_distortion(text: str) -> tuple:
    """'k1,k2,p1,p2,k3' (or 4 values) -> floats; one-line ConfigError naming --distortion."""
    import math
    try:
        vals = tuple(parse_number(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) not in (4, 5) or not all(math.isfinite(v) and abs(v) <= 10 for v in vals):
        raise ConfigError(f"--distortion: expected 5 comma-separated numbers k1,k2,p1,p2,k3 within ±10, "
                          f"got '{text[:80]}'")
    return vals


def simulate_options(args) -> dict:
    """The keyword arguments of :func:`posekit.ceiling.sim.simulation.simulate` from the parsed flags."""
    return dict(seed=args.seed, dots=args.dots, duration_s=args.duration_s, fps=args.fps, holes=args.holes,
                noise_grey=args.noise_grey, realistic=args.realistic, config=args.config,
                distortion=None if args.distortion is None else parse_distortion(args.distortion),
                frames_png=args.frames_png, **{k: getattr(args, k) for k in _EFFECTS})


def run_simulate(args) -> int:
    from ..ceiling.sim.simulation import dump_scene_config, scene_config, scene_effects, simulate, simulation_dots

    if args.dots is not None:
        simulation_dots(args.dots)
    if args.duration_s is not None and not args.duration_s > 0:
        raise ConfigError(f"--duration-s: expected a positive number of seconds, got {args.duration_s}")
    check_flags(args)
    options = simulate_options(args)
    scene = scene_config(**{k: v for k, v in options.items() if k != "frames_png"})    # every check, before output
    if args.dump_config:
        sys.stdout.write(dump_scene_config(scene))
        return 0
    if not args.out:
        raise ConfigError("--out: an output folder is required (or use --dump-config)")
    out_folder(args)
    with staged(args) as tmp:
        config, paths = simulate(tmp, progress=_progress, **options)
    paths = _moved(paths, tmp, Path(args.out))
    print(f"wrote {paths.n_frames} frames ({config.width_px}x{config.height_px}, {config.fps:g} fps) to "
          f"{paths.video}; truth {paths.truth.name}, calibration {paths.calibration_points.name}, "
          f"reference {paths.reference.name}, lens {paths.camera.name}"
          + (f", frames in {paths.frames_dir}" if paths.frames_dir else ""))
    print("effects: " + ", ".join(scene_effects(config)))
    return 0
