"""``posekit localcal simulate`` and ``posekit localcal demo``: look-then-move episodes on the
simulated long-reach arm, with the paper's tables (2, 3, 4) and figures (6, 7, 8, 9)."""

import contextlib
import shlex
import sys

from .._numbers import parse_number
from ..errors import ConfigError, EstimationError
from ..verdict import batch_exit_code
from ._common import add_overwrite, out_folder, staged
from ._flags import bounded_float, bounded_int, check_flags, seed, workers

#: Most episodes of one simulate run (a few seconds each), most look-then-move updates per episode.
MAX_RUNS, MAX_UPDATES = 10_000, 100
#: Fastest camera, Hz (a VO camera runs at 10-60 Hz; the images along a motion grow with it).
MAX_CAMERA_HZ = 100.0
#: Largest start joint value, deg (mm for a prismatic joint).
MAX_START_Q = 1e6

__all__ = ["add_demo_parser", "add_simulate_parser", "run_demo", "run_simulate"]


def add_simulate_parser(verbs):
    """Add ``simulate`` to the ``posekit localcal`` verbs (an argparse sub-parsers object)."""
    s = verbs.add_parser(
        "simulate", help="repeated look-then-move episodes of one method (Tables 2-4, Figs. 6-9)",
        description="Run RUNS simulated look-then-move episodes of the line-equation or the trajectory-"
                    "matching method on the simulated HIAB033-like long-reach arm; print the paper's "
                    "tables and write them (CSV), results.json, the figures (PNG) and report.html to OUT.")
    s.add_argument("--method", required=True, choices=["line", "trajectory"], help="range adjustment method")
    s.add_argument("--runs", type=bounded_int(1, MAX_RUNS), default=10,
                   help=f"number of episodes, 1..{MAX_RUNS} (default 10)")
    s.add_argument("--seed", type=seed, default=0, help="random seed (default 0; same seed, same numbers)")
    s.add_argument("--updates", type=bounded_int(1, MAX_UPDATES), default=2,
                   help=f"look-then-move updates per episode, 1..{MAX_UPDATES} (default 2)")
    s.add_argument("--scheduler", default="serial",
                   help="serial (default, in this process), local (a Dask cluster on this machine) "
                        "or a Dask scheduler address tcp://HOST:PORT")
    s.add_argument("--workers", type=workers, default=None,
                   help="worker processes of the local cluster, 1..256 (--scheduler local; default: one per core)")
    s.add_argument("--no-timestamps", action="store_true",
                   help="trajectory method: match VO and encoder trajectories without timestamps "
                        "(correspondence-free, as the paper does)")
    s.add_argument("--matcher", default="cpd", choices=["cpd", "hybrid"],
                   help="with --no-timestamps: the fine matcher, cpd (rigid CPD on positions, default) or hybrid "
                        "(positions and orientations, as the paper's hybrid mixture model)")
    s.add_argument("--calibration-tilt-deg", type=bounded_float(0.0, 45.0, "deg"), default=0.0,
                   help="trajectory method: tilt the calibration path's inner waypoints by this angle, 0..45 deg "
                        "(default 0: the paper's orientation-holding path)")
    s.add_argument("--registration", default="auto", choices=["auto", "match", "handeye"],
                   help="trajectory method: how VO is registered to the robot: match (the paper's trajectory "
                        "matching), handeye (camera mount and VO frame together, for a camera off the tool "
                        "point on a rotating path) or auto (default: handeye when the path tilts)")
    s.add_argument("--occlude-ooi", default="never",
                   help="hide the OOI from the camera: never (default), calibration (during the circle or "
                        "the calibration path) or always")
    _camera_options(s)
    s.add_argument("--robot", default="hiab033",
                   help="the long-reach arm: a bundled model (hiab033, the default HIAB033-like crane) or a "
                        "URDF file of your own arm")
    s.add_argument("--base-link", default=None, help="URDF robot: the chain's base link (default: the root)")
    s.add_argument("--tip-link", default=None,
                   help="URDF robot: the TCP link the camera is mounted on (default: the arm's tip, fingers left out)")
    s.add_argument("--start-q-deg", default=None,
                   help="start joint values, comma-separated, deg (mm for prismatic joints); required "
                        "for any robot but hiab033")
    s.add_argument("--ooi-distance-mm", type=bounded_float(500.0, 2000.0, "mm"), default=760.0, metavar="MM",
                   help="distance of the object of interest in front of the camera at the start, 500..2000 mm "
                        "(default 760: sized for the 5 m crane; a smaller arm reaches a closer one)")
    s.add_argument("--error-scale", type=bounded_float(0.0, 10.0), default=1.0, metavar="F",
                   help="scale of the simulated non-kinematic errors, 0..10 (default 1: the crane's 2-6 cm at the tip)")
    s.add_argument("--truth", action="store_true", help="also print the simulator's true errors")
    s.add_argument("--out", required=True, help="output folder")
    add_overwrite(s)
    s.set_defaults(func=run_simulate)
    return s


