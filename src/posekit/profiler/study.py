"""Design studies of the paper's §III by simulation: Table I (corner count) and Fig. 3 (noise).

Each study is a list of tasks run through :func:`posekit.sweep.run_tasks`; one task is one
random gauge with all of its poses and both estimators (``cf``: the closed form,
eq. 9–14; ``mle``: the refined CF-Opt). Gauge k of a study with n corners comes from the
seed sequence ``[seed, n, k]`` (:func:`posekit.sweep.task_seed`), split into the gauge's
shape, its poses and its noise, so:

- the same seed gives the same numbers on any number of workers;
- the m-gauge subsets of Table I are nested (the first m of ``max(m)`` gauges);
- the noise study draws the same gauges, poses and standard-normal noise as the corners
  study and scales the noise per level, so its 5 µm row equals Table I's n = 5 row and
  its curves are smooth (common random numbers).

A profile *fails* when its corners cannot be detected, the estimator raises, or the
estimate is off by more than :data:`FAIL_UM` (translation error or reprojection error;
the paper's '-' in Table I). The statistics are over every estimate returned, those
beyond :data:`FAIL_UM` included: leaving them out would censor the errors (at 45 µm of
noise most CF estimates and, along the weakly observed y, many CF-Opt ones exceed it).
The reprojection error is the estimator's own (:attr:`PoseEstimate.reprojection_um`: mean
distance of the measured corners, mapped into G, from their ridges), a residual.
The simulated sensor is mounted the normal way round, so the studies solve with
``mounting='normal'`` by default ('auto' also tries the reversed corner order, as the
CLI does, at a cost).
Figures and report: :mod:`posekit.profiler.study_report`. Fig. 4: :mod:`.study_limits`.
"""

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, EstimationError, ProfileError
from ..sweep import run_tasks, task_seed
from .corners import detect_corners
from .design import random_gauge
from .evaluate import pose_errors
from .sensor import LJ_X8400, NoiseModel, Workspace, render_profiles, sample_poses
from .solve import MOUNTINGS, solve_pose

__all__ = ["CornersConfig", "CornersStudy", "NoiseConfig", "NoiseStudy", "corners_study", "noise_study",
           "study_gauge", "estimate_profiles", "FAIL_UM", "METHODS", "TABLE1_COLUMNS", "PAPER_TABLE1",
           "PAPER_TABLE1_M"]

#: The estimators compared: closed form (CF) and refined (CF-Opt).
METHODS = ("cf", "mle")
#: An estimate whose translation or reprojection error exceeds this (µm) counts as a failure.
FAIL_UM = 1e3
#: Status codes of one profile and method.
OK, DETECTION, ESTIMATION, DIVERGED = 0, 1, 2, 3
STATUS_NAMES = {DETECTION: "corner detection failed", ESTIMATION: "estimator failed",
                DIVERGED: f"error > {FAIL_UM:g} µm"}

TABLE1_COLUMNS = ("n", "m", "method", "reproj_mean_um", "reproj_std_um", "t_err_mean_um", "rot_err_mean_deg",
                  "failures")
#: The paper's Table I, "mean/std" of the reprojection error in µm ('-' failure, '*' < 1 µm).
PAPER_TABLE1_M = (10, 50, 100, 150)
PAPER_TABLE1 = {
    ("cf", 4): ("-/-", "-/-", "-/-", "-/-"),
    ("cf", 5): ("10/10", "10/11", "9/9", "10/10"),
    ("cf", 7): ("3/2", "4/3", "3/2", "4/3"),
    ("cf", 10): ("3/1", "2/1", "2/1", "2/1"),
    ("mle", 4): ("1/*", "1/*", "1/*", "1/*"),
    ("mle", 5): ("*/*", "*/*", "*/*", "*/*"),
    ("mle", 7): ("*/*", "1/*", "1/*", "1/*"),
    ("mle", 10): ("1/*", "1/*", "1/*", "1/*"),
}


def _ints(values, name, minimum):
    out = tuple(int(v) for v in np.atleast_1d(values))
    if not out or min(out) < minimum:
        raise ConfigError(f"{name}: expected integers >= {minimum}, got {list(out)}")
    return out


