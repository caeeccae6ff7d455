"""Offline closed-loop step responses of the flange and the analysis behind Table IV.

One 12 ms controller cycle ``k`` (start ``t_k = k T``), as in the paper's trigger scheme
(§II-A) and as the networked loop must reproduce it:

1. at ``t_k`` the robot controller triggers the profiler; the scan sees the flange at
   its true position ``p(t_k)``; the pose estimate ``m_k = p(t_k) + noise`` reaches the
   processing unit within the same cycle (~7 ms of transfer, < 1 ms of estimation);
2. the processing unit computes ``u_{k+1} = controller(t_{k+1}, r_{k+1}, m_k)`` and sends
   it before ``t_{k+1}``;
3. the robot holds ``u_{k+1}`` over ``[t_{k+1}, t_{k+2})``.

So the command held in cycle k uses the measurement taken at the start of cycle
``k - delay_cycles``; ``delay_cycles=1`` is the real loop above, ``0`` an ideal loop that
applies each measurement at the instant it is taken. The reference passed to the
controller is the one of the cycle being commanded. A 250 Hz "VICON" log of the true
position is sampled inside the cycles.
"""

from collections import defaultdict
from dataclasses import dataclass, field

import numpy as np

from ...errors import ConfigError
from .control import OpenLoop
from .response import step_metrics
from .robotsim import RobotSimulator

__all__ = ["StepResult", "simulate_step", "simulate_impulse", "run_table4", "table4", "aggregate_table4",
           "format_table4", "AXES"]

AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0), "xyz": (1.0, 1.0, 1.0)}
"""Step directions: one axis, or the composite +x+y+z (each axis moves by ``step_mm``)."""


@dataclass
class StepResult:
    """One simulated step response; arrays in the gauge frame G, mm.

    Attributes
    ----------
    axis : str
        ``"x"``, ``"y"``, ``"z"`` or ``"xyz"``.
    step_mm : float
        Step size per moving axis, mm.
    mode : str
        ``"open"`` or ``"closed"`` (the controller's ``mode``).
    seed : int or None
        Seed of the run.
    t_step_s : float
        Step instant (a cycle start), s.
    t_s : ndarray, shape (K,)
        Cycle starts ``t_k``, s.
    position_mm : ndarray, shape (K, 3)
        True flange position at ``t_k``.
    reference_mm, command_mm : ndarray, shape (K, 3)
        Reference and command of cycle k (held over ``[t_k, t_{k+1})``).
    measured_mm : ndarray, shape (K, 3)
        Pose estimate of the scan taken at ``t_k`` (NaN where the measurement failed).
    t_truth_s : ndarray, shape (M,)
        Times of the ground-truth log (250 Hz by default), s.
    truth_mm : ndarray, shape (M, 3)
        True flange position at ``t_truth_s``.
    """

    axis: str
    step_mm: float
    mode: str
    seed: int | None
    t_step_s: float
    t_s: np.ndarray
    position_mm: np.ndarray
    reference_mm: np.ndarray
    command_mm: np.ndarray
    measured_mm: np.ndarray
    t_truth_s: np.ndarray
    truth_mm: np.ndarray
    noise_um: float = field(default=0.0)

    def components(self) -> list[str]:
        """Axes that move in this step (``["x", "y", "z"]`` for the composite)."""
        return [c for c, d in zip("xyz", AXES[self.axis]) if d]

    def metrics(self, source: str = "measured", **kwargs) -> dict[str, dict]:
        """:func:`~posekit.profiler.loop.response.step_metrics` of each moving axis.

        Parameters
        ----------
        source : {"measured", "truth", "position"}
            ``"measured"``: the pose estimates at 83.3 Hz (what the paper's method
            records); ``"truth"``: the 250 Hz ground-truth log (the VICON of Fig. 5);
            ``"position"``: the true position at the cycle starts.
        **kwargs
            Passed to ``step_metrics`` (``window_s``, ``band_hz``, ...).

        Failed estimates (NaN) are bridged by linear interpolation in time so that the
        record stays uniformly sampled for the spectrum.

        Returns
        -------
        dict
            ``{component: metrics}`` for each moving axis.
        """
        if source == "measured":
            t, y = self.t_s, self.measured_mm
        elif source == "truth":
            t, y = self.t_truth_s, self.truth_mm
        elif source == "position":
            t, y = self.t_s, self.position_mm
        else:
            raise ConfigError(f"StepResult.metrics: source must be 'measured', 'truth' or 'position', got {source!r}")
        out = {}
        for c in self.components():
            i = "xyz".index(c)
            ok = np.isfinite(y[:, i])
            if ok.sum() < 4:
                raise ConfigError(f"StepResult.metrics: fewer than 4 valid {source} samples on {c}")
            yi = y[:, i] if ok.all() else np.interp(t, t[ok], y[ok, i])     # bridge failed estimates
            kw = {"noise_mm": 1e-3 * self.noise_um if source == "measured" else 0.0, **kwargs}
            out[c] = step_metrics(t, yi, self.step_mm, t_step_s=self.t_step_s, **kw)
        return out


