"""Sensor-placement design, the paper's stated purpose: which sensor configuration to buy for a seam.

Every configuration — a sensor count from the user's list (0..4), for each count every
increasing choice of that many distances from the user's grid, optionally with and without the
angle measurement — is simulated on the user's seam (their configuration: robot, trajectory,
process, filter) for ``runs`` episodes, the same episode seeds for every configuration (common
random numbers: the ranking is not noise between draws). The episodes run on Dask through
:func:`posekit.sweep.run_tasks` (a local cluster by default, a scheduler address for a
cluster), one task per configuration and run.

Ranking: by ``score`` = ``‖RMSE_t‖ + lever_mm · ‖RMSE_r‖`` — the root-sum-square of the
three translation RMSEs (mm, seam frame) plus the rotation RMSEs (rad) turned into mm at
``lever_mm`` (default 100 mm: a rotation error of the tool moves a point that far from the TCP
by this much; the welding wire's stick-out and the torch reach are of that order). Lower is
better. ``ranking.csv`` holds every configuration with its six RMSEs.
"""

import itertools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from posekit.errors import ConfigError, PosekitError
from posekit.seam.frontend.compare import episode_seeds
from posekit.sweep import run_tasks

__all__ = [
    "DEFAULT_LEVER_MM",
    "MAX_CONFIGURATIONS",
    "RANKING_COLUMNS",
    "DesignConfiguration",
    "SensorDesign",
    "design_configurations",
    "design_task",
    "distance_grid",
    "sensor_design",
    "write_design",
]

#: Lever arm turning rotation RMSE into mm in the score (see the module docstring).
DEFAULT_LEVER_MM = 100.0
#: Most configurations of one design (all counts 0..4 from 12 distances: 794; 4 from 20: 4,845 alone).
MAX_CONFIGURATIONS = 2_000
#: Columns of ``ranking.csv`` (DESIGN.md: ``sensors,distances_mm,rmse_x_mm,…,score``), then extras.
RANKING_COLUMNS = ("sensors", "distances_mm", "rmse_x_mm", "rmse_y_mm", "rmse_z_mm", "rmse_rx_deg",
                   "rmse_ry_deg", "rmse_rz_deg", "score", "rank", "angle", "kinematic_score", "runs", "status",
                   "error")
_AXES = ("x", "y", "z", "rx", "ry", "rz")


@dataclass(frozen=True)
class DesignConfiguration:
    """One sensor configuration: ``distances_mm`` ahead of the tool (one per sensor) and the angle."""

    distances_mm: tuple[float, ...]
    angle: bool = False

    @property
    def sensors(self) -> int:
        return len(self.distances_mm)

    @property
    def label(self) -> str:
        d = "/".join(f"{v:g}" for v in self.distances_mm)
        return f"{self.sensors} sensor{'s' if self.sensors != 1 else ''}" + (f" @ {d} mm" if d else "") + (
            " + angle" if self.angle else "")


def distance_grid(text: str) -> tuple[float, ...]:
    """``'A:B:STEP'`` → ``(A, A+STEP, ..., B)`` in mm (B included when on the grid); ``'20,45'`` → a list.

    Raises
    ------
    ConfigError
        Not numbers, ``A > B``, ``STEP <= 0``, a distance outside (0, 1000] mm, more than 50 values.
    """
    text = str(text).strip()
    bad_text = ConfigError(f"--distances-mm: expected A:B:STEP or a comma-separated list of mm, got '{text[:60]}'")
    try:
        numbers = tuple(float(v) for v in text.split(":" if ":" in text else ","))
    except ValueError:
        raise bad_text from None
    if not all(math.isfinite(v) for v in numbers) or (":" in text and len(numbers) != 3):
        raise bad_text
    if ":" in text:
        a, b, step = numbers
        if step <= 0.0 or a > b:
            raise ConfigError(f"--distances-mm: expected A:B:STEP with A <= B and STEP > 0, got '{text}'")
        if not (b - a) / step < 1e6:                 # inf for a huge span over a tiny step: no int() of it
            raise ConfigError(f"--distances-mm: '{text}' gives more than 1,000,000 distances; expected at most 50")
        n = int(math.floor((b - a) / step + 1e-9)) + 1
        if n > 50:
            raise ConfigError(f"--distances-mm: '{text}' gives {n} distances; expected at most 50")
        values = tuple(round(a + i * step, 9) for i in range(n))
    else:
        values = numbers
    bad = [v for v in values if not 0.0 < v <= 1000.0]
    if bad:
        raise ConfigError(f"--distances-mm: {bad[0]:g} mm is outside (0, 1000] mm (a sensor ahead of the tool)")
    if len(set(values)) != len(values):
        raise ConfigError(f"--distances-mm: '{text}' repeats a distance")
    if len(values) > 50:
        raise ConfigError(f"--distances-mm: {len(values)} distances; expected at most 50")
    return tuple(sorted(values))


