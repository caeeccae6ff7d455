"""Tuning study (§III-A, Fig. 6): which filter parameters matter for the tracking error.

Each *run* of the study draws a random perturbation of the chosen filter parameters (the
*factors*), simulates ``episodes`` episodes with them and records the RMSE of the six
tool-pose errors ``x, y, z`` (mm) and ``rx, ry, rz`` (rad; the tables and the linear models use
degrees). A linear model (statsmodels OLS, with an intercept) of each RMSE on the factor values
then gives one p-value per factor and error;
:func:`~posekit.seam.frontend.study_effects.rank_parameters` orders the factors by their smallest
p-value. An integer parameter (``filter.particles``, ``filter.anneal_stages``) takes its draw rounded.

Reproducibility: run ``i`` draws its factor values from ``task_seed(seed, i, 0)`` and the
seed of its episode ``j`` from ``task_seed(seed, i, 1, j)``; the draws are made before the
tasks are sent out and nothing depends on the worker, so the same seed gives the same table
in a single process (``scheduler='serial'``), on a local cluster or on a remote one, and the
first R runs of a larger study are the R runs of a smaller one.

The factors: :mod:`posekit.seam.frontend.study_factors`; the linear models and the ranking:
:mod:`posekit.seam.frontend.study_effects`.
"""

import copy
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from posekit._extras import require
from posekit.errors import ConfigError, EstimationError, PosekitError
from posekit.seam.frontend.report import ERROR_AXES
from posekit.seam.frontend.study_effects import (
    ALPHA,
    ERROR_NAMES,
    RANKED_COLUMNS,
    ParameterEffects,
    fit_parameter_effects,
    rank_parameters,
)
from posekit.seam.frontend.study_factors import Factor, factor_value, get_dotted, make_factors, set_dotted, study_base
from posekit.sweep import run_tasks, task_seed

__all__ = ["RUN_COLUMNS", "SeamStudy", "seam_study", "study_task", "write_study"]


RUN_COLUMNS = ("run", "status", *ERROR_NAMES, "error")


@dataclass
class SeamStudy:
    """Result of :func:`seam_study`.

    Attributes
    ----------
    base : dict
        The base configuration (``SeamConfig.model_dump()``).
    factors : tuple of Factor
    X : ndarray, shape (R, P)
        Factor values of each run.
    rmse : ndarray, shape (R, 6)
        RMSE of ``x, y, z`` (mm) and ``rx, ry, rz`` (rad) of each run, NaN for a failed run
        (``runs.csv``, the effects and the report show the rotations in degrees: :data:`ERROR_NAMES`).
    status : list of str
        ``'ok'`` or ``'error'`` per run; ``messages`` holds the reason of a failure.
    effects : ParameterEffects or None
        None when too few runs succeeded (``effects_error`` says why).
    ranked : list of dict
        :func:`rank_parameters` rows.
    """

    base: dict
    factors: tuple
    seed: int
    episodes: int
    X: np.ndarray
    rmse: np.ndarray
    status: list
    messages: list
    seconds: np.ndarray
    effects: ParameterEffects | None
    effects_error: str
    ranked: list
    wall_s: float
    task_cpu_s: float
    scheduler: str = field(default="local")

    def run_rows(self) -> list[dict]:
        """One dict per run with the :data:`RUN_COLUMNS`, each factor's value and ``seconds`` (CPU)."""
        rows = []
        for i in range(len(self.X)):
            row = {"run": i, "status": self.status[i], "seconds": float(self.seconds[i]), "error": self.messages[i]}
            row.update({name: float(v) for name, v in zip(ERROR_NAMES, _rmse_deg(self.rmse[i]))})
            row.update({f.name: float(v) for f, v in zip(self.factors, self.X[i])})
            rows.append(row)
        return rows


def _rmse_deg(rmse: np.ndarray) -> np.ndarray:
    """``(..., 6)`` RMSE rows ``[mm, mm, mm, rad, rad, rad]`` as ``[mm, mm, mm, deg, deg, deg]`` (a copy)."""
    out = np.array(rmse, dtype=float, copy=True)
    out[..., 3:] = np.degrees(out[..., 3:])
    return out


def _episode_seed(seed: int, run: int, episode: int) -> int:
    return int(task_seed(seed, run, 1, episode).generate_state(1)[0])