def add_demo_parser(verbs):
    """Add ``demo`` to the ``posekit localcal`` verbs."""
    s = verbs.add_parser(
        "demo", help="one look-then-move episode of each method, with the tables",
        description="Run one simulated look-then-move episode of the line-equation method and one of the "
                    "trajectory-matching method (two updates each) and print the paper's tables. "
                    "Writes nothing unless --out is given.")
    s.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")
    _camera_options(s)
    s.add_argument("--out", default=None, help="write tables, figures and report.html to OUT/line and OUT/trajectory")
    add_overwrite(s)
    s.set_defaults(func=run_demo)
    return s


def _camera_options(s):
    s.add_argument("--no-distortion", action="store_true",
                   help="rectified camera images (default: the lens distortion is rendered and undistorted "
                        "in the detection)")
    s.add_argument("--vo", default="stereo", choices=["stereo", "isotropic"],
                   help="VO error model: stereo (default; noise and drift grow with depth, ZED2-like baseline) "
                        "or isotropic (1 mm white noise, 3 mm per sqrt(m) drift: the first simulator's)")
    s.add_argument("--camera-hz", type=bounded_float(0.001, MAX_CAMERA_HZ, "Hz"), default=10.0,
                   help="camera images per second along the circular path, 0.001..100 Hz (line method; default 10)")
    s.add_argument("--plot-hz", type=bounded_float(0.0, MAX_CAMERA_HZ, "Hz"), default=2.0,
                   help="camera images per second along the other motions, for the error plots, 0..100 Hz "
                        "(default 2; 0 = none)")


def _config(args, **extra):
    import math

    from ..localcal.sim.episode import EpisodeConfig
    if not (math.isfinite(args.camera_hz) and args.camera_hz > 0):
        raise ConfigError(f"--camera-hz: expected a rate > 0, got {args.camera_hz:g}")
    if not (math.isfinite(args.plot_hz) and args.plot_hz >= 0):
        raise ConfigError(f"--plot-hz: expected a rate >= 0, got {args.plot_hz:g}")
    check_flags(args)
    vo = {}
    if args.vo == "isotropic":
        from ..localcal.sim.vo import VONoise
        vo = {"vo_stereo": None, "vo_noise_mm": VONoise.noise_mm, "vo_noise_rad": VONoise.noise_rad,
              "vo_drift_mm_per_sqrt_m": VONoise.drift_mm_per_sqrt_m,
              "vo_drift_rad_per_sqrt_m": VONoise.drift_rad_per_sqrt_m}
    elif args.vo != "stereo":
        raise ConfigError(f"--vo: expected stereo or isotropic, got '{args.vo}'")
    return EpisodeConfig(camera_hz=args.camera_hz, plot_hz=args.plot_hz, lens_distortion=not args.no_distortion,
                         **vo, **extra)


