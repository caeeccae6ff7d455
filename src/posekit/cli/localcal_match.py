"""``posekit localcal match``: the transform that maps a camera trajectory into the robot base."""

from ._config import add_config_arguments
from ._flags import bounded_float, check_flags
from .localcal_inputs import add_pair_args, add_trajectory_args, print_result, read_options

__all__ = ["add_match_parser", "run_match"]


def add_match_parser(verbs):
    """Add the ``match`` verb to the ``localcal`` sub-parsers ``verbs``."""
    p = verbs.add_parser(
        "match", help="transform from a camera (VO/SLAM) trajectory to the kinematic (base) frame",
        description="Match a camera trajectory (VO/SLAM world frame) with the kinematic TCP trajectory "
                    "(robot base frame). Writes {R, t_mm, rmse_mm, mean_abs_err_mm, max_abs_err_mm, status, "
                    "reasons, std_rot_deg, std_t_mm, ...}: p_base = R p_camera + t; std_* are 1 sigma about the "
                    "base axes. Exit 1 when the verdict is suspect (the file is written first).")
    add_pair_args(p, kinematic_help="TCP poses in the robot base frame", out_metavar="RESULT.json")
    p.add_argument("--no-timestamps", dest="timestamps", action="store_false",
                   help="ignore the timestamps: correspondence-free point-set registration")
    # --max-dt > 0 is checked by match_trajectories (max_dt_s) with its own message
    p.add_argument("--max-dt", type=bounded_float(None, 10.0, "s"), default=0.02, metavar="S",
                   help="largest time difference of an associated pose pair, (0, 10] s (default 0.02)")
    p.add_argument("--time-offset", type=bounded_float(-1e10, 1e10, "s"), default=None, metavar="S",
                   help="known clock offset t_kinematic - t_camera, -1e10..1e10 s (default: estimated)")
    p.add_argument("--max-offset", type=bounded_float(0.0, 86400.0, "s"), default=1.0, metavar="S",
                   help="search the clock offset within +-S seconds, 0..86400 (default 1)")
    p.add_argument("--with-scale", action="store_true",
                   help="also estimate a scale (Sim(3)), for a monocular VO trajectory")
    p.add_argument("--outlier-fraction", type=bounded_float(0.0, 0.5, hi_open=True), default=0.05, metavar="F",
                   help="expected fraction of gross outliers, [0, 0.5) (default 0.05)")
    p.add_argument("--matcher", choices=("cpd", "hybrid"), default="cpd",
                   help="fine matcher with --no-timestamps: cpd (positions) or hybrid (positions and "
                        "orientations, hybrid-mixture style) (default cpd)")
    p.add_argument("--residuals", default=None, metavar="FILE.csv",
                   help="also write every pose pair's residual (stamps, indices, ex ey ez and their norm in mm, kept)")
    p.add_argument("--plot", default=None, metavar="DIR",
                   help="also write the figures (trajectories.png: both paths in the base frame; error.png: "
                        "the error of every pair over time) to the folder DIR")
    p.add_argument("--overwrite", action="store_true", help="replace an existing --plot folder")
    add_trajectory_args(p)
    add_config_arguments(p)
    p.set_defaults(func=run_match)
    return p


def run_match(args) -> int:
    """Run ``posekit localcal match`` (:func:`posekit.localcal.match_files`); returns the exit code
    (0 ok, 1 suspect)."""
    import numpy as np

    from ..geometry import rotation_angle_between
    from ..io import check_out_folder
    from ..localcal.commands import match_files

    if args.plot is not None:                      # first, as the library does: a plot folder we may not write
        check_out_folder(args.plot, overwrite=args.overwrite, flag="--plot")
    check_flags(args)
    run = match_files(args.camera, args.kinematic, args.out, camera_read=read_options(args, "camera"),
                      kinematic_read=read_options(args, "kinematic"), residuals=args.residuals, plot=args.plot,
                      overwrite=args.overwrite, use_timestamps=args.timestamps, max_dt_s=args.max_dt,
                      time_offset_s=args.time_offset, max_offset_s=args.max_offset, with_scale=args.with_scale,
                      outlier_fraction=args.outlier_fraction, matcher=args.matcher)
    reg, src, dst = run.result, run.camera, run.kinematic
    angle = np.rad2deg(float(rotation_angle_between(np.eye(3), reg.R, check=False)))
    how = (f"{reg.n_pairs} pose pairs ({reg.pairing} stamps within {args.max_dt:g} s) at a clock offset of "
           f"{reg.time_offset_s * 1000:+.1f} ms" if args.timestamps
           else f"{len(src)} camera poses against {len(dst)} kinematic poses without timestamps")
    lines = [
        f"matched {how}; {reg.pairs_used} used, {reg.pairs_dropped} dropped as outliers",
        f"R: {angle:.3f} deg rotation, t_mm: [{reg.t_mm[0]:.2f}, {reg.t_mm[1]:.2f}, {reg.t_mm[2]:.2f}]"
        + (f", scale {reg.scale:.5f} (1 sigma {reg.std_scale:.2g})" if args.with_scale else ""),
        f"rmse {reg.rmse_mm:.2f} mm over the pairs used ({reg.rmse_all_mm:.2f} mm over all); mean |e| x,y,z "
        + ", ".join(f"{v:.2f}" for v in reg.mean_abs_err_mm)
        + " mm; max |e| " + ", ".join(f"{v:.2f}" for v in reg.max_abs_err_mm) + " mm",
        "std (1 sigma, base axes): rotation " + ", ".join(f"{v:.3g}" for v in reg.std_rot_deg)
        + " deg; t " + ", ".join(f"{v:.3g}" for v in reg.std_t_mm) + " mm",
    ]
    if reg.scale_drift is not None:
        d = reg.scale_drift
        lines.append(f"scale drift along the path {d.relative:+.2%} (1 sigma {d.std:.2%}, {d.segments} segments)")
    lines += [f"note: {n}" for n in reg.notes]
    if "residuals" in run.written:
        lines.append(f"wrote {run.written['residuals']} ({reg.n_pairs} rows)")
    if "plot" in run.written:
        lines.append(f"wrote trajectories.png and error.png to {args.plot}")
    return print_result(run.written["json"], reg, lines, "match")
