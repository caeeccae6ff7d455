"""Seam tracking one sample at a time (:class:`SeamTracker`) and on a recorded episode (:func:`track_log`).

Online use, one call per sample as the cell produces it::

    from posekit.seam.frontend.logs_setup import LogSetup
    from posekit.seam.frontend.tracker import SeamTracker

    cfg = setup.seam_config(profile="my-cell-profile.yaml")    # the cell + its fitted profile (seam tune)
    tracker = SeamTracker(cfg, seam_mm, seed=0)                  # seam_mm (K, 3), base frame
    for sample in stream:                                        # your robot + sensor interface
        est = tracker.step(sample.time_s, sample.qref, sample.q, sample.force_tool_n,
                           laser_mm=sample.laser_mm)            # (S, 2), NaN rows = no reading
        send(est.T_base_tool, est.status, est.spread)            # within the sensor period

The first call draws the particle cloud from the robot density about ``Fk(q)``. Every call does one
filter step (propagate with the program's increment ``Fk(qref_k) Fk(qref_{k-1})⁻¹``, weight with the
joints, the force and each laser reading at the time it was taken, estimate, resample); nothing is kept
beyond the particles and the last 64 samples' program joints (for the readings' times), so memory and
time per step are constant. A reading ``latency_s`` old (the cell's declared latency, else the profile's)
is compared with the tool where the program had it then; ``reading_time_s`` (a sensor's own stamps)
overrides that. A laser sample that arrives between two joint samples is a step of its own: give the
joints at its time (interpolated or the latest); :func:`track_log` interpolates them on a recorded log.

Timing (``posekit bench seam``, row ``seam.tracker.N1000``): median and p99 of
:meth:`SeamTracker.step` at 1,000 particles with tempering on.
"""

import math
import time
from dataclasses import dataclass

import numpy as np

from posekit.errors import ConfigError
from posekit.geometry import invert_transform
from posekit.seam.engine.densities import joint_compliance
from posekit.seam.engine.filter import SeamParticleFilter
from posekit.seam.engine.integrity import STATUSES
from posekit.seam.engine.step import StepEstimate, StepInputs
from posekit.seam.engine.trend import trend_filter
from posekit.seam.frontend.cell_signature import mismatch_reason
from posekit.seam.frontend.config import SeamConfig, cell_from_config
from posekit.verdict import Verdict, status_counts

__all__ = ["SPREAD_COLUMNS", "SeamTrackResult", "SeamTracker", "TrackEstimate", "step_record", "track_columns",
           "track_log", "track_metrics", "write_track"]

#: The six reported spreads of ``estimates.csv`` (DESIGN.md, seam).
SPREAD_COLUMNS = ("std_x_mm", "std_y_mm", "std_z_mm", "std_rx_deg", "std_ry_deg", "std_rz_deg")


@dataclass
class TrackEstimate:
    """One step of :class:`SeamTracker`.

    Attributes
    ----------
    time_s : float
    T_base_tool : ndarray, shape (4, 4)
        Estimated tool pose in the robot base frame, mm.
    spread : ndarray, shape (6,)
        Reported standard deviation ``[x, y, z (mm), rx, ry, rz (rad)]`` about the estimate, in
        its frame.
    status : str
        ``tracking``, ``degraded`` or ``lost`` (the engine's integrity verdict).
    ess : float
        Effective sample size after the update.
    lasers_used : int
    T_kinematic : ndarray, shape (4, 4)
        The kinematics-only pose ``Fk(q)`` (with the filter's compliance model), mm.
    T_nominal : ndarray, shape (4, 4)
        ``Fk(qref)``, the programmed pose (the seam frame of the errors), mm.
    step_ms : float
        Wall time of the filter step.
    raw : StepEstimate
        The engine's record of the step.
    """

    time_s: float
    T_base_tool: np.ndarray
    spread: np.ndarray
    status: str
    ess: float
    lasers_used: int
    T_kinematic: np.ndarray
    T_nominal: np.ndarray
    step_ms: float
    raw: StepEstimate

    @property
    def verdict(self) -> Verdict:
        """The step's :class:`posekit.verdict.Verdict`: its status, the failing test as the reason, and the
        spread as ``std`` (``x_mm``, ``y_mm``, ``z_mm``, ``rx_deg``, ``ry_deg``, ``rz_deg``; tool frame)."""
        names = ("x_mm", "y_mm", "z_mm", "rx_deg", "ry_deg", "rz_deg")
        std = [float(v) for v in self.spread[:3]] + [math.degrees(float(v)) for v in self.spread[3:]]
        return Verdict(self.status, (self.raw.reason,) if self.raw.reason else (), dict(zip(names, std)))


