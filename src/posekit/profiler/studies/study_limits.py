"""Fig. 4 by simulation: the range of motion a gauge allows (§III-D).

(a) *Range of motion vs gauge size.* A random gauge is scaled in x and z (its cross-section;
    slopes and β unchanged) to a sweep of widths, or cut to a sweep of lengths along its
    ridges. From the nominal pose the sensor is translated along F's x, z (width sweep)
    or y (length sweep) until the pose is lost; the range is the length of the interval
    around the nominal pose where it is kept, by two criteria: geometric visibility
    (:func:`~posekit.profiler.sim.poses.visible_mask`, 3 mm margins) and actual tracking
    (every corner detected on a rendered, noisy profile and a CF-Opt estimate that fits
    them within :data:`~posekit.profiler.studies.study.FAIL_UM`). The edges are found by a coarse
    scan and bisection.
(b) *Success rate vs tilt α.* Gauges whose steepest faces (one each way) make exactly β
    with the vertical are viewed at a tilt α about F's y axis, pivoting at the gauge,
    with a small random jitter; the rate of tracked poses falls to 0 past α ≈ β (the
    self-occlusion of §III-D; the laser fan's own half-angle of about 14° moves the
    cut-off by up to that much either way, depending on where the steep face sits).

Seeds: gauge k of the width sweep comes from ``[seed, 4001, n, k]``, of the length sweep
from ``[seed, 4002, n, k]``, of tilt β from ``[seed, 4003, round(1000 β), k]``.
"""

import time
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError, GaugeError
from ...sweep import run_tasks, task_seed
from ..gauge.design import random_gauge
from ..gauge.model import Gauge, gauge_from_design
from ..sensor import LJ_X8400, NoiseModel
from ..sim.poses import nominal_pose, visible_mask
from ..sim.render import render_profiles
from .study import DIVERGED, FAIL_UM, METHODS, OK, estimate_profiles

__all__ = ["LimitsConfig", "LimitsStudy", "limits_study", "scaled_gauge", "range_summary", "tilt_summary"]

_TAG_WIDTH, _TAG_LENGTH, _TAG_TILT = 4001, 4002, 4003
_AXES = {"x": 0, "y": 1, "z": 2}


def _floats(values, name, lo=-np.inf, hi=np.inf):
    out = tuple(float(v) for v in np.atleast_1d(values))
    if not out or not all(np.isfinite(v) and lo <= v <= hi for v in out):
        raise ConfigError(f"{name}: expected values in [{lo:g}, {hi:g}], got {list(out)}")
    return out


@dataclass(frozen=True)
class LimitsConfig:
    """Sizes (mm) and angles (deg) of the Fig. 4 simulation."""

    n_corners: int = 5
    gauges: int = 3
    widths_mm: tuple[float, ...] = tuple(float(w) for w in range(40, 261, 20))
    lengths_mm: tuple[float, ...] = tuple(float(v) for v in range(10, 81, 10))
    betas_deg: tuple[float, ...] = (30.0, 45.0, 60.0)
    tilts_deg: tuple[float, ...] = tuple(float(a) for a in np.arange(-75.0, 75.1, 2.5))
    tilt_poses: int = 10
    jitter_mm: tuple[float, float, float] = (5.0, 5.0, 10.0)
    jitter_deg: float = 2.0
    step_mm: float = 5.0
    resolution_mm: float = 0.25
    noise: NoiseModel = NoiseModel()
    seed: int = 0

    def __post_init__(self):
        if int(self.n_corners) < 4 or int(self.gauges) < 1 or int(self.tilt_poses) < 1 or int(self.seed) < 0:
            raise ConfigError(f"limits: expected n_corners >= 4, gauges >= 1, tilt_poses >= 1 and seed >= 0, "
                              f"got {self.n_corners}, {self.gauges}, {self.tilt_poses}, {self.seed}")
        object.__setattr__(self, "widths_mm", _floats(self.widths_mm, "widths_mm", 1.0))
        object.__setattr__(self, "lengths_mm", _floats(self.lengths_mm, "lengths_mm", 1.0))
        object.__setattr__(self, "betas_deg", _floats(self.betas_deg, "betas_deg", 5.0, 85.0))
        object.__setattr__(self, "tilts_deg", _floats(self.tilts_deg, "tilts_deg", -89.0, 89.0))
        if not (0 < self.resolution_mm <= self.step_mm):
            raise ConfigError(f"limits: expected 0 < resolution_mm <= step_mm, got {self.resolution_mm}, "
                              f"{self.step_mm}")