def _check_common(poses, seed, beta_min_deg, mounting):
    if int(poses) < 1:
        raise ConfigError(f"poses: expected >= 1 pose per gauge, got {poses}")
    if int(seed) < 0:
        raise ConfigError(f"seed: expected an integer >= 0, got {seed}")
    if not 0 < beta_min_deg < 90:
        raise ConfigError(f"beta_min_deg: expected a value in (0, 90), got {beta_min_deg}")
    if mounting not in MOUNTINGS:
        raise ConfigError(f"mounting: expected one of {', '.join(MOUNTINGS)}, got '{mounting}'")


@dataclass(frozen=True)
class CornersConfig:
    """Table I: ``corners`` × ``gauges`` (m values) × ``poses`` random poses, both methods."""

    corners: tuple[int, ...] = (4, 5, 7, 10)
    gauges: tuple[int, ...] = PAPER_TABLE1_M
    poses: int = 100
    noise: NoiseModel = NoiseModel()
    seed: int = 0
    workspace: Workspace = Workspace()
    beta_min_deg: float = 50.0
    mounting: str = "normal"

    def __post_init__(self):
        object.__setattr__(self, "corners", _ints(self.corners, "corners", 4))
        object.__setattr__(self, "gauges", _ints(self.gauges, "gauges", 1))
        _check_common(self.poses, self.seed, self.beta_min_deg, self.mounting)


@dataclass(frozen=True)
class NoiseConfig:
    """Fig. 3: one corner count, ``gauges`` × ``poses`` at each noise level (z; x = ``x_ratio`` × z)."""

    noise_um: tuple[float, ...] = tuple(float(v) for v in range(0, 50, 5))
    n_corners: int = 5
    gauges: int = 150
    poses: int = 100
    x_ratio: float = 2.0
    seed: int = 0
    workspace: Workspace = Workspace()
    beta_min_deg: float = 50.0
    mounting: str = "normal"

    def __post_init__(self):
        levels = tuple(float(v) for v in np.atleast_1d(self.noise_um))
        if not levels or not all(np.isfinite(v) and v >= 0 for v in levels):
            raise ConfigError(f"noise_um: expected noise levels >= 0 µm, got {list(levels)}")
        object.__setattr__(self, "noise_um", levels)
        _ints(self.n_corners, "n_corners", 4)
        _ints(self.gauges, "gauges", 1)
        if not (np.isfinite(self.x_ratio) and self.x_ratio >= 0):
            raise ConfigError(f"x_ratio: expected a number >= 0, got {self.x_ratio}")
        _check_common(self.poses, self.seed, self.beta_min_deg, self.mounting)


def study_gauge(n_corners: int, k: int, seed: int, poses: int, *, beta_min_deg=50.0,
                workspace: Workspace = Workspace(), model=LJ_X8400):
    """Gauge k of a study: the gauge, its poses and its noise generator, from ``[seed, n, k]``.

    Returns
    -------
    gauge : Gauge
    Ts_G_F : ndarray, shape (poses, 4, 4)
        Poses of the profiler in the gauge frame, mm.
    noise_rng : numpy.random.Generator
        The generator of the profiles' noise.
    """
    ss_gauge, ss_poses, ss_noise = task_seed(seed, n_corners, k).spawn(3)
    gauge = random_gauge(n_corners, np.random.default_rng(ss_gauge), beta_min_deg=beta_min_deg, model=model)
    Ts = sample_poses(gauge, poses, np.random.default_rng(ss_poses), workspace, model)
    return gauge, Ts, np.random.default_rng(ss_noise)


