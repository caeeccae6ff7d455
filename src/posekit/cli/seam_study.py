"""``posekit seam study``: Monte-Carlo tuning study of the filter parameters (Fig. 6)."""

import math
import sys

from .._numbers import parse_number
from ..errors import ConfigError
from ._common import add_dask_args, add_overwrite, check_dask_args, local_scheduler
from ._flags import bounded_float, bounded_int, check_flags, seed

#: Most random parameter draws, most episodes per draw, and most episodes in all (a study of
#: 100,000 default episodes takes about a day on 2 cores: more belongs on a cluster, in parts;
#: ``posekit.seam.frontend.commands_batch.MAX_STUDY_EPISODES``, a test keeps them equal).
MAX_RUNS, MAX_EPISODES, MAX_STUDY_EPISODES = 10_000, 100, 100_000

__all__ = ["add_study_parser", "parse_factors"]


def add_study_parser(verbs):
    """Add ``study`` to the ``posekit seam`` sub-parsers."""
    p = verbs.add_parser("study", help="randomly perturbed filter parameters on Dask, OLS of each error RMSE, "
                                       "Fig. 6 p-value heatmap, ranked parameters (CSV, PNG, report.html)")
    p.add_argument("--config", default=None, help="base YAML configuration (default: the paper's setup)")
    from .seam_simulate import TRAJECTORIES

    p.add_argument("--trajectory", choices=TRAJECTORIES, default=None,
                   help="overrides trajectory.kind")
    p.add_argument("--sensors", type=int, choices=(0, 1, 2, 3, 4), default=None, help="overrides cell.sensors.count, 0..4")
    from .seam_simulate import _PARTICLES, _STEPS, MAX_PARTICLES, MAX_STEPS

    p.add_argument("--particles", type=_PARTICLES, default=None,
                   help=f"overrides filter.particles, 1..{MAX_PARTICLES}")
    p.add_argument("--steps", type=_STEPS, default=None, help=f"overrides trajectory.steps, 2..{MAX_STEPS}")
    p.add_argument("--runs", type=bounded_int(1, MAX_RUNS), default=100,
                   help=f"random parameter draws, 1..{MAX_RUNS} (default 100)")
    p.add_argument("--episodes", type=bounded_int(1, MAX_EPISODES), default=1,
                   help=f"episodes per draw, errors pooled, 1..{MAX_EPISODES}; runs × episodes at most "
                        f"{MAX_STUDY_EPISODES:,} (default 1)")
    p.add_argument("--parameters", default=None,
                   help="comma-separated dotted keys to perturb, each optionally KEY=LOW:HIGH "
                        "(default: the profile's walk and plateau, the filter's kernel bandwidth and ESS threshold)")
    p.add_argument("--spread", type=bounded_float(0.0, 1.0, lo_open=True, hi_open=True), default=0.5,
                   help="relative half-range of a perturbation around the base value, (0, 1) (default 0.5)")
    p.add_argument("--seed", type=seed, default=0, help="study seed (default 0; same seed, same table)")
    add_dask_args(p)
    p.add_argument("--dump-config", action="store_true",
                   help="print the effective configuration (--config with the overrides; loadable by --config) "
                        "and exit")
    p.add_argument("--out", default=None, help="output folder (required unless --dump-config)")
    add_overwrite(p)
    p.set_defaults(func=run_study)
    return p


def parse_factors(text: str | None):
    """``'profile.plateau.d0_mm,profile.walk.z_mm=0:0.1'`` -> (names, {name: (low, high)})."""
    if text is None:
        return None, {}
    names, ranges = [], {}
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        name, _, rng = item.partition("=")
        names.append(name.strip())
        if rng:
            try:
                lo, hi = (parse_number(v) for v in rng.split(":"))
            except ValueError:
                raise ConfigError(f"--parameters: expected KEY or KEY=LOW:HIGH, got '{item[:80]}'") from None
            if not (math.isfinite(lo) and math.isfinite(hi)):
                raise ConfigError(f"--parameters: expected finite LOW and HIGH in KEY=LOW:HIGH, got '{item[:80]}'")
            ranges[name.strip()] = (lo, hi)
    if not names:
        raise ConfigError(f"--parameters: expected at least one dotted key, got '{text}'")
    return names, ranges


def run_study(args) -> int:
    from ..seam.frontend.commands_batch import check_study_size, study
    from ..seam.frontend.config import dump_config
    from ..seam.frontend.report import ERROR_AXES
    from ._common import out_folder, staged
    from .seam_simulate import build_config

    check_dask_args(args)
    for flag, v in (("--runs", args.runs), ("--episodes", args.episodes)):
        if v < 1:
            raise ConfigError(f"{flag}: expected an integer >= 1, got {v}")
    cfg = build_config(args)
    if args.dump_config:
        sys.stdout.write(dump_config(cfg))
        return 0
    if not args.out:
        raise ConfigError("--out: an output folder is required (or use --dump-config)")
    check_flags(args)
    check_study_size(args.runs, args.episodes)
    names, ranges = parse_factors(args.parameters)
    out_folder(args)
    with staged(args) as tmp:
        run = study(cfg, tmp, runs=args.runs, episodes=args.episodes, parameters=names, ranges=ranges,
                    spread=args.spread, seed=args.seed, scheduler=local_scheduler(args), n_workers=args.workers)
    result, failed = run.study, run.failed
    print(f"seam study: {len(result.X)} runs × {result.episodes} episode(s), {len(result.factors)} parameters, "
          f"{failed} failed; {result.wall_s:.1f} s wall, {result.task_cpu_s:.1f} s CPU in the tasks")
    if result.effects is None:
        print(f"no linear models: {result.effects_error}")
    else:
        print(f"{'rank':>4}  {'parameter':<28}{'min log10 p':>12}  most affected   " +
              "".join(f"{'lg p ' + a:>9}" for a in ERROR_AXES))
        for r in result.ranked:
            print(f"{r['rank']:>4}  {r['parameter']:<28}{r['min_log10_p']:>12.2f}  {r['most_affected']:<14}  "
                  + "".join(f"{r['log10_p_' + a]:>9.2f}" for a in ERROR_AXES))
    print(f"wrote {args.out}: {', '.join(run.written)}")
    sys.stdout.flush()
    if failed:  # a batch with failed items: every row is written, the exit code says so
        print(f"posekit: error: {failed} of {len(result.X)} study runs failed; their rows in runs.csv say why",
              file=sys.stderr)
    return run.exit_code