def study_task(task: dict) -> dict:
    """One study run (top level, picklable): simulate its episodes, return the RMSE per error axis (mm, rad).

    ``task`` holds ``config`` (a full configuration dict with the factor values set), ``seeds``
    (one int per episode) and ``run``. Any failure (a bad configuration, a failed estimate, a
    numerical breakdown at extreme parameter values) gives ``status='error'`` and the reason on
    one line, never an exception: one bad run must not cancel the study.
    """
    from posekit.seam.frontend.config import config_from_dict
    from posekit.seam.frontend.episode import run_episode

    t0 = time.process_time()
    try:
        cfg = config_from_dict(task["config"], f"study run {task['run']}")
        errors = np.concatenate([run_episode(cfg, int(s)).error for s in task["seeds"]], axis=0)  # mm, rad
        rmse = np.sqrt(np.nanmean(errors ** 2, axis=0))  # mm, rad
        return {"run": task["run"], "status": "ok", "rmse": rmse.tolist(), "error": "",
                "seconds": time.process_time() - t0}
    except Exception as exc:  # noqa: BLE001 -- recorded in the run's row (DESIGN: never drop an item)
        text = str(exc).splitlines()[0] if str(exc) else ""
        if not isinstance(exc, PosekitError):
            text = f"{type(exc).__name__}: {text}" if text else type(exc).__name__
        return {"run": task["run"], "status": "error", "rmse": [float("nan")] * 6, "error": text or type(exc).__name__,
                "seconds": time.process_time() - t0}


def seam_study(config, *, runs: int = 100, factors: Sequence[Factor] | None = None, episodes: int = 1,
               seed: int = 0, scheduler=None, n_workers: int | None = None,
               progress: bool | None = None) -> SeamStudy:
    """Monte-Carlo tuning study: random filter parameters, RMSE per axis, OLS per error.

    Parameters
    ----------
    config : SeamConfig
        The base configuration (trajectory, sensors, robot, process, filter).
    runs : int
        Number of random parameter draws (>= 1; the OLS needs >= P + 2 successful ones).
    factors : sequence of Factor, optional
        The perturbed parameters (default :func:`make_factors` of the base config).
    episodes : int
        Simulated episodes per run (their errors are pooled into one RMSE per axis).
    seed : int
        Study seed (>= 0); see the module docstring for how runs derive theirs.
    scheduler, n_workers, progress
        Passed to :func:`posekit.sweep.run_tasks` (None: a local Dask cluster; 'serial';
        or a scheduler address ``tcp://HOST:PORT``).

    Returns
    -------
    SeamStudy
    """
    from posekit.seam.frontend.config import config_from_dict

    if int(runs) < 1:
        raise ConfigError(f"study runs: expected >= 1, got {runs}")
    if int(episodes) < 1:
        raise ConfigError(f"study episodes: expected >= 1 per run, got {episodes}")
    if int(seed) < 0:
        raise ConfigError(f"study seed: expected an integer >= 0, got {seed}")
    require("statsmodels.api", "studies", "posekit seam study")      # for the OLS at the end: say so now
    base = study_base(config)
    factors = tuple(factors) if factors is not None else make_factors(base)
    lows = np.array([f.low for f in factors])
    highs = np.array([f.high for f in factors])
    # integer parameters (particle count, stages, steps) take the drawn value rounded; a tuple key
    # (cell.sensors.distances_mm, simulation.force_n) is scaled as a whole by its draw
    integer = np.array([type(get_dotted(base, f.name)) is int for f in factors], dtype=bool)
    X = np.empty((int(runs), len(factors)))
    tasks = []
    for i in range(int(runs)):
        rng = np.random.default_rng(task_seed(seed, i, 0))
        X[i] = lows + (highs - lows) * rng.random(len(factors))
        X[i, integer] = np.round(X[i, integer])
        cfg = copy.deepcopy(base)
        for f, v in zip(factors, X[i]):
            set_dotted(cfg, f.name, factor_value(base, f.name, v))
        tasks.append({"run": i, "config": cfg, "seeds": [_episode_seed(seed, i, j) for j in range(int(episodes))]})
    # A bad range (e.g. a noise pushed below 0) is the user's error: say so before any work starts.
    for f in factors:
        for v in (f.low, f.high):
            cfg = copy.deepcopy(base)
            set_dotted(cfg, f.name, factor_value(base, f.name, v))
            try:
                config_from_dict(cfg, "study")
            except PosekitError as exc:
                raise ConfigError(f"study factor '{f.name}': range [{f.low:g}, {f.high:g}] leaves the valid "
                                  f"configurations ({str(exc).splitlines()[0]})") from None
    t0 = time.perf_counter()
    out = run_tasks(study_task, tasks, scheduler=scheduler, n_workers=n_workers, progress=progress,
                    desc="seam study")
    wall = time.perf_counter() - t0
    rmse = np.array([r["rmse"] for r in out], dtype=float).reshape(len(out), 6)
    status = [r["status"] for r in out]
    messages = [r["error"] for r in out]
    seconds = np.array([r["seconds"] for r in out], dtype=float)
    names = tuple(f.name for f in factors)
    try:
        effects = fit_parameter_effects(X, _rmse_deg(rmse), names)  # responses named ERROR_NAMES (mm, deg)
        ranked, why = rank_parameters(effects, factors), ""
    except EstimationError as exc:
        effects, ranked, why = None, [], str(exc)
    sched = "local" if scheduler is None else (scheduler if isinstance(scheduler, str) else "client")
    return SeamStudy(base=base, factors=factors, seed=int(seed), episodes=int(episodes), X=X, rmse=rmse,
                     status=status, messages=messages, seconds=seconds, effects=effects, effects_error=why,
                     ranked=ranked, wall_s=wall, task_cpu_s=float(seconds.sum()), scheduler=sched)