def _robot_options(args) -> dict:
    """``robot``, ``base_link``, ``tip_link``, ``start_q`` of EpisodeConfig from the flags, with the
    robot loaded once here so that a bad file or link is a one-line error before any run."""
    import math

    from ..robots import load_robot

    start = None
    if args.start_q_deg is not None:
        try:
            values = [parse_number(v) for v in args.start_q_deg.split(",")]
        except ValueError:
            raise ConfigError(f"--start-q-deg: expected comma-separated numbers, got '{args.start_q_deg[:80]}'") from None
        if not all(math.isfinite(v) for v in values):
            raise ConfigError(f"--start-q-deg: expected finite values, got '{args.start_q_deg[:80]}'")
        if not all(abs(v) <= MAX_START_Q for v in values):
            raise ConfigError(f"--start-q-deg: expected values in -{MAX_START_Q:.0e}..{MAX_START_Q:.0e} deg (mm for a "
                              f"prismatic joint), got '{args.start_q_deg[:80]}'")
        start = values
    options = {"robot": args.robot, "base_link": args.base_link, "tip_link": args.tip_link}
    model = load_robot(args.robot, args.base_link, args.tip_link)
    if start is not None:
        if len(start) != model.n_joints:
            raise ConfigError(f"--start-q-deg: expected {model.n_joints} values for {model.name}, got {len(start)}")
        rad = [math.radians(v) if r else v for v, r in zip(start, model.is_revolute)]
        options["start_q"] = tuple(rad)
    elif args.robot != "hiab033":
        raise ConfigError(f"--start-q-deg: required for --robot {args.robot} (the crane's start pose fits only "
                          f"the crane); give its {model.n_joints} start joint values in deg (chain "
                          f"{getattr(model, 'base_link', 'base')} → {getattr(model, 'tip_link', 'flange')})")
    if args.robot != "hiab033":
        print(f"robot {model.summary}" + "".join(f"; {note}" for note in getattr(model, "notes", ())))
    return options


def _write(result, out, command):
    """``write_experiment`` with a write failure as a one-line ConfigError."""
    from ..localcal.plots import write_experiment
    try:
        return write_experiment(result, out, command=command)
    except OSError as exc:
        raise ConfigError(f"--out {out}: cannot write the results ({exc.strerror or exc})") from None


def _all_failed(result):
    """Every run failed: one line naming the first reason (the CLI prints it and exits 1)."""
    from ..errors import EstimationError
    if all(ep is None for ep in result.episodes):
        n = len(result.episodes)
        raise EstimationError(f"{result.method} method: all {n} run(s) failed; run 1: {result.failures[0]}")


def _scheduler(text: str):
    if text == "local":
        return None
    if text == "serial" or "://" in text:
        return text
    raise ConfigError(f"--scheduler: expected serial, local or a Dask address like tcp://HOST:PORT, got '{text}'")


def _workers(args):
    if args.workers is None:
        return None
    if args.scheduler != "local":
        raise ConfigError("--workers sets the size of the local cluster; it needs --scheduler local")
    if not 1 <= args.workers <= 256:
        raise ConfigError(f"--workers: expected 1 to 256 worker processes, got {args.workers}")
    return args.workers


