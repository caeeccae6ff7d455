"""The calibration points of the ceiling camera: ceiling points (X, Y) in mm and their pixels (u, v)
as seen, in a CSV file with the header ``X,Y,u,v`` (what a user clicks, or what
``posekit ceiling simulate`` writes), and their undistortion through a lens model before the
homography (:mod:`posekit.ceiling.camera.homography`) is fitted to them.

Pixels: u to the right, v down, the centre of the top-left pixel at (0, 0).
"""

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ...errors import CalibrationError
from ...io import check_rows, parse_number, read_text, write_text_atomic

__all__ = ["CSV_HEADER", "MAX_POINTS", "CalibrationPoints", "read_points_csv", "write_points_csv",
           "undistort_calibration_points"]

#: Header of a calibration-points CSV file.
CSV_HEADER = ("X", "Y", "u", "v")
#: Most calibration points a file or a call may hold. A ceiling grid seen by one camera has tens
#: to hundreds of crossings; at this limit RANSAC and the refinement take about a second.
MAX_POINTS = 10_000


class CalibrationPoints(NamedTuple):
    """Correspondences read from a points CSV file."""

    world_xy: np.ndarray
    """(N, 2) ceiling points (X, Y), mm."""
    image_uv: np.ndarray
    """(N, 2) image points (u, v), px."""
    lines: np.ndarray
    """(N,) the line of each point in the file (1-based, the header is line 1)."""


def read_points_csv(path) -> CalibrationPoints:
    """Read calibration points from a CSV file with the header ``X,Y,u,v``.

    Blank lines and lines starting with ``#`` are skipped.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    CalibrationPoints
        ``(world_xy (N, 2) mm, image_uv (N, 2) px, lines (N,))``.

    Raises
    ------
    CalibrationError
        Missing or empty file, wrong header, a row without 4 finite numbers (naming the
        line), fewer than 4 or more than :data:`MAX_POINTS` points, a world or image point
        that repeats an earlier line.
    """
    path = Path(path)
    text = read_text(path, expected="a CSV of calibration points 'X,Y,u,v'", error=CalibrationError)
    check_rows(text, str(path), "lines (points, comments and blank lines)", error=CalibrationError,
               limit=2 * MAX_POINTS + 1000)         # before splitting the text into lines
    rows, lines, header_seen = [], [], False
    for lineno, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = [f.strip() for f in stripped.split(",")]
        if not header_seen:
            if tuple(fields) != CSV_HEADER:
                raise CalibrationError(f"{path} line {lineno}: expected the header 'X,Y,u,v', got '{stripped[:60]}'")
            header_seen = True
            continue
        if len(fields) != 4:
            raise CalibrationError(f"{path} line {lineno}: expected 4 values X,Y,u,v, got {len(fields)} "
                                   f"('{stripped[:60]}')")
        values = []
        for name, field in zip(CSV_HEADER, fields):
            try:
                value = parse_number(field)
            except ValueError:
                raise CalibrationError(f"{path} line {lineno}: {name} is '{field[:30]}'; expected a number") from None
            if not math.isfinite(value):
                raise CalibrationError(f"{path} line {lineno}: {name} is '{field}'; expected a finite number")
            values.append(value)
        if len(rows) == MAX_POINTS:
            raise CalibrationError(f"{path} line {lineno}: more than {MAX_POINTS} calibration points; expected "
                                   f"at most {MAX_POINTS} (a ceiling grid in view has tens to hundreds of crossings)")
        rows.append(values)
        lines.append(lineno)
    if not header_seen:
        raise CalibrationError(f"{path}: file is empty; expected the header 'X,Y,u,v' and one point per line")
    if len(rows) < 4:
        raise CalibrationError(f"{path}: {len(rows)} calibration points; a homography needs at least 4 "
                               "(6 or more let RANSAC reject a mis-clicked one)")
    for cols, what, why in (((0, 1), "world point X={:g}, Y={:g}", "each ceiling point once"),
                            ((2, 3), "image point u={:g}, v={:g}",
                             "distinct pixels (two ceiling points cannot share one)")):
        seen = {}
        for k, row in enumerate(rows):
            key = (row[cols[0]], row[cols[1]])
            first = seen.setdefault(key, k)
            if first != k:
                raise CalibrationError(f"{path} line {lines[k]}: {what.format(*key)} repeats line {lines[first]}; "
                                       f"expected {why}")
    arr = np.array(rows, dtype=np.float64)
    return CalibrationPoints(arr[:, :2], arr[:, 2:], np.array(lines))


def write_points_csv(path, world_xy, image_uv):
    """Write correspondences as a points CSV (``X,Y,u,v``; world mm, image px).

    Parameters
    ----------
    path : str or Path
    world_xy : array_like, shape (N, 2)
    image_uv : array_like, shape (N, 2)
    """
    world = np.asarray(world_xy, dtype=float).reshape(-1, 2)
    image = np.asarray(image_uv, dtype=float).reshape(-1, 2)
    body = "".join(f"{X:.6g},{Y:.6g},{u:.4f},{v:.4f}\n" for (X, Y), (u, v) in zip(world, image))
    write_text_atomic(path, ",".join(CSV_HEADER) + "\n" + body, error=CalibrationError)


def undistort_calibration_points(camera, image_uv, lines=None) -> np.ndarray:
    """Undistorted pixels (N, 2) of calibration points ``image_uv`` (N, 2) px with ``camera``.

    Raises
    ------
    CalibrationError
        A point outside the lens model's image circle (no ray is imaged there), naming its line
        (``lines``, as read from the CSV) or its index.
    """
    uv = np.asarray(image_uv, dtype=float).reshape(-1, 2)
    und = camera.undistort_points(uv)
    bad = np.flatnonzero(~np.isfinite(und).all(axis=1))
    if bad.size:
        k = int(bad[0])
        where = f"line {lines[k]}" if lines is not None else f"point {k}"
        raise CalibrationError(f"{where}: u={uv[k, 0]:g} v={uv[k, 1]:g} is outside the image circle of the "
                               "camera's lens model; expected pixels of the camera the --camera file describes")
    w, h = camera.image_size
    out = np.flatnonzero((uv[:, 0] < -0.5) | (uv[:, 1] < -0.5) | (uv[:, 0] > w - 0.5) | (uv[:, 1] > h - 0.5))
    if out.size:
        k = int(out[0])
        where = f"line {lines[k]}" if lines is not None else f"point {k}"
        raise CalibrationError(f"{where}: u={uv[k, 0]:g} v={uv[k, 1]:g} is outside the {w}x{h} image of the "
                               "--camera file; expected pixels of that camera")
    return und