def _gaussian_measurement(noise_um: float):
    def measure(t_s, position_mm, rng):
        return position_mm + rng.normal(0.0, 1e-3 * noise_um, 3)
    return measure


def _run(x0: np.ndarray, reference: np.ndarray, controller, robot: RobotSimulator, measure,
         delay_cycles: int, seed, truth_rate_hz: float):
    """The cycle loop of the module doc; returns the recorded arrays."""
    T = robot.period_s
    n = reference.shape[0]
    ss_robot, ss_meas = np.random.SeedSequence(seed).spawn(2)
    rng = np.random.default_rng(ss_meas)
    robot.reset(x0_mm=x0, seed=np.random.default_rng(ss_robot))
    controller.reset()
    t = np.arange(n) * T
    pos, cmd, meas = (np.empty((n, 3)) for _ in range(3))
    t_truth = np.arange(int(np.floor(n * T * truth_rate_hz + 1e-9)) + 1) / truth_rate_hz
    truth = np.empty((t_truth.size, 3))
    truth[0] = x0
    j = 1
    rest = np.asarray(measure(-T, x0.copy(), rng), dtype=float)   # the scan before the run
    for k in range(n):
        pos[k] = robot.position_mm
        meas[k] = measure(t[k], pos[k].copy(), rng)
        used = meas[k - delay_cycles] if k >= delay_cycles else rest
        cmd[k] = controller(t[k], reference[k], used)
        robot.step(cmd[k])
        j_end = np.searchsorted(t_truth, robot.time_s + 1e-12)
        if j_end > j:
            truth[j:j_end] = robot.position_at(t_truth[j:j_end])
            j = j_end
    return t, pos, cmd, meas, t_truth[:j], truth[:j]


def _check_run(axis, amplitude_mm, delay_cycles, truth_rate_hz, name):
    if axis not in AXES:
        raise ConfigError(f"{name}: axis must be one of {sorted(AXES)}, got {axis!r}")
    if not (np.isfinite(amplitude_mm) and amplitude_mm != 0):
        raise ConfigError(f"{name}: the step/pulse size must be finite and non-zero, got {amplitude_mm!r}")
    if delay_cycles not in (0, 1, 2, 3):
        raise ConfigError(f"{name}: delay_cycles must be 0..3, got {delay_cycles!r}")
    if not (np.isfinite(truth_rate_hz) and truth_rate_hz > 0):
        raise ConfigError(f"{name}: truth_rate_hz must be > 0, got {truth_rate_hz!r}")


