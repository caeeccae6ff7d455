"""The truth of a rendered video (``truth.csv``) and a track's errors against it.

Positions in mm on the ceiling plane (world frame W of :mod:`posekit.ceiling.sim.render`), headings in
degrees, image points in px.
"""

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputFileError
from .accuracy import error_stats

__all__ = ["SceneTruthTable", "read_truth_csv", "compare_with_truth"]


@dataclass
class SceneTruthTable:
    """``truth.csv`` of a render: per frame, arrays with a leading frame axis (mm, degrees, px)."""

    frame: np.ndarray
    time_s: np.ndarray
    xy: np.ndarray
    heading_deg: np.ndarray
    red_visible: np.ndarray
    green_visible: np.ndarray
    uv: np.ndarray


def read_truth_csv(path) -> SceneTruthTable:
    """Read the renderer's ``truth.csv`` (``frame,time_s,x,y,heading_deg,red_visible,green_visible``
    and optionally ``red_u,red_v``)."""
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read the truth CSV ({exc.strerror or exc})") from None
    need = ("frame", "time_s", "x", "y", "heading_deg", "red_visible", "green_visible")
    if not rows or any(k not in rows[0] for k in need):
        raise InputFileError(f"{path}: expected the columns {','.join(need)}")

    def col(name, default=np.nan):
        return np.array([float(r[name]) if r.get(name, "") not in ("", None) else default for r in rows])

    return SceneTruthTable(frame=col("frame").astype(int), time_s=col("time_s"),
                           xy=np.column_stack([col("x"), col("y")]), heading_deg=col("heading_deg"),
                           red_visible=col("red_visible", 0).astype(bool),
                           green_visible=col("green_visible", 0).astype(bool),
                           uv=np.column_stack([col("red_u"), col("red_v")]))


def compare_with_truth(result, truth: SceneTruthTable) -> dict:
    """Errors of a track against the truth of its render.

    Returns
    -------
    dict
        ``ok``/``predicted`` : ErrorStats of the position (mm) over the rows of that status;
        ``raw`` : ErrorStats of the accepted measurements before filtering;
        ``heading`` : dict ``mean_deg, std_deg, rms_deg, max_abs_deg, n`` (rows with a heading);
        ``ok_without_dot`` : rows ``ok`` whose red dot was not visible (must be 0);
        ``visible_not_ok`` : rows whose red dot was visible but not ``ok`` (missed or gated).
    """
    n = min(len(result.rows), len(truth.frame))
    if n == 0:
        raise InputFileError("compare_with_truth: the track or the truth is empty")
    xy = result.xy()[:n]
    status = result.status()[:n]
    T = truth.xy[:n]
    raw = np.array([r.measured.get("red", (np.nan, np.nan)) for r in result.rows[:n]], dtype=float)
    out = {s: error_stats(np.where((status == s)[:, None], xy, np.nan), T) for s in ("ok", "predicted")}
    out["raw"] = error_stats(raw, T)
    h = result.heading_deg()[:n]
    dh = (h - truth.heading_deg[:n] + 180.0) % 360.0 - 180.0
    dh = dh[np.isfinite(dh)]
    out["heading"] = ({"n": int(dh.size), "mean_deg": float(dh.mean()), "std_deg": float(dh.std()),
                       "rms_deg": float(np.sqrt(np.mean(dh ** 2))), "max_abs_deg": float(np.abs(dh).max())}
                      if dh.size else {"n": 0})
    vis = truth.red_visible[:n]
    out["ok_without_dot"] = int(np.sum((status == "ok") & ~vis))
    out["visible_not_ok"] = int(np.sum(vis & (status != "ok")))
    return out
