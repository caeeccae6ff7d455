"""Repeated look-then-move episodes and the paper's tables (Tables 2, 3 and 4).

:func:`run_experiment` runs ``runs`` independent episodes of one method (each with its own
task seed, so the numbers do not depend on the scheduler) and builds:

``line``
    Table 2: per run the image-based absolute rotation errors after the orientation
    adjustment (deg) and the absolute position errors after each update (mm); a mean row.
``trajectory``
    Table 3: per run the mean and maximum absolute errors after point-set matching (mm);
    Table 4: per run the absolute position errors after each update (mm); mean rows.

Every row has ``status`` and ``error`` (the reason): ``ok``; ``suspect`` when the episode ran but
its trajectory registration (match or hand-eye) was ``suspect`` (its numbers are kept, in the
mean too); ``error`` when it failed (NaN values, left out of the mean). The words are
:mod:`posekit.verdict`'s. The true errors (simulation truth, not
the camera's) are in extra tables with the suffix ``_truth``.
"""

import math
import time
from dataclasses import dataclass, field

import numpy as np

from posekit.errors import ConfigError, PosekitError
from posekit.localcal.studies.episode import LocalcalEpisode, run_localcal_episode
from posekit.localcal.studies.episode_config import METHODS, EpisodeConfig
from posekit.sweep import SERIAL, run_tasks, task_seed
from posekit.verdict import Verdict, status_counts

__all__ = [
    "PAPER_TABLE2_MEAN",
    "PAPER_TABLE3",
    "PAPER_TABLE4_MEAN",
    "RUN_STATUSES",
    "ExperimentResult",
    "episode_status",
    "episode_verdict",
    "format_table",
    "run_experiment",
    "table_columns",
]

#: The status words of a run (posekit.verdict's): done and trusted, done but the registration is
#: suspect, failed.
RUN_STATUSES = ("ok", "suspect", "error")

#: Mean row of the paper's Table 2 (line method): e_θx, e_θy, e_θz [deg], e_x, e_y, e_z [mm].
PAPER_TABLE2_MEAN = (1.58, 1.57, 6.64, 24.0, 29.0, 338.0)
#: The paper's Table 3 (one measurement): mean and maximum absolute matching errors x, y, z [mm].
PAPER_TABLE3 = {"mean": (3.7, 1.8, 14.2), "max": (21.9, 25.4, 58.2)}
#: Mean row of the paper's Table 4 (trajectory method): 1st input e_x, e_y, e_z, 2nd input e_x, e_y, e_z [mm].
PAPER_TABLE4_MEAN = (7.6, 27.4, 95.9, 3.3, 1.2, 92.3)


@dataclass
class ExperimentResult:
    """Episodes of one method and their tables.

    Attributes
    ----------
    method : str
        ``'line'`` or ``'trajectory'``.
    seed : int
        The experiment's seed (run i uses ``task_seed(seed, i)``).
    updates : int
        Look-then-move updates per episode.
    episodes : list of LocalcalEpisode or None
        One per run, in order (None for a failed run).
    failures : list of str or None
        The error of each run (None when it succeeded).
    tables : dict of str to list of dict
        ``'table2'`` (line) or ``'table3'`` and ``'table4'`` (trajectory), plus
        ``'<name>_truth'`` variants; rows ``run 1`` … ``run N`` and ``mean``.
    wall_s : float
        Wall time of the runs, s.
    """

    method: str
    seed: int
    updates: int
    episodes: list
    failures: list
    tables: dict = field(default_factory=dict)
    wall_s: float = 0.0

    @property
    def verdicts(self) -> list[Verdict]:
        """The :class:`posekit.verdict.Verdict` of every run (:func:`episode_verdict`)."""
        return [episode_verdict(ep, fail) for ep, fail in zip(self.episodes, self.failures)]

    @property
    def statuses(self) -> list[str]:
        """One of :data:`RUN_STATUSES` per run (:func:`episode_status`)."""
        return [v.status for v in self.verdicts]

    @property
    def status_counts(self) -> dict:
        """``{"ok": n, "suspect": n, "error": n}`` over the runs."""
        return status_counts(self.statuses, RUN_STATUSES)


