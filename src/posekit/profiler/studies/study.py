"""Design studies of the paper's §III by simulation: Table I (corner count), and what every study shares.

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
distance of the measured corners, mapped into G, from their ridges), a residual, in µm.
Beside it, the paper's own Table I metric, eq. (17) (:func:`ridge_direction_error`): the
difference between a ridge's direction ``s = [u, 1, w]`` and the direction ``ŝ`` from the
ridge's point ``q`` to the estimated corner, both with unit y-component. It is
dimensionless — the corner's offset from its ridge, in the plane y = const of G, divided by
its distance |y - y_q| along the ridge from q — and is reported × 10³ (µm per mm; the
paper's Table I calls its numbers µm). It depends on where q sits on the ridge: with q in
the plane the laser sweeps it divides by |y| → 0. Table I takes q at the end of the block
(y = y_min of the gauge's extent, G's origin at an end face as a drawing often has it); the
diagnostics also give it with q at y = 0 of the gauge file (mid-block). For the closed
form the corners study also solves each profile with F's origin moved along z to the
stand-off depth (the ``standoff_*`` samples: the closed form is not invariant to where F's
origin is); :attr:`CornersStudy.gap` and :mod:`~posekit.profiler.studies.study_report` explain the
closed-form gap to the paper with these numbers.
The simulated sensor is mounted the normal way round, so the studies solve with
``mounting='normal'`` by default ('auto' also tries the reversed corner order, as the
CLI does, at a cost).
Figures and report: :mod:`posekit.profiler.studies.study_report`. Fig. 3: :mod:`.study_noise`; Fig. 4:
:mod:`.study_limits`.
"""

import time
from dataclasses import dataclass, field

import numpy as np

from ...errors import ConfigError, EstimationError, ProfileError
from ...sweep import run_tasks, task_seed
from ..estimate.closed_form import closed_form
from ..estimate.corners import detect_corners
from ..estimate.solve import solve_pose
from ..gauge.design import random_gauge
from ..gauge.model import MOUNTINGS
from ..sensor import LJ_X8400, NoiseModel
from ..sim.poses import Workspace, sample_poses
from ..sim.render import render_profiles
from .evaluate import pose_errors

__all__ = ["CornersConfig", "CornersStudy", "corners_study", "study_gauge", "estimate_profiles", "ridge_direction_error",
           "check_ints", "check_common", "summary_row", "merge_failures", "FAIL_UM", "METHODS", "TABLE1_COLUMNS",
           "PAPER_TABLE1", "PAPER_TABLE1_M", "GAP_COLUMNS"]

#: The estimators compared: closed form (CF) and refined (CF-Opt).
METHODS = ("cf", "mle")
#: An estimate whose translation or reprojection error exceeds this (µm) counts as a failure.
FAIL_UM = 1e3
#: Status codes of one profile and method.
OK, DETECTION, ESTIMATION, DIVERGED = 0, 1, 2, 3
STATUS_NAMES = {DETECTION: "corner detection failed", ESTIMATION: "estimator failed",
                DIVERGED: f"error > {FAIL_UM:g} µm"}

TABLE1_COLUMNS = ("n", "m", "method", "reproj_mean_um", "reproj_std_um", "eq17_mean_um_per_mm",
                  "eq17_std_um_per_mm", "t_err_mean_um", "rot_err_mean_deg", "failures")
#: The closed-form gap to the paper, per n (over all gauges): see :attr:`CornersStudy.gap`.
GAP_COLUMNS = ("n", "paper_cf", "reproj_mean_um", "reproj_std_um", "eq17_mean_um_per_mm", "eq17_std_um_per_mm",
               "eq17_mid_median_um_per_mm", "eq17_mid_mean_um_per_mm", "eq17_mid_std_um_per_mm",
               "standoff_reproj_mean_um", "standoff_reproj_std_um", "standoff_eq17_mean_um_per_mm",
               "standoff_eq17_std_um_per_mm", "t_err_mean_um", "standoff_t_err_mean_um", "corner_std_um")