def estimate_profiles(gauge, Ts_G_F, profiles, mounting="auto"):
    """Detect, solve by both :data:`METHODS` and score every profile against its true pose.

    Parameters
    ----------
    gauge : Gauge
    Ts_G_F : ndarray, shape (K, 4, 4)
        True poses, mm.
    profiles : ndarray, shape (K, N, 2)
        Profiles (x, z) in F, mm, NaN = no return.
    mounting : str

    Returns
    -------
    dict of ndarray
        ``status`` (K, 2) int8 (0 ok, 1 detection, 2 estimator, 3 error > :data:`FAIL_UM`);
        ``reproj_um`` (K, 2); ``err`` (K, 2, 6) pose errors ``[mm, rad]`` in G;
        ``std`` (K, 6) the mle's predicted standard deviations ``[mm, rad]``; and
        ``examples``: {(method, status): first message}.
    """
    K = len(Ts_G_F)
    status = np.zeros((K, 2), np.int8)
    reproj = np.full((K, 2), np.nan)
    T_est = np.tile(np.eye(4), (K, 2, 1, 1))
    std = np.full((K, 6), np.nan)
    examples = {}
    for k in range(K):
        try:
            corners = detect_corners(profiles[k], gauge.n_corners, gauge_name=gauge.name)
        except ProfileError as exc:
            status[k] = DETECTION
            for method in METHODS:
                examples.setdefault((method, DETECTION), str(exc))
            continue
        for j, method in enumerate(METHODS):
            try:
                est = solve_pose(corners, gauge, method=method, mounting=mounting)
            except EstimationError as exc:
                status[k, j] = ESTIMATION
                examples.setdefault((method, ESTIMATION), str(exc))
                continue
            T_est[k, j] = est.T_G_F
            reproj[k, j] = est.reprojection_um
            if method == "mle":
                std[k] = np.sqrt(np.diag(est.cov))
    err = pose_errors(T_est, Ts_G_F[:, None])
    err[status != OK] = np.nan
    t_err_um = np.linalg.norm(err[..., :3], axis=-1) * 1e3
    diverged = (status == OK) & ~((t_err_um <= FAIL_UM) & (reproj <= FAIL_UM))
    status[diverged] = DIVERGED
    for j, method in enumerate(METHODS):
        for k in np.flatnonzero(diverged[:, j])[:1]:
            examples.setdefault((method, DIVERGED), f"translation error {t_err_um[k, j]:.0f} µm, "
                                                    f"reprojection {reproj[k, j]:.0f} µm")
    return {"status": status, "reproj_um": reproj, "err": err, "std": std, "examples": examples}


def _summary(status, reproj, err):
    """One table row's statistics over profiles (any leading shape) of one method: means
    over every estimate returned, failures = no estimate + estimates beyond FAIL_UM."""
    ok = np.isin(status, (OK, DIVERGED))
    t_err = np.linalg.norm(err[..., :3], axis=-1)[ok] * 1e3
    rot = np.degrees(np.linalg.norm(err[..., 3:], axis=-1))[ok]
    r = reproj[ok]
    nan = float("nan")
    return {"reproj_mean_um": float(r.mean()) if r.size else nan,
            "reproj_std_um": float(r.std()) if r.size else nan,
            "t_err_mean_um": float(t_err.mean()) if r.size else nan,
            "rot_err_mean_deg": float(rot.mean()) if r.size else nan,
            "failures": int(np.sum(status != OK))}


def _merge_examples(parts):
    """{(method, status): [count, first message]} over tasks' results."""
    out = {}
    for part in parts:
        for key, msg in part["examples"].items():
            out.setdefault(key, [0, msg])
        for j, method in enumerate(METHODS):
            codes, counts = np.unique(part["status"][..., j], return_counts=True)
            for code, c in zip(codes, counts):
                if code != OK and (method, int(code)) in out:
                    out[(method, int(code))][0] += int(c)
    return {k: tuple(v) for k, v in sorted(out.items())}


# --------------------------------------------------------------------------- Table I


@dataclass(frozen=True)
class CornersStudy:
    """Result of :func:`corners_study`.

    Attributes
    ----------
    config : CornersConfig
    table : list of dict
        Rows of Table I with keys :data:`TABLE1_COLUMNS`, ordered by method, n, m.
    diagnostics : list of dict
        Per method and n over all gauges: RMSE of the translation error along x, y, z of
        G and the median |error| over every estimate returned (including those beyond
        :data:`FAIL_UM`), with the gauges' mean ridge skew ``ptp(u)`` and β (y is seen
        only through the skew of the ridges).
    samples : dict
        Per n: ``status`` (max m, poses, 2), ``reproj_um`` (…, 2), ``err`` (…, 2, 6),
        and the gauges' ``beta_deg`` and ``skew`` (max m,).
    failures : dict
        ``{(method, status): (count, example message)}``.
    wall_s : float
        Wall time of the study, s.
    task_cpu_s : float
        CPU time spent in the tasks, summed over workers, s.
    """

    config: CornersConfig
    table: list
    diagnostics: list
    samples: dict = field(repr=False)
    failures: dict
    wall_s: float
    task_cpu_s: float


