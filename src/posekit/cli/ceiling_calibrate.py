"""``posekit ceiling calibrate``: the camera's homography from ceiling points (paper §IV-A)."""

import sys
from pathlib import Path

from .._numbers import parse_number
from ._config import add_config_arguments
from ._flags import bounded_float, check_flags, check_range, seed

__all__ = ["add_calibrate_parser", "run_calibrate"]


def add_calibrate_parser(verbs):
    """Add the ``calibrate`` verb to the ``ceiling`` sub-parsers ``verbs``."""
    c = verbs.add_parser(
        "calibrate", help="homography between the ceiling and the image from corresponding points",
        description="Calibrate the fixed camera: the homography from ceiling (X, Y) to image (u, v). "
                    "With --from-image, POINTS.csv holds 4 or more approximate grid corners and every "
                    "T-bar crossing in the reference image is found and used. Exit 1 (the file written, marked "
                    "suspect) when the points contradict the --camera lens model or RANSAC keeps fewer than half "
                    "of them: track never marks a row ok with it.")
    c.add_argument("points", metavar="POINTS.csv",
                   help="CSV 'X,Y,u,v': world points on the ceiling (mm) and their pixels")
    c.add_argument("--out", required=True, metavar="CAL.json", help="calibration file to write")
    c.add_argument("--camera", metavar="CAMERA.json",
                   help="lens of the camera (posekit ceiling camera): the points' pixels are undistorted first and "
                        "the homography maps undistorted pixels (pass the same file to track); without it the "
                        "camera is taken as distortion-free")
    c.add_argument("--image-size", metavar="WxH", default=None,
                   help="size of the images the points were clicked in (default: the --camera's or the "
                        "--from-image's); track then refuses frames of another shape and scales for another "
                        "resolution")
    c.add_argument("--residuals", choices=("all", "worst", "none"), default="all",
                   help="print the residual of every point (all, default), the 10 worst, or none")
    c.add_argument("--no-refine", dest="refine", action="store_false",
                   help="keep the DLT estimate (default: refine the reprojection error)")
    g = c.add_mutually_exclusive_group()
    g.add_argument("--ransac", dest="ransac", action="store_const", const=True, default=None,
                   help="reject mis-clicked points by RANSAC (default: on from 6 points)")
    g.add_argument("--no-ransac", dest="ransac", action="store_const", const=False, help="use every point")
    c.add_argument("--threshold-px", type=bounded_float(0.01, 1e4, "px"), default=3.0,
                   help="RANSAC inlier threshold on the reprojection error, 0.01..10000 px (default 3)")
    c.add_argument("--seed", type=seed, default=0, help="random seed of RANSAC (default 0)")
    c.add_argument("--from-image", metavar="REF.png",
                   help="reference image of the ceiling grid: find all T-bar crossings from the seed points")
    c.add_argument("--grid", default="600,1200", metavar="SX,SY",
                   help="T-bar spacing along X and Y, 10..100000 mm (default 600,1200)")
    c.add_argument("--grid-origin", default="0,0", metavar="X0,Y0",
                   help="world position of one crossing, -1e6..1e6 mm (default 0,0)")
    c.add_argument("--bar-mm", type=bounded_float(0.1, 1e3, "mm"), default=15.0,
                   help="T-bar width, 0.1..1000 mm and under 10 %% of the spacing (default 15)")
    c.add_argument("--light-bars", action="store_true", help="the T-bars are lighter than the tiles")
    c.add_argument("--write-points", metavar="FOUND.csv",
                   help="with --from-image: write the crossings found as a points CSV")
    add_config_arguments(c)
    c.set_defaults(func=run_calibrate)
    return c


