"""Files written by ``posekit seam simulate|demo|study``: CSV tables and ``report.html``.

:func:`write_estimates_csv` writes the per-step record of every episode (truth, estimate,
nominal pose, errors); :func:`write_html` writes a self-contained ``report.html`` that embeds
each figure (base64) next to a link to its PNG file, and the tables given as dict rows.
Units at this edge: positions in mm, quaternions ``[w, x, y, z]``, errors in mm and degrees
(the unit is in every column name).
"""

import csv
import html
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from posekit.geometry import quaternion_from_matrix
from posekit.report import html_figure, to_jsonable, write_csv, write_html, write_json
from posekit.report import html_table as _html_table

__all__ = [
    "ERROR_AXES",
    "ERROR_COLUMNS",
    "ESTIMATE_COLUMNS",
    "html_figure",
    "html_table",
    "read_estimates_csv",
    "write_csv",
    "write_estimates_csv",
    "write_html",
    "write_json",
    "write_simulation",
]

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
                     "ess", "step_ms",
                     # [seam engine, issue 15] integrity: simulate.STATUS_COLUMNS (status, std_x_mm .. std_rz_deg)
                     "status", "std_x_mm", "std_y_mm", "std_z_mm", "std_rx_deg", "std_ry_deg", "std_rz_deg"])


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
        ``kinematic_error`` (T, 6) ``[x, y, z mm, rx, ry, rz rad]`` in the seam frame,
        ``spread`` (T, 6) (mm, rad), ``ess`` (T,) and ``step_ms`` (T,). The rotations are written
        in degrees (the ``*_deg`` columns).

    Returns
    -------
    pathlib.Path
        ``path``. Columns: :data:`ESTIMATE_COLUMNS`; numbers with 10 significant digits.
    """
    from posekit.seam.frontend.episode_metrics import STATUS_COLUMNS, status_columns
    from posekit.seam.frontend.seam_frame import to_degrees

    path = Path(path)
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(ESTIMATE_COLUMNS)
        for run, r in enumerate(results):
            n = len(r.t_s)
            block = np.hstack([np.arange(n)[:, None], np.asarray(r.t_s, float)[:, None], _poses(r.truth),
                               _poses(r.estimate), _poses(r.nominal), to_degrees(r.error),
                               to_degrees(r.kinematic_error), to_degrees(r.spread),
                               np.asarray(r.ess, float)[:, None], np.asarray(r.step_ms, float)[:, None]])
            cols = status_columns(r)  # [seam engine, issue 15] the verdict and the six 1-sigma spreads
            stds = np.column_stack([cols[c] for c in STATUS_COLUMNS[1:]])
            for row, st, sd in zip(block, cols["status"], stds):
                w.writerow([run, int(row[0]), *(f"{v:.10g}" for v in row[1:]), st, *(f"{v:.10g}" for v in sd)])
    return path


def read_estimates_csv(path) -> dict[str, np.ndarray]:
    """Read an ``estimates.csv`` back: column name -> (rows,) float array (``status``: str array)."""
    with Path(path).open(newline="") as f:
        reader = csv.reader(f)
        header = next(reader)
        rows = np.array(list(reader), dtype=str).reshape(-1, len(header))
    return {name: (rows[:, i] if name == "status" else rows[:, i].astype(float)) for i, name in enumerate(header)}


def _num(v: float) -> str:
    if math.isnan(v):
        return "–"
    if v != 0 and not 1e-3 <= abs(v) < 1e6:
        return f"{v:.3g}"
    return f"{v:.0f}" if abs(v) >= 1000 else f"{v:.4g}"


def _cell(v, column: str = "") -> str:
    if isinstance(v, (float, np.floating)):
        return _num(float(v))
    return html.escape(str(v))


def html_table(rows: Sequence[Mapping], columns: Sequence[str], headers: Sequence[str] | None = None) -> str:
    """An HTML table of dict rows (floats with 4 significant digits)."""
    return _html_table(rows, columns, headers, cell=_cell)


def _fact(value) -> str:
    """One metrics.json value as a table cell's text: numbers as in the tables, a mapping as
    ``key value, ...``, a list comma-separated."""
    value = to_jsonable(value)
    if isinstance(value, Mapping):
        return ", ".join(f"{k} {_fact(v)}" for k, v in value.items())
    if isinstance(value, list):
        return ", ".join(_fact(v) for v in value)
    if isinstance(value, float):
        return _num(value)
    return "–" if value is None else str(value)


def _rmse_rows(metrics: Mapping) -> list[dict]:
    rows = []
    for i, a in enumerate(ERROR_AXES):
        unit, key = ("mm", "rmse_mm") if i < 3 else ("deg", "rmse_deg")
        rows.append({"axis": f"{a} ({unit})", "filter": float(metrics[key][a]),
                     "kinematics only": float(metrics.get(f"kinematic_{key}", {}).get(a, float("nan")))})
    return rows


def write_simulation(out, results: Sequence, metrics: Mapping, config_yaml: str = "", *,
                     comparison: Sequence | None = None, title: str = "Seam tracking simulation") -> dict:
    """Write the files of ``posekit seam simulate`` / ``demo`` into folder ``out``.

    Parameters
    ----------
    out : path-like
        Output folder (created).
    results : sequence of EpisodeResult
        The episodes of the main configuration (run 0 may carry recorded particles).
    metrics : mapping
        ``posekit.seam.frontend.episode_metrics.metrics(results)`` (the metrics.json contract); written as is,
        plus ``comparison`` (label -> RMSE per axis) when ``comparison`` is given.
    config_yaml : str
        The effective configuration, shown in the report and written to ``config.yaml``.
    comparison : sequence of ConfigurationSet, optional
        Trajectory × sensor-count sets for Fig. 8 (and both trajectories in Fig. 9).
    title : str
        Title of the report.

    Returns
    -------
    dict
        Name -> path of every file written: ``metrics``, ``estimates``, ``config``, ``fig5``
        (only when run 0 recorded particles), ``fig8``, ``fig9``, ``errors``, ``report``.
    """
    from posekit.seam.frontend import plots

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    data = dict(metrics)
    if comparison:
        data["comparison"] = {s.label: {k: s.metrics[k] for k in ("rmse_mm", "rmse_deg", "kinematic_rmse_mm",
                                                                  "kinematic_rmse_deg") if k in s.metrics}
                              for s in comparison}
    paths = {"metrics": write_json(out / "metrics.json", data),
             "estimates": write_estimates_csv(out / "estimates.csv", results)}
    if config_yaml:
        paths["config"] = out / "config.yaml"
        paths["config"].write_text(config_yaml, encoding="utf-8")
    r0 = results[0]
    sections = []
    if getattr(r0, "particles", None) is not None:
        paths["fig5"] = plots.plot_particle_density(
            r0.particles, r0.truth_coords, out / "fig5_density.png",
            title="Run 0: particle density per state dimension (heatmap, each step scaled to its peak), truth (cyan)")
        sections.append(("Fig. 5 — particle density over time", html_figure(
            paths["fig5"], "Recorded particles of run 0 per state dimension, in the seam frame")))
    if comparison:
        groups = {s.label: s.errors() for s in comparison}
        caption = "Error distributions per trajectory and sensor count (same filter parameters)"
        series = {}
        for s in comparison:
            series.setdefault(s.trajectory, plots.positions_in_frame(s.results[0].nominal))
        fig9_caption = "Nominal trajectories in the tool frame at the start"
    else:
        groups = {"particle filter": np.concatenate([r.error for r in results]),
                  "kinematics only": np.concatenate([r.kinematic_error for r in results])}
        caption = "Error distributions of the filter and of the robot kinematics alone, all runs"
        ref = r0.nominal[0]
        series = {k: plots.positions_in_frame(getattr(r0, k), ref) for k in ("nominal", "truth", "estimate",
                                                                            "kinematic")}
        fig9_caption = "Run 0: nominal, true, estimated and kinematics-only tool positions (start tool frame)"
    paths["fig8"] = plots.plot_error_distributions(groups, out / "fig8_errors.png")
    paths["fig9"] = plots.plot_tool_paths(series, out / "fig9_trajectories.png")
    paths["errors"] = plots.plot_tracking_errors(np.stack([r.error for r in results]),
                                                  np.stack([r.kinematic_error for r in results]),
                                                  out / "errors_time.png", t_s=r0.t_s,
                                                  spread=np.stack([r.spread for r in results]))
    paths["ess"] = plots.plot_ess(r0.ess, r0.resampled, r0.config.filter.particles, out / "ess.png", t_s=r0.t_s,
                                  status=getattr(r0, "status", None))
    if getattr(r0, "snapshot", None) is not None:
        paths["fig5_hypotheses"] = plots.plot_measurement_hypotheses(r0.snapshot, r0.seam,
                                                                     out / "fig5_hypotheses.png")
        sections.append(("Fig. 5 — measurement hypotheses", html_figure(
            paths["fig5_hypotheses"], "Run 0: each particle's hypothesis of the seam point its sensor saw, "
                                      "coloured by its weight after the update")))
    sections.insert(0, ("RMSE per axis (seam frame, all runs and steps)",
                        html_table(_rmse_rows(metrics), ["axis", "filter", "kinematics only"])))
    if comparison:
        rows = []
        for s in comparison:
            row = {"configuration": s.label}
            row.update({a: float(s.metrics["rmse_mm"][a]) for a in ERROR_AXES[:3]})
            row.update({a: float(s.metrics["rmse_deg"][a]) for a in ERROR_AXES[3:]})
            rows.append(row)
        sections.append(("RMSE per configuration (mm, deg)", html_table(rows, ["configuration", *ERROR_AXES])))
    sections += [("Fig. 8 — error distributions", html_figure(paths["fig8"], caption)),
                 ("Fig. 9 — trajectories", html_figure(paths["fig9"], fig9_caption)),
                 ("Errors over time", html_figure(paths["errors"], "Per-step error of every run, the filter's "
                                                                   "reported ±2σ of run 0 shaded")),
                 ("Effective sample size", html_figure(paths["ess"], "Run 0: ESS / N after each update, the "
                                                                     "resampling steps, the integrity status"))]
    if config_yaml:
        sections.append(("Configuration", f"<pre>{html.escape(config_yaml)}</pre>"))
    skip = {"rmse_mm", "rmse_deg", "kinematic_rmse_mm", "kinematic_rmse_deg", "comparison"}
    facts = [{"metric": str(k), "value": _fact(v)} for k, v in metrics.items() if k not in skip]
    cfg_link = ", <a href='config.yaml'>config.yaml</a>" if config_yaml else ""
    intro = (f"<p>Files: <a href='metrics.json'>metrics.json</a>, <a href='estimates.csv'>estimates.csv</a>"
             f"{cfg_link}.</p>" + html_table(facts, ["metric", "value"]))
    paths["report"] = write_html(out, title, intro, sections)
    return paths