def write_study(study: SeamStudy, out) -> Path:
    """Write ``fig6_pvalues.png``, ``parameters_ranked.csv``, ``runs.csv`` and ``report.html`` into ``out``.

    Returns the ``report.html`` path.
    """
    import html
    import json

    from posekit.seam.frontend.plots import plot_pvalue_heatmap
    from posekit.seam.frontend.report import html_figure, html_table, write_csv, write_html

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = [f.name for f in study.factors]
    write_csv(out / "runs.csv", study.run_rows(), [*RUN_COLUMNS, *names])
    sections = []
    if study.effects is not None:
        write_csv(out / "parameters_ranked.csv", study.ranked, RANKED_COLUMNS)
        fig = plot_pvalue_heatmap(study.effects.log10_p, names, ERROR_AXES, out / "fig6_pvalues.png",
                                  title=f"log10 p-values of the filter parameters ({study.effects.n} runs)")
        sections.append(("Fig. 6 — significance of the filter parameters",
                         html_figure(fig, "log10 p-value of each parameter in the OLS model of each error RMSE")))
        r2 = ", ".join(f"{a}: {v:.2f}" for a, v in zip(ERROR_AXES, study.effects.rsquared))
        sections.append(("Parameters ranked by their smallest p-value",
                         f"<p>R² of the models: {html.escape(r2)}. 'significant': p &lt; {ALPHA} / 6.</p>"
                         + html_table(study.ranked, ["rank", "parameter", "low", "high", "min_log10_p",
                                                     "most_affected", "significant"])))
    else:
        (out / "parameters_ranked.csv").write_text(",".join(RANKED_COLUMNS) + "\n")
        sections.append(("No linear models", f"<p>{html.escape(study.effects_error)}</p>"))
    failed = [r for r in study.run_rows() if r["status"] != "ok"]
    ok = _rmse_deg(study.rmse[np.array(study.status) == "ok"])
    summary = [{"error": n, "mean": float(np.mean(ok[:, i])) if len(ok) else float("nan"),
                "min": float(np.min(ok[:, i])) if len(ok) else float("nan"),
                "max": float(np.max(ok[:, i])) if len(ok) else float("nan")} for i, n in enumerate(ERROR_NAMES)]
    sections.append(("RMSE over the runs", html_table(summary, ["error", "mean", "min", "max"])))
    if failed:
        sections.append(("Failed runs", html_table(failed, ["run", "error"])))
    factors = [{"parameter": f.name, "low": f.low, "high": f.high} for f in study.factors]
    sections.append(("Factors", html_table(factors, ["parameter", "low", "high"])))
    sections.append(("Base configuration", f"<pre>{html.escape(json.dumps(study.base, indent=1))}</pre>"))
    intro = (f"<p>{len(study.X)} runs × {study.episodes} episode(s), seed {study.seed}, scheduler "
             f"{html.escape(study.scheduler)}; {len(failed)} failed. Wall time {study.wall_s:.1f} s, CPU time in "
             f"the tasks {study.task_cpu_s:.1f} s. Tables: <a href='parameters_ranked.csv'>parameters_ranked.csv</a>, "
             f"<a href='runs.csv'>runs.csv</a>.</p>")
    return write_html(out, "Seam tracking: filter tuning study", intro, sections)
