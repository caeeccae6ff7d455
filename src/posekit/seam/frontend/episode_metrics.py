"""Pooled accuracy, speed and integrity of simulated episodes: ``metrics.json`` of ``posekit seam
simulate`` and the per-step status columns of ``estimates.csv``.

Errors and spreads are pooled over every step of the episodes; the reported tables show the
rotations in degrees (:func:`~posekit.seam.frontend.seam_frame.to_degrees`).
"""

import numpy as np

from posekit.seam.engine.integrity import STATUSES
from posekit.seam.frontend.episode import EpisodeResult
from posekit.seam.frontend.seam_frame import AXES, to_degrees
from posekit.verdict import status_counts

__all__ = [
    "STATUS_COLUMNS",
    "confident_wrong_fraction",
    "confident_wrong_share",
    "integrity_summary",
    "metrics",
    "status_columns",
]


def _plateau_metrics(results: list[EpisodeResult]) -> dict:
    """``plateau_ratio_max`` and ``outside_plateau_runs`` of :func:`metrics` (none without the ratios)."""
    ratios = [r.plateau_ratio for r in results if r.plateau_ratio is not None and r.plateau_ratio.size]
    if len(ratios) < len(results):
        return {}
    peak = np.array([float(np.max(x)) for x in ratios])
    return {"plateau_ratio_max": float(round(float(peak.max()), 6)),
            "outside_plateau_runs": float(round(float(np.mean(peak > 1.0)), 6))}


def _rmse(errors: np.ndarray) -> np.ndarray:
    return np.sqrt(np.nanmean(errors ** 2, axis=0))


def metrics(results: list[EpisodeResult]) -> dict:
    """Pooled accuracy and speed of episodes: the ``metrics.json`` of ``posekit seam simulate``.

    Returns
    -------
    dict
        ``rmse_mm {x, y, z}``, ``rmse_deg {rx, ry, rz}``, ``kinematic_rmse_mm``,
        ``kinematic_rmse_deg``, ``step_ms_median``, ``step_ms_p95``, ``runs``, ``steps``,
        ``particles``, ``sensors``, ``sensor_distances_mm``, ``trajectory``, ``resampler``,
        ``knots_kept``, ``trend_max_error_mm``, ``recoveries``, ``laser_missing_fraction``,
        ``spread_median_mm``, ``spread_median_deg``; ``status_counts`` ``{tracking, degraded,
        lost}`` (steps over all runs), ``coverage_2sigma`` ``{x, y, z, rx, ry, rz}`` (fraction of
        steps whose absolute error <= 2 × the reported spread) and ``tracking_beyond_3sigma`` (fraction
        of the steps whose error exceeds 3 × the reported spread on some axis that are
        ``tracking``; null when there are none) and ``confident_wrong`` (the fraction of all steps
        that are ``tracking`` and beyond 3 × the spread: :func:`confident_wrong_fraction`);
        ``plateau_ratio_max`` (the largest offset of the truth from the kinematic pose in radii
        of the filter's robot plateau,
        :func:`~posekit.seam.frontend.episode.plateau_ratio`) and ``outside_plateau_runs`` (the
        fraction of runs whose truth leaves the plateau at some step: the filter's ``d0``/``kd``
        do not describe the simulated robot, paper eq. 7).
    """
    if not results:
        from posekit.errors import EstimationError

        raise EstimationError("metrics: expected at least one episode result, got none")
    cfg = results[0].config
    err = to_degrees(_rmse(np.concatenate([r.error for r in results])))  # the metrics.json edge: mm, deg
    kin = to_degrees(_rmse(np.concatenate([r.kinematic_error for r in results])))
    step = np.concatenate([r.step_ms for r in results])
    spread = to_degrees(np.median(np.concatenate([r.spread for r in results]), axis=0))
    laser = np.concatenate([r.laser_mm.reshape(-1, 2) for r in results])
    cov, counts, beyond = integrity_summary(results)

    def fl(v):
        return float(round(float(v), 6))

    return {
        "rmse_mm": {a: fl(v) for a, v in zip(AXES[:3], err[:3])},
        "rmse_deg": {a: fl(v) for a, v in zip(AXES[3:], err[3:])},
        "kinematic_rmse_mm": {a: fl(v) for a, v in zip(AXES[:3], kin[:3])},
        "kinematic_rmse_deg": {a: fl(v) for a, v in zip(AXES[3:], kin[3:])},
        "step_ms_median": fl(np.median(step)),
        "step_ms_p95": fl(np.percentile(step, 95)),
        "runs": len(results),
        "steps": int(results[0].t_s.shape[0]),
        "particles": cfg.filter.particles,
        "sensors": cfg.cell.sensors.count,
        "sensor_distances_mm": list(cfg.cell.sensors.resolved_distances_mm()),
        "trajectory": cfg.trajectory.kind,
        "resampler": cfg.filter.resampler,
        "knots_kept": results[0].knots_kept,
        "trend_max_error_mm": fl(results[0].trend_max_error_mm),
        "recoveries": int(sum(r.recoveries for r in results)),
        "laser_missing_fraction": fl(np.mean(~np.isfinite(laser[:, 0]))) if laser.size else 0.0,
        "spread_median_mm": {a: fl(v) for a, v in zip(AXES[:3], spread[:3])},
        "spread_median_deg": {a: fl(v) for a, v in zip(AXES[3:], spread[3:])},
        "status_counts": counts,
        "coverage_2sigma": {a: fl(v) for a, v in zip(AXES, cov)},
        "tracking_beyond_3sigma": None if beyond is None else fl(beyond),
        "confident_wrong": fl(confident_wrong_fraction(results)),
        **_plateau_metrics(results),
    }