def episode_verdict(ep: LocalcalEpisode | None, failure: str | None = None) -> Verdict:
    """The verdict of one run: ``error`` (the failure as its reason) for a failed run,
    ``suspect`` with the registration's reasons when its registration (match or hand-eye) was
    suspect, else ``ok``. The run's numbers are the simulation's (no std)."""
    if ep is None:
        return Verdict.failed(failure or "the episode failed")
    return ep.verdict


def episode_status(ep: LocalcalEpisode | None) -> str:
    """``error`` for a failed run, ``suspect`` when its registration was, else ``ok``
    (the status of :func:`episode_verdict`)."""
    return episode_verdict(ep).status


def _update_columns(updates: int) -> list[str]:
    return [f"e{axis}_{k}_mm" for k in range(1, updates + 1) for axis in "xyz"]


def table_columns(name: str, updates: int) -> list[str]:
    """Column names of a table (``table2``, ``table3``, ``table4`` or their ``_truth`` variants).

    Parameters
    ----------
    name : str
        Table name.
    updates : int
        Look-then-move updates per episode (Tables 2 and 4 have three columns per update).

    Returns
    -------
    list of str
        ``run``, the value columns (``*_deg`` in degrees, ``*_mm`` in mm), ``status``, ``error``.

    Raises
    ------
    ConfigError
        An unknown table name.
    """
    base = name.removesuffix("_truth")
    if base == "table2":
        cols = ["rot_x_deg", "rot_y_deg", "rot_z_deg"] + _update_columns(updates)
    elif base == "table3":
        cols = ["mean_x_mm", "mean_y_mm", "mean_z_mm", "max_x_mm", "max_y_mm", "max_z_mm"]
    elif base == "table4":
        cols = _update_columns(updates)
    else:
        raise ConfigError(f"unknown table {name!r}, expected table2, table3 or table4")
    return ["run"] + cols + ["status", "error"]


def _nan_row(cols):
    return {c: math.nan for c in cols}


def _values(ep: LocalcalEpisode, base: str, truth: bool, updates: int) -> list[float]:
    if base == "table3":
        m = ep.matching
        return list(m["mean_abs_err_mm"]) + list(m["max_abs_err_mm"])
    err = np.abs(ep.true_errors_mm if truth else ep.errors_mm)[:updates]
    vals = err.reshape(-1).tolist()
    if base == "table2":
        rot = ep.true_rotation_after_deg if truth else ep.rotation_after_deg
        vals = list(np.asarray(rot, float)) + vals
    return vals


def _build_table(name: str, episodes, failures, updates: int) -> list[dict]:
    base = name.removesuffix("_truth")
    truth = name.endswith("_truth")
    cols = table_columns(name, updates)
    value_cols = cols[1:-2]
    rows = []
    for i, (ep, fail) in enumerate(zip(episodes, failures)):
        row = {"run": f"run {i + 1}"}
        verdict = episode_verdict(ep, fail)
        if ep is None:
            row.update(_nan_row(value_cols), status=verdict.status, error=fail)
        else:
            why = verdict.reason
            row.update(dict(zip(value_cols, (float(v) for v in _values(ep, base, truth, updates)))),
                       status=verdict.status, error=f"registration suspect: {why}" if why else "")
        rows.append(row)
    ok = [r for r in rows if r["status"] != "error"]
    mean = {"run": "mean", "status": "ok" if ok else "error",
            "error": "" if ok else "every run failed"}
    for c in value_cols:
        mean[c] = float(np.mean([r[c] for r in ok])) if ok else math.nan
    rows.append(mean)
    return rows


def _tables_for(method: str, episodes, failures, updates: int) -> dict:
    names = ["table2"] if method == "line" else ["table3", "table4"]
    tables = {}
    for name in names:
        tables[name] = _build_table(name, episodes, failures, updates)
        if name != "table3":
            tables[name + "_truth"] = _build_table(name + "_truth", episodes, failures, updates)
    return tables


def _run_task(task):
    """One episode (top level, picklable, for :func:`posekit.sweep.run_tasks`)."""
    try:
        return run_localcal_episode(task["method"], task["seed"], updates=task["updates"], config=task["config"]), None
    except PosekitError as exc:
        return None, f"{type(exc).__name__}: {exc}"