def simulate_step(axis: str, step_mm: float, controller, *, robot: RobotSimulator | None = None,
                  duration_s: float = 1.5, t_step_s: float = 0.12, measurement=None, noise_um: float = 3.0,
                  delay_cycles: int = 1, seed=None, x0_mm=(0.0, 0.0, 0.0),
                  truth_rate_hz: float = 250.0) -> StepResult:
    """Simulate a step of the flange under ``controller`` (see the module doc for the timing).

    Parameters
    ----------
    axis : {"x", "y", "z", "xyz"}
        Step direction (``"xyz"``: all three axes by ``step_mm`` at once).
    step_mm : float
        Step size, mm (signed).
    controller : callable
        ``controller(t_s, reference_mm, measured_mm) -> command_mm`` with ``reset()``
        (:class:`~posekit.profiler.loop.control.PDController` or ``OpenLoop``); reset first.
    robot : RobotSimulator, optional
        The plant, reset to rest at ``x0_mm`` first; default ``RobotSimulator()`` (linear GP12).
    duration_s : float
        Length of the run, s.
    t_step_s : float
        Step instant, s, rounded to a cycle start.
    measurement : callable, optional
        ``measurement(t_s, position_mm, rng) -> measured_mm``: the pose estimate of the
        flange (shape (3,), mm, G; NaN for a failed estimate) from its true position at the
        scan instant. Default: true position + Gaussian noise of ``noise_um`` per axis.
    noise_um : float
        Standard deviation of the default measurement noise, µm.
    delay_cycles : int
        Cycles between a scan and the cycle whose command uses it (1: the real loop).
    seed : int or None
        Seeds the measurement noise and the robot's process noise (same seed, same run).
    x0_mm : array_like, shape (3,)
        Start position in G, mm.
    truth_rate_hz : float
        Rate of the ground-truth log, Hz.

    Returns
    -------
    StepResult
    """
    _check_run(axis, step_mm, delay_cycles, truth_rate_hz, "simulate_step")
    robot = RobotSimulator() if robot is None else robot
    n = round(duration_s / robot.period_s)
    k_step = round(t_step_s / robot.period_s)
    if not (1 <= k_step < n - 10):
        raise ConfigError(f"simulate_step: t_step_s = {t_step_s} s must be at least one cycle into the "
                          f"run and leave 10 cycles of the {duration_s} s run")
    x0 = np.asarray(x0_mm, dtype=float)
    if x0.shape != (3,) or not np.all(np.isfinite(x0)):
        raise ConfigError(f"simulate_step: x0_mm must be 3 finite values in mm, got {x0_mm!r}")
    ref = np.repeat(x0[None], n, axis=0)
    ref[k_step:] += float(step_mm) * np.asarray(AXES[axis])
    measure = _gaussian_measurement(noise_um) if measurement is None else measurement
    t, pos, cmd, meas, t_truth, truth = _run(x0, ref, controller, robot, measure, delay_cycles, seed, truth_rate_hz)
    return StepResult(axis=axis, step_mm=float(step_mm), mode=getattr(controller, "mode", "closed"),
                      seed=seed, t_step_s=k_step * robot.period_s, t_s=t, position_mm=pos, reference_mm=ref,
                      command_mm=cmd, measured_mm=meas, t_truth_s=t_truth, truth_mm=truth,
                      noise_um=float(noise_um) if measurement is None else 0.0)


def simulate_impulse(axis: str, pulse_mm: float = 0.5, *, robot: RobotSimulator | None = None,
                     duration_s: float = 1.5, t_pulse_s: float = 0.12, noise_um: float = 3.0, seed=None,
                     truth_rate_hz: float = 250.0) -> StepResult:
    """Open-loop response to a one-cycle command pulse (the impulse test of Fig. 5(c)-(d)).

    The reference (and command) is ``pulse_mm`` along ``axis`` for the one cycle starting
    at ``t_pulse_s`` and 0 otherwise; the mode rings freely from ``t_pulse_s + T``. Feed
    the result to :func:`~posekit.profiler.loop.response.impulse_resonance` with
    ``t_free_s = result.t_step_s + T``. ``step_mm`` of the result holds the pulse height.
    """
    _check_run(axis, pulse_mm, 0, truth_rate_hz, "simulate_impulse")
    robot = RobotSimulator() if robot is None else robot
    n = round(duration_s / robot.period_s)
    k = round(t_pulse_s / robot.period_s)
    if not (1 <= k < n - 10):
        raise ConfigError(f"simulate_impulse: t_pulse_s = {t_pulse_s} s must be at least one cycle into the "
                          f"run and leave 10 cycles of the {duration_s} s run")
    ref = np.zeros((n, 3))
    ref[k] = float(pulse_mm) * np.asarray(AXES[axis])
    controller = OpenLoop()
    t, pos, cmd, meas, t_truth, truth = _run(np.zeros(3), ref, controller, robot, _gaussian_measurement(noise_um), 0,
                                             seed, truth_rate_hz)
    return StepResult(axis=axis, step_mm=float(pulse_mm), mode="open", seed=seed, t_step_s=k * robot.period_s,
                      t_s=t, position_mm=pos, reference_mm=ref, command_mm=cmd, measured_mm=meas,
                      t_truth_s=t_truth, truth_mm=truth, noise_um=float(noise_um))


