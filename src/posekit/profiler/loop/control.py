"""Position compensation of the flange from the measured pose (paper §IV-C): PD and open loop.

Both controllers share one interface, called once per 12 ms controller cycle::

    command_mm = controller(t_s, reference_mm, measured_mm)     # arrays of shape (3,)
    controller.reset()

``reference_mm`` is the desired flange position for the cycle the command will be held in,
``measured_mm`` the latest flange position estimated from a laser profile (gauge frame G,
mm; NaN or None when the estimate failed), and the returned command is the position sent
to the robot controller for that cycle. See :mod:`~posekit.profiler.loop.loop_sim` for the
timing of a cycle.
"""

import numpy as np

from ...errors import ConfigError
from ...geometry import matrix_from_quaternion
from ..sensor import LJ_X8400
from ..sim.poses import nominal_pose
from .robotsim import PERIOD_S

__all__ = ["OpenLoop", "PDController", "TargetCompensator", "make_compensator", "CONTROLLERS", "DEFAULT_KP",
           "DEFAULT_KD", "DEFAULT_LIMIT_MM"]

#: The pose server's controllers (``posekit profiler serve --controller``): none, the open-loop
#: baseline (command 0), the PD compensation.
CONTROLLERS = ("none", "open", "pd")
#: Largest correction per axis of the server's PD compensation unless told, mm.
DEFAULT_LIMIT_MM = 2.0

DEFAULT_KP = (-0.275, -0.60, -0.325)
"""Default proportional gains on (x, y, z), dimensionless; negative on purpose, see
:class:`PDController`."""

DEFAULT_KD = (0.0, -0.001, 0.0)
"""Default derivative gains on (x, y, z), s."""


def _gains(value, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim > 1 or arr.size not in (1, 3) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"PDController: {name} must be a finite scalar or 3 values (x, y, z), got {value!r}")
    return np.broadcast_to(arr.reshape(-1), (3,)).copy()


