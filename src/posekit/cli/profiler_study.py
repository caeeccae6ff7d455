"""``posekit profiler study corners|noise|limits``: the paper's design studies (Table I, Fig. 3, Fig. 4)."""

import math
import sys
from pathlib import Path

from .._numbers import parse_number
from ..errors import ConfigError
from ._common import (
    SCHEDULER_HELP,
    add_deprecated,
    add_overwrite,
    check_workspace,
    local_scheduler,
    overwrite_flag,
    parse_triplet,
    replace_own_flag,
)
from ._config import add_config_arguments
from ._flags import MAX_NOISE_UM, MAX_PROFILES, bounded_float, bounded_int, check_flags, check_range, seed, workers

__all__ = ["add_study_parser", "parse_numbers"]

#: Most values one list flag expands to (``START:STOP:STEP`` included), checked before allocating.
MAX_VALUES = 1000
#: Most corners of a random gauge (the paper studies 4..10; beyond ~15 none fits the profiler's view).
MAX_CORNERS = 50
#: Most random gauges per corner count, size or beta.
MAX_GAUGES = 10_000
#: Most simulated profiles of one study (about 1 ms each with both methods: hours on 2 cores).
MAX_STUDY_PROFILES = 10**7
_POSES = bounded_int(1, MAX_PROFILES, flag="--count")
_NOISE = bounded_float(0.0, MAX_NOISE_UM, "µm")
_CORNERS = bounded_int(4, MAX_CORNERS)
_GAUGES = bounded_int(1, MAX_GAUGES)


def parse_numbers(text: str, name: str, integer: bool = False, *, lo=None, hi=None, unit: str = "",
                  max_count: int = MAX_VALUES) -> tuple:
    """'4,5,7,10' or 'START:STOP:STEP' (inclusive) → a tuple of numbers; ConfigError naming ``--name``.

    At most ``max_count`` values (counted before anything is allocated), each in ``lo..hi``
    (``unit`` for the message) when given.
    """
    import numpy as np
    bad = ConfigError(f"--{name}: expected comma-separated numbers or START:STOP:STEP, got '{text[:80]}'")
    if ":" in text:
        try:
            start, stop, step = (parse_number(v) for v in text.split(":"))
        except ValueError:
            raise bad from None
        if not (math.isfinite(start) and math.isfinite(stop) and math.isfinite(step)) or step <= 0 or stop < start:
            raise bad
        count = (stop - start) / step + 1
        if count > max_count:
            raise ConfigError(f"--{name}: '{text[:80]}' gives {count:.3g} values; expected at most {max_count}")
        values = np.arange(start, stop + 0.5 * step, step)
    else:
        parts = text.split(",")
        if len(parts) > max_count:
            raise ConfigError(f"--{name}: {len(parts)} values; expected at most {max_count}")
        try:
            values = np.array([parse_number(v) for v in parts])
        except ValueError:
            raise bad from None
    if integer:
        if not np.all(values == np.round(values)):
            raise ConfigError(f"--{name}: expected integers, got '{text}'")
    if lo is not None and hi is not None:
        for v in values:
            check_range(f"--{name}", float(v), lo, hi, unit, what="integers" if integer else "numbers",
                        shown=repr(text))
    if integer:
        return tuple(int(v) for v in values)
    return tuple(float(v) for v in values)


def _common(p, out_default):
    p.add_argument("--seed", type=seed, default=0, help="random seed (same seed, same numbers; default 0)")
    p.add_argument("--out", default=out_default, help=f"output folder (default {out_default}, replaced on each run while it holds only posekit's files)")
    add_overwrite(p, out_default)
    p.add_argument("--scheduler", default=None, help=SCHEDULER_HELP)
    p.add_argument("--workers", type=workers, default=None,
                   help="worker processes of the local cluster, 1..256 (default: one per core)")
    add_config_arguments(p)


def _workspace(p):
    p.add_argument("--translation-mm", default="10,10,40",
                   help="pose half-ranges x,y,z in G, 0..1000 mm (default 10,10,40)")
    p.add_argument("--rotation-deg", default="4,4,8", help="pose half-ranges about F's x,y,z, 0..180 deg (default 4,4,8)")
    p.add_argument("--beta-min-deg", type=bounded_float(0.0, 90.0, "deg", lo_open=True, hi_open=True), default=50.0,
                   help="random gauges: smallest angle of a face from the vertical, (0, 90) deg (default 50)")