class SeamTracker:
    """The seam-tracking particle filter fed one sample at a time.

    Parameters
    ----------
    cfg : SeamConfig
        ``cell`` (robot with tool, sensor mounts and latencies, compliance), ``filter`` and ``profile``
        are used (:meth:`posekit.seam.frontend.logs.LogSetup.seam_config` builds one from a recorded
        episode's setup).
    seam_mm : array_like, shape (K, 3)
        The nominal seam in the robot base frame, in travel order, mm. It is trend-filtered
        once here (eq. 10: ``filter.trend_lambda``, ``filter.trend_eps_mm``).
    seed : int
        The filter draws from ``SeedSequence([seed, 2])`` (as ``posekit seam simulate`` does for
        the episode seed): the same samples and seed give the same estimates.
    seam_normal : array_like, shape (3,), optional
        Workpiece normal in the base frame (for the angle measurement); default ``-z``.
    knots_mm : array_like, shape (M, 3), optional
        An already trend-filtered seam (skips the trend filter).
    """

    def __init__(self, cfg: SeamConfig, seam_mm, *, seed: int = 0, seam_normal=None, knots_mm=None):
        self.cfg = cfg
        self.cell = cell_from_config(cfg.cell)
        self.settings = cfg.filter.settings()
        self.profile = cfg.profile_model()
        #: Why every step is ``degraded`` at best: the profile was fitted on another cell (None: this one, or a
        #: profile that names none; :mod:`posekit.seam.frontend.cell_signature`).
        self.cell_mismatch = mismatch_reason(cfg.profile.fitted.cell if cfg.profile.fitted else None, self.cell)
        self.chain = self.cell.chain
        seam = np.asarray(seam_mm, dtype=np.float64)
        if knots_mm is None:
            knots_mm = trend_filter(seam, lam=cfg.filter.trend_lambda, eps_mm=cfg.filter.trend_eps_mm).polyline
        self.knots_mm = np.asarray(knots_mm, dtype=np.float64)
        self.seam_normal = None if seam_normal is None else np.asarray(seam_normal, dtype=np.float64)
        self.rng = np.random.default_rng(np.random.SeedSequence([int(seed), 2]))
        self.filter: SeamParticleFilter | None = None
        self.n_sensors = self.cell.n_sensors
        self._T_prev = None
        c = self.cell.compliance_rad_per_nm
        self._base_cj = joint_compliance(c) if c > 0.0 else None
        self.steps = 0
        #: The last step's measured force in the base frame (``R(Fk(q)) f_tool``, N), as the filter used it.
        self.force_base_n: np.ndarray | None = None

    def _check(self, name, a, shape):
        a = np.asarray(a, dtype=np.float64)
        if a.shape != shape:
            raise ConfigError(f"SeamTracker.step: {name} has shape {a.shape}; expected {shape}")
        return a

    def step(self, time_s: float, qref, q, force_tool_n, *, laser_mm=None, angle_rad=None,
             torque_tool_nm=None, reading_time_s=None) -> TrackEstimate:
        """One filter step on one sample.

        Parameters
        ----------
        time_s : float
            The sample's time, s (recorded with the estimate).
        qref : array_like, shape (n,)
            The program's reference joints at this time, rad.
        q : array_like, shape (n,)
            Measured joints, rad.
        force_tool_n : array_like, shape (3,) or (6,)
            Force on the tool in the tool frame of the measured pose, N; six values: a wrench
            whose last three are the torque in N·m (as ``torque_tool_nm``).
        laser_mm : array_like, shape (S, 2), optional
            Each sensor's reading ``(x, z)`` in its frame, mm; NaN row = no reading.
        angle_rad : array_like, shape (S,), optional
            Angle readings (``sensors.angle``), rad, NaN = none.
        torque_tool_nm : array_like, shape (3,), optional
            Torque on the tool, tool frame, N·m: it enters the joint torques ``τ = J_vᵀ f +
            J_ωᵀ m`` of the filter's compliance model (``cell.compliance_rad_per_nm``).
        reading_time_s : array_like, shape (S,), optional
            Each reading's own time stamp (s, same clock as ``time_s``; NaN: the sensor's latency).

        Returns
        -------
        TrackEstimate
        """
        n = self.chain.n_joints
        qref = self._check("qref", qref, (n,))
        q = self._check("q", q, (n,))
        w = np.asarray(force_tool_n, dtype=np.float64).ravel()
        if w.shape == (6,):
            w, torque_tool_nm = w[:3], w[3:]
        w = self._check("force_tool_n", w, (3,))
        T_nom = self.chain.forward_kinematics(qref, check=False)
        R_meas = self.chain.forward_kinematics(q, check=False)[:3, :3]
        force_base = R_meas @ w
        self.force_base_n = force_base
        if self.filter is None:
            self.filter = SeamParticleFilter(self.cell, self.settings, self.profile, self.knots_mm, self.rng,
                                             T_init=T_nom, seam_normal=self.seam_normal,
                                             degraded_reason=self.cell_mismatch)
            inc = np.eye(4)
        else:
            inc = T_nom @ invert_transform(self._T_prev, check=False)
        if torque_tool_nm is not None and self._base_cj is not None:
            m_base = R_meas @ self._check("torque_tool_nm", torque_tool_nm, (3,))
            chain, base = self.chain, self._base_cj

            def cj(qq, tau_nmm):  # τ = J_vᵀ f + J_ωᵀ m (N·mm)
                return base(qq, tau_nmm + 1e3 * chain.geometric_jacobian(qq, check=False)[3:].T @ m_base)

            self.filter.compliance = cj
        elif self._base_cj is not None:
            self.filter.compliance = self._base_cj
        laser = None
        if self.n_sensors:
            laser = (np.full((self.n_sensors, 2), np.nan) if laser_mm is None
                     else self._check("laser_mm", laser_mm, (self.n_sensors, 2)))
        angle = None
        if self.cell.angle and self.n_sensors and angle_rad is not None:
            angle = self._check("angle_rad", angle_rad, (self.n_sensors,))
        lag = None
        if reading_time_s is not None and self.n_sensors:
            lag = float(time_s) - self._check("reading_time_s", reading_time_s, (self.n_sensors,))
        inputs = StepInputs(inc, T_nom, q, force_base, float(time_s), qref, laser, angle, lag)
        t0 = time.perf_counter()
        est = self.filter.step(inputs)
        ms = (time.perf_counter() - t0) * 1e3
        self._T_prev = T_nom
        self.steps += 1
        return TrackEstimate(float(time_s), est.T, np.asarray(est.spread, dtype=np.float64), est.status,
                             float(est.ess), int(est.lasers_used), est.T_kinematic, T_nom, ms, est)


