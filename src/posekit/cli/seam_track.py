"""``posekit seam track LOGDIR --out DIR``: the filter on a recorded episode (DESIGN.md, seam)."""

import sys

from ._common import add_overwrite, out_folder, staged
from ._common import progress as _progress
from ._config import add_config_arguments
from ._flags import check_flags

__all__ = ["add_track_parser"]


def add_track_parser(verbs):
    """Add ``track`` to the ``posekit seam`` sub-parsers."""
    p = verbs.add_parser("track", help="run the filter on a recorded episode (setup.yaml, seam.csv, log.csv[, "
                                       "truth.csv]): estimates.csv with status and spreads, metrics.json")
    p.add_argument("logdir", metavar="LOGDIR", help="the recorded episode's folder")
    p.add_argument("--profile", default=None, metavar="PROFILE.yaml",
                   help="the cell's fitted profile (posekit seam tune; default: the setup's, else the shipped one)")
    p.add_argument("--jsonl", default=None, metavar="FILE|-",
                   help="also write one JSON object per step as it is produced (t_mm, q_wxyz, status, std_mm, "
                        "std_deg, ...); '-' for stdout")
    p.add_argument("--out", required=True, help="output folder")
    add_overwrite(p)
    add_config_arguments(p)
    p.set_defaults(func=run_track)
    return p


def run_track(args) -> int:
    from ..seam.frontend.commands import track_episode
    from ..seam.frontend.logs import read_episode_log

    check_flags(args)
    out_folder(args)
    from .seam_simulate import layout_notes

    with layout_notes():
        log = read_episode_log(args.logdir, profile=args.profile)
    from ..seam.frontend.cell_signature import config_mismatch

    why = config_mismatch(log.config)
    if why is not None:   # said before the run: every step will be degraded at best
        print(f"warning: {why}; every step is degraded at best", file=sys.stderr)
    with staged(args) as tmp:
        run = track_episode(log, tmp, jsonl=args.jsonl,
                            progress=lambda it, total, desc: _progress(it, total=total, desc=desc, unit="step"))
    m = run.metrics
    s = len(log.setup.sensors)
    print(f"seam track: {m['steps']} steps ({m['interpolated_steps']} with interpolated joints), "
          f"{log.config.cell.robot.label}, {s} sensor{'s' if s != 1 else ''}, {log.config.filter.particles} particles; "
          f"filter step median {m['step_ms_median']:.3f} ms, p99 {m['step_ms_p99']:.3f} ms")
    counts = m["status_counts"]
    print("status: " + (", ".join(f"{k} {v}" for k, v in counts.items()) if counts else "none reported"))
    if "rmse_mm" in m:
        from .seam_simulate import _rmse_values, rmse_table

        print("RMSE per axis in the seam frame against truth.csv (mm, deg):")
        print(rmse_table([("filter", _rmse_values(m)), ("kinematics only", _rmse_values(m, "kinematic_"))]))
    if m.get("outside_plateau_steps", 0.0) > 0.0:
        from .seam_simulate import plateau_warning

        plateau_warning("the true pose", f"at {100 * m['outside_plateau_steps']:.1f} % of the steps",
                        m["plateau_ratio_max"])
    print(f"wrote {args.out}: estimates.csv, metrics.json, ess.png" + (", errors_time.png" if "rmse_mm" in m else ""))
    sys.stdout.flush()
    return run.exit_code
