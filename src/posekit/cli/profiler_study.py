"""``posekit profiler study corners|noise|limits``: the paper's design studies (Table I, Fig. 3, Fig. 4)."""

import math
import sys
from pathlib import Path

from ..errors import ConfigError
from ._common import add_deprecated, add_overwrite, out_folder, parse_triplet, staged

__all__ = ["add_study_parser", "parse_numbers"]


def parse_numbers(text: str, name: str, integer: bool = False) -> tuple:
    """'4,5,7,10' or 'START:STOP:STEP' (inclusive) → a tuple of numbers; ConfigError naming ``--name``."""
    import numpy as np
    try:
        if ":" in text:
            start, stop, step = (float(v) for v in text.split(":"))
            if step <= 0 or stop < start:
                raise ValueError
            values = np.arange(start, stop + 0.5 * step, step)
        else:
            values = np.array([float(v) for v in text.split(",")])
    except ValueError:
        raise ConfigError(f"--{name}: expected comma-separated numbers or START:STOP:STEP, got '{text}'") from None
    if integer:
        if not np.all(values == np.round(values)):
            raise ConfigError(f"--{name}: expected integers, got '{text}'")
        return tuple(int(v) for v in values)
    return tuple(float(v) for v in values)


def _common(p, out_default):
    p.add_argument("--seed", type=int, default=0, help="random seed (same seed, same numbers; default 0)")
    p.add_argument("--out", default=out_default, help=f"output folder (default {out_default}, replaced on each run)")
    add_overwrite(p, out_default)
    p.add_argument("--scheduler", default=None,
                   help="Dask scheduler address tcp://HOST:PORT, or 'serial' (default: a local cluster)")
    p.add_argument("--workers", type=int, default=None,
                   help="worker processes of the local cluster (default: one per core)")


def _workspace(p):
    p.add_argument("--translation-mm", default="10,10,40", help="pose half-ranges x,y,z in G, mm (default 10,10,40)")
    p.add_argument("--rotation-deg", default="4,4,8", help="pose half-ranges about F's x,y,z, deg (default 4,4,8)")
    p.add_argument("--beta-min-deg", type=float, default=50.0,
                   help="random gauges: smallest angle of a face from the vertical, deg (default 50)")


def add_study_parser(verbs):
    """Add ``study`` with sub-verbs corners|noise|limits to the ``posekit profiler`` sub-parsers."""
    p = verbs.add_parser("study", help="design studies of the paper: Table I, Fig. 3, Fig. 4 (CSV, PNG, HTML)")
    kinds = p.add_subparsers(dest="study", metavar="STUDY")
    kinds.required = True

    c = kinds.add_parser("corners", help="Table I: errors vs corner count n and number of random gauges m")
    c.add_argument("--corners", default="4,5,7,10", help="corner counts n (default 4,5,7,10)")
    c.add_argument("--gauges", default="10,50,100,150", help="numbers of random gauges m (default 10,50,100,150)")
    c.add_argument("--count", dest="poses", type=int, default=100, help="random poses per gauge (default 100)")
    add_deprecated(c, "--poses", "--count", "poses", int)
    c.add_argument("--noise-um", type=float, default=5.0, help="Gaussian noise in z, µm (default 5)")
    c.add_argument("--noise-x-um", type=float, default=None, help="noise in x, µm (default: twice --noise-um)")
    _workspace(c)
    _common(c, "study_corners")
    c.set_defaults(func=run_study)

    n = kinds.add_parser("noise", help="Fig. 3: reprojection error and covariance vs noise level")
    n.add_argument("--noise-um", default="0:45:5", help="noise levels in z, µm (default 0:45:5)")
    n.add_argument("--noise-x-ratio", type=float, default=2.0, help="noise in x / noise in z (default 2)")
    n.add_argument("--corners", type=int, default=5, help="corner count n (default 5)")
    n.add_argument("--gauges", type=int, default=150, help="random gauges (default 150)")
    n.add_argument("--count", dest="poses", type=int, default=100, help="random poses per gauge (default 100)")
    add_deprecated(n, "--poses", "--count", "poses", int)
    _workspace(n)
    _common(n, "study_noise")
    n.set_defaults(func=run_study)

    lim = kinds.add_parser("limits", help="Fig. 4: range of motion vs gauge size, success rate vs tilt")
    lim.add_argument("--corners", type=int, default=5, help="corner count n (default 5)")
    lim.add_argument("--gauges", type=int, default=3, help="random gauges per size and per beta (default 3)")
    lim.add_argument("--widths-mm", default="40:260:20", help="gauge widths, mm (default 40:260:20)")
    lim.add_argument("--lengths-mm", default="10:80:10", help="gauge lengths along the ridges, mm (default 10:80:10)")
    lim.add_argument("--betas-deg", default="30,45,60", help="gauge beta, deg (default 30,45,60)")
    lim.add_argument("--tilts-deg", default="-75:75:2.5", help="tilts alpha about F's y, deg (default -75:75:2.5)")
    lim.add_argument("--tilt-poses", type=int, default=10, help="jittered poses per gauge and tilt (default 10)")
    lim.add_argument("--noise-um", type=float, default=5.0, help="Gaussian noise in z, µm (x: twice; default 5)")
    _common(lim, "study_limits")
    lim.set_defaults(func=run_study)
    return p