@dataclass
class SeamTrackResult:
    """:func:`track_log` on a recorded episode.

    Attributes
    ----------
    time_s : ndarray, shape (T,)
    estimate, kinematic, nominal : ndarray, shape (T, 4, 4)
        Estimated, kinematics-only and programmed (``Fk(qref)``) tool poses, base frame, mm.
    spread : ndarray, shape (T, 6)
        ``[mm, mm, mm, rad, rad, rad]``.
    status : list of str
    ess, step_ms : ndarray, shape (T,)
    lasers_used : ndarray of int, shape (T,)
    interpolated : ndarray of bool, shape (T,)
    truth : ndarray, shape (T, 4, 4) or None
        True tool poses in the base frame (``Fk(qref) T_seam_tool``), when the log has truth.
    force_base_n : ndarray, shape (T, 3) or None
        The measured force in the base frame (``R(Fk(q)) f_tool``), N, as the filter used it.
    config : SeamConfig or None
        The configuration the log was tracked with.
    reason : list of str or None
        Per step the failing consistency test(s) (None where the step is ``tracking``).
    """

    time_s: np.ndarray
    estimate: np.ndarray
    kinematic: np.ndarray
    nominal: np.ndarray
    spread: np.ndarray
    status: list
    ess: np.ndarray
    step_ms: np.ndarray
    lasers_used: np.ndarray
    interpolated: np.ndarray
    truth: np.ndarray | None
    resampled: np.ndarray | None = None
    particles: int = 0
    force_base_n: np.ndarray | None = None
    config: SeamConfig | None = None
    reason: list | None = None