def run_simulate(args) -> int:
    """Run ``posekit localcal simulate``; the exit code is 0 if every run succeeded, else 1."""
    from ..localcal.plots import tables_text
    from ..localcal.sim.episode import METHODS, OCCLUSIONS
    from ..localcal.sim.experiments import run_experiment

    if args.method not in METHODS:
        raise ConfigError(f"--method: expected one of {' | '.join(METHODS)}, got '{args.method}'")
    if args.runs < 1:
        raise ConfigError(f"--runs: expected an integer >= 1, got {args.runs}")
    if args.updates < 1:
        raise ConfigError(f"--updates: expected an integer >= 1, got {args.updates}")
    if args.seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {args.seed}")
    if args.occlude_ooi not in OCCLUSIONS:
        raise ConfigError(f"--occlude-ooi: expected one of {' | '.join(OCCLUSIONS)}, got '{args.occlude_ooi}'")
    if args.matcher != "cpd" and not args.no_timestamps:
        raise ConfigError(f"--matcher {args.matcher} is the matcher without timestamps; add --no-timestamps")
    if args.registration == "handeye" and args.no_timestamps:
        raise ConfigError("--registration handeye needs timestamps; drop --no-timestamps")
    config = _config(args, use_timestamps=not args.no_timestamps, occlude_ooi=args.occlude_ooi,
                     matcher=args.matcher, calibration_tilt_deg=args.calibration_tilt_deg,
                     registration=args.registration, ooi_distance_mm=args.ooi_distance_mm,
                     error_scale=args.error_scale, **_robot_options(args))
    out_folder(args)
    result = run_experiment(args.method, args.runs, args.seed, updates=args.updates, config=config,
                            scheduler=_scheduler(args.scheduler), progress=sys.stderr.isatty(),
                            n_workers=_workers(args))
    command = "posekit localcal simulate " + " ".join(
        shlex.quote(a) for a in sys.argv[3:]) if sys.argv[1:3] == ["localcal", "simulate"] else ""
    with staged(args) as tmp:
        files = _write(result, tmp, command)       # every run has its row, failed ones with status=error
    hint = _view_hint(args, result)
    if hint and all(ep is None for ep in result.episodes):
        print(hint, file=sys.stderr)
    _all_failed(result)
    print(tables_text(result, truth=args.truth))
    counts = result.status_counts
    print(f"\nruns: {counts['ok']} ok, {counts['suspect']} suspect, {counts['error']} failed (of "
          f"{len(result.episodes)}) in {result.wall_s:.1f} s; wrote {len(files)} files to {args.out} (report.html)")
    if hint:
        print(hint, file=sys.stderr)
    return batch_exit_code(result.statuses)


def _view_hint(args, result) -> str:
    """One line for a robot whose runs lost the markers from view: which flags move them."""
    lost = [f for f in result.failures if f and "not seen by the camera" in f]
    if not lost or args.robot == "hiab033":
        return ""
    return (f"posekit: hint: {len(lost)} run(s) lost the markers from view; the scene is sized for the 5 m crane: "
            "bring the object closer (--ooi-distance-mm 500), start with free reach along the camera axis "
            "(--start-q-deg) or shrink the errors (--error-scale)")


def run_demo(args) -> int:
    """Run ``posekit localcal demo``; the exit code is 0 (a failed episode is a one-line error)."""
    from pathlib import Path

    from ..localcal.plots import tables_text
    from ..localcal.sim.experiments import run_experiment

    if args.seed < 0:
        raise ConfigError(f"--seed: expected an integer >= 0, got {args.seed}")
    config = _config(args)
    if args.out:
        out_folder(args)
    failure = None
    with staged(args) if args.out else contextlib.nullcontext() as tmp:
        for method in ("line", "trajectory"):
            result = run_experiment(method, 1, args.seed, updates=2, config=config, scheduler="serial",
                                    progress=sys.stderr.isatty())
            if args.out:
                _write(result, Path(tmp) / method, f"posekit localcal demo --seed {args.seed}")
            try:
                _all_failed(result)                 # one episode: it failed, so the demo did
            except EstimationError as exc:          # what ran is still written, then the error
                failure = exc
                break
            print(f"== {method} method: one look-then-move episode, seed {args.seed} ==")
            print(tables_text(result))
            print()
    if failure is not None:
        raise failure
    if args.out:
        print(f"wrote the tables, figures and report.html to {Path(args.out) / 'line'} and "
              f"{Path(args.out) / 'trajectory'}")
    return 0
