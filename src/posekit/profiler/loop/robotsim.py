"""Flange of a 6-axis industrial robot under its own position controller (paper §IV-C).

A Yaskawa GP12-like manipulator driven through the manufacturer's interface at 83.3 Hz
(period ``T`` = 12 ms), translation only: the flange position ``p`` (x, y, z) in the gauge
frame G, in mm; the orientation stays at its reference. Each axis follows the command
``u`` through one structural mode (natural frequency ``f_n`` ≈ 10 Hz, damping ratio ζ)::

    p'' + 2 ζ_eff ω_n p' + ω_n² p = ω_n² (u + w_k),     ζ_eff = ζ + c (|p'| / v_ref)^q

with ω_n = 2π f_n, the command held constant over each 12 ms cycle (zero-order hold) and
``w_k`` an optional per-cycle Gaussian disturbance (process noise) added to the held
command (v_ref = 100 mm/s). With ``c`` = 0 (default) the system is linear and is propagated exactly
(matrix exponential of the homogeneous system in the deviation ``p - u``); with ``c`` > 0
(the amplitude-dependent damping the paper's 2 mm steps show, see :data:`GP12_NONLINEAR`)
it is integrated by fixed-step RK4 in a compiled kernel. Both are deterministic.

The defaults reproduce the open loop of Table IV: a 1 mm step overshoots by
exp(-πζ/√(1-ζ²)) = 5.4 %, 66 % and 14 % on x, y and z.
"""

from dataclasses import dataclass

import numpy as np

from posekit._jit import njit

from ...errors import ConfigError

__all__ = ["RobotSimulator", "GP12_LINEAR", "GP12_NONLINEAR", "PERIOD_S", "V_REF_MM_S"]

PERIOD_S = 0.012
"""Period of the manufacturer's position controller (83.3 Hz), s."""


@dataclass(frozen=True)
class _Params:
    zeta: tuple
    f_n_hz: tuple
    damping_gain: tuple
    damping_exponent: float


GP12_LINEAR = _Params(zeta=(0.68, 0.13, 0.53), f_n_hz=(10.0, 10.0, 10.0),
                      damping_gain=(0.0, 0.0, 0.0), damping_exponent=3.0)
"""Linear model: the open-loop 1 mm damping ratios of Table IV on (x, y, z)."""

GP12_NONLINEAR = _Params(zeta=(0.6788, 0.0660, 0.4887), f_n_hz=(10.0, 10.0, 10.0),
                         damping_gain=(0.2095, 0.7233, 2.4133), damping_exponent=3.0)
"""Amplitude-dependent damping ζ + c (|v| / 100 mm/s)³, (ζ, c) fitted per axis so that
1 mm and 2 mm steps overshoot as in Table IV's open loop (x 5.39/4.86 %, y 65.88/39.48 %,
z 13.98/8.06 %). Phenomenological: the paper reports the effect, not its cause."""


V_REF_MM_S = 100.0
"""Reference speed of the amplitude-dependent damping, mm/s."""


@njit(cache=True, nogil=True)
def _zeta_eff(zeta, gain, expo, v):  # pragma: no cover - compiled
    return zeta + gain * (abs(v) / V_REF_MM_S) ** expo


@njit(cache=True, nogil=True)
def _rk4(state, u, wn, zeta, gain, expo, duration, max_step):  # pragma: no cover - compiled
    """Integrate p'' = ω²(u - p) - 2 ζ_eff(v) ω v over ``duration``; state (3, 2) in place."""
    if duration <= 0.0:
        return
    n = int(np.ceil(duration / max_step - 1e-9))
    h = duration / n
    for a in range(3):
        w2 = wn[a] * wn[a]
        c = 2.0 * wn[a]
        z, g = zeta[a], gain[a]
        p = state[a, 0]
        v = state[a, 1]
        for _ in range(n):
            k1p = v
            k1v = w2 * (u[a] - p) - c * _zeta_eff(z, g, expo, v) * v
            v2 = v + 0.5 * h * k1v
            k2v = w2 * (u[a] - p - 0.5 * h * k1p) - c * _zeta_eff(z, g, expo, v2) * v2
            v3 = v + 0.5 * h * k2v
            k3v = w2 * (u[a] - p - 0.5 * h * v2) - c * _zeta_eff(z, g, expo, v3) * v3
            v4 = v + h * k3v
            k4v = w2 * (u[a] - p - h * v3) - c * _zeta_eff(z, g, expo, v4) * v4
            p += h / 6.0 * (k1p + 2.0 * v2 + 2.0 * v3 + v4)
            v += h / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
        state[a, 0] = p
        state[a, 1] = v