def _noise_model(z_um, x_um):
    from ..profiler.sensor import NoiseModel
    for flag, v in (("--noise-um", z_um), ("--noise-x-um", x_um)):
        if v is not None and not (math.isfinite(v) and v >= 0):
            raise ConfigError(f"{flag} must be a finite number >= 0, got {v:g}")
    return NoiseModel(sigma_x_um=2.0 * z_um if x_um is None else x_um, sigma_z_um=z_um)


def _build(args):
    """The study function and its configuration from the parsed flags."""
    from ..profiler.sensor import Workspace
    if args.study == "limits":
        from ..profiler.study_limits import LimitsConfig, limits_study
        cfg = LimitsConfig(n_corners=args.corners, gauges=args.gauges,
                           widths_mm=parse_numbers(args.widths_mm, "widths-mm"),
                           lengths_mm=parse_numbers(args.lengths_mm, "lengths-mm"),
                           betas_deg=parse_numbers(args.betas_deg, "betas-deg"),
                           tilts_deg=parse_numbers(args.tilts_deg, "tilts-deg"), tilt_poses=args.tilt_poses,
                           noise=_noise_model(args.noise_um, None), seed=args.seed)
        return limits_study, cfg
    from ..profiler.study import CornersConfig, NoiseConfig, corners_study, noise_study
    ws = Workspace(translation_mm=parse_triplet(args.translation_mm, "translation-mm"),
                   rotation_deg=parse_triplet(args.rotation_deg, "rotation-deg"))
    if args.study == "corners":
        cfg = CornersConfig(corners=parse_numbers(args.corners, "corners", integer=True),
                            gauges=parse_numbers(args.gauges, "gauges", integer=True), poses=args.poses,
                            noise=_noise_model(args.noise_um, args.noise_x_um), seed=args.seed, workspace=ws,
                            beta_min_deg=args.beta_min_deg)
        return corners_study, cfg
    cfg = NoiseConfig(noise_um=parse_numbers(args.noise_um, "noise-um"), n_corners=args.corners,
                      gauges=args.gauges, poses=args.poses, x_ratio=args.noise_x_ratio, seed=args.seed,
                      workspace=ws, beta_min_deg=args.beta_min_deg)
    return noise_study, cfg


def _print_summary(study, out):
    from ..profiler.study import CornersStudy, NoiseStudy
    if isinstance(study, CornersStudy):
        print("method    n     m  reproj mean/std (µm)   t_err (µm)  rot_err (deg)  failures")
        for r in study.table:
            print(f"{r['method']:<6} {r['n']:>4} {r['m']:>5}  {r['reproj_mean_um']:>9.3g} / {r['reproj_std_um']:<9.3g}"
                  f" {r['t_err_mean_um']:>10.3g}  {r['rot_err_mean_deg']:>12.3g}  {r['failures']:>8}")
    elif isinstance(study, NoiseStudy):
        print("noise (µm) method  reproj mean/std (µm)   t_err (µm)  failures")
        for r in study.table:
            print(f"{r['noise_um']:>10g} {r['method']:<6} {r['reproj_mean_um']:>9.3g} / {r['reproj_std_um']:<9.3g}"
                  f" {r['t_err_mean_um']:>10.3g}  {r['failures']:>8}")
    print(f"wrote {out} ({study.wall_s:.1f} s wall, {study.task_cpu_s:.1f} s CPU in the tasks)")


def run_study(args) -> int:
    from ..profiler.study_report import write_report
    if args.workers is not None and args.scheduler is not None:
        raise ConfigError("--workers sets the size of the local cluster; it cannot be combined with --scheduler")
    fn, cfg = _build(args)
    out_folder(args)
    study = fn(cfg, scheduler=args.scheduler, n_workers=args.workers)
    with staged(args) as tmp:
        write_report(study, tmp)
    report = Path(args.out) / "report.html"
    _print_summary(study, report)
    sys.stdout.flush()
    return 0
