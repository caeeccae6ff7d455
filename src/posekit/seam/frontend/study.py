"""Tuning study (§III-A, Fig. 6): which filter parameters matter for the tracking error.

Each *run* of the study draws a random perturbation of the chosen filter parameters (the
*factors*), simulates ``episodes`` episodes with them and records the RMSE of the six
tool-pose errors ``x, y, z`` (mm) and ``rx, ry, rz`` (rad; the tables and the linear models use
degrees). A linear model (statsmodels OLS,
with an intercept) of each RMSE on the factor values then gives one p-value per factor and
error; :func:`rank_parameters` orders the factors by their smallest p-value. An integer
parameter (``filter.particles``, ``filter.anneal_stages``) takes its draw rounded.

A factor is a dotted key of the configuration (:func:`study_base`: the profile's values as bare numbers): a
number (drawn in ``[low, high]``), an item of a tuple key (``simulation.force_n[2]``,
``cell.sensors.distances_mm[1]``) or a whole tuple key (``cell.sensors.distances_mm``,
``simulation.force_n``), whose draw is a scale applied to every item (``[low, high]`` default
``1 ± spread``): the sensors move out together, the force grows.

Reproducibility: run ``i`` draws its factor values from ``task_seed(seed, i, 0)`` and the
seed of its episode ``j`` from ``task_seed(seed, i, 1, j)``; the draws are made before the
tasks are sent out and nothing depends on the worker, so the same seed gives the same table
in a single process (``scheduler='serial'``), on a local cluster or on a remote one, and the
first R runs of a larger study are the R runs of a smaller one.
"""

import copy
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from posekit._extras import require
from posekit.errors import ConfigError, EstimationError, PosekitError
from posekit.seam.frontend.report import ERROR_AXES
from posekit.sweep import run_tasks, task_seed

__all__ = [
    "DEFAULT_FACTORS",
    "ERROR_NAMES",
    "RANKED_COLUMNS",
    "RUN_COLUMNS",
    "Factor",
    "ParameterEffects",
    "SeamStudy",
    "factor_value",
    "fit_parameter_effects",
    "get_dotted",
    "is_tuple_factor",
    "make_factors",
    "rank_parameters",
    "seam_study",
    "set_dotted",
    "study_base",
    "study_task",
    "write_study",
]

#: The filter parameters perturbed by default (dotted keys of :class:`~posekit.seam.frontend.config.SeamConfig`).
DEFAULT_FACTORS = ("profile.walk.x_mm", "profile.walk.y_mm", "profile.walk.z_mm", "profile.walk.rx_deg",
                   "profile.walk.ry_deg", "profile.walk.rz_deg", "profile.plateau.d0_mm",
                   "profile.plateau.kd_mm_per_n", "profile.plateau.d0_deg", "profile.plateau.kd_deg_per_n",
                   "filter.regularize_h", "filter.ess_threshold")
#: Names of the six responses (RMSE over all steps of a run's episodes).
ERROR_NAMES = tuple(f"rmse_{a}_{'mm' if i < 3 else 'deg'}" for i, a in enumerate(ERROR_AXES))
#: Significance level of the ``significant`` column (before the Bonferroni correction over errors).
ALPHA = 0.05


@dataclass(frozen=True)
class Factor:
    """One perturbed parameter: a dotted config key drawn uniformly from ``[low, high]`` (its unit)."""

    name: str
    low: float
    high: float

    def __post_init__(self):
        if not (np.isfinite(self.low) and np.isfinite(self.high) and self.low < self.high):
            raise ConfigError(f"study factor '{self.name}': expected a range low < high, "
                              f"got [{self.low:g}, {self.high:g}]")


def _split_index(key: str) -> tuple[str, int | None]:
    """``'simulation.force_n[2]'`` → ``('simulation.force_n', 2)``; ``'a.b'`` → ``('a.b', None)``."""
    if key.endswith("]") and "[" in key:
        name, _, idx = key[:-1].rpartition("[")
        try:
            return name, int(idx)
        except ValueError:
            raise ConfigError(f"study factor '{key}': expected KEY[INDEX] with an integer index") from None
    return key, None


def get_dotted(data: Mapping, key: str):
    """``data['a']['b']`` for ``key='a.b'`` (``'a.b[i]'``: item i of a tuple key); ConfigError naming
    the key when it does not exist."""
    name, idx = _split_index(key)
    node = data
    for part in name.split("."):
        if not isinstance(node, Mapping) or part not in node:
            raise ConfigError(f"study factor '{key}': no such configuration key")
        node = node[part]
    if idx is not None:
        if not isinstance(node, (list, tuple)) or not -len(node) <= idx < len(node):
            size = len(node) if isinstance(node, (list, tuple)) else "no"
            raise ConfigError(f"study factor '{key}': '{name}' has {size} items; expected an index within them")
        node = node[idx]
    return node