def design_configurations(counts: Sequence[int], distances_mm: Sequence[float],
                          angle: str = "off") -> list[DesignConfiguration]:
    """Every configuration: for each count, every increasing choice of ``count`` distances.

    Parameters
    ----------
    counts : sequence of int
        Sensor counts, each 0..4.
    distances_mm : sequence of float
        The candidate distances ahead of the tool, mm.
    angle : {'off', 'on', 'both'}
        Without the angle measurement, with it (sensors >= 1), or both variants.
    """
    counts = sorted(set(int(c) for c in counts))
    bad = [c for c in counts if not 0 <= c <= 4]
    if bad or not counts:
        raise ConfigError(f"--sensors: expected counts in 0..4, got {list(counts) if counts else 'none'}")
    if angle not in ("off", "on", "both"):
        raise ConfigError(f"--angle: expected off, on or both, got '{angle}'")
    grid = sorted(float(d) for d in distances_mm)
    per_combo = 2 if angle == "both" else 1
    total = sum(math.comb(len(grid), c) * (1 if c == 0 else per_combo) for c in counts if c <= len(grid))
    if total > MAX_CONFIGURATIONS:                   # counted before the (slow) enumeration
        raise ConfigError(f"{total:,} sensor configurations; expected at most {MAX_CONFIGURATIONS:,}: "
                          "fewer --sensors counts or a coarser --distances-mm grid")
    out = []
    for c in counts:
        if c > len(grid):
            raise ConfigError(f"--sensors {c}: only {len(grid)} distances on the grid; expected at least {c}")
        for combo in itertools.combinations(grid, c):
            variants = (False,) if c == 0 or angle == "off" else (True,) if angle == "on" else (False, True)
            out += [DesignConfiguration(tuple(combo), a) for a in variants]
    if len(out) > MAX_CONFIGURATIONS:
        raise ConfigError(f"{len(out):,} sensor configurations; expected at most {MAX_CONFIGURATIONS:,}: "
                          "fewer --sensors counts or a coarser --distances-mm grid")
    return out


def _config_dict(base: dict, conf: DesignConfiguration) -> dict:
    import copy

    from posekit.seam.frontend.compare import resize_sensors

    data = resize_sensors(copy.deepcopy(base), conf.sensors)
    data["cell"]["sensors"].update({"distances_mm": list(conf.distances_mm) or None, "mounts": None,
                                    "angle": bool(conf.angle)})
    return data