def _corners_task(task):
    cpu0 = time.process_time()
    cfg, n, k = task
    gauge, Ts, rng = study_gauge(n, k, cfg.seed, cfg.poses, beta_min_deg=cfg.beta_min_deg,
                                 workspace=cfg.workspace)
    profiles = render_profiles(gauge, Ts, cfg.noise, rng)
    out = estimate_profiles(gauge, Ts, profiles, cfg.mounting)
    out["beta_deg"] = gauge.beta_deg
    out["skew"] = float(np.ptp(gauge.ridge_s[:, 0]))
    del out["std"]
    out["cpu_s"] = time.process_time() - cpu0
    return out


def corners_study(config: CornersConfig = CornersConfig(), *, scheduler=None, n_workers=None,
                  progress=None) -> CornersStudy:
    """Table I: reprojection and pose errors vs corner count n and gauge count m.

    ``len(corners) × max(gauges) × poses`` profiles in ``len(corners) × max(gauges)``
    tasks; the row for m uses the first m gauges. Scheduler arguments as
    :func:`posekit.sweep.run_tasks`.
    """
    t0 = time.perf_counter()
    m_max = max(config.gauges)
    tasks = [(config, n, k) for n in config.corners for k in range(m_max)]
    results = run_tasks(_corners_task, tasks, scheduler=scheduler, n_workers=n_workers, progress=progress,
                        desc="corners study")
    samples = {}
    for i, n in enumerate(config.corners):
        part = results[i * m_max:(i + 1) * m_max]
        samples[n] = {key: np.stack([p[key] for p in part])
                      for key in ("status", "reproj_um", "err", "beta_deg", "skew")}
    table = []
    for j, method in enumerate(METHODS):
        for n in config.corners:
            s = samples[n]
            for m in config.gauges:
                row = {"n": n, "m": m, "method": method}
                row.update(_summary(s["status"][:m, :, j], s["reproj_um"][:m, :, j], s["err"][:m, :, j]))
                table.append(row)
    return CornersStudy(config=config, table=table, diagnostics=_diagnostics(samples, m_max), samples=samples,
                        failures=_merge_examples(results), wall_s=time.perf_counter() - t0,
                        task_cpu_s=sum(r["cpu_s"] for r in results))


def _diagnostics(samples, m):
    """Per method and n over all m gauges: error per axis and median over every estimate
    returned (also those beyond FAIL_UM), and the gauges' mean ridge skew and β."""
    rows = []
    for j, method in enumerate(METHODS):
        for n, s in samples.items():
            got = np.isin(s["status"][:m, :, j], (OK, DIVERGED))
            e = s["err"][:m, :, j][got]
            rmse = np.sqrt(np.mean(e[:, :3] ** 2, axis=0)) * 1e3 if got.any() else np.full(3, np.nan)
            t = np.linalg.norm(e[:, :3], axis=1) * 1e3
            rows.append({"n": n, "method": method, "estimates": int(got.sum()),
                         "beyond_fail_um": int(np.sum(s["status"][:m, :, j] == DIVERGED)),
                         "t_err_median_um": float(np.median(t)) if t.size else np.nan,
                         "rmse_x_um": float(rmse[0]), "rmse_y_um": float(rmse[1]), "rmse_z_um": float(rmse[2]),
                         "ridge_skew_mean": float(np.mean(s["skew"][:m])),
                         "beta_mean_deg": float(np.mean(s["beta_deg"][:m]))})
    return rows


# --------------------------------------------------------------------------- Fig. 3


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
    out = {key: np.stack([p[key] for p in parts]) for key in ("status", "reproj_um", "err", "std")}
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
    data = {key: np.concatenate([r[key] for r in results], axis=1) for key in ("status", "reproj_um", "err", "std")}
    table, cov = [], []
    j_mle = METHODS.index("mle")
    for i, level in enumerate(config.noise_um):
        for j, method in enumerate(METHODS):
            row = {"noise_um": level, "method": method}
            row.update(_summary(data["status"][i, :, j], data["reproj_um"][i, :, j], data["err"][i, :, j]))
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
    return NoiseStudy(config=config, table=table, covariance=cov, failures=_merge_examples(results),
                      wall_s=time.perf_counter() - t0, task_cpu_s=sum(r["cpu_s"] for r in results))