def _design(gauge: Gauge):
    """(ridge_x, slopes_x, ridge_u, height, y_slope0) such that gauge_from_design rebuilds it."""
    nz = gauge.normals[:, 2]
    return (gauge.ridge_q[:, 0], -gauge.normals[:, 0] / nz, gauge.ridge_s[:, 0],
            float(np.mean(gauge.ridge_q[:, 2])), float(-gauge.normals[0, 1] / nz[0]))


def scaled_gauge(gauge: Gauge, width_mm: float | None = None, length_mm: float | None = None,
                 slopes_x=None) -> Gauge:
    """The gauge scaled in x and z to ``width_mm`` (block width), cut to ``length_mm``
    along y (centred), and/or with new face slopes ``dz/dx`` (shape (n + 1,)).

    Scaling x and z by the same factor keeps every slope in the cross-section, so β and
    the gauge's shape are unchanged; only its size differs.
    """
    ridge_x, a, u, height, b0 = _design(gauge)
    x0, x1 = gauge.x_range
    y0, y1 = gauge.y_range
    s = 1.0 if width_mm is None else width_mm / (x1 - x0)
    if length_mm is not None:
        yc = 0.5 * (y0 + y1)
        y0, y1 = yc - 0.5 * length_mm, yc + 0.5 * length_mm
    a = a if slopes_x is None else np.asarray(slopes_x, dtype=np.float64)
    return gauge_from_design(gauge.name, ridge_x * s, a, u * s, height_mm=height * s, y_slope0=b0 * s,
                             extent=((x0 * s, x1 * s), (y0, y1)))


def _tracked(gauge, Ts, noise, rng):
    """Per pose: every corner detected and a CF-Opt estimate that fits them (reprojection
    error <= FAIL_UM), shape (K,) bool. Accuracy is not asked for: a small gauge or a
    shallow one pins y down less well, but it is still in view."""
    profiles = render_profiles(gauge, Ts, noise, rng)
    out = estimate_profiles(gauge, Ts, profiles, mounting="normal")
    j = METHODS.index("mle")
    return np.isin(out["status"][:, j], (OK, DIVERGED)) & (out["reproj_um"][:, j] <= FAIL_UM)


def _shift(T0, axis, d):
    """Poses T0 translated by d (mm, shape (K,)) along F's axis ``axis``."""
    d = np.atleast_1d(np.asarray(d, dtype=np.float64))
    Ts = np.repeat(T0[None], len(d), axis=0)
    Ts[:, :3, 3] += d[:, None] * T0[None, :3, axis]
    return Ts


def _visible_interval(gauge, T0, axis, limit, res):
    d = np.arange(-np.ceil(limit / res), np.ceil(limit / res) + 1) * res
    ok = visible_mask(gauge, _shift(T0, axis, d))
    i0 = len(d) // 2
    if not ok[i0]:
        return np.nan, np.nan
    hi = i0
    while hi + 1 < len(d) and ok[hi + 1]:
        hi += 1
    lo = i0
    while lo > 0 and ok[lo - 1]:
        lo -= 1
    return float(d[lo]), float(d[hi])


def _tracked_edge(gauge, T0, axis, sign, limit, cfg, rng):
    """Farthest offset (mm, signed) still tracked, walking out from 0 then bisecting."""
    good, chunk = 0.0, 8
    while good < limit:
        d = good + cfg.step_mm * np.arange(1, chunk + 1)
        d = d[d <= limit + cfg.step_mm]
        ok = _tracked(gauge, _shift(T0, axis, sign * d), cfg.noise, rng)
        if ok.all():
            good = float(d[-1])
            continue
        bad = float(d[np.argmin(ok)])
        good = float(d[np.argmin(ok) - 1]) if np.argmin(ok) > 0 else good
        while bad - good > cfg.resolution_mm:
            mid = 0.5 * (good + bad)
            if _tracked(gauge, _shift(T0, axis, [sign * mid]), cfg.noise, rng)[0]:
                good = mid
            else:
                bad = mid
        return sign * good
    return sign * good