def design_task(task: dict) -> dict:
    """One episode of one configuration (top level, picklable): squared-error sums per axis.

    ``task``: ``config`` (a configuration dict), ``seed``, ``index``. Returns ``{"index",
    "status", "sse" (6,), "kin_sse" (6,), "steps", "error"}`` with rotations in rad²; a failure
    is recorded (``status='error'``), never raised.
    """
    from posekit.seam.frontend.config import config_from_dict
    from posekit.seam.frontend.episode import run_episode

    try:
        cfg = config_from_dict(task["config"], f"design configuration {task['index']}")
        r = run_episode(cfg, int(task["seed"]))
        e = np.asarray(r.error, dtype=np.float64)  # mm, rad
        k = np.asarray(r.kinematic_error, dtype=np.float64)
        return {"index": task["index"], "status": "ok", "sse": (e ** 2).sum(axis=0).tolist(),
                "kin_sse": (k ** 2).sum(axis=0).tolist(), "steps": int(e.shape[0]), "error": ""}
    except Exception as exc:  # noqa: BLE001 -- recorded in the configuration's row (never drop an item)
        text = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        if not isinstance(exc, PosekitError):
            text = f"{type(exc).__name__}: {text}"
        return {"index": task["index"], "status": "error", "sse": [math.nan] * 6, "kin_sse": [math.nan] * 6,
                "steps": 0, "error": text}


@dataclass
class SensorDesign:
    """Result of :func:`sensor_design`.

    Attributes
    ----------
    configurations : list of DesignConfiguration
    rmse : ndarray, shape (C, 6)
        Pooled RMSE of every configuration over its runs: x, y, z (mm), rx, ry, rz (rad).
    kinematic_rmse : ndarray, shape (6,)
        The kinematics-only RMSE (the same for every configuration: the same episodes).
    score : ndarray, shape (C,)
        ``‖rmse_t‖ + lever_mm ‖rmse_r‖`` (mm); NaN for a failed configuration.
    order : ndarray of int, shape (C,)
        Configuration indices, best first.
    status, messages : list of str
    runs, seed : int
    lever_mm : float
    trajectory : str
    wall_s : float
    """

    configurations: list
    rmse: np.ndarray
    kinematic_rmse: np.ndarray
    score: np.ndarray
    order: np.ndarray
    status: list
    messages: list
    runs: int
    seed: int
    lever_mm: float
    trajectory: str
    wall_s: float

    def rows(self) -> list[dict]:
        """``ranking.csv`` rows, best first (:data:`RANKING_COLUMNS`; rotations in degrees)."""
        kin_score = _score(self.kinematic_rmse[None], self.lever_mm)[0]
        out = []
        for rank, i in enumerate(self.order, start=1):
            c = self.configurations[i]
            row = {"sensors": c.sensors, "distances_mm": ";".join(f"{d:g}" for d in c.distances_mm),
                   "score": float(self.score[i]), "rank": rank, "angle": int(c.angle),
                   "kinematic_score": float(kin_score), "runs": self.runs, "status": self.status[i],
                   "error": self.messages[i]}
            for j, a in enumerate(_AXES):
                v = self.rmse[i, j]
                row[f"rmse_{a}_{'mm' if j < 3 else 'deg'}"] = float(v if j < 3 else math.degrees(v))
            out.append(row)
        return out


def _score(rmse: np.ndarray, lever_mm: float) -> np.ndarray:
    return np.linalg.norm(rmse[:, :3], axis=1) + lever_mm * np.linalg.norm(rmse[:, 3:], axis=1)