def _triple(value, name: str, positive: bool = True) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.ndim > 1 or arr.size not in (1, 3) or not np.all(np.isfinite(arr)):
        raise ConfigError(f"RobotSimulator: {name} must be a finite scalar or 3 values "
                          f"(x, y, z), got {value!r}")
    arr = np.broadcast_to(arr.reshape(-1), (3,)).copy()
    if positive and np.any(arr <= 0):
        raise ConfigError(f"RobotSimulator: {name} must be > 0, got {arr.tolist()}")
    return arr


class RobotSimulator:
    """Flange translation of a position-controlled industrial robot, one controller cycle per step.

    Parameters
    ----------
    zeta : float or sequence of 3 floats
        Damping ratio ζ of the structural mode on (x, y, z), > 0 (≥ 1 is overdamped).
    f_n_hz : float or sequence of 3 floats
        Undamped natural frequency of the mode on (x, y, z), Hz.
    period_s : float
        Controller period T, s (12 ms for the 83.3 Hz controller).
    x0_mm : array_like, shape (3,)
        Initial flange position in the gauge frame G, mm; the robot starts at rest there,
        commanded to stay there.
    seed : int, numpy.random.Generator or None
        Seed of the process noise (unused when ``process_noise_um`` is 0); an int makes
        every :meth:`reset` replay the same noise.
    process_noise_um : float
        Standard deviation of a Gaussian disturbance added to the command held in each
        cycle (servo and interpolation jitter), µm per axis.
    damping_gain : float or sequence of 3 floats
        ``c`` in ζ_eff = ζ + c (|v| / 100 mm/s)^q: the growth of the damping ratio at
        100 mm/s on (x, y, z), >= 0; 0 keeps the model linear and exact.
    damping_exponent : float
        ``q`` in ζ_eff, > 0.
    max_substep_s : float
        Largest RK4 step of the nonlinear integrator, s (unused in the linear case).

    Attributes
    ----------
    time_s : float
        Time of the current state, s (0 at construction; ``k T`` after ``k`` steps).
    position_mm, velocity_mm_s : ndarray, shape (3,)
        Current flange position in G (mm) and velocity (mm/s).

    Examples
    --------
    >>> robot = RobotSimulator()
    >>> p = [robot.step([0.0, 1.0, 0.0])[1] for _ in range(5)]
    >>> round(float(max(p)), 2)       # y overshoots by ~65 % (sampled every 12 ms)
    1.65
    """

    def __init__(self, zeta=GP12_LINEAR.zeta, f_n_hz=GP12_LINEAR.f_n_hz,
                 period_s: float = PERIOD_S, x0_mm=(0.0, 0.0, 0.0), seed=None, *,
                 process_noise_um: float = 0.0, damping_gain=0.0, damping_exponent: float = 3.0,
                 max_substep_s: float = 5e-4):
        self.zeta = _triple(zeta, "zeta")
        self.f_n_hz = _triple(f_n_hz, "f_n_hz")
        self.damping_gain = _triple(damping_gain, "damping_gain", positive=False)
        if np.any(self.damping_gain < 0):
            raise ConfigError(f"RobotSimulator: damping_gain must be >= 0, got {self.damping_gain.tolist()}")
        if not (np.isfinite(damping_exponent) and damping_exponent > 0):
            raise ConfigError(f"RobotSimulator: damping_exponent must be > 0, got {damping_exponent!r}")
        self.damping_exponent = float(damping_exponent)
        if not (np.isfinite(period_s) and period_s > 0):
            raise ConfigError(f"RobotSimulator: period_s must be > 0, got {period_s!r}")
        if not (np.isfinite(process_noise_um) and process_noise_um >= 0):
            raise ConfigError(f"RobotSimulator: process_noise_um must be >= 0, got {process_noise_um!r}")
        if not (np.isfinite(max_substep_s) and 0 < max_substep_s <= period_s):
            raise ConfigError(f"RobotSimulator: max_substep_s must be in (0, period_s], got {max_substep_s!r}")
        x0 = np.asarray(x0_mm, dtype=float)
        if x0.shape != (3,) or not np.all(np.isfinite(x0)):
            raise ConfigError(f"RobotSimulator: x0_mm must be 3 finite values in mm, got {x0_mm!r}")
        self.period_s = float(period_s)
        self.process_noise_um = float(process_noise_um)
        self.max_substep_s = float(max_substep_s)
        self.nonlinear = bool(np.any(self.damping_gain > 0))
        self._wn = 2.0 * np.pi * self.f_n_hz
        self._x0 = x0
        self._seed = seed
        self._phi_T = self._phi(np.array([self.period_s]))[0]          # (3, 2, 2)
        self._a11, self._a12 = self._phi_T[:, 0, 0].copy(), self._phi_T[:, 0, 1].copy()
        self._a21, self._a22 = self._phi_T[:, 1, 0].copy(), self._phi_T[:, 1, 1].copy()
        self._phi_cache: dict = {}
        self.reset()

    @classmethod
    def gp12(cls, nonlinear: bool = False, **kwargs) -> "RobotSimulator":
        """A GP12-like robot: :data:`GP12_LINEAR` or, with ``nonlinear``, :data:`GP12_NONLINEAR`.

        Keyword arguments are passed to the constructor (``x0_mm``, ``seed``, ...).
        """
        p = GP12_NONLINEAR if nonlinear else GP12_LINEAR
        return cls(zeta=p.zeta, f_n_hz=p.f_n_hz, damping_gain=p.damping_gain,
                   damping_exponent=p.damping_exponent,
                   **kwargs)

    # ------------------------------------------------------------------ state
    def reset(self, x0_mm=None, seed=None) -> None:
        """Back to rest at ``x0_mm`` (default: the constructor's) at time 0; reseed the noise."""
        if x0_mm is not None:
            x0 = np.asarray(x0_mm, dtype=float)
            if x0.shape != (3,) or not np.all(np.isfinite(x0)):
                raise ConfigError(f"RobotSimulator.reset: x0_mm must be 3 finite values in mm, got {x0_mm!r}")
            self._x0 = x0
        self._rng = np.random.default_rng(self._seed if seed is None else seed)
        self._state = np.stack([self._x0, np.zeros(3)], axis=1)        # (3, 2): p, v
        self._k = 0
        self._last_start = self._state.copy()
        self._last_u = self._x0.copy()

    @property
    def time_s(self) -> float:
        """Time of the current state, s."""
        return self._k * self.period_s

    @property
    def cycle(self) -> int:
        """Number of controller cycles simulated so far."""
        return self._k

    @property
    def position_mm(self) -> np.ndarray:
        """Flange position in the gauge frame G, shape (3,), mm."""
        return self._state[:, 0].copy()

    @property
    def velocity_mm_s(self) -> np.ndarray:
        """Flange velocity in G, shape (3,), mm/s."""
        return self._state[:, 1].copy()

    # --------------------------------------------------------------- dynamics
    def _phi(self, tau: np.ndarray) -> np.ndarray:
        """Transition matrices ``expm(A τ)`` of the homogeneous linear system, shape (len(tau), 3, 2, 2).

        Closed form for any ζ (complex ω_d covers ζ > 1, the sinc covers ζ = 1).
        """
        tau = np.asarray(tau, dtype=float)[:, None]                    # (n, 1)
        wn, sigma = self._wn, self.zeta * self._wn
        wd = wn * np.sqrt(1.0 - self.zeta ** 2 + 0j)
        ex = np.exp(-sigma * tau)
        sn = (tau * np.sinc(wd * tau / np.pi)).real                    # sin(ω_d τ) / ω_d
        cs = np.cos(wd * tau).real
        out = np.empty(tau.shape[:1] + (3, 2, 2))
        out[..., 0, 0] = ex * (cs + sigma * sn)
        out[..., 0, 1] = ex * sn
        out[..., 1, 0] = -wn * wn * ex * sn
        out[..., 1, 1] = ex * (cs - sigma * sn)
        return out

    def _propagate(self, start: np.ndarray, u: np.ndarray, tau: np.ndarray) -> np.ndarray:
        """States (len(tau), 3, 2) reached from ``start`` after each ``tau`` with command ``u`` held."""
        if not self.nonlinear:
            d, v = start[:, 0] - u, start[:, 1]
            ns = np.round(tau * 1e9).astype(np.int64)            # cache per whole ns
            key = ns.tobytes()
            phi = self._phi_cache.get(key)
            if phi is None:
                phi = self._phi(ns * 1e-9)
                if len(self._phi_cache) < 256:
                    self._phi_cache[key] = phi
            out = np.empty((tau.size, 3, 2))
            out[:, :, 0] = phi[..., 0, 0] * d + phi[..., 0, 1] * v + u
            out[:, :, 1] = phi[..., 1, 0] * d + phi[..., 1, 1] * v
            return out
        out = np.empty((tau.size, 3, 2))
        for i, t in enumerate(tau):
            s = start.copy()
            _rk4(s, u, self._wn, self.zeta, self.damping_gain, self.damping_exponent,
                 float(t), self.max_substep_s)
            out[i] = s
        return out

    def step(self, command_mm) -> np.ndarray:
        """Advance one controller cycle holding ``command_mm``; return the new position.

        Parameters
        ----------
        command_mm : array_like, shape (3,)
            Commanded flange position in G for this cycle, mm (held for ``period_s``).

        Returns
        -------
        position_mm : ndarray, shape (3,)
            Flange position in G at the end of the cycle (time ``time_s``), mm.
        """
        u = np.array(command_mm, dtype=float)
        if u.shape != (3,) or not np.isfinite(u).all():
            raise ConfigError(f"RobotSimulator.step: command_mm must be 3 finite values in mm, got {command_mm!r}")
        if self.process_noise_um > 0:
            u = u + self._rng.normal(0.0, 1e-3 * self.process_noise_um, 3)
        self._last_start = self._state
        self._last_u = u
        if self.nonlinear:
            new = self._state.copy()
            _rk4(new, u, self._wn, self.zeta, self.damping_gain, self.damping_exponent,
                 self.period_s, self.max_substep_s)
            self._state = new
        else:
            d = self._state[:, 0] - u
            v = self._state[:, 1]
            self._state = np.empty((3, 2))
            self._state[:, 0] = self._a11 * d + self._a12 * v + u
            self._state[:, 1] = self._a21 * d + self._a22 * v
        self._k += 1
        return self._state[:, 0].copy()

    def position_at(self, t_s) -> np.ndarray:
        """Flange position at times inside the last simulated cycle (a 250 Hz log, a trigger).

        The command of a cycle is known at its start, so a scan triggered ``δ`` after the
        start of cycle k is ``step(u_k)`` followed by ``position_at(t_k + δ)``; the scan at
        the start of the cycle (δ = 0, the paper's trigger) is simply ``position_mm``
        before the step.

        Parameters
        ----------
        t_s : float or array_like, shape (n,)
            Times in ``[time_s - period_s, time_s]``, s.

        Returns
        -------
        ndarray, shape (3,) or (n, 3)
            Flange position in G, mm.

        Raises
        ------
        ConfigError
            If a time lies outside the last cycle (or no cycle was simulated yet and
            ``t_s`` is not 0).
        """
        t = np.atleast_1d(np.asarray(t_s, dtype=float))
        t_end = self.time_s
        t_start = max(t_end - self.period_s, 0.0)
        eps = 1e-9 * self.period_s
        if t.ndim != 1 or np.any(~np.isfinite(t)) or np.any(t < t_start - eps) or np.any(t > t_end + eps):
            raise ConfigError(f"RobotSimulator.position_at: times must lie in the last cycle "
                              f"[{t_start:.6f}, {t_end:.6f}] s, got {np.asarray(t_s).tolist()}")
        if self._k == 0:
            out = np.repeat(self._state[None, :, 0], t.size, axis=0)
        else:
            tau = np.clip(t - t_start, 0.0, self.period_s)
            out = self._propagate(self._last_start, self._last_u, tau)[:, :, 0]
        return out[0] if np.ndim(t_s) == 0 else out