def _pair(text, option, lo, hi):
    """'600,1200' -> (600.0, 1200.0), each in ``lo..hi`` mm; a one-line ConfigError naming ``option``."""
    from ..errors import ConfigError
    try:
        vals = tuple(parse_number(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 2:
        raise ConfigError(f"{option}: expected two comma-separated numbers, got '{text[:80]}'")
    for v in vals:
        check_range(option, v, lo, hi, "mm", what="two numbers", shown=repr(text))
    return vals


def _print_residuals(args, run) -> None:
    """Per-point residuals (px in the image, mm on the ceiling) and why RANSAC rejected each point."""
    import numpy as np

    cal, world, seen, lines = run.calibration, run.world, run.seen, run.lines
    e_px, e_mm, lens = run.residual_px, run.residual_mm, run.lens_pattern
    n, rejected = len(world), run.rejected
    if rejected.size:
        n_lens = run.rejected_lens
        why = []
        if n_lens:
            why.append(f"{n_lens} follow the radial pattern of lens distortion (not mis-clicks: use --camera)")
        if rejected.size - n_lens:
            why.append(f"{rejected.size - n_lens} are off the fit alone (mis-clicked or wrong X, Y?)")
        print(f"RANSAC rejected {rejected.size} of {n} points (more than {args.threshold_px:g} px from the fit of "
              f"the others): " + "; ".join(why))
        if run.too_many_rejected:
            print("posekit: warning: RANSAC rejected more than a third of the points: check the points, or raise "
                  "--threshold-px if the clicks are coarse", file=sys.stderr)
    if args.residuals == "none":
        return
    order = np.arange(n) if args.residuals == "all" else np.argsort(-np.nan_to_num(e_px, nan=np.inf))[:10]
    print(("residual of each point" if args.residuals == "all" else "the 10 largest residuals")
          + " (px in the image, mm on the ceiling):")
    for k in order:
        where = f"line {lines[k]}" if lines is not None else f"crossing {k}"
        tag = "" if cal.inliers[k] else ("  rejected (lens pattern)" if lens[k] else "  rejected")
        print(f"  {where}: X={world[k, 0]:g} Y={world[k, 1]:g} u={seen[k, 0]:g} v={seen[k, 1]:g}: "
              f"{e_px[k]:.2f} px, {e_mm[k]:.1f} mm{tag}")


def run_calibrate(args) -> int:
    """Run ``posekit ceiling calibrate``; returns the exit code (0; 1 when the calibration is
    suspect, after writing it)."""
    import math

    from ..ceiling.camera.commands import calibrate_file
    from ..errors import ConfigError

    if not (math.isfinite(args.threshold_px) and args.threshold_px > 0):
        raise ConfigError(f"--threshold-px must be a number > 0, got {args.threshold_px:g}")
    check_flags(args)
    grid_mm = _pair(args.grid, "--grid", 10.0, 1e5)
    origin_mm = _pair(args.grid_origin, "--grid-origin", -1e6, 1e6)
    size = _image_size(args.image_size) if args.image_size else None
    run = calibrate_file(args.points, args.out, camera=args.camera, image_size=size, refine=args.refine,
                         ransac=args.ransac, threshold_px=args.threshold_px, seed=args.seed,
                         from_image=args.from_image, grid=grid_mm, grid_origin=origin_mm, bar_mm=args.bar_mm,
                         light_bars=args.light_bars, write_points=args.write_points)
    cal, radial = run.calibration, run.radial
    if run.found is not None:
        print(f"found {run.found} grid crossings in {args.from_image}"
              + (" (undistorted with --camera)" if args.camera else ""))
        if args.write_points:
            print(f"wrote the crossings to {args.write_points}")
    n, n_in = cal.n_points, int(cal.inliers.sum())
    how = f"RANSAC at {args.threshold_px:g} px, " if run.ransac_used else ""
    how += "refined" if args.refine else "DLT only"
    how += f", pixels undistorted with {args.camera}" if args.camera else ", no lens model"
    print(f"calibrated from {n_in} of {n} points ({how}): rms {cal.rms_px:.3f} px in the image, "
          f"{cal.rms_world:.3f} world units (mm) on the ceiling")
    _print_residuals(args, run)
    if run.lens_distortion_seen:
        print(f"posekit: warning: looks like lens distortion: calibrate the camera (posekit ceiling camera) and "
              f"pass --camera; a plain homography leaves {radial.rms_px:.1f} px rms that grows with the distance "
              f"from the image centre (r^3 term {radial.k_r3_px:+.1f} px, t = {radial.t_stat:.1f}, "
              f"{100 * radial.explained:.0f} % of the residuals)", file=sys.stderr)
    print(f"wrote {Path(args.out)}", file=sys.stdout)
    if run.exit_code:
        print(f"posekit: suspect: {'; '.join(cal.reasons)}"[:600], file=sys.stderr)
    return run.exit_code


def _image_size(text: str) -> tuple[int, int]:
    """'864x480' -> (864, 480); a one-line ConfigError naming --image-size."""
    import re

    from ..errors import ConfigError
    m = re.fullmatch(r"\s*(\d{1,6})\s*[xX]\s*(\d{1,6})\s*", text or "")
    if not m or not all(1 <= int(g) <= 100_000 for g in m.groups()):
        raise ConfigError(f"--image-size: expected WIDTHxHEIGHT in px (e.g. 864x480), got '{str(text)[:40]}'")
    return int(m.group(1)), int(m.group(2))