def sensor_design(config, *, counts: Sequence[int] = (0, 1, 2), distances_mm: Sequence[float] = (20.0, 40.0, 60.0),
                  angle: str = "off", runs: int = 3, seed: int = 0, lever_mm: float = DEFAULT_LEVER_MM,
                  scheduler=None, n_workers: int | None = None, progress: bool | None = None) -> SensorDesign:
    """Simulate every sensor configuration on the configured seam and rank them.

    Parameters
    ----------
    config : SeamConfig
        The user's cell: robot, trajectory (the seam), process, filter; its ``sensors`` section
        gives the noise, range and dropout of every sensor (count and distances are the design's).
    counts, distances_mm, angle
        See :func:`design_configurations`.
    runs : int
        Episodes per configuration (the same seeds for all, from ``seed``).
    lever_mm : float
        Lever arm of the score (mm), > 0.
    scheduler, n_workers, progress
        :func:`posekit.sweep.run_tasks` (None: a local Dask cluster; 'serial'; ``tcp://HOST:PORT``).

    Returns
    -------
    SensorDesign
    """
    if int(runs) < 1:
        raise ConfigError(f"--runs: expected an integer >= 1, got {runs}")
    if not (math.isfinite(lever_mm) and lever_mm > 0.0):
        raise ConfigError(f"--lever-mm: expected a positive number of mm, got {lever_mm}")
    confs = design_configurations(counts, distances_mm, angle)
    base = config.model_dump(mode="json")
    base["profile"] = config.profile.model_dump(mode="json", exclude_none=True)
    from posekit.seam.frontend.config import config_from_dict

    for i, c in enumerate(confs):   # an impossible configuration is the user's error: say so before any work
        config_from_dict(_config_dict(base, c), f"design configuration '{c.label}'")
    seeds = episode_seeds(int(seed), int(runs))
    tasks = [{"index": i, "config": _config_dict(base, c), "seed": s} for i, c in enumerate(confs) for s in seeds]
    t0 = time.perf_counter()
    out = run_tasks(design_task, tasks, scheduler=scheduler, n_workers=n_workers, progress=progress,
                    desc="seam design")
    wall = time.perf_counter() - t0
    C = len(confs)
    sse = np.zeros((C, 6))
    kin_sse = np.zeros((C, 6))
    steps = np.zeros(C)
    status, messages = ["ok"] * C, [""] * C
    for r in out:
        i = r["index"]
        if r["status"] != "ok":
            status[i], messages[i] = "error", messages[i] or r["error"]
            continue
        sse[i] += r["sse"]
        kin_sse[i] += r["kin_sse"]
        steps[i] += r["steps"]
    ok = np.flatnonzero(np.array(status) == "ok")
    # the kinematics-only pose does not see the sensors: the same episodes give the same errors
    kin, kin_steps = (kin_sse[ok[0]], steps[ok[0]]) if ok.size else (np.full(6, np.nan), 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        rmse = np.sqrt(sse / steps[:, None])
        kinematic = np.sqrt(kin / kin_steps) if kin_steps else np.full(6, np.nan)
    rmse[np.array(status) != "ok"] = np.nan
    score = _score(rmse, lever_mm)
    order = np.argsort(np.where(np.isfinite(score), score, np.inf), kind="stable")
    return SensorDesign(confs, rmse, kinematic, score, order, status, messages, int(runs), int(seed),
                        float(lever_mm), config.trajectory.kind, wall)


def write_design(design: SensorDesign, out) -> dict:
    """Write ``ranking.csv``, ``ranking.png`` (the figure) and ``report.html`` into ``out``;
    returns their paths by name."""
    import html
    from pathlib import Path

    from posekit.seam.frontend.plots import plot_design_ranking
    from posekit.seam.frontend.report import html_figure, html_table, write_csv, write_html

    out = Path(out)
    rows = design.rows()
    paths = {"ranking.csv": write_csv(out / "ranking.csv", rows, RANKING_COLUMNS)}
    fig = plot_design_ranking(rows, out / "ranking.png",
                              title=f"Sensor configurations on the {design.trajectory} seam "
                                    f"({design.runs} runs each; lower is better)")
    paths["ranking.png"] = fig
    best = rows[0]
    intro = (f"<p>{len(rows)} configurations × {design.runs} episodes (seed {design.seed}), {design.wall_s:.1f} s. "
             f"Score = ‖RMSE translation‖ + {design.lever_mm:g} mm × ‖RMSE rotation (rad)‖. Best: "
             f"{html.escape(design.configurations[design.order[0]].label)} (score {best['score']:.3f} mm).</p>")
    cols = ["rank", "sensors", "distances_mm", "angle", *RANKING_COLUMNS[2:9]]
    paths["report.html"] = write_html(out, "Seam tracking: sensor-placement design", intro,
                                      [("Ranking", html_figure(fig, "score of each configuration")),
                                       ("Table", html_table(rows, cols))])
    return paths
