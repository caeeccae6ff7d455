"""Fig. 3 by simulation: the reprojection error of CF and CF-Opt against the noise level, and
the predicted against the empirical translation error of CF-Opt (§III).

Same gauges, poses and noise draws as :func:`~posekit.profiler.studies.study.corners_study`
(gauge k from the seed sequence ``[seed, n, k]``): the study's 5 µm row is Table I's. Each level
σ scales the same standard-normal draws, so the levels differ by the noise alone.
"""

import time
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError
from ...sweep import run_tasks
from ..sensor import X_PER_Z, NoiseModel
from ..sim.poses import Workspace
from ..sim.render import render_profiles
from .study import (
    DIVERGED,
    METHODS,
    OK,
    check_common,
    check_ints,
    estimate_profiles,
    merge_failures,
    study_gauge,
    summary_row,
)

__all__ = ["NoiseConfig", "NoiseStudy", "noise_study"]


@dataclass(frozen=True)
class NoiseConfig:
    """Fig. 3: one corner count, ``gauges`` × ``poses`` at each noise level (z; x = ``x_ratio`` × z)."""

    noise_um: tuple[float, ...] = tuple(float(v) for v in range(0, 50, 5))
    n_corners: int = 5
    gauges: int = 150
    poses: int = 100
    x_ratio: float = X_PER_Z
    seed: int = 0
    workspace: Workspace = Workspace()
    beta_min_deg: float = 50.0
    mounting: str = "normal"

    def __post_init__(self):
        levels = tuple(float(v) for v in np.atleast_1d(self.noise_um))
        if not levels or not all(np.isfinite(v) and v >= 0 for v in levels):
            raise ConfigError(f"noise_um: expected noise levels >= 0 µm, got {list(levels)}")
        object.__setattr__(self, "noise_um", levels)
        check_ints(self.n_corners, "n_corners", 4)
        check_ints(self.gauges, "gauges", 1)
        if not (np.isfinite(self.x_ratio) and self.x_ratio >= 0):
            raise ConfigError(f"x_ratio: expected a number >= 0, got {self.x_ratio}")
        check_common(self.poses, self.seed, self.beta_min_deg, self.mounting)


@dataclass(frozen=True)
class NoiseStudy:
    """Result of :func:`noise_study`.

    Attributes
    ----------
    config : NoiseConfig
    table : list of dict
        Per noise level and method: ``noise_um``, ``method`` and the statistics of
        :data:`TABLE1_COLUMNS` (reprojection mean/std, mean pose errors, failures).
    covariance : list of dict
        Per noise level and axis x, y, z of G (mle only, over every estimate returned, also
        those beyond :data:`FAIL_UM`): ``predicted_std_um`` (RMS of the estimator's own
        std), ``empirical_rmse_um`` (RMSE of the translation error) and ``normalized_rms``
        (RMS of error / predicted std; 1 when the covariance is right).
    failures : dict
        ``{(method, status): (count, example message)}``.
    wall_s, task_cpu_s : float
        Wall time of the study and CPU time in its tasks, s.
    """

    config: NoiseConfig
    table: list
    covariance: list
    failures: dict
    wall_s: float
    task_cpu_s: float


def _noise_task(task):
    cpu0 = time.process_time()
    cfg, k = task
    gauge, Ts, rng = study_gauge(cfg.n_corners, k, cfg.seed, cfg.poses, beta_min_deg=cfg.beta_min_deg,
                                 workspace=cfg.workspace)
    clean = render_profiles(gauge, Ts, NoiseModel(0.0, 0.0), 0)
    # The draws of render_profiles (x, then z): level σ adds σ·Z, bit for bit its noise.
    zx = rng.standard_normal(clean.shape[:2])
    zz = rng.standard_normal(clean.shape[:2])
    parts = []
    for level in cfg.noise_um:
        profiles = clean.copy()
        profiles[..., 0] += (cfg.x_ratio * level * 1e-3) * zx
        profiles[..., 1] += (level * 1e-3) * zz
        parts.append(estimate_profiles(gauge, Ts, profiles, cfg.mounting))
    out = {key: np.stack([p[key] for p in parts]) for key in ("status", "reproj_um", "eq17", "err", "std")}
    out["examples"] = {}
    for p in parts:
        for key, msg in p["examples"].items():
            out["examples"].setdefault(key, msg)
    out["cpu_s"] = time.process_time() - cpu0
    return out


def noise_study(config: NoiseConfig = NoiseConfig(), *, scheduler=None, n_workers=None,
                progress=None) -> NoiseStudy:
    """Fig. 3: reprojection error vs noise for CF and CF-Opt, and the predicted vs
    empirical translation error of CF-Opt. ``gauges`` tasks, each with every noise level.
    Scheduler arguments as :func:`posekit.sweep.run_tasks`.
    """
    t0 = time.perf_counter()
    tasks = [(config, k) for k in range(config.gauges)]
    results = run_tasks(_noise_task, tasks, scheduler=scheduler, n_workers=n_workers, progress=progress,
                        desc="noise study")
    # (gauges, levels, poses, ...) -> (levels, gauges * poses, ...)
    data = {key: np.concatenate([r[key] for r in results], axis=1)
            for key in ("status", "reproj_um", "eq17", "err", "std")}
    table, cov = [], []
    j_mle = METHODS.index("mle")
    for i, level in enumerate(config.noise_um):
        for j, method in enumerate(METHODS):
            row = {"noise_um": level, "method": method}
            row.update(summary_row(data["status"][i, :, j], data["reproj_um"][i, :, j], data["err"][i, :, j],
                                data["eq17"][i, :, j]))
            table.append(row)
        ok = np.isin(data["status"][i, :, j_mle], (OK, DIVERGED))       # no censoring of large errors
        err = data["err"][i, ok, j_mle, :3]
        std = data["std"][i, ok, :3]
        for a, axis in enumerate("xyz"):
            with np.errstate(divide="ignore", invalid="ignore"):
                z = err[:, a] / std[:, a]
            cov.append({"noise_um": level, "axis": axis,
                        "predicted_std_um": float(np.sqrt(np.mean(std[:, a] ** 2)) * 1e3) if ok.any() else np.nan,
                        "empirical_rmse_um": float(np.sqrt(np.mean(err[:, a] ** 2)) * 1e3) if ok.any() else np.nan,
                        "normalized_rms": float(np.sqrt(np.mean(z**2))) if level > 0 and ok.any() else np.nan})
    return NoiseStudy(config=config, table=table, covariance=cov, failures=merge_failures(results),
                      wall_s=time.perf_counter() - t0, task_cpu_s=sum(r["cpu_s"] for r in results))