def _range_task(task):
    cfg, axis, k, i_size = task
    tag = _TAG_LENGTH if axis == "y" else _TAG_WIDTH
    ss_gauge, ss_noise = task_seed(cfg.seed, tag, cfg.n_corners, k).spawn(2)
    if axis == "y":
        size = cfg.lengths_mm[i_size]
        base = random_gauge(cfg.n_corners, np.random.default_rng(ss_gauge), y_half_mm=0.5 * max(cfg.lengths_mm),
                            u_spread=0.1, strict_length=True)
        gauge = scaled_gauge(base, length_mm=size)
        limit = 0.5 * size + 5.0
    else:
        size = cfg.widths_mm[i_size]
        gauge = scaled_gauge(random_gauge(cfg.n_corners, np.random.default_rng(ss_gauge)), width_mm=size)
        limit = LJ_X8400.z_far - LJ_X8400.z_near if axis == "z" else LJ_X8400.half_width(LJ_X8400.z_far)
    rng = np.random.default_rng(ss_noise.spawn(i_size + 1)[-1])
    T0 = nominal_pose(gauge)
    a = _AXES[axis]
    v_lo, v_hi = _visible_interval(gauge, T0, a, limit, cfg.resolution_mm)
    if _tracked(gauge, T0[None], cfg.noise, rng)[0]:
        t_lo = _tracked_edge(gauge, T0, a, -1.0, limit, cfg, rng)
        t_hi = _tracked_edge(gauge, T0, a, 1.0, limit, cfg, rng)
    else:
        t_lo = t_hi = np.nan
    return {"axis": axis, "size_mm": size, "gauge": k,
            "lower_tracked_mm": t_lo, "upper_tracked_mm": t_hi, "range_tracked_mm": np.nan_to_num(t_hi - t_lo),
            "lower_visible_mm": v_lo, "upper_visible_mm": v_hi, "range_visible_mm": np.nan_to_num(v_hi - v_lo)}


def _tilt_gauge(n, beta_deg, rng):
    """A random gauge whose steepest rising and falling faces make exactly β with the vertical."""
    for _ in range(100):
        g = random_gauge(n, rng, beta_min_deg=beta_deg, u_spread=0.05)   # little skew: β set by the x-slopes
        a = _design(g)[1].copy()
        steep = np.tan(np.radians(90.0 - beta_deg))
        a[a > 0] *= steep / a[a > 0].max()
        a[a < 0] *= steep / -a[a < 0].min()
        try:
            return scaled_gauge(g, slopes_x=a)
        except GaugeError:
            continue
    raise ConfigError(f"limits: no gauge with {n} corners and beta = {beta_deg:g} deg in 100 tries")


def _tilt_task(task):
    from scipy.spatial.transform import Rotation  # imported here: only the limits study needs it

    cfg, beta, k = task
    ss_gauge, ss_poses, ss_noise = task_seed(cfg.seed, _TAG_TILT, round(1000 * beta), k).spawn(3)
    gauge = _tilt_gauge(cfg.n_corners, beta, np.random.default_rng(ss_gauge))
    rng = np.random.default_rng(ss_poses)
    T0 = nominal_pose(gauge)
    pivot_F = np.array([0.0, 0.0, LJ_X8400.z_mid])
    pivot_G = T0[:3, :3] @ pivot_F + T0[:3, 3]
    alphas = np.repeat(np.radians(cfg.tilts_deg), cfg.tilt_poses)
    m = alphas.size
    jitter = np.radians(cfg.jitter_deg) * rng.uniform(-1, 1, (m, 3))
    jitter[:, 1] = alphas                                   # tilt about F's y, exactly α
    R = T0[:3, :3] @ Rotation.from_euler("YXZ", jitter[:, [1, 0, 2]]).as_matrix()
    Ts = np.repeat(np.eye(4)[None], m, axis=0)
    Ts[:, :3, :3] = R
    Ts[:, :3, 3] = pivot_G - R @ pivot_F + rng.uniform(-1, 1, (m, 3)) * np.asarray(cfg.jitter_mm)
    tracked = _tracked(gauge, Ts, cfg.noise, np.random.default_rng(ss_noise))
    visible = visible_mask(gauge, Ts)
    shape = (len(cfg.tilts_deg), cfg.tilt_poses)
    return {"beta_deg": beta, "gauge": k, "beta_actual_deg": gauge.beta_deg,
            "tracked": tracked.reshape(shape).sum(axis=1), "visible": visible.reshape(shape).sum(axis=1)}


