"""Files written by ``posekit seam simulate|demo|study``: CSV tables and ``report.html``.

:func:`write_estimates_csv` writes the per-step record of every episode (truth, estimate,
nominal pose, errors); :func:`write_html` writes a self-contained ``report.html`` that embeds
each figure (base64) next to a link to its PNG file, and the tables given as dict rows.
Units at this edge: positions in mm, quaternions ``[w, x, y, z]``, errors in mm and degrees
(the unit is in every column name).
"""

import base64
import csv
import html
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import numpy as np

from ..geometry import quaternion_from_matrix

__all__ = ["ERROR_AXES", "ERROR_COLUMNS", "ESTIMATE_COLUMNS", "write_estimates_csv", "read_estimates_csv",
           "write_csv", "write_json", "write_html", "html_table", "html_figure"]

#: The six error axes of the seam frame: translations (mm) then rotations (deg).
ERROR_AXES = ("x", "y", "z", "rx", "ry", "rz")
#: Error column suffixes with their units.
ERROR_COLUMNS = ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")


def _pose_columns(prefix: str) -> list[str]:
    return [f"{prefix}_{c}" for c in ("x_mm", "y_mm", "z_mm", "qw", "qx", "qy", "qz")]


#: Columns of ``estimates.csv``, one row per run and step.
ESTIMATE_COLUMNS = (["run", "step", "t_s", *_pose_columns("truth"), *_pose_columns("estimate"),
                     *_pose_columns("nominal"), *(f"err_{c}" for c in ERROR_COLUMNS),
                     *(f"kin_err_{c}" for c in ERROR_COLUMNS), *(f"spread_{c}" for c in ERROR_COLUMNS),
                     "ess", "step_ms"])


def _poses(T: np.ndarray) -> np.ndarray:
    """(T, 4, 4) poses -> (T, 7) ``[x, y, z, qw, qx, qy, qz]`` (mm, unit quaternion with qw >= 0)."""
    q = np.asarray(quaternion_from_matrix(T[:, :3, :3]), dtype=float).reshape(-1, 4)
    q = np.where(q[:, :1] < 0, -q, q)
    return np.hstack([T[:, :3, 3], q])


def write_estimates_csv(path, results: Sequence) -> Path:
    """Write ``estimates.csv``: one row per run and time step.

    Parameters
    ----------
    path : path-like
        The CSV file to write.
    results : sequence of EpisodeResult
        The episodes, in run order. Each provides ``t_s`` (T,), ``truth``, ``estimate``,
        ``nominal`` (T, 4, 4) poses of the tool in the world frame W (mm), ``error`` and
        ``kinematic_error`` (T, 6) ``[x, y, z mm, rx, ry, rz deg]`` in the seam frame,
        ``spread`` (T, 6), ``ess`` (T,) and ``step_ms`` (T,).

    Returns
    -------
    pathlib.Path
        ``path``. Columns: :data:`ESTIMATE_COLUMNS`; numbers with 10 significant digits.
    """
    path = Path(path)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(ESTIMATE_COLUMNS)
        for run, r in enumerate(results):
            n = len(r.t_s)
            block = np.hstack([np.arange(n)[:, None], np.asarray(r.t_s, float)[:, None], _poses(r.truth),
                               _poses(r.estimate), _poses(r.nominal), r.error, r.kinematic_error, r.spread,
                               np.asarray(r.ess, float)[:, None], np.asarray(r.step_ms, float)[:, None]])
            for row in block:
                w.writerow([run, int(row[0]), *(f"{v:.10g}" for v in row[1:])])
    return path


def read_estimates_csv(path) -> dict[str, np.ndarray]:
    """Read an ``estimates.csv`` back: column name -> (rows,) float array."""
    with Path(path).open(newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        data = np.array([[float(v) for v in row] for row in reader], dtype=float).reshape(-1, len(header))
    return {name: data[:, i] for i, name in enumerate(header)}


def write_csv(path, rows: Sequence[Mapping], columns: Sequence[str]) -> Path:
    """Write dict rows with exactly ``columns`` (floats with 6 significant digits, NaN as 'nan')."""
    path = Path(path)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for row in rows:
            w.writerow([f"{row[c]:.6g}" if isinstance(row[c], float) else row[c] for c in columns])
    return path


def _jsonable(obj):
    if isinstance(obj, Mapping):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _jsonable(obj.tolist())
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        return v if math.isfinite(v) else None
    if isinstance(obj, np.integer):
        return int(obj)
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def write_json(path, data) -> Path:
    """Write ``data`` as indented JSON (NumPy scalars and arrays converted; NaN/inf as null)."""
    path = Path(path)
    path.write_text(json.dumps(_jsonable(data), indent=2) + "\n", encoding="utf-8")
    return path


def _num(v: float) -> str:
    if math.isnan(v):
        return "–"
    if v != 0 and not 1e-3 <= abs(v) < 1e6:
        return f"{v:.3g}"
    return f"{v:.0f}" if abs(v) >= 1000 else f"{v:.4g}"


def _cell(v) -> str:
    if isinstance(v, (float, np.floating)):
        return _num(float(v))
    return html.escape(str(v))


def html_table(rows: Sequence[Mapping], columns: Sequence[str], headers: Sequence[str] | None = None) -> str:
    """An HTML table of dict rows (floats with 4 significant digits)."""
    head = "".join(f"<th>{html.escape(h)}</th>" for h in (headers or columns))
    body = "".join("<tr>" + "".join(f"<td>{_cell(r.get(c, ''))}</td>" for c in columns) + "</tr>" for r in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def html_figure(path, caption: str) -> str:
    """A ``<figure>`` that embeds the PNG at ``path`` (base64) and links the file by name."""
    path = Path(path)
    data = base64.b64encode(path.read_bytes()).decode("ascii")
    name = html.escape(path.name)
    return (f'<figure><img src="data:image/png;base64,{data}" alt="{name}">'
            f'<figcaption>{html.escape(caption)} (<a href="{name}">{name}</a>)</figcaption></figure>')


def write_html(out, title: str, intro: str, sections: Iterable[tuple[str, str]]) -> Path:
    """Write ``out/report.html`` with a title, an intro (HTML) and (heading, HTML) sections."""
    out = Path(out)
    style = ("body{font-family:sans-serif;max-width:1100px;margin:2em auto;color:#222}"
             "table{border-collapse:collapse;margin:1em 0}td,th{border:1px solid #bbb;padding:3px 8px;"
             "text-align:right}th{background:#eee}img{max-width:100%}figure{margin:1.5em 0}"
             "pre{background:#f6f6f6;padding:.5em;overflow-x:auto}")
    body = "".join(f"<h2>{html.escape(h)}</h2>{content}" for h, content in sections)
    text = (f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
            f"<style>{style}</style></head><body><h1>{html.escape(title)}</h1>{intro}{body}</body></html>")
    path = out / "report.html"
    path.write_text(text, encoding="utf-8")
    return path
