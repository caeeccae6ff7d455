"""``posekit demo`` (the closed-loop experiment) and ``posekit profiler accuracy``."""

from ._common import progress
from ._flags import MAX_NOISE_UM, MAX_PROFILES, bounded_float, bounded_int, check_flags, seed

__all__ = ["add_parser"]


def add_parser(sub):
    p = sub.add_parser("demo", help="the closed loop of the paper's §IV-C on the bundled gauge "
                                    "(same as `posekit profiler loop --out posekit-demo`)")
    from .profiler_loop import add_loop_arguments, run_loop
    add_loop_arguments(p, out_default="posekit-demo")
    p.set_defaults(func=run_loop)


def add_accuracy_arguments(p):
    p.add_argument("--gauge", default="demo-5", help="bundled gauge name or YAML file (default demo-5)")
    p.add_argument("--count", type=bounded_int(1, MAX_PROFILES, "profiles"), default=1000,
                   help=f"number of profiles, 1..{MAX_PROFILES} (default 1000)")
    p.add_argument("--noise-um", type=bounded_float(0.0, MAX_NOISE_UM, "µm"), default=5.0,
                   help="noise in z, 0..10000 µm (x: twice that); default 5")
    p.add_argument("--seed", type=seed, default=0, help="random seed (default 0)")


def run_accuracy(args) -> int:
    from ..errors import ConfigError
    from ..profiler.gauge.model import resolve_gauge
    from ..profiler.sensor import NoiseModel
    from ..profiler.studies.evaluate import accuracy, accuracy_table

    if args.count < 1:
        raise ConfigError(f"--count must be >= 1, got {args.count}")
    check_flags(args)
    gauge = resolve_gauge(args.gauge)
    noise = NoiseModel.from_z_um(args.noise_um)
    print(f"posekit profiler accuracy: {args.count} simulated LJ-X8400-like profiles of gauge '{gauge.name}' "
          f"({gauge.n_corners} corners), noise {noise.sigma_z_um:g} µm in z / {noise.sigma_x_um:g} µm in x, "
          f"seed {args.seed}")
    rows = accuracy(gauge, args.count, noise_um=args.noise_um, seed=args.seed,
                    progress=lambda it, method: progress(it, total=args.count, desc=method))
    print()
    print(accuracy_table(rows, args.count))
    return 0