def run_experiment(method: str, runs: int = 10, seed: int = 0, *, updates: int = 2,
                   config: EpisodeConfig | None = None, scheduler=SERIAL,
                   progress: bool | None = None, n_workers: int | None = None) -> ExperimentResult:
    """Run ``runs`` look-then-move episodes of one method and build the paper's tables.

    Parameters
    ----------
    method : {'line', 'trajectory'}
        Range adjustment method.
    runs : int
        Number of episodes (>= 1); run i uses ``task_seed(seed, i)``.
    seed : int
        Seed of the experiment (>= 0).
    updates : int
        Look-then-move updates per episode (>= 1).
    config : EpisodeConfig, optional
        Episode settings (defaults: :class:`EpisodeConfig`).
    scheduler : 'serial', None or str
        Passed to :func:`posekit.sweep.run_tasks`; ``'serial'`` (default) runs in this
        process, None starts a local Dask cluster, an address uses a running scheduler.
    n_workers : int, optional
        Worker processes of the local cluster (``scheduler=None`` only).
    progress : bool, optional
        Progress bar; default only on a terminal.

    Returns
    -------
    ExperimentResult

    Raises
    ------
    ConfigError
        An unknown method, ``runs < 1``, ``updates < 1`` or a bad scheduler.
    """
    if method not in METHODS:
        raise ConfigError(f"method: expected one of {' | '.join(METHODS)}, got {method!r}")
    if int(runs) != runs or runs < 1:
        raise ConfigError(f"runs must be an integer >= 1, got {runs!r}")
    if int(updates) != updates or updates < 1:
        raise ConfigError(f"updates must be an integer >= 1, got {updates!r}")
    config = config or EpisodeConfig()
    tasks = [{"method": method, "seed": task_seed(seed, i), "updates": int(updates), "config": config}
             for i in range(int(runs))]
    t0 = time.perf_counter()
    out = run_tasks(_run_task, tasks, scheduler=scheduler, progress=progress, desc=f"localcal {method}",
                    n_workers=n_workers)
    wall = time.perf_counter() - t0
    episodes = [ep for ep, _ in out]
    failures = [fail for _, fail in out]
    result = ExperimentResult(method, int(seed), int(updates), episodes, failures, wall_s=wall)
    result.tables = _tables_for(method, episodes, failures, int(updates))
    return result


# --------------------------------------------------------------------------- text tables

_HEAD = {"rot_x_deg": "e_θx[deg]", "rot_y_deg": "e_θy[deg]", "rot_z_deg": "e_θz[deg]",
         "mean_x_mm": "mean x", "mean_y_mm": "mean y", "mean_z_mm": "mean z",
         "max_x_mm": "max x", "max_y_mm": "max y", "max_z_mm": "max z"}


def _header(col: str) -> str:
    if col in _HEAD:
        return _HEAD[col]
    if col.startswith("e") and col.endswith("_mm") and col[2:-3].lstrip("_").isdigit():
        return f"e_{col[1]}#{col[3:-3]}[mm]"
    return col


def format_table(rows: list[dict], columns: list[str], title: str = "") -> str:
    """A fixed-width text table (2 decimals for degrees, 1 for mm; errors after the table).

    Parameters
    ----------
    rows : list of dict
        Table rows (as in :attr:`ExperimentResult.tables`).
    columns : list of str
        Columns to show, in order (``status`` and ``error`` are left out of the grid).
    title : str
        Line printed above the table.

    Returns
    -------
    str
        The table; a line per failed run follows it with the reason.
    """
    cols = [c for c in columns if c not in ("status", "error")]
    head = [_header(c) for c in cols]

    def cell(r, c):
        v = r[c]
        if isinstance(v, str):
            return v
        if math.isnan(v):
            return "-"
        return f"{v:.2f}" if c.endswith("_deg") else f"{v:.1f}"

    body = [[cell(r, c) for c in cols] for r in rows]
    widths = [max(len(h), *(len(b[i]) for b in body)) for i, h in enumerate(head)]
    lines = [title] if title else []
    lines.append("  ".join(h.rjust(w) if i else h.ljust(w) for i, (h, w) in enumerate(zip(head, widths))))
    for b in body:
        lines.append("  ".join(v.rjust(w) if i else v.ljust(w) for i, (v, w) in enumerate(zip(b, widths))))
    for r in rows:
        if r.get("status") == "error" and r["run"] != "mean":
            lines.append(f"  {r['run']} failed: {r['error']}")
    return "\n".join(lines)