def track_log(log, *, progress=None, on_step=None, profile=None) -> SeamTrackResult:
    """Run the filter over a recorded episode (:func:`posekit.seam.frontend.logs.read_episode_log`).

    Each row of ``log.csv`` is one step; joints on laser-only rows are the interpolated ones.
    The filter's seed is ``setup.yaml``'s ``seed``; a log written by ``posekit seam simulate
    --save-log`` reproduces that run's estimates. ``on_step(k, TrackEstimate)`` is called after
    every step (e.g. to stream it out). ``profile`` (:class:`posekit.seam.model.Profile`) replaces the episode's
    own (``seam tune`` judging a candidate).
    """
    tracker = SeamTracker(log.config, log.seam_mm, seed=log.setup.seed, seam_normal=log.setup.seam_normal)
    if profile is not None:          # a candidate for this very cell
        tracker.profile = profile
        tracker.cell_mismatch = None
    T = len(log.time_s)
    est = np.empty((T, 4, 4))
    kin = np.empty((T, 4, 4))
    nom = np.empty((T, 4, 4))
    spread = np.empty((T, 6))
    ess = np.empty(T)
    ms = np.empty(T)
    used = np.empty(T, dtype=int)
    resampled = np.zeros(T, dtype=bool)
    force_base = np.empty((T, 3))
    status, reason = [], []
    it = range(T) if progress is None else progress(range(T), total=T, desc="steps")
    for k in it:
        r = tracker.step(log.time_s[k], log.qref[k], log.q[k], log.force_tool_n[k],
                         laser_mm=log.laser_mm[k] if log.laser_mm.shape[1] else None,
                         angle_rad=None if log.angle_rad is None else log.angle_rad[k],
                         torque_tool_nm=None if log.torque_tool_nm is None else log.torque_tool_nm[k],
                         reading_time_s=None if log.reading_time_s is None else log.reading_time_s[k])
        est[k], kin[k], nom[k], spread[k] = r.T_base_tool, r.T_kinematic, r.T_nominal, r.spread
        ess[k], ms[k], used[k] = r.ess, r.step_ms, r.lasers_used
        status.append(r.status)
        reason.append(r.raw.reason)
        resampled[k] = r.raw.resampled
        force_base[k] = tracker.force_base_n
        if on_step is not None:
            on_step(k, r)
    truth = None if log.truth_seam_tool is None else np.matmul(nom, log.truth_seam_tool)
    return SeamTrackResult(log.time_s.copy(), est, kin, nom, spread, status, ess, ms, used, log.interpolated.copy(),
                           truth, resampled, log.config.filter.particles, force_base, log.config, reason)


def track_metrics(result: SeamTrackResult) -> dict:
    """``metrics.json`` of ``posekit seam track``: steps, status counts, step times; with truth also
    the RMSE per axis in the seam frame (``rmse_mm``, ``rmse_deg``), the kinematics-only RMSE,
    ``coverage_2sigma`` (fraction of steps with ``|error| <= 2 × spread``, per axis),
    ``confident_wrong`` (fraction of steps ``tracking`` and beyond 3 × the spread on some axis),
    ``plateau_ratio_max`` and ``outside_plateau_steps`` (the truth's largest offset from the
    kinematic pose in radii of the filter's robot plateau, and the fraction of steps outside it:
    :func:`posekit.seam.frontend.episode.plateau_ratio`; outside, the filter's ``d0``/``kd`` do not
    describe the robot, paper eq. 7))."""
    from posekit.seam.frontend.episode import plateau_ratio
    from posekit.seam.frontend.episode_metrics import confident_wrong_share
    from posekit.seam.frontend.seam_frame import AXES, seam_frame_errors

    def fl(v):
        return float(round(float(v), 6))

    counts = status_counts((s for s in result.status if s), STATUSES)
    out = {
        "steps": len(result.time_s),
        "status_counts": {k: v for k, v in counts.items() if v},
        "step_ms_median": fl(np.median(result.step_ms)),
        "step_ms_p99": fl(np.percentile(result.step_ms, 99)),
        "interpolated_steps": int(result.interpolated.sum()),
        "laser_steps": int((result.lasers_used > 0).sum()),
        "spread_median_mm": {a: fl(v) for a, v in zip(AXES[:3], np.median(result.spread[:, :3], axis=0))},
        "spread_median_deg": {a: fl(math.degrees(v)) for a, v in zip(AXES[3:], np.median(result.spread[:, 3:], axis=0))},
    }
    if result.truth is not None:
        err = seam_frame_errors(result.estimate, result.truth, result.nominal)
        kin = seam_frame_errors(result.kinematic, result.truth, result.nominal)
        rm, rk = np.sqrt(np.mean(err ** 2, axis=0)), np.sqrt(np.mean(kin ** 2, axis=0))
        cover = np.mean(np.abs(err) <= 2.0 * result.spread, axis=0)
        out.update({
            "rmse_mm": {a: fl(v) for a, v in zip(AXES[:3], rm[:3])},
            "rmse_deg": {a: fl(math.degrees(v)) for a, v in zip(AXES[3:], rm[3:])},
            "kinematic_rmse_mm": {a: fl(v) for a, v in zip(AXES[:3], rk[:3])},
            "kinematic_rmse_deg": {a: fl(math.degrees(v)) for a, v in zip(AXES[3:], rk[3:])},
            "coverage_2sigma": {a: fl(v) for a, v in zip(AXES, cover)},
            "confident_wrong": fl(confident_wrong_share(np.any(np.abs(err) > 3.0 * result.spread, axis=1),
                                                        result.status)),
        })
        if result.config is not None and result.force_base_n is not None:
            ratio = plateau_ratio(result.config, result.truth, result.kinematic, result.force_base_n)
            out.update({"plateau_ratio_max": fl(np.max(ratio)) if np.isfinite(np.max(ratio)) else None,
                        "outside_plateau_steps": fl(np.mean(ratio > 1.0))})
    return out