def add_study_parser(verbs):
    """Add ``study`` with sub-verbs corners|noise|limits to the ``posekit profiler`` sub-parsers."""
    p = verbs.add_parser("study", help="design studies of the paper: Table I, Fig. 3, Fig. 4 (CSV, PNG, HTML)")
    kinds = p.add_subparsers(dest="study", metavar="STUDY")
    kinds.required = True

    c = kinds.add_parser("corners", help="Table I: errors vs corner count n and number of random gauges m")
    c.add_argument("--corners", default="4,5,7,10", help=f"corner counts n, 4..{MAX_CORNERS} (default 4,5,7,10)")
    c.add_argument("--gauges", default="10,50,100,150",
                   help=f"numbers of random gauges m, 1..{MAX_GAUGES} (default 10,50,100,150)")
    c.add_argument("--count", dest="poses", type=_POSES, default=100,
                   help=f"random poses per gauge, 1..{MAX_PROFILES} (default 100)")
    add_deprecated(c, "--poses", "--count", "poses", _POSES)
    c.add_argument("--noise-um", type=_NOISE, default=5.0, help="Gaussian noise in z, 0..10000 µm (default 5)")
    c.add_argument("--noise-x-um", type=_NOISE, default=None,
                   help="noise in x, 0..10000 µm (default: twice --noise-um)")
    _workspace(c)
    _common(c, "study_corners")
    c.set_defaults(func=run_study)

    n = kinds.add_parser("noise", help="Fig. 3: reprojection error and covariance vs noise level")
    n.add_argument("--noise-um", default="0:45:5", help="noise levels in z, 0..10000 µm (default 0:45:5)")
    n.add_argument("--noise-x-ratio", type=bounded_float(0.0, 100.0), default=None,
                   help="noise in x / noise in z, 0..100 (default 2, the LJ-X8400's 10/5 µm)")
    n.add_argument("--corners", type=_CORNERS, default=5, help=f"corner count n, 4..{MAX_CORNERS} (default 5)")
    n.add_argument("--gauges", type=_GAUGES, default=150, help=f"random gauges, 1..{MAX_GAUGES} (default 150)")
    n.add_argument("--count", dest="poses", type=_POSES, default=100,
                   help=f"random poses per gauge, 1..{MAX_PROFILES} (default 100)")
    add_deprecated(n, "--poses", "--count", "poses", _POSES)
    _workspace(n)
    _common(n, "study_noise")
    n.set_defaults(func=run_study)

    lim = kinds.add_parser("limits", help="Fig. 4: range of motion vs gauge size, success rate vs tilt")
    lim.add_argument("--corners", type=_CORNERS, default=5, help=f"corner count n, 4..{MAX_CORNERS} (default 5)")
    lim.add_argument("--gauges", type=_GAUGES, default=3,
                     help=f"random gauges per size and per beta, 1..{MAX_GAUGES} (default 3)")
    lim.add_argument("--widths-mm", default="40:260:20", help="gauge widths, 1..1000 mm (default 40:260:20)")
    lim.add_argument("--lengths-mm", default="10:80:10",
                     help="gauge lengths along the ridges, 1..1000 mm (default 10:80:10)")
    lim.add_argument("--betas-deg", default="30,45,60", help="gauge beta, 5..85 deg (default 30,45,60)")
    lim.add_argument("--tilts-deg", default="-75:75:2.5",
                     help="tilts alpha about F's y, -89..89 deg (default -75:75:2.5)")
    lim.add_argument("--tilt-poses", type=bounded_int(1, 1000), default=10,
                     help="jittered poses per gauge and tilt, 1..1000 (default 10)")
    lim.add_argument("--noise-um", type=_NOISE, default=5.0, help="Gaussian noise in z, 0..10000 µm (x: twice; default 5)")
    _common(lim, "study_limits")
    lim.set_defaults(func=run_study)
    return p


def _noise_model(z_um, x_um):
    from ..profiler.sensor import NoiseModel
    for flag, v in (("--noise-um", z_um), ("--noise-x-um", x_um)):
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise ConfigError(f"{flag} must be a finite number >= 0, got {v:g}")
    return NoiseModel.from_z_um(z_um, x_um)


