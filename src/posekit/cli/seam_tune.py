"""``posekit seam tune LOGDIR [LOGDIR ...] --out PROFILE.yaml [--with-truth [--cross-check [--scheduler ADDR |
--workers N]]]``: fit a cell's profile (``--dump-config``: the cell configuration it works with); the cross-check's
folds run on Dask (a local cluster by default)."""

import sys
import time
from pathlib import Path

from ._common import SCHEDULER_HELP
from ._flags import bounded_int, seed, workers

__all__ = ["add_tune_parser"]

#: Most episodes ``--simulate`` makes (``posekit.seam.frontend.commands_batch.MAX_SIMULATED``; a test keeps
#: them equal).
MAX_SIMULATED = 100


def add_tune_parser(verbs):
    """Add ``tune`` to the ``posekit seam`` sub-parsers."""
    p = verbs.add_parser("tune", help="fit a profile (walk, plateau, laser noise, latency) from recorded episodes: "
                                      "from the laser innovations, or with --with-truth from the errors")
    p.add_argument("logdirs", nargs="*", metavar="LOGDIR", help="recorded episodes of one cell")
    p.add_argument("--with-truth", action="store_true",
                   help="fit from the errors against each episode's truth.csv (a reference such as a laser tracker)")
    p.add_argument("--from", dest="base", default=None, metavar="PROFILE.yaml",
                   help="the profile whose values are kept where the data do not pin them (default: the setup's, "
                        "else the shipped default)")
    p.add_argument("--share-sensors", action="store_true",
                   help="one laser noise and one latency for every sensor")
    p.add_argument("--cross-check", action="store_true",
                   help="with --with-truth: also leave each episode out in turn, fit on the others and track it: "
                        "its 2σ coverage per axis, tracking and confident-wrong shares (one fit per episode)")
    p.add_argument("--scheduler", default=None,
                   help="--cross-check: where its folds run: " + SCHEDULER_HELP)
    p.add_argument("--workers", type=workers, default=None,
                   help="--cross-check: worker processes of the local cluster, 1..256 (default: one per core)")
    p.add_argument("--simulate", type=bounded_int(1, MAX_SIMULATED), default=None, metavar="RUNS",
                   help=f"fit on RUNS episodes simulated now (1..{MAX_SIMULATED}; with --config, --seed), "
                        "written to a temporary folder; how the shipped default profile is made")
    p.add_argument("--config", default=None,
                   help="configuration of the simulated episodes (--simulate; default: the paper's setup)")
    p.add_argument("--trajectory", default=None, metavar="KINDS",
                   help="--simulate: RUNS episodes of each comma-separated trajectory kind (xy,yz,line,bend; default "
                        "the configuration's)")
    p.add_argument("--seed", type=seed, default=None,
                   help="seed of the simulated episodes (--simulate; default the configuration's, 0)")
    p.add_argument("--dump-config", action="store_true",
                   help="print the cell configuration it works with (--simulate: the simulated one, with "
                        "--trajectory KIND and --seed; else the recorded episodes' setup; --from as its profile), "
                        "loadable by --config of every seam verb, and exit")
    p.add_argument("--out", default=None, metavar="PROFILE.yaml",
                   help="the profile file to write (required unless --dump-config)")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.set_defaults(func=run_tune)
    return p


def run_tune(args) -> int:
    from ..errors import ConfigError
    from ..seam.frontend.commands_batch import tune, tune_config
    from ._flags import check_flags
    from .seam_simulate import layout_notes

    check_flags(args)
    if args.dump_config:
        from ..seam.frontend.config import dump_config

        with layout_notes():
            cfg = tune_config(args.logdirs, base=args.base, simulate=args.simulate, config=args.config,
                              trajectory=args.trajectory, seed=args.seed)
        sys.stdout.write(dump_config(cfg))
        return 0
    if not args.out:
        raise ConfigError("--out: a profile file is required (or use --dump-config)")
    if args.cross_check and not args.with_truth:
        raise ConfigError("--cross-check: needs --with-truth (each left-out episode is scored against its truth.csv)")
    if args.cross_check and args.simulate is not None:
        raise ConfigError("--cross-check: recorded episodes only, not --simulate (track held-out simulated "
                          "episodes with posekit seam simulate --profile)")
    if (args.scheduler is not None or args.workers is not None) and not args.cross_check:
        raise ConfigError(f"{'--scheduler' if args.scheduler is not None else '--workers'}: only with --cross-check "
                          "(its folds are what runs in parallel)")
    if args.cross_check:
        from ..seam.frontend.tune_check import check_cross_check
        from ._common import check_dask_args, check_scheduler

        check_dask_args(args)
        check_scheduler(args.scheduler)
        check_cross_check(args.logdirs)
    t0 = time.monotonic()

    def stage(text):   # what the fit is doing, on stderr (a fit takes seconds to minutes)
        print(f"posekit seam tune: [{time.monotonic() - t0:5.1f} s] {text}", file=sys.stderr, flush=True)

    with layout_notes():
        result = tune(args.out, args.logdirs, with_truth=args.with_truth, base=args.base,
                      share_sensors=args.share_sensors, simulate=args.simulate, config=args.config,
                      trajectory=args.trajectory, seed=args.seed, overwrite=args.overwrite, stage=stage)
    from ..seam.frontend.tune import tune_report

    print(tune_report(result))
    unpinned = len(result.unpinned)
    print(f"wrote {Path(args.out)}" + (f" ({unpinned} value(s) kept from the base profile: the data do not pin them)"
                                      if unpinned else ""))
    if args.cross_check:
        from ..seam.frontend.tune_check import cross_check, cross_check_report
        from ._common import local_scheduler

        sys.stdout.flush()
        print(cross_check_report(cross_check(args.logdirs, base=args.base, share_sensors=args.share_sensors,
                                             stage=stage, scheduler=local_scheduler(args), n_workers=args.workers)))
    # a profile from a few episodes depends on which (benchmarks/seam_training_sets.py): say how to check it
    print(f"next: check it on episodes it was not fitted on: posekit seam track EPISODE --profile {args.out} --out "
          "DIR (with a truth.csv, DIR/metrics.json has the 2σ coverage per axis and confident_wrong)")
    sys.stdout.flush()
    return 0