@dataclass(frozen=True)
class LimitsStudy:
    """Result of :func:`limits_study`.

    Attributes
    ----------
    config : LimitsConfig
    ranges : list of dict
        Per axis (x, z: vs width; y: vs length), size and gauge: the interval of offsets
        along F's axis (mm) where the pose is tracked / visible, and its length.
    tilts : list of dict
        Per β, gauge and tilt α: ``trials``, ``tracked``, ``visible`` counts.
    wall_s, task_cpu_s : float
        Wall time of the study and CPU time in its tasks, s.
    """

    config: LimitsConfig
    ranges: list
    tilts: list
    wall_s: float
    task_cpu_s: float


def limits_study(config: LimitsConfig = LimitsConfig(), *, scheduler=None, n_workers=None,
                 progress=None) -> LimitsStudy:
    """Fig. 4 (a) range of motion vs gauge size and (b) success rate vs tilt, by simulation.

    Scheduler arguments as :func:`posekit.sweep.run_tasks`.
    """
    t0 = time.perf_counter()
    range_tasks = [(config, axis, k, i) for axis, sizes in (("x", config.widths_mm), ("z", config.widths_mm),
                                                             ("y", config.lengths_mm))
                   for i in range(len(sizes)) for k in range(config.gauges)]
    tilt_tasks = [(config, beta, k) for beta in config.betas_deg for k in range(config.gauges)]
    out = run_tasks(_limits_task, [("range", t) for t in range_tasks] + [("tilt", t) for t in tilt_tasks],
                    scheduler=scheduler, n_workers=n_workers, progress=progress, desc="limits study")
    ranges = [{k: v for k, v in r.items() if k != "cpu_s"} for r in out[:len(range_tasks)]]
    tilts = []
    for r in out[len(range_tasks):]:
        for i, alpha in enumerate(config.tilts_deg):
            tilts.append({"beta_deg": r["beta_deg"], "alpha_deg": alpha, "gauge": r["gauge"],
                          "beta_actual_deg": r["beta_actual_deg"], "trials": config.tilt_poses,
                          "tracked": int(r["tracked"][i]), "visible": int(r["visible"][i])})
    return LimitsStudy(config=config, ranges=ranges, tilts=tilts, wall_s=time.perf_counter() - t0,
                       task_cpu_s=sum(r["cpu_s"] for r in out))


def _limits_task(task):
    cpu0 = time.process_time()
    kind, t = task
    out = _range_task(t) if kind == "range" else _tilt_task(t)
    out["cpu_s"] = time.process_time() - cpu0
    return out


def range_summary(study: LimitsStudy) -> list:
    """Mean, min and max range over gauges per axis and size, with the paper's margin model
    for x (measuring width at the stand-off depth minus the gauge width, mm)."""
    rows = []
    keys = sorted({(r["axis"], r["size_mm"]) for r in study.ranges}, key=lambda k: ("xzy".index(k[0]), k[1]))
    for axis, size in keys:
        sel = [r for r in study.ranges if r["axis"] == axis and r["size_mm"] == size]
        tr = np.array([r["range_tracked_mm"] for r in sel])
        vi = np.array([r["range_visible_mm"] for r in sel])
        margin = 2 * LJ_X8400.half_width(LJ_X8400.z_mid) - size if axis == "x" else np.nan
        rows.append({"axis": axis, "size_mm": size, "range_tracked_mean_mm": float(tr.mean()),
                     "range_tracked_min_mm": float(tr.min()), "range_tracked_max_mm": float(tr.max()),
                     "range_visible_mean_mm": float(vi.mean()), "margin_model_mm": float(max(margin, 0.0))
                     if axis == "x" else np.nan})
    return rows


def tilt_summary(study: LimitsStudy) -> list:
    """Success (tracked) and visible rate per β and α, over gauges and jittered poses."""
    rows = []
    for beta in study.config.betas_deg:
        for alpha in study.config.tilts_deg:
            sel = [r for r in study.tilts if r["beta_deg"] == beta and r["alpha_deg"] == alpha]
            trials = sum(r["trials"] for r in sel)
            rows.append({"beta_deg": beta, "alpha_deg": alpha, "trials": trials,
                         "success_rate": sum(r["tracked"] for r in sel) / trials,
                         "visible_rate": sum(r["visible"] for r in sel) / trials})
    return rows