def _build(args):
    """The study's configuration from the parsed flags (:func:`~posekit.profiler.studies.study_report.run_study`
    picks the study by its type)."""
    from ..profiler.sim.poses import Workspace
    if args.study == "limits":
        from ..profiler.studies.study_limits import LimitsConfig
        cfg = LimitsConfig(n_corners=args.corners, gauges=args.gauges,
                           widths_mm=parse_numbers(args.widths_mm, "widths-mm", lo=1.0, hi=1e3, unit="mm"),
                           lengths_mm=parse_numbers(args.lengths_mm, "lengths-mm", lo=1.0, hi=1e3, unit="mm"),
                           betas_deg=parse_numbers(args.betas_deg, "betas-deg", lo=5.0, hi=85.0, unit="deg"),
                           tilts_deg=parse_numbers(args.tilts_deg, "tilts-deg", lo=-89.0, hi=89.0, unit="deg"),
                           tilt_poses=args.tilt_poses, noise=_noise_model(args.noise_um, None), seed=args.seed)
        return cfg
    from ..profiler.studies.study import CornersConfig
    from ..profiler.studies.study_noise import NoiseConfig
    ws = Workspace(translation_mm=parse_triplet(args.translation_mm, "translation-mm"),
                   rotation_deg=parse_triplet(args.rotation_deg, "rotation-deg"))
    check_workspace(ws, args)
    if args.study == "corners":
        cfg = CornersConfig(corners=parse_numbers(args.corners, "corners", integer=True, lo=4, hi=MAX_CORNERS),
                            gauges=parse_numbers(args.gauges, "gauges", integer=True, lo=1, hi=MAX_GAUGES),
                            poses=args.poses, noise=_noise_model(args.noise_um, args.noise_x_um), seed=args.seed,
                            workspace=ws, beta_min_deg=args.beta_min_deg)
        return cfg
    cfg = NoiseConfig(noise_um=parse_numbers(args.noise_um, "noise-um", lo=0.0, hi=MAX_NOISE_UM, unit="µm"),
                      n_corners=args.corners,
                      gauges=args.gauges, poses=args.poses, seed=args.seed,
                      workspace=ws, beta_min_deg=args.beta_min_deg,
                      **({} if args.noise_x_ratio is None else {"x_ratio": args.noise_x_ratio}))
    return cfg


def _check_size(args, cfg) -> None:
    """At most :data:`MAX_STUDY_PROFILES` simulated profiles in the whole study."""
    if args.study == "corners":
        n, how = len(cfg.corners) * sum(cfg.gauges) * cfg.poses, "corner counts × gauges × --count"
    elif args.study == "noise":
        n, how = len(cfg.noise_um) * cfg.gauges * cfg.poses, "noise levels × --gauges × --count"
    else:
        n = cfg.gauges * (len(cfg.widths_mm) * len(cfg.lengths_mm) + len(cfg.betas_deg) * len(cfg.tilts_deg)
                          * cfg.tilt_poses)
        how = "--gauges × (widths × lengths + betas × tilts × --tilt-poses)"
    if n > MAX_STUDY_PROFILES:
        raise ConfigError(f"study of {n:.3g} simulated gauge poses ({how}); expected at most "
                          f"{MAX_STUDY_PROFILES:.0e} (hours on 2 cores): fewer gauges, poses or values")


def _print_summary(study, out):
    from ..profiler.studies.study import CornersStudy
    from ..profiler.studies.study_noise import NoiseStudy
    if isinstance(study, CornersStudy):
        print("method    n     m  reproj mean/std (µm)   eq.17 ×10³ mean/std   t_err (µm)  rot_err (deg)  failures")
        for r in study.table:
            print(f"{r['method']:<6} {r['n']:>4} {r['m']:>5}  {r['reproj_mean_um']:>9.3g} / {r['reproj_std_um']:<9.3g}"
                  f" {r['eq17_mean_um_per_mm']:>9.3g} / {r['eq17_std_um_per_mm']:<9.3g}"
                  f" {r['t_err_mean_um']:>10.3g}  {r['rot_err_mean_deg']:>12.3g}  {r['failures']:>8}")
    elif isinstance(study, NoiseStudy):
        print("noise (µm) method  reproj mean/std (µm)   t_err (µm)  failures")
        for r in study.table:
            print(f"{r['noise_um']:>10g} {r['method']:<6} {r['reproj_mean_um']:>9.3g} / {r['reproj_std_um']:<9.3g}"
                  f" {r['t_err_mean_um']:>10.3g}  {r['failures']:>8}")
    print(f"wrote {out} ({study.wall_s:.1f} s wall, {study.task_cpu_s:.1f} s CPU in the tasks)")


def run_study(args) -> int:
    from ..profiler.studies.study_report import run_study as study
    if args.workers is not None and args.scheduler is not None:
        raise ConfigError("--workers sets the size of the local cluster; it cannot be combined with --scheduler")
    check_flags(args)
    cfg = _build(args)
    _check_size(args, cfg)
    result = study(cfg, args.out, scheduler=local_scheduler(args), n_workers=args.workers,
                   overwrite=overwrite_flag(args), replace_own=replace_own_flag(args))
    report = Path(args.out) / "report.html"
    _print_summary(result, report)
    sys.stdout.flush()
    return 0