#: Per-step integrity columns of ``estimates.csv`` (DESIGN.md seam contract), after the existing ones.
STATUS_COLUMNS = ("status", "std_x_mm", "std_y_mm", "std_z_mm", "std_rx_deg", "std_ry_deg", "std_rz_deg")


def status_columns(result: EpisodeResult) -> dict:
    """The per-step ``status`` and the six reported spreads of one episode, by column name.

    Returns
    -------
    dict
        :data:`STATUS_COLUMNS` -> array (T,): ``status`` (str: tracking | degraded | lost) and
        ``std_x_mm .. std_rz_deg``, the filter's 1σ per axis (mm, deg) in the estimate's frame
        (the CSV edge: ``EpisodeResult.spread`` converted from rad).
    """
    n = result.t_s.shape[0]
    status = result.status if result.status is not None else np.full(n, "tracking")
    out = {"status": np.asarray(status, dtype=str)}
    for name, col in zip(STATUS_COLUMNS[1:], to_degrees(result.spread).T):
        out[name] = col
    return out


def integrity_summary(results: list[EpisodeResult]) -> tuple[np.ndarray, dict, float | None]:
    """Honesty of the reported spread and verdicts over episodes.

    Returns
    -------
    coverage : ndarray, shape (6,)
        Fraction of steps with ``|error| <= 2 × spread`` per axis (x, y, z, rx, ry, rz).
    status_counts : dict
        ``{"tracking": int, "degraded": int, "lost": int}`` over all steps.
    tracking_beyond_3sigma : float or None
        Of the steps whose error exceeds 3 × the spread on some axis, the fraction reported
        ``tracking`` (the DESIGN "Trust" failure: a confident wrong pose); None if no such step.
    """
    err, spr, status, beyond = _pooled_steps(results)
    with np.errstate(invalid="ignore"):
        coverage = np.mean(err <= 2.0 * spr, axis=0)
    counts = status_counts(np.asarray(status).tolist(), STATUSES)
    frac = float(np.mean(status[beyond] == "tracking")) if beyond.any() else None
    return coverage, counts, frac


def confident_wrong_fraction(results: list[EpisodeResult]) -> float:
    """Fraction of all steps that are ``tracking`` while the error exceeds 3 × the reported spread on
    some axis: the confident wrong poses of DESIGN.md "Trust", counted over every step (where
    :func:`integrity_summary`'s ``tracking_beyond_3sigma`` is their share of the steps beyond 3σ)."""
    _, _, status, beyond = _pooled_steps(results)
    return confident_wrong_share(beyond, status)


def confident_wrong_share(beyond: np.ndarray, status) -> float:
    """Fraction of steps ``tracking`` among ``beyond (T,)`` (error beyond 3 × the spread on some axis)
    and ``status (T,)``: :func:`confident_wrong_fraction` of one array of steps (``seam track``)."""
    return float(np.mean(np.asarray(beyond, dtype=bool) & (np.asarray(status) == "tracking")))


def _pooled_steps(results: list[EpisodeResult]):
    """Every step of the episodes: ``|error|`` and spread ``(T, 6)``, status ``(T,)`` and whether the
    error exceeds 3 × the spread on some axis ``(T,)``."""
    err = np.abs(np.concatenate([r.error for r in results]))
    spr = np.concatenate([r.spread for r in results])
    status = np.concatenate([status_columns(r)["status"] for r in results])
    with np.errstate(invalid="ignore"):
        beyond = np.any(err > 3.0 * spr, axis=1)
    return err, spr, status, beyond
