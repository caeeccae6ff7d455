"""``posekit ceiling camera``: lens calibration (K, distortion) from chessboard images."""

import re
import sys
from pathlib import Path

from ..errors import ConfigError
from ._config import add_config_arguments
from ._flags import bounded_float, check_flags

__all__ = ["add_camera_parser", "run_camera", "parse_board"]



def add_camera_parser(verbs):
    """Add the ``camera`` verb to the ``ceiling`` sub-parsers ``verbs``."""
    c = verbs.add_parser(
        "camera", help="lens calibration (K, distortion) from chessboard images",
        description="Calibrate the ceiling camera's lens with OpenCV from images of a printed chessboard "
                    "(pinhole K and distortion k1, k2, p1, p2, k3). Views where the board is not found are "
                    "named and skipped; at least 3 must remain. Hold the board close to the image corners "
                    "too: the summary reports how much of the image the corners cover. Use the result with "
                    "--camera on 'calibrate', 'track' and 'demo'.")
    c.add_argument("images", nargs="+", metavar="IMAGE",
                   help="chessboard images or folders of them (one camera, one resolution; a view of another "
                        "size is named and skipped)")
    c.add_argument("--board", required=True, metavar="COLSxROWS",
                   help="inner corners of the chessboard, e.g. 9x6 (a board of 10x7 squares)")
    c.add_argument("--square-mm", required=True, type=bounded_float(0.1, 1e4, "mm"),
                   help="side of one square, 0.1..10000 mm")
    c.add_argument("--out", required=True, metavar="CAMERA.json", help="camera file to write")
    c.add_argument("--k3", action="store_true",
                   help="also estimate k3 (wide-angle lenses, boards seen into the corners); default k3 = 0, "
                        "which extrapolates better beyond the area the boards covered")
    add_config_arguments(c)
    c.set_defaults(func=run_camera)
    return c


def parse_board(text: str) -> tuple[int, int]:
    """'9x6' -> (9, 6): inner corners, each 2..100; one-line ConfigError naming --board."""
    m = re.fullmatch(r"\s*(\d{1,4})\s*[xX×,]\s*(\d{1,4})\s*", text or "")
    if not m or not all(2 <= int(g) <= 100 for g in m.groups()):
        raise ConfigError(f"--board: expected the inner corners as COLSxROWS, each 2..100 (e.g. 9x6), "
                          f"got '{str(text)[:40]}'")
    return int(m.group(1)), int(m.group(2))


def expand_images(paths) -> list:
    """The image paths of ``paths``, a folder replaced by its images sorted by name
    (:func:`posekit.ceiling.camera.commands.expand_images`)."""
    from ..ceiling.camera.commands import expand_images as _expand

    return _expand(paths)


def run_camera(args) -> int:
    """Run ``posekit ceiling camera``; returns the exit code (0)."""
    from ..ceiling.camera.commands import calibrate_lens_files

    check_flags(args)
    board = parse_board(args.board)
    run = calibrate_lens_files(args.images, board, args.square_mm, args.out, k3=args.k3,
                               on_unreadable=lambda name, why: print(f"posekit: warning: {why}; view skipped",
                                                                     file=sys.stderr))
    result = run.result
    for name, why in result.skipped:
        print(f"posekit: warning: {name}: {why}; view skipped", file=sys.stderr)
    for w in result.warnings:
        print(f"posekit: warning: {w}", file=sys.stderr)
    cam = result.camera
    K, d = cam.K, cam.dist
    print(f"calibrated the lens from {len(result.used)} of {run.views} views ({board[0]}x{board[1]} inner corners, "
          f"{args.square_mm:g} mm squares): rms {cam.rms_px:.3f} px")
    print(f"  fx {K[0, 0]:.2f} px, fy {K[1, 1]:.2f} px, cx {K[0, 2]:.2f} px, cy {K[1, 2]:.2f} px "
          f"({cam.image_size[0]}x{cam.image_size[1]})")
    print(f"  k1 {d[0]:+.5f}, k2 {d[1]:+.5f}, p1 {d[2]:+.6f}, p2 {d[3]:+.6f}, k3 {d[4]:+.5f}"
          + ("" if args.k3 else " (fixed)"))
    worst = int(result.per_view_rms_px.argmax())
    print(f"  per view rms: median {float(_median(result.per_view_rms_px)):.3f} px, worst "
          f"{result.per_view_rms_px[worst]:.3f} px ({result.used[worst]})")
    print(f"  coverage: the boards cover {100 * result.coverage:.0f} % of the image, "
          f"{result.cells_hit} of 9 cells of a 3x3 grid")
    if run.low_coverage:
        print("posekit: warning: the corners do not reach every part of the image; the distortion there is "
              "extrapolated: add views with the board near the uncovered edges and corners", file=sys.stderr)
    print(f"wrote {Path(args.out)}")
    return 0


def _median(x):
    import numpy as np
    return np.median(x)