#: The paper's Table I, "mean/std" of its reprojection error, eq. (17) ('-' failure, '*' < 1).
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


def check_ints(values, name, minimum):
    out = tuple(int(v) for v in np.atleast_1d(values))
    if not out or min(out) < minimum:
        raise ConfigError(f"{name}: expected integers >= {minimum}, got {list(out)}")
    return out


def check_common(poses, seed, beta_min_deg, mounting):
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
        object.__setattr__(self, "corners", check_ints(self.corners, "corners", 4))
        object.__setattr__(self, "gauges", check_ints(self.gauges, "gauges", 1))
        check_common(self.poses, self.seed, self.beta_min_deg, self.mounting)


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


def ridge_direction_error(T_G_F, corners_F, gauge, y_q=0.0):
    """The paper's eq. (17): ``‖s - ŝ‖`` per corner, dimensionless.

    ``ŝ = (T_G_F p - q) / (T_G_F p - q)_y`` is the direction from ridge k's point ``q`` (at
    ``y = y_q`` on the ridge) to corner k mapped into G, and ``s = [u, 1, w]`` the ridge's
    direction, both with unit y-component: the corner's offset from its ridge in the plane
    y = const, divided by its distance along y from q.

    Parameters
    ----------
    T_G_F : array_like, shape (..., 4, 4)
        Estimated poses, mm.
    corners_F : array_like, shape (..., n, 2)
        Measured corners (x, z) in F, mm, in ridge order.
    gauge : Gauge
    y_q : float
        y of the ridges' points q in G, mm (the paper's ``q_y = 0`` in its frame).

    Returns
    -------
    ndarray, shape (..., n)
        Dimensionless (× 10³: µm of offset per mm along the ridge); inf or NaN for a corner
        in the plane y = y_q.

    Examples
    --------
    >>> from posekit.profiler import bundled_gauge
    >>> g = bundled_gauge("demo-5")
    >>> T = np.eye(4); T[1, 3] = 5.0                        # laser plane y = 5 mm of G
    >>> p = g.ridge_q + 5.0 * g.ridge_s                     # the ridges' points there, in F (x, z)
    >>> c = p[:, [0, 2]] - T[[0, 2], 3]
    >>> c[0, 0] += 0.01                                     # corner 0 off by 10 µm along x
    >>> np.round(ridge_direction_error(T, c, g) * 1e3, 6).tolist()      # 10 µm / 5 mm
    [2.0, 0.0, 0.0, 0.0, 0.0]
    """
    T = np.asarray(T_G_F, dtype=np.float64)
    c = np.asarray(corners_F, dtype=np.float64)
    p = (T[..., None, :3, 0] * c[..., :, 0:1] + T[..., None, :3, 2] * c[..., :, 1:2] + T[..., None, :3, 3])
    v = p - (gauge.ridge_q + y_q * gauge.ridge_s)
    with np.errstate(divide="ignore", invalid="ignore"):
        s_hat = v / v[..., 1:2]
    return np.linalg.norm(gauge.ridge_s - s_hat, axis=-1)


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
        ``reproj_um`` (K, 2); ``eq17`` and ``eq17_mid`` (K, 2): eq. (17) × 10³ (µm per mm),
        mean over the corners, with q at the block's end and at y = 0;
        ``err`` (K, 2, 6) pose errors ``[mm, rad]`` in G;
        ``std`` (K, 6) the mle's predicted standard deviations ``[mm, rad]``; and
        ``examples``: {(method, status): first message}.
    """
    K = len(Ts_G_F)
    status = np.zeros((K, 2), np.int8)
    reproj = np.full((K, 2), np.nan)
    eq17 = np.full((K, 2, 2), np.nan)
    T_est = np.tile(np.eye(4), (K, 2, 1, 1))
    std = np.full((K, 6), np.nan)
    examples = {}
    for k in range(K):
        try:
            corners = detect_corners(profiles[k], gauge)
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
            pts = corners.points[::-1] if est.reversed else corners.points
            for i, y_q in enumerate((gauge.y_range[0], 0.0)):
                eq17[k, j, i] = ridge_direction_error(est.T_G_F, pts, gauge, y_q).mean() * 1e3
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
    return {"status": status, "reproj_um": reproj, "eq17": eq17[..., 0], "eq17_mid": eq17[..., 1], "err": err,
            "std": std, "examples": examples}


def summary_row(status, reproj, err, eq17):
    """One table row's statistics over profiles (any leading shape) of one method: means
    over every estimate returned, failures = no estimate + estimates beyond FAIL_UM."""
    ok = np.isin(status, (OK, DIVERGED))
    t_err = np.linalg.norm(err[..., :3], axis=-1)[ok] * 1e3
    rot = np.degrees(np.linalg.norm(err[..., 3:], axis=-1))[ok]
    r = reproj[ok]
    e = eq17[ok]
    e = e[np.isfinite(e)]                   # inf: a corner exactly at q (eq. 17 divides by its distance)
    nan = float("nan")
    return {"reproj_mean_um": float(r.mean()) if r.size else nan,
            "reproj_std_um": float(r.std()) if r.size else nan,
            "eq17_mean_um_per_mm": float(e.mean()) if e.size else nan,
            "eq17_std_um_per_mm": float(e.std()) if e.size else nan,
            "t_err_mean_um": float(t_err.mean()) if r.size else nan,
            "rot_err_mean_deg": float(rot.mean()) if r.size else nan,
            "failures": int(np.sum(status != OK))}


def merge_failures(parts):
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
    gap : list of dict
        Per n, the closed form over all gauges, keys :data:`GAP_COLUMNS`: the paper's CF
        cell (largest m), our reprojection error (µm), eq. (17) × 10³ with q at the block's
        end and at y = 0 (median, mean, std: heavy-tailed), the same with F's origin moved
        to the stand-off depth (``standoff_*``), the mean true translation error of both, and
        the corners' mean standard deviation (µm, from the line fits).
    """

    config: CornersConfig
    table: list
    diagnostics: list
    samples: dict = field(repr=False)
    failures: dict
    wall_s: float
    task_cpu_s: float
    gap: list = field(default_factory=list)