def track_columns(truth: bool) -> list[str]:
    """Columns of ``estimates.csv`` of ``posekit seam track`` (errors only with truth; last, the failing test's
    ``reason``, empty where the step is ``tracking``)."""
    from posekit.seam.frontend.report import ERROR_COLUMNS

    cols = ["step", "time_s", "tx_mm", "ty_mm", "tz_mm", "qw", "qx", "qy", "qz", "status", *SPREAD_COLUMNS,
            "ess", "lasers_used", "interpolated", "step_ms"]
    return cols + ([f"err_{c}" for c in ERROR_COLUMNS] if truth else []) + ["reason"]


def write_track(folder, result: SeamTrackResult) -> dict:
    """Write ``estimates.csv`` (per step: the tool pose in the robot base frame, ``status``, the six
    spreads; errors in the seam frame when the log has truth), ``metrics.json``
    (:func:`track_metrics`), ``ess.png`` (effective sample size, resampling, status) and, with
    truth, ``errors_time.png`` (errors with the reported ±2σ) into ``folder``; returns the metrics."""
    import csv
    from pathlib import Path

    from posekit.report import write_json
    from posekit.seam.frontend.report import _poses
    from posekit.seam.frontend.seam_frame import seam_frame_errors

    folder = Path(folder)
    m = track_metrics(result)
    has_truth = result.truth is not None
    poses = _poses(result.estimate)
    spread = result.spread.copy()
    spread[:, 3:] = np.degrees(spread[:, 3:])
    err = err_rad = None
    if has_truth:
        err_rad = seam_frame_errors(result.estimate, result.truth, result.nominal)
        err = err_rad.copy()
        err[:, 3:] = np.degrees(err[:, 3:])
    with (folder / "estimates.csv").open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(track_columns(has_truth))
        for k in range(len(result.time_s)):
            row = [k, f"{result.time_s[k]:.10g}", *(f"{v:.10g}" for v in poses[k]), result.status[k],
                   *(f"{v:.6g}" for v in spread[k]), f"{result.ess[k]:.6g}", int(result.lasers_used[k]),
                   int(result.interpolated[k]), f"{result.step_ms[k]:.4g}"]
            if has_truth:
                row += [f"{v:.6g}" for v in err[k]]
            w.writerow(row + [(result.reason[k] if result.reason is not None else None) or ""])
    write_json(folder / "metrics.json", m)
    from posekit.seam.frontend import plots

    if result.resampled is not None and result.particles:
        plots.plot_ess(result.ess, result.resampled, result.particles, folder / "ess.png", t_s=result.time_s,
                       status=result.status)
    if has_truth:  # the plots take mm, rad (they draw degrees)
        kin = seam_frame_errors(result.kinematic, result.truth, result.nominal)
        plots.plot_tracking_errors(err_rad[None], kin[None], folder / "errors_time.png", t_s=result.time_s,
                                   spread=result.spread[None], title="Tool-pose error in the seam frame against truth.csv")
    return m



def step_record(k: int, est: TrackEstimate) -> dict:
    """One step as a JSON-ready dict (``posekit seam track --jsonl``): ``step``, ``time_s``, ``t_mm``
    (3, base frame), ``q_wxyz`` (4), ``status``, ``std_mm`` (3), ``std_deg`` (3), ``ess``, ``lasers_used``,
    ``reason`` (the failing test; None where ``tracking``)."""
    from posekit.seam.frontend.report import _poses

    pose = _poses(est.T_base_tool[None])[0]
    return {"step": int(k), "time_s": float(est.time_s), "t_mm": [float(v) for v in pose[:3]],
            "q_wxyz": [float(v) for v in pose[3:]], "status": est.status,
            "std_mm": [float(v) for v in est.spread[:3]], "std_deg": [math.degrees(v) for v in est.spread[3:]],
            "ess": float(est.ess), "lasers_used": int(est.lasers_used), "reason": est.raw.reason}