def run_table4(controllers: dict, *, axes=("x", "y", "z", "xyz"), steps_mm=(1.0, 2.0), seeds=range(10),
               robot_factory=RobotSimulator, **kwargs) -> list[StepResult]:
    """All step responses of Table IV: every controller × axis × step × seed.

    Parameters
    ----------
    controllers : dict
        ``{name: controller}`` (e.g. ``{"open": OpenLoop(), "closed": PDController()}``).
    axes, steps_mm, seeds
        The grid.
    robot_factory : callable
        Returns a fresh :class:`~posekit.profiler.loop.robotsim.RobotSimulator`.
    **kwargs
        Passed to :func:`simulate_step`.
    """
    return [simulate_step(a, s, c, robot=robot_factory(), seed=seed, **kwargs)
            for c in controllers.values() for a in axes for s in steps_mm for seed in seeds]


def table4(results, source: str = "measured", **kwargs) -> list[dict]:
    """Mean and standard deviation of Mp, ζ and Mf over repeated runs (Table IV layout).

    Parameters
    ----------
    results : iterable of StepResult
    source, **kwargs
        See :meth:`StepResult.metrics`.

    Returns
    -------
    list of dict
        One row per (axis, component, step_mm, mode), in first-seen order, with keys
        ``axis, component, step_mm, mode, n, Mp_pct, Mp_pct_std, zeta, zeta_std, Mf_um,
        Mf_um_std, f_peak_hz`` (means, and sample standard deviations over the runs).
    """
    groups = defaultdict(list)
    for r in results:
        for comp, m in r.metrics(source, **kwargs).items():
            groups[(r.axis, comp, r.step_mm, r.mode)].append(m)
    return aggregate_table4(groups)


def aggregate_table4(groups) -> list[dict]:
    """The one Table IV aggregation: mean and sample standard deviation (ddof 1) of Mp, ζ, Mf.

    Parameters
    ----------
    groups : mapping
        ``(axis, component, step_mm, mode) -> [metrics dict with Mp_pct, zeta, Mf_um, f_peak_hz]``,
        one dict per run, in the order the rows should appear.

    Returns
    -------
    list of dict
        As :func:`table4`.
    """
    rows = []
    for (axis, comp, step, mode), ms in groups.items():
        row = {"axis": axis, "component": comp, "step_mm": step, "mode": mode, "n": len(ms)}
        for key in ("Mp_pct", "zeta", "Mf_um"):
            v = np.array([m[key] for m in ms])
            row[key] = float(v.mean())
            row[key + "_std"] = float(v.std(ddof=1)) if v.size > 1 else 0.0
        row["f_peak_hz"] = float(np.mean([m["f_peak_hz"] for m in ms]))
        rows.append(row)
    return rows


def format_table4(rows, paper=None) -> str:
    """The one plain-text Table IV: a line per row, ``mean ± std`` and the closed-loop improvement.

    Parameters
    ----------
    rows : list of dict
        From :func:`table4` / :func:`aggregate_table4`.
    paper : mapping, optional
        ``(axis, step_mm, mode) -> (Mp %, ζ, Mf µm)`` printed beside each row (the paper's).
    """
    index = {(r["axis"], r["component"], r["step_mm"], r["mode"]): r for r in rows}
    head = f"{'axis':<6}{'step':>5} {'mode':<7}{'Mp (%)':>16}{'zeta':>14}{'Mf (um)':>16}"
    lines = [head + ("   paper Mp/zeta/Mf" if paper else "")]
    for (axis, comp, step, mode), r in index.items():
        name = axis if axis == comp else f"{axis}:{comp}"
        cells = [f"{r[k]:.2f} ± {r[k + '_std']:.2f}" for k in ("Mp_pct", "zeta", "Mf_um")]
        p = (paper or {}).get((axis, step, mode))
        ptxt = "" if p is None else f"   {p[0]:.2f} / {p[1]:.2f} / {p[2]:.2f}"
        lines.append(f"{name:<6}{step:>5g} {mode:<7}{cells[0]:>16}{cells[1]:>14}{cells[2]:>16}{ptxt}")
        if mode == "closed" and (axis, comp, step, "open") in index:
            o = index[(axis, comp, step, "open")]
            imp = [100 * (o["Mp_pct"] - r["Mp_pct"]) / o["Mp_pct"] if o["Mp_pct"] else float("nan"),
                   100 * (r["zeta"] - o["zeta"]) / o["zeta"],
                   100 * (o["Mf_um"] - r["Mf_um"]) / o["Mf_um"]]
            lines.append(f"{'':<6}{'':>5} {'improv.':<7}" + "".join(
                f"{v:>15.1f}%" if i != 1 else f"{v:>13.1f}%" for i, v in enumerate(imp)))
    return "\n".join(lines)