def _corners_task(task):
    cpu0 = time.process_time()
    cfg, n, k = task
    gauge, Ts, rng = study_gauge(n, k, cfg.seed, cfg.poses, beta_min_deg=cfg.beta_min_deg,
                                 workspace=cfg.workspace)
    profiles = render_profiles(gauge, Ts, cfg.noise, rng)
    out = estimate_profiles(gauge, Ts, profiles, cfg.mounting)
    out.update(_cf_standoff(gauge, Ts, profiles, cfg))
    out["beta_deg"] = gauge.beta_deg
    out["skew"] = float(np.ptp(gauge.ridge_s[:, 0]))
    del out["std"]
    out["cpu_s"] = time.process_time() - cpu0
    return out


def _cf_standoff(gauge, Ts, profiles, cfg):
    """The closed form with F's origin moved along z to the stand-off depth (corners z - z0,
    then back): reprojection (µm), eq. (17) × 10³ (q at the block's end) and translation
    error (µm) per profile, and the corners' mean standard deviation (µm); NaN where it fails."""
    z0 = LJ_X8400.z_mid if cfg.workspace.standoff_mm is None else cfg.workspace.standoff_mm
    shift = np.eye(4)
    shift[2, 3] = -z0                                   # T_G_F = T_G_F' @ shift, with F' at depth z0
    out = np.full((len(Ts), 4), np.nan)
    for k in range(len(Ts)):
        try:
            c = detect_corners(profiles[k], gauge)
            T = closed_form(c.points - [0.0, z0], gauge) @ shift
        except (ProfileError, EstimationError):
            continue
        d = np.linalg.norm(np.cross(c.points @ T[:3, [0, 2]].T + T[:3, 3] - gauge.ridge_q, gauge.ridge_s), axis=1)
        out[k] = (1e3 * np.mean(d / np.linalg.norm(gauge.ridge_s, axis=1)),
                  1e3 * ridge_direction_error(T, c.points, gauge, gauge.y_range[0]).mean(),
                  1e3 * np.linalg.norm(Ts[k, :3, 3] - T[:3, 3]), 1e3 * np.sqrt(np.mean(np.diag(c.cov))))
    return {"standoff_reproj_um": out[:, 0], "standoff_eq17": out[:, 1], "standoff_t_err_um": out[:, 2],
            "corner_std_um": out[:, 3]}


