"""``posekit seam tune LOGDIR [LOGDIR ...] --out PROFILE.yaml [--with-truth]``: fit a cell's profile."""

import sys

from ..errors import ConfigError
from ._flags import bounded_int, seed

__all__ = ["add_tune_parser"]

#: Most episodes ``--simulate`` makes.
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
    p.add_argument("--simulate", type=bounded_int(1, MAX_SIMULATED), default=None, metavar="RUNS",
                   help=f"fit on RUNS episodes simulated now (1..{MAX_SIMULATED}; with --config, --seed), "
                        "written to a temporary folder; how the shipped default profile is made")
    p.add_argument("--config", default=None, help="configuration of the simulated episodes (--simulate)")
    p.add_argument("--trajectory", default=None, metavar="KINDS",
                   help="--simulate: RUNS episodes of each comma-separated trajectory kind (xy,yz,line,bend; default "
                        "the configuration's)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the simulated episodes (--simulate; default 0)")
    p.add_argument("--out", required=True, metavar="PROFILE.yaml", help="the profile file to write")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --out file")
    p.set_defaults(func=run_tune)
    return p


def _command(args) -> list:
    """The command line that reproduces this run (``--overwrite`` left out), as recorded in the profile."""
    out = ["posekit", "seam", "tune", *args.logdirs]
    if args.simulate is not None:
        out += ["--simulate", args.simulate]
        out += ["--config", args.config] if args.config else []
        out += ["--trajectory", args.trajectory] if args.trajectory else []
        out += ["--seed", args.seed]
    out += ["--with-truth"] if args.with_truth else []
    out += ["--share-sensors"] if args.share_sensors else []
    out += ["--from", args.base] if args.base else []
    return out + ["--out", args.out]


def run_tune(args) -> int:
    import shlex
    from pathlib import Path

    from ..seam.frontend.profile import write_profile
    from ..seam.frontend.tune import tune_profile, tune_report, tune_simulated
    from ._flags import check_flags
    from .seam_simulate import layout_notes

    check_flags(args)
    out = Path(args.out)
    if out.exists() and not args.overwrite:
        raise ConfigError(f"--out {out}: exists; expected a new file (or --overwrite)")
    if args.simulate is None and not args.logdirs:
        raise ConfigError("seam tune: expected at least one LOGDIR (or --simulate RUNS)")
    if args.simulate is not None and args.logdirs:
        raise ConfigError("seam tune: expected LOGDIRs or --simulate RUNS, not both")
    if args.simulate is None and (args.config is not None or args.trajectory is not None):
        raise ConfigError("--config, --trajectory: only with --simulate (a recorded episode's setup.yaml describes "
                          "its cell)")
    command = " ".join(shlex.quote(str(a)) for a in _command(args))
    with layout_notes():
        if args.simulate is None:
            result = tune_profile(args.logdirs, with_truth=args.with_truth, base=args.base,
                                  share_sensors=args.share_sensors, command=command)
        else:
            kinds = None if args.trajectory is None else [k.strip() for k in args.trajectory.split(",")]
            result = tune_simulated(args.config, args.simulate, kinds, args.seed, with_truth=args.with_truth,
                                    base=args.base, share_sensors=args.share_sensors, command=command)
    header = (f"posekit seam profile, fitted by: {command}\n"
              f"from {result.episodes} episode(s), {result.steps} samples "
              f"({'errors against truth.csv' if result.method == 'truth' else 'laser innovations'})")
    write_profile(out, result.profile, header)
    print(tune_report(result))
    unpinned = len(result.unpinned)
    print(f"wrote {out}" + (f" ({unpinned} value(s) kept from the base profile: the data do not pin them)"
                            if unpinned else ""))
    sys.stdout.flush()
    return 0