def _vector(value, name: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{name} must be 3 finite values (x, y, z) in mm, got {value!r}")
    return arr


class OpenLoop:
    """Pass the reference through: the robot's own controller alone (Table IV "Open-Loop")."""

    mode = "open"

    def __call__(self, t_s: float, reference_mm, measured_mm=None) -> np.ndarray:
        """Return ``reference_mm`` (shape (3,), mm, frame G) unchanged."""
        return _vector(reference_mm, "OpenLoop: reference_mm").copy()

    def reset(self) -> None:
        """Nothing to forget."""

    def __repr__(self) -> str:
        return "OpenLoop()"


class PDController:
    """Per-axis PD compensation of the commanded flange position.

    ``u_k = r_k + sat(Kp e_k + Kd D_k)`` with ``e_k = r_k - y_k`` (reference minus the
    measured flange position, mm, frame G) and ``D_k = (e_k - e_{k-1}) / Δt`` (``Δt`` the
    time between calls, the period on the first call), optionally low-pass filtered
    ``D_k ← a D_{k-1} + (1 - a) D_k``, ``a = τ / (τ + Δt)``, ``τ = 1 / (2π f_c)``. The
    correction is clipped to ``±limit_mm`` per axis (a PD holds no state that can wind up;
    the clip bounds what a bad measurement can do to the robot).

    A missing measurement (None or any NaN) gives zero correction for that cycle (open
    loop) and restarts the derivative, so the next valid sample does not kick.

    Why the default gains are negative: a scan taken at ``t_k`` drives the robot over
    ``[t_{k+1}, t_{k+2})``, on average 1.5 cycles (18 ms) later — 65° of lag at the 10 Hz
    mode. Through that lag the feedback ``-Kp y(t - 18 ms)`` contains ``+0.91 Kp ẏ / ω``,
    which changes the mode's damping ratio by about ``-0.45 Kp``: a positive Kp *removes*
    damping, a negative Kp (``|Kp| y`` fed back positively, the ``(1 + Kp) r`` feed-through
    shaping the step) adds it. The derivative's 90° lead minus that lag and the half
    cycle of the backward difference leaves ~0°, so Kd mostly changes the stiffness.

    The defaults were chosen per axis by a grid search (Kp in [-0.9, 0.3], Kd in ±4 ms)
    maximising the worst damping ratio of the discrete closed-loop poles over plant
    variations f_n = 8–12 Hz and ζ × 0.7–1.3 (spectral radius ≤ 0.85), then checked on
    the Table IV step metrics with :mod:`~posekit.profiler.loop.loop_sim` (3 µm noise, one-cycle
    delay, linear and nonlinear plant): closed-loop pole damping 0.90 / 0.80 / 0.90 on
    x / y / z (open loop 0.68 / 0.13 / 0.53), worst case 0.74 / 0.55 / 0.67. They stay
    stable with 0 or 2 cycles of delay but are tuned for 1. ``-1 < Kp < 0`` is required.
    With ``limit_mm`` = 2 a step saturates the correction above ``2 / |Kp|`` mm (3.3 mm on
    y); larger steps are still better damped than the open loop, less so.

    Parameters
    ----------
    kp : float or sequence of 3 floats
        Proportional gains on (x, y, z), dimensionless.
    kd : float or sequence of 3 floats
        Derivative gains on (x, y, z), s.
    period_s : float
        Controller period, s.
    limit_mm : float or sequence of 3 floats
        Largest correction ``|u - r|`` per axis, mm.
    derivative_filter_hz : float or None
        Cut-off f_c of the derivative's first-order low-pass, Hz; None: unfiltered.

    Examples
    --------
    >>> pd = PDController(kp=0.5, kd=0.0)
    >>> pd(0.0, [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]).tolist()
    [1.5, 0.0, 0.0]
    """

    mode = "closed"

    def __init__(self, kp=DEFAULT_KP, kd=DEFAULT_KD, period_s: float = PERIOD_S, limit_mm=2.0,
                 derivative_filter_hz: float | None = None):
        self.kp = _gains(kp, "kp")
        self.kd = _gains(kd, "kd")
        self.limit_mm = _gains(limit_mm, "limit_mm")
        if np.any(self.limit_mm <= 0):
            raise ConfigError(f"PDController: limit_mm must be > 0, got {self.limit_mm.tolist()}")
        if not (np.isfinite(period_s) and period_s > 0):
            raise ConfigError(f"PDController: period_s must be > 0, got {period_s!r}")
        if derivative_filter_hz is not None and not (np.isfinite(derivative_filter_hz) and derivative_filter_hz > 0):
            raise ConfigError(f"PDController: derivative_filter_hz must be > 0 or None, got {derivative_filter_hz!r}")
        self.period_s = float(period_s)
        self.derivative_filter_hz = derivative_filter_hz
        self.reset()

    def reset(self) -> None:
        """Forget the previous error, derivative and time."""
        self._e_prev = None
        self._d_prev = np.zeros(3)
        self._t_prev = None
        self.last_correction_mm = np.zeros(3)

    def __call__(self, t_s: float, reference_mm, measured_mm) -> np.ndarray:
        """Command for the next cycle.

        Parameters
        ----------
        t_s : float
            Time of this control cycle, s (sets Δt of the derivative).
        reference_mm : array_like, shape (3,)
            Desired flange position in G, mm.
        measured_mm : array_like, shape (3,), or None
            Estimated flange position in G, mm; None or NaN when unavailable.

        Returns
        -------
        ndarray, shape (3,)
            Commanded flange position in G, mm.
        """
        r = _vector(reference_mm, "PDController: reference_mm")
        y = None if measured_mm is None else np.asarray(measured_mm, dtype=float)
        if y is not None and y.shape != (3,):
            raise ConfigError(f"PDController: measured_mm must be 3 values (x, y, z) in mm, got {measured_mm!r}")
        dt = self.period_s
        if self._t_prev is not None and t_s - self._t_prev > 0:
            dt = float(t_s - self._t_prev)
        self._t_prev = float(t_s)
        if y is None or not np.all(np.isfinite(y)):
            self._e_prev = None
            self._d_prev = np.zeros(3)
            self.last_correction_mm = np.zeros(3)
            return r.copy()
        e = r - y
        d = np.zeros(3) if self._e_prev is None else (e - self._e_prev) / dt
        if self.derivative_filter_hz is not None and self._e_prev is not None:
            tau = 1.0 / (2.0 * np.pi * self.derivative_filter_hz)
            a = tau / (tau + dt)
            d = a * self._d_prev + (1.0 - a) * d
        self._e_prev, self._d_prev = e, d
        c = np.clip(self.kp * e + self.kd * d, -self.limit_mm, self.limit_mm)
        self.last_correction_mm = c
        return r + c

    def __repr__(self) -> str:
        return (f"PDController(kp={self.kp.tolist()}, kd={self.kd.tolist()}, period_s={self.period_s}, "
                f"limit_mm={self.limit_mm.tolist()}, derivative_filter_hz={self.derivative_filter_hz})")


class TargetCompensator:
    """The pose server's controller: hold the flange at a target pose (``serve --controller``).

    The loop's compensation (:class:`~posekit.profiler.loop.loop.FlangeCompensator`) for a real
    cell: each estimated pose ``T_G_F`` gives the flange's displacement from the target as
    the displacement of the laser spot (the point at ``standoff_mm`` on F's z axis, free of
    the weakly observable y-shift / x-tilt combination), ``measured = spot(T_G_F) -
    spot(T_target)``, and the controller is asked to hold a zero displacement:
    ``command = controller(t_s, 0, measured)``. The robot interface adds ``command_mm`` to
    its programmed target (G's axes taken as the robot's; rotate it otherwise) and holds it
    for the next cycle, as in the loop.

    Parameters
    ----------
    controller : PDController or OpenLoop
        Called once per good pose with ``t_s`` the sensor's time stamp (s; the PD's Δt
        comes from consecutive stamps).
    T_target_G_F : array_like, shape (4, 4)
        The target pose of F in G, mm.
    standoff_mm : float
        Depth of the laser spot on F's z axis, mm.

    A call ``hold(seq, t_s, T_G_F, cov)`` (the server's controller interface) returns
    ``{"command_mm": [3], "measured_mm": [3]}``, mm in G.

    Examples
    --------
    >>> import numpy as np
    >>> hold = TargetCompensator(PDController(kp=-0.5, kd=0.0), np.eye(4), standoff_mm=400.0)
    >>> T = np.eye(4); T[:3, 3] = [0.2, 0.0, 0.0]                     # 0.2 mm off along x
    >>> hold(0, 0.0, T, None)
    {'command_mm': [0.1, 0.0, 0.0], 'measured_mm': [0.2, 0.0, 0.0]}
    """

    def __init__(self, controller, T_target_G_F, standoff_mm: float):
        if not callable(controller) or not hasattr(controller, "reset"):
            raise ConfigError("TargetCompensator: controller must be a PDController or OpenLoop")
        T = np.asarray(T_target_G_F, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ConfigError(f"TargetCompensator: T_target_G_F must be a finite (4, 4) pose in mm, got shape {T.shape}")
        if not (np.isfinite(standoff_mm) and standoff_mm > 0):
            raise ConfigError(f"TargetCompensator: standoff_mm must be > 0, got {standoff_mm!r}")
        self.controller = controller
        self.T_target = T
        self.spot_F = np.array([0.0, 0.0, float(standoff_mm), 1.0])
        self.spot_target = (T @ self.spot_F)[:3]
        self._zero = np.zeros(3)
        controller.reset()

    def __call__(self, seq, t_s, T_G_F, cov) -> dict:
        m = (np.asarray(T_G_F, dtype=float) @ self.spot_F)[:3] - self.spot_target
        u = self.controller(float(t_s), self._zero, m)
        return {"command_mm": [float(v) for v in u], "measured_mm": [float(v) for v in m]}

    def __repr__(self) -> str:
        return f"TargetCompensator({self.controller!r}, standoff_mm={self.spot_F[2]:g})"


def make_compensator(kind: str, gauge, *, kp=None, kd=None, limit_mm: float | None = None,
                     derivative_filter_hz: float | None = None, target_mm=None, target_q_wxyz=None,
                     standoff_mm: float | None = None) -> "TargetCompensator | None":
    """The pose server's controller (``posekit profiler serve --controller``), or None for ``'none'``.

    Parameters
    ----------
    kind : {'none', 'open', 'pd'}
        :data:`CONTROLLERS`.
    gauge : Gauge
        The default target is the nominal pose above its centre
        (:func:`~posekit.profiler.sim.poses.nominal_pose`).
    kp, kd : float or 3 floats, optional
        PD gains on x, y, z (default :data:`DEFAULT_KP`, :data:`DEFAULT_KD`).
    limit_mm : float, optional
        Largest correction per axis, mm (default :data:`DEFAULT_LIMIT_MM`).
    derivative_filter_hz : float, optional
        Low-pass cut-off of the derivative, Hz (default: none).
    target_mm : 3 floats, optional
        Target position of F in G, mm.
    target_q_wxyz : 4 floats, optional
        Target orientation of F in G, a unit quaternion (normalised; off by more than 1e-3 in
        norm is an error).
    standoff_mm : float, optional
        Depth of the laser spot the controller holds, and of the default target, mm
        (default: mid-range of the LJ-X8400).
    """
    if kind not in CONTROLLERS:
        raise ConfigError(f"unknown controller '{kind}'; expected one of {', '.join(CONTROLLERS)}")
    if kind == "none":
        return None
    standoff = LJ_X8400.z_mid if standoff_mm is None else float(standoff_mm)
    T = nominal_pose(gauge, standoff_mm=standoff)
    if target_mm is not None:
        T[:3, 3] = _vector(target_mm, "target_mm")
    if target_q_wxyz is not None:
        q = np.asarray(target_q_wxyz, dtype=float)
        norm = float(np.linalg.norm(q)) if q.shape == (4,) and np.all(np.isfinite(q)) else float("nan")
        if not abs(norm - 1.0) <= 1e-3:
            raise ConfigError(f"target_q_wxyz: expected a unit quaternion [w, x, y, z], got {list(q.ravel())}")
        T[:3, :3] = matrix_from_quaternion(q / norm)
    if kind == "open":
        law = OpenLoop()
    else:
        law = PDController(kp=DEFAULT_KP if kp is None else kp, kd=DEFAULT_KD if kd is None else kd,
                           limit_mm=DEFAULT_LIMIT_MM if limit_mm is None else limit_mm,
                           derivative_filter_hz=derivative_filter_hz)
    return TargetCompensator(law, T, standoff)