def set_dotted(data: dict, key: str, value) -> None:
    """Set ``data['a']['b'] = value`` for ``key='a.b'`` in place (the key must exist); ``'a.b[i]'``
    sets item i of a tuple key."""
    get_dotted(data, key)
    name, idx = _split_index(key)
    *path, last = name.split(".")
    node = data
    for part in path:
        node = node[part]
    if idx is None:
        node[last] = value
    else:
        items = list(node[last])
        items[idx] = value
        node[last] = items


def is_tuple_factor(base: Mapping, name: str) -> bool:
    """Whether ``name`` is a whole tuple key (``cell.sensors.distances_mm``, ``simulation.force_n``): its
    factor value is a scale applied to every item."""
    value = get_dotted(base, name)
    return isinstance(value, (list, tuple))


def factor_value(base: Mapping, name: str, x: float):
    """The configuration value of factor ``name`` drawn as ``x``: ``x`` itself (rounded for an
    integer key), or for a whole tuple key the base items scaled by ``x``."""
    value = get_dotted(base, name)
    if isinstance(value, (list, tuple)):
        return [float(v) * float(x) for v in value]
    return int(round(x)) if type(value) is int else float(x)


def make_factors(base: Mapping, names: Sequence[str] | None = None, *, spread: float = 0.5,
                 ranges: Mapping[str, tuple[float, float]] | None = None) -> tuple[Factor, ...]:
    """Factors around a base configuration.

    Parameters
    ----------
    base : mapping
        The base configuration as a dict (:func:`study_base`).
    names : sequence of str, optional
        Dotted keys to perturb (default :data:`DEFAULT_FACTORS`, less those whose base value
        is 0 and that have no explicit range).
    spread : float
        Relative half-range: a factor is drawn from ``[v (1 - spread), v (1 + spread)]`` around
        its base value v; 0 < spread < 1.
    ranges : mapping of str to (low, high), optional
        Explicit ranges that replace the relative one (for parameters whose base is 0).

    Returns
    -------
    tuple of Factor
    """
    if not 0.0 < spread < 1.0:
        raise ConfigError(f"study spread: expected a fraction 0 < spread < 1, got {spread:g}")
    ranges = dict(ranges or {})
    explicit = names is not None
    names = list(names if explicit else DEFAULT_FACTORS)
    for k in ranges:
        if k not in names:
            names.append(k)
    factors = []
    for name in names:
        value = get_dotted(base, name)
        if name in ranges:
            lo, hi = ranges[name]
            factors.append(Factor(name, float(lo), float(hi)))
            continue
        if isinstance(value, (list, tuple)):  # a tuple key: one scale for all of its items
            if not value or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value):
                raise ConfigError(f"study factor '{name}': expected a tuple of numbers, got {value!r}")
            factors.append(Factor(name, 1.0 - spread, 1.0 + spread))
            continue
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(f"study factor '{name}': expected a numeric parameter, got {value!r}")
        if value == 0:
            if explicit:
                raise ConfigError(f"study factor '{name}': its base value is 0, so a relative range is empty; "
                                  f"give an explicit range {name}=LOW:HIGH")
            continue
        a, b = sorted((value * (1 - spread), value * (1 + spread)))
        factors.append(Factor(name, float(a), float(b)))
    if not factors:
        raise ConfigError("study: no factor to perturb")
    return tuple(factors)


@dataclass
class ParameterEffects:
    """Linear models (OLS with intercept) of each error on the factors.

    Attributes
    ----------
    parameters : tuple of str, length P
    errors : tuple of str, length E
    coef : ndarray, shape (E, P)
        Slopes: change of the error (its unit) per unit of the factor.
    pvalues : ndarray, shape (E, P)
        Two-sided t-test p-values of the slopes.
    rsquared : ndarray, shape (E,)
    n : int
        Runs used in the fit.
    """

    parameters: tuple
    errors: tuple
    coef: np.ndarray
    pvalues: np.ndarray
    rsquared: np.ndarray
    n: int

    @property
    def log10_p(self) -> np.ndarray:
        """(E, P) log10 of the p-values (p = 0 is clipped to 1e-300)."""
        return np.log10(np.clip(self.pvalues, 1e-300, 1.0))


