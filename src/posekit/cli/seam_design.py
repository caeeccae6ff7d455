"""``posekit seam design``: which sensor configuration to buy for a seam (the paper's purpose).

``posekit seam design --config CFG --sensors 1,2,3 --distances-mm A:B:STEP --runs R --out DIR``
simulates every configuration (on a local Dask cluster by default, in this process without Dask,
``--scheduler`` for a cluster), ranks them by the tool-pose RMSE on the configured seam and writes
``DIR/ranking.csv`` (``sensors,distances_mm,rmse_x_mm,…,score``), ``ranking.png`` and
``report.html``.
"""

import sys

from .._numbers import parse_int
from ..errors import ConfigError
from ._common import (
    add_dask_args,
    add_overwrite,
    check_dask_args,
    check_scheduler,
    local_scheduler,
    out_folder,
    staged,
)
from ._flags import bounded_float, bounded_int, check_flags, seed

__all__ = ["add_design_parser", "parse_counts"]

#: Most episodes of one design (configurations × runs): ``posekit.seam.frontend.commands_batch``'s.
MAX_DESIGN_EPISODES = 100_000


def parse_counts(text: str) -> tuple[int, ...]:
    """``'1,2,3'`` → (1, 2, 3); a one-line ConfigError for anything but counts 0..4."""
    try:
        counts = tuple(parse_int(v.strip()) for v in str(text).split(",") if v.strip() != "")
    except ValueError:
        raise ConfigError(f"--sensors: expected comma-separated sensor counts 0..4, got '{str(text)[:60]}'") from None
    if not counts or any(not 0 <= c <= 4 for c in counts):
        raise ConfigError(f"--sensors: expected comma-separated sensor counts 0..4, got '{str(text)[:60]}'")
    return counts


def add_design_parser(verbs):
    """Add ``design`` to the ``posekit seam`` sub-parsers."""
    p = verbs.add_parser("design", help="sensor-placement design: every sensor count × distance (× angle) simulated "
                                        "on Dask and ranked by the pose RMSE on your seam (ranking.csv, figure)")
    p.add_argument("--config", default=None, help="YAML configuration of the cell and seam (default: the paper's)")
    from .seam_simulate import _PARTICLES, _STEPS, MAX_PARTICLES, MAX_STEPS, TRAJECTORIES

    p.add_argument("--profile", default=None, metavar="PROFILE.yaml",
                   help="the filter's fitted profile (posekit seam tune; overrides the configuration's)")
    p.add_argument("--trajectory", choices=TRAJECTORIES, default=None, help="overrides trajectory.kind")
    p.add_argument("--sensors", default="0,1,2", help="sensor counts to try, comma-separated, each 0..4 "
                                                       "(default 0,1,2)")
    p.add_argument("--distances-mm", default="20:80:20",
                   help="candidate distances ahead of the tool, A:B:STEP or a list 20,35,50 (mm; default 20:80:20)")
    p.add_argument("--angle", choices=("off", "on", "both"), default="off",
                   help="the angle measurement: off, on, or both variants of every configuration (default off)")
    p.add_argument("--runs", type=bounded_int(1, 1000), default=3,
                   help="episodes per configuration, 1..1000, the same seeds for all (default 3)")
    p.add_argument("--particles", type=_PARTICLES, default=None, help=f"overrides filter.particles, 1..{MAX_PARTICLES}")
    p.add_argument("--steps", type=_STEPS, default=None, help=f"overrides trajectory.steps, 2..{MAX_STEPS}")
    p.add_argument("--lever-mm", type=bounded_float(0.0, 1e4, "mm", lo_open=True), default=100.0,
                   help="lever arm turning the rotation RMSE into mm in the score (default 100)")
    p.add_argument("--seed", type=seed, default=0, help="seed of the episodes (default 0)")
    add_dask_args(p)
    p.add_argument("--dump-config", action="store_true",
                   help="print the effective configuration (--config with the overrides; loadable by --config) "
                        "and exit")
    p.add_argument("--out", default=None, help="output folder (required unless --dump-config)")
    add_overwrite(p)
    p.set_defaults(func=run_design, sensors_count=None)
    return p


def run_design(args) -> int:
    from ..seam.frontend.commands import episode_config
    from ..seam.frontend.commands_batch import check_design_size, design
    from ..seam.frontend.config import dump_config
    from ..seam.frontend.design import distance_grid
    from .seam_simulate import layout_notes

    check_dask_args(args)
    check_flags(args)
    check_scheduler(args.scheduler)
    counts = parse_counts(args.sensors)
    grid = distance_grid(args.distances_mm)
    with layout_notes():
        cfg = episode_config(args.config, profile=args.profile, trajectory=args.trajectory,
                             particles=args.particles, steps=args.steps)
    if args.dump_config:
        sys.stdout.write(dump_config(cfg))
        return 0
    if not args.out:
        raise ConfigError("--out: an output folder is required (or use --dump-config)")
    check_design_size(counts, grid, args.angle, args.runs)
    out_folder(args)
    with staged(args) as tmp:
        run = design(cfg, tmp, sensors=counts, distances_mm=grid, angle=args.angle, runs=args.runs, seed=args.seed,
                     lever_mm=args.lever_mm, scheduler=local_scheduler(args), n_workers=args.workers)
    result, rows, failed = run.design, run.design.rows(), run.failed
    print(f"seam design: {len(rows)} configurations × {result.runs} runs on the {result.trajectory} seam, "
          f"{cfg.filter.particles} particles, {result.wall_s:.1f} s; {failed} failed")
    print(f"score = ‖RMSE translation‖ + {result.lever_mm:g} mm × ‖RMSE rotation‖ (mm; lower is better); "
          f"kinematics only: {rows[0]['kinematic_score']:.3f}")
    print(f"{'rank':>4}  {'sensors':>7}  {'distances_mm':<16}{'angle':>6}" +
          "".join(f"{a:>9}" for a in ("x mm", "y mm", "z mm", "rx deg", "ry deg", "rz deg")) + f"{'score':>9}")
    for r in rows[:15]:
        print(f"{r['rank']:>4}  {r['sensors']:>7}  {r['distances_mm'] or '-':<16}{'yes' if r['angle'] else 'no':>6}"
              + "".join(f"{r[c]:>9.3f}" for c in ("rmse_x_mm", "rmse_y_mm", "rmse_z_mm", "rmse_rx_deg",
                                                   "rmse_ry_deg", "rmse_rz_deg")) + f"{r['score']:>9.3f}")
    if len(rows) > 15:
        print(f"... {len(rows) - 15} more in ranking.csv")
    print(f"wrote {args.out}: {', '.join(run.paths)}")
    sys.stdout.flush()
    if failed:
        print(f"posekit: error: {failed} of {len(rows)} configurations failed; their rows in ranking.csv say why",
              file=sys.stderr)
    return run.exit_code
