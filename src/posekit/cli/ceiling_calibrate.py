"""``posekit ceiling calibrate``: the camera's homography from ceiling points (paper §IV-A)."""

import sys
from pathlib import Path

from .._extras import require
from ._flags import bounded_float, check_flags, check_range, seed

__all__ = ["add_calibrate_parser", "run_calibrate"]


def add_calibrate_parser(verbs):
    """Add the ``calibrate`` verb to the ``ceiling`` sub-parsers ``verbs``."""
    c = verbs.add_parser(
        "calibrate", help="homography between the ceiling and the image from corresponding points",
        description="Calibrate the fixed camera: the homography from ceiling (X, Y) to image (u, v). "
                    "With --from-image, POINTS.csv holds 4 or more approximate grid corners and every "
                    "T-bar crossing in the reference image is found and used.")
    c.add_argument("points", metavar="POINTS.csv",
                   help="CSV 'X,Y,u,v': world points on the ceiling (mm) and their pixels")
    c.add_argument("--out", required=True, metavar="CAL.json", help="calibration file to write")
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
    c.set_defaults(func=run_calibrate)
    return c


def _pair(text, option, lo, hi):
    """'600,1200' -> (600.0, 1200.0), each in ``lo..hi`` mm; a one-line ConfigError naming ``option``."""
    from ..errors import ConfigError
    try:
        vals = tuple(float(v) for v in text.split(","))
    except ValueError:
        vals = ()
    if len(vals) != 2:
        raise ConfigError(f"{option}: expected two comma-separated numbers, got '{text[:80]}'")
    for v in vals:
        check_range(option, v, lo, hi, "mm", what="two numbers", shown=repr(text))
    return vals


def _points_from_image(args, seeds, grid_mm, origin_mm):
    cv2 = require("cv2", "vision", "posekit ceiling calibrate --from-image")
    import numpy as np

    from ..ceiling.calibration import write_points_csv
    from ..ceiling.grid import CeilingGrid, find_grid_corners
    from ..errors import CalibrationError
    from ..io import read_image

    img = read_image(args.from_image, cv2.IMREAD_GRAYSCALE, error=CalibrationError)
    if img is None:
        raise CalibrationError(f"{args.from_image}: cannot decode the image; expected an image file OpenCV reads")
    grid = CeilingGrid(grid_mm, origin_mm, args.bar_mm)
    corners = find_grid_corners(img, grid, seed_world=seeds.world_xy, seed_image=seeds.image_uv,
                                polarity="light" if args.light_bars else "dark")
    print(f"found {len(corners.image_uv)} grid crossings in {args.from_image}")
    if args.write_points:
        write_points_csv(args.write_points, corners.world_xy, corners.image_uv)
        print(f"wrote the crossings to {args.write_points}")
    lines = np.arange(len(corners.image_uv)) + 2 if args.write_points else None
    return corners.world_xy, corners.image_uv, lines


def run_calibrate(args) -> int:
    """Run ``posekit ceiling calibrate``; returns the exit code (0)."""
    import numpy as np

    from ..ceiling.calibration import calibrate, read_points_csv
    from ..errors import ConfigError

    if not (np.isfinite(args.threshold_px) and args.threshold_px > 0):
        raise ConfigError(f"--threshold-px must be a number > 0, got {args.threshold_px:g}")
    check_flags(args)
    grid_mm = _pair(args.grid, "--grid", 10.0, 1e5)
    origin_mm = _pair(args.grid_origin, "--grid-origin", -1e6, 1e6)
    pts = read_points_csv(args.points)
    if args.from_image:
        world, image, lines = _points_from_image(args, pts, grid_mm, origin_mm)
    else:
        if args.write_points:
            raise ConfigError("--write-points needs --from-image")
        world, image, lines = pts.world_xy, pts.image_uv, pts.lines
    cal = calibrate(world, image, refine=args.refine, ransac=args.ransac,
                    threshold_px=args.threshold_px, rng=args.seed)
    n, n_in = cal.n_points, int(cal.inliers.sum())
    ransac_used = args.ransac if args.ransac is not None else n >= 6
    how = f"RANSAC at {args.threshold_px:g} px, " if ransac_used else ""
    how += "refined" if args.refine else "DLT only"
    print(f"calibrated from {n_in} of {n} points ({how}): rms {cal.rms_px:.3f} px in the image, "
          f"{cal.rms_world:.3f} world units (mm) on the ceiling")
    rejected = np.flatnonzero(~cal.inliers)
    if rejected.size:
        err = np.linalg.norm(cal.world_to_image(world[rejected], invalid="nan") - image[rejected], axis=1)
        print(f"rejected {rejected.size} point(s) as mismatched:")
        for k, e in zip(rejected, err):
            where = f"line {lines[k]}" if lines is not None else f"crossing {k}"
            print(f"  {where}: X={world[k, 0]:g} Y={world[k, 1]:g} u={image[k, 0]:g} v={image[k, 1]:g} "
                  f"({e:.1f} px from the fit)")
    out = Path(args.out)
    cal.to_json(out)
    print(f"wrote {out}", file=sys.stdout)
    return 0