def fit_parameter_effects(X: np.ndarray, Y: np.ndarray, parameters: Sequence[str],
                          errors: Sequence[str] = ERROR_NAMES) -> ParameterEffects:
    """OLS of each column of ``Y`` on the columns of ``X`` (plus an intercept).

    Parameters
    ----------
    X : ndarray, shape (R, P)
        Factor values of each run (their config units).
    Y : ndarray, shape (R, E)
        Responses of each run (e.g. RMSE per error axis). Rows with a non-finite value in X
        or Y are left out of every model.
    parameters, errors : sequence of str
        Names of the P factors and E responses.

    Returns
    -------
    ParameterEffects

    Raises
    ------
    EstimationError
        Fewer than P + 2 usable runs, or a factor that does not vary.
    """
    sm = require("statsmodels.api", "studies", "the seam study's parameter effects (OLS)")

    X = np.asarray(X, dtype=float)
    Y = np.asarray(Y, dtype=float)
    if X.ndim != 2 or Y.ndim != 2 or len(X) != len(Y) or X.shape[1] != len(parameters) or \
            Y.shape[1] != len(errors):
        raise ConfigError(f"parameter effects: expected X (R, {len(parameters)}) and Y (R, {len(errors)}), "
                          f"got {X.shape} and {Y.shape}")
    ok = np.all(np.isfinite(X), axis=1) & np.all(np.isfinite(Y), axis=1)
    n, p = int(ok.sum()), X.shape[1]
    if n < p + 2:
        raise EstimationError(f"parameter effects: {n} usable runs for {p} factors; need at least {p + 2} "
                              f"(raise --runs)")
    Xo = X[ok]
    flat = [parameters[j] for j in range(p) if np.ptp(Xo[:, j]) == 0]
    if flat:
        raise EstimationError(f"parameter effects: factor(s) {', '.join(flat)} do not vary over the runs")
    design = sm.add_constant(Xo, has_constant="add")
    coef = np.empty((Y.shape[1], p))
    pv = np.empty((Y.shape[1], p))
    r2 = np.empty(Y.shape[1])
    for e in range(Y.shape[1]):
        fit = sm.OLS(Y[ok, e], design).fit()
        coef[e] = fit.params[1:]
        pv[e] = fit.pvalues[1:]
        r2[e] = fit.rsquared
    return ParameterEffects(tuple(parameters), tuple(errors), coef, pv, r2, n)


RANKED_COLUMNS = ("rank", "parameter", "low", "high", "min_log10_p", "most_affected", "significant",
                  *(f"log10_p_{a}" for a in ERROR_AXES),
                  *(f"range_effect_{a}_{'mm' if i < 3 else 'deg'}" for i, a in enumerate(ERROR_AXES)))


def rank_parameters(effects: ParameterEffects, factors: Sequence[Factor]) -> list[dict]:
    """Factors ordered by their smallest p-value over the errors (most significant first).

    Each row: ``rank`` (1 = matters most), ``parameter``, its range, ``min_log10_p``, the error
    it affects most (``most_affected``), ``significant`` (smallest p < 0.05 / E, Bonferroni
    over the E errors), the log10 p-value per error, and ``range_effect_*``: the change of each
    error's RMSE predicted over the factor's whole range (slope × (high - low)).
    """
    lp = effects.log10_p
    n_err = len(effects.errors)
    rows = []
    for j, f in enumerate(factors):
        col = lp[:, j]
        e = int(np.nanargmin(col)) if np.any(np.isfinite(col)) else 0
        row = {"parameter": f.name, "low": f.low, "high": f.high, "min_log10_p": float(col[e]),
               "most_affected": effects.errors[e],
               "significant": "yes" if col[e] < np.log10(ALPHA / n_err) else "no"}
        for i, a in enumerate(ERROR_AXES[:n_err]):
            row[f"log10_p_{a}"] = float(col[i])
            row[f"range_effect_{a}_{'mm' if i < 3 else 'deg'}"] = float(effects.coef[i, j] * (f.high - f.low))
        rows.append(row)
    rows.sort(key=lambda r: (r["min_log10_p"], r["parameter"]))
    for k, r in enumerate(rows, 1):
        r["rank"] = k
    return rows


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


def study_base(config) -> dict:
    """The configuration as the mapping a study perturbs: ``SeamConfig.model_dump`` with the profile's values as
    bare numbers (``profile.walk.z_mm``, ``profile.plateau.d0_mm`` are factors like any other key)."""
    base = config.model_dump(mode="json")
    base["profile"] = config.profile.plain()
    return base


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
    from posekit.seam.frontend.simulate import run_episode

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