def _gap(samples, m):
    """The closed-form rows of :attr:`CornersStudy.gap` over the first m gauges."""
    j = METHODS.index("cf")
    rows = []
    for n, s in samples.items():
        got = np.isin(s["status"][:m, :, j], (OK, DIVERGED))

        def stats(a):
            a = a[got]
            a = a[np.isfinite(a)]
            return (float(np.mean(a)), float(np.std(a)), float(np.median(a))) if a.size else (np.nan,) * 3

        r, e17, mid, sr, se = (stats(s[key][:m, :, j] if s[key].ndim == 3 else s[key][:m])
                               for key in ("reproj_um", "eq17", "eq17_mid", "standoff_reproj_um", "standoff_eq17"))
        t = stats(np.linalg.norm(s["err"][:m, :, j, :3], axis=-1) * 1e3)
        st = stats(s["standoff_t_err_um"][:m])
        paper = PAPER_TABLE1.get(("cf", n), ("",) * len(PAPER_TABLE1_M))[-1]
        rows.append({"n": n, "paper_cf": paper, "reproj_mean_um": r[0], "reproj_std_um": r[1],
                     "eq17_mean_um_per_mm": e17[0], "eq17_std_um_per_mm": e17[1],
                     "eq17_mid_median_um_per_mm": mid[2], "eq17_mid_mean_um_per_mm": mid[0],
                     "eq17_mid_std_um_per_mm": mid[1], "standoff_reproj_mean_um": sr[0],
                     "standoff_reproj_std_um": sr[1], "standoff_eq17_mean_um_per_mm": se[0],
                     "standoff_eq17_std_um_per_mm": se[1], "t_err_mean_um": t[0], "standoff_t_err_mean_um": st[0],
                     "corner_std_um": stats(s["corner_std_um"][:m])[0]})
    return rows


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
                      for key in ("status", "reproj_um", "eq17", "eq17_mid", "err", "beta_deg", "skew",
                                  "standoff_reproj_um", "standoff_eq17", "standoff_t_err_um", "corner_std_um")}
    table = []
    for j, method in enumerate(METHODS):
        for n in config.corners:
            s = samples[n]
            for m in config.gauges:
                row = {"n": n, "m": m, "method": method}
                row.update(summary_row(s["status"][:m, :, j], s["reproj_um"][:m, :, j], s["err"][:m, :, j],
                                    s["eq17"][:m, :, j]))
                table.append(row)
    return CornersStudy(config=config, table=table, diagnostics=_diagnostics(samples, m_max), samples=samples,
                        failures=merge_failures(results), wall_s=time.perf_counter() - t0,
                        task_cpu_s=sum(r["cpu_s"] for r in results), gap=_gap(samples, m_max))


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
            mid = s["eq17_mid"][:m, :, j][got]
            mid = mid[np.isfinite(mid)]
            rows.append({"n": n, "method": method, "estimates": int(got.sum()),
                         "eq17_mid_median_um_per_mm": float(np.median(mid)) if mid.size else np.nan,
                         "beyond_fail_um": int(np.sum(s["status"][:m, :, j] == DIVERGED)),
                         "t_err_median_um": float(np.median(t)) if t.size else np.nan,
                         "rmse_x_um": float(rmse[0]), "rmse_y_um": float(rmse[1]), "rmse_z_um": float(rmse[2]),
                         "ridge_skew_mean": float(np.mean(s["skew"][:m])),
                         "beta_mean_deg": float(np.mean(s["beta_deg"][:m]))})
    return rows


# --------------------------------------------------------------------------- Fig. 3


