"""Pose filters for a stream of estimates: a constant-velocity Kalman filter on SE(3), and
information-weighted fusion of the last K estimates.

One profile pins down x, z and the rotations about y and z of the sensor to microns and
millidegrees, but the shift along y and the tilt about x only as one combination (they are
almost perfectly anti-correlated, see :mod:`~posekit.profiler.estimate.solve`): on ``demo-5`` at the
nominal pose σ(y) ≈ 170 µm against σ(x) ≈ 5 µm. A stream holds many profiles of nearly the
same pose, and both filters here combine them with each estimate's full 6×6 covariance, so
the weak combination is averaged down where it is weak and the well-known components keep
their precision.

Both filters take one estimate at a time::

    out = pose_filter.update(t_s, T_G_F, cov)      # -> FilteredPose
    pose_filter.reset()

``T_G_F`` (4, 4) is the estimated pose of the profiler frame F in the gauge frame G, mm;
``cov`` (6, 6) its covariance ``[δt (mm), δθ (rad)]`` with both parts in G
(``t_true = t + δt``, ``R_true = Exp(δθ) R``: the convention of
:class:`~posekit.profiler.estimate.solve.PoseEstimate`). The output carries the same convention.

:class:`ConstantVelocityFilter`
    12-state error-state Kalman filter (pose and its velocity, white-noise acceleration
    between samples). Follows a moving robot with a lag set by ``accel_mm_s2``; an estimate
    that disagrees with the prediction beyond a χ² gate is rejected, and ``max_rejects`` of
    them in a row re-start the filter at the new pose (a step the motion model did not allow).
:class:`WindowFusion`
    The information-weighted mean of the last K estimates: exact for a robot at rest, K
    samples of lag otherwise. An estimate that disagrees with the older ones beyond the gate
    drops them (the robot moved), so a step is followed at once.
"""

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ...errors import ConfigError
from ...geometry import matrix_from_rotation_vector, quaternion_from_matrix, rotation_vector_from_matrix

__all__ = ["FilteredPose", "ConstantVelocityFilter", "WindowFusion", "FILTERS", "make_filter"]

#: Names accepted by :func:`make_filter` (and ``posekit profiler serve --filter``).
FILTERS = ("cv", "window")
_GATE_PROBABILITY = 1e-6       # an estimate whose χ²(6) exceeds this tail is implausible


def _chi2_gate(probability: float, dof: int = 6) -> float:
    from scipy.stats import chi2
    return float(chi2.isf(probability, dof))


@dataclass(frozen=True)
class FilteredPose:
    """One output of a pose filter.

    Attributes
    ----------
    status : str
        ``init`` (first estimate, or the first after a reset by time), ``ok`` (the estimate
        was combined), ``rejected`` (the estimate failed the gate: the output is the
        prediction), ``reset`` (the filter re-started at this estimate: the robot moved in
        a way the model did not allow).
    T_G_F : ndarray, shape (4, 4)
        Filtered pose of F in G, mm.
    cov : ndarray, shape (6, 6)
        Its covariance ``[δt (mm), δθ (rad)]`` in G.
    velocity : ndarray, shape (6,)
        ``[v (mm/s), ω (rad/s)]`` in G (zeros for :class:`WindowFusion`).
    nis : float
        Normalised innovation squared of the estimate against the prediction (χ² with 6
        dof when the models hold); NaN when there was nothing to compare.
    count : int
        Estimates combined into this output (1 after ``init``/``reset``).
    """

    status: str
    T_G_F: np.ndarray
    cov: np.ndarray
    velocity: np.ndarray
    nis: float
    count: int

    @property
    def std_t_um(self) -> np.ndarray:
        """Standard deviation of the translation along x, y, z of G, µm, shape (3,)."""
        return np.sqrt(np.abs(np.diag(self.cov)[:3])) * 1e3

    @property
    def std_rot_deg(self) -> np.ndarray:
        """Standard deviation of the rotation about x, y, z of G, degrees, shape (3,)."""
        return np.degrees(np.sqrt(np.abs(np.diag(self.cov)[3:])))

    def to_record(self) -> dict:
        """The ``filter`` field of a server record (JSON-ready: lists of floats, no NaN).

        ``{"status", "t_mm": [3], "q_wxyz": [4], "std_t_um": [3], "std_rot_deg": [3],
        "cov": 6×6 [mm, rad] in G, "v_mm_s": [3], "w_rad_s": [3], "nis": float|null,
        "count": int}``
        """
        cov = self.cov
        return {"status": self.status,
                "t_mm": [float(v) for v in self.T_G_F[:3, 3]],
                "q_wxyz": [float(v) for v in quaternion_from_matrix(self.T_G_F[:3, :3], check=False)],
                "std_t_um": [float(v) for v in self.std_t_um],
                "std_rot_deg": [float(v) for v in self.std_rot_deg],
                "cov": [[float(v) for v in row] for row in cov],
                "v_mm_s": [float(v) for v in self.velocity[:3]],
                "w_rad_s": [float(v) for v in self.velocity[3:]],
                "nis": float(self.nis) if math.isfinite(self.nis) else None,
                "count": int(self.count)}


def _check_estimate(T_G_F, cov) -> tuple[np.ndarray, np.ndarray]:
    T = np.asarray(T_G_F, dtype=float)
    C = np.asarray(cov, dtype=float)
    if T.shape != (4, 4) or C.shape != (6, 6):
        raise ConfigError(f"pose filter: expected T_G_F of shape (4, 4) and cov (6, 6), got {T.shape} and {C.shape}")
    if not (np.all(np.isfinite(T)) and np.all(np.isfinite(C))):
        raise ConfigError("pose filter: the pose and its covariance must be finite (the closed form 'cf' has no "
                          "covariance: use the 'mle' method)")
    return T, 0.5 * (C + C.T)


def _difference(T_a, T_b) -> np.ndarray:
    """``[t_a - t_b, Log(R_a R_bᵀ)]``: the left error of pose a about pose b, shape (6,)."""
    d = np.empty(6)
    d[:3] = T_a[:3, 3] - T_b[:3, 3]
    d[3:] = rotation_vector_from_matrix(T_a[:3, :3] @ T_b[:3, :3].T, check=False)
    return d


def _apply(T, dx) -> np.ndarray:
    """Pose T moved by the left twist dx = [δt, δθ] in G."""
    out = T.copy()
    out[:3, 3] += dx[:3]
    out[:3, :3] = matrix_from_rotation_vector(dx[3:]) @ T[:3, :3]
    return out


def _positive(value, name: str) -> float:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
        raise ConfigError(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)


class ConstantVelocityFilter:
    """Error-state Kalman filter on SE(3) with a constant-velocity motion model.

    State: the pose ``T_G_F`` and its velocity ``[v (mm/s), ω (rad/s)]`` in G; error state
    ``[δt, δθ, δv, δω]`` (12) with the left convention of the estimates' covariance.
    Between two estimates ``dt`` apart the velocity is held (``t += v dt``,
    ``R ← Exp(ω dt) R``) and gains the covariance of a piecewise-constant white
    acceleration of standard deviation ``accel_mm_s2`` (translation) and
    ``angular_accel_rad_s2`` (rotation) per axis: ``σ² [[dt⁴/4, dt³/2], [dt³/2, dt²]]``.
    Each estimate is a direct measurement of the pose with its own 6×6 covariance.

    Parameters
    ----------
    accel_mm_s2 : float
        Typical acceleration of the flange, mm/s² (1σ per axis). Small: heavy smoothing of
        a robot at rest; large: little lag on a moving one (a 1 mm oscillation at 10 Hz
        accelerates at about 4,000 mm/s²). With the default 10 and estimates every 12 ms
        of a gauge at rest (``demo-5``, LJ-X8400 noise) the variance of y and of the tilt
        about x drops about 13-fold, of x and z 2-3-fold, and about 95 % of the errors stay
        within two of the filter's standard deviations.
    angular_accel_rad_s2 : float
        The same for the rotation, rad/s² (default 0.025: 10 mm/s² at 400 mm).
    init_speed_mm_s, init_rate_rad_s : float
        1σ of the unknown velocity when the filter (re)starts.
    gate_probability : float
        An estimate whose normalised innovation (χ², 6 dof) lies beyond this tail is rejected.
    max_rejects : int
        This many rejected estimates in a row re-start the filter at the latest one.
    max_gap_s : float
        A gap between estimates longer than this (or time going backwards) re-starts the
        filter (status ``init``).

    Examples
    --------
    >>> import numpy as np
    >>> f = ConstantVelocityFilter()
    >>> T = np.eye(4); cov = np.diag([1e-6, 1e-2, 1e-6, 1e-6, 1e-6, 1e-6])   # y known to 100 µm
    >>> [f.update(0.012 * k, T, cov).status for k in range(3)]
    ['init', 'ok', 'ok']
    >>> bool(f.update(0.036, T, cov).std_t_um[1] < 100.0)                  # four estimates: better
    True
    """

    def __init__(self, accel_mm_s2: float = 10.0, angular_accel_rad_s2: float = 0.025, *,
                 init_speed_mm_s: float = 50.0, init_rate_rad_s: float = 0.1,
                 gate_probability: float = _GATE_PROBABILITY, max_rejects: int = 3, max_gap_s: float = 0.5):
        self.accel_mm_s2 = _positive(accel_mm_s2, "ConstantVelocityFilter: accel_mm_s2")
        self.angular_accel_rad_s2 = _positive(angular_accel_rad_s2, "ConstantVelocityFilter: angular_accel_rad_s2")
        self.init_speed_mm_s = _positive(init_speed_mm_s, "ConstantVelocityFilter: init_speed_mm_s")
        self.init_rate_rad_s = _positive(init_rate_rad_s, "ConstantVelocityFilter: init_rate_rad_s")
        if not (isinstance(gate_probability, float) and 0.0 < gate_probability < 1.0):
            raise ConfigError(f"ConstantVelocityFilter: gate_probability must be in (0, 1), got {gate_probability!r}")
        if not (isinstance(max_rejects, int) and max_rejects >= 1):
            raise ConfigError(f"ConstantVelocityFilter: max_rejects must be an integer >= 1, got {max_rejects!r}")
        self.max_gap_s = _positive(max_gap_s, "ConstantVelocityFilter: max_gap_s")
        self.gate = _chi2_gate(gate_probability)
        self.max_rejects = max_rejects
        self._accel2 = np.array([self.accel_mm_s2] * 3 + [self.angular_accel_rad_s2] * 3) ** 2
        self._diag = np.arange(6)
        self.reset()

    def reset(self) -> None:
        """Forget the state; the next estimate starts the filter."""
        self.T = None
        self.v = np.zeros(6)
        self.P = np.zeros((12, 12))
        self._t = None
        self._rejects = 0
        self._count = 0

    def _start(self, t_s: float, T, C, status: str) -> FilteredPose:
        self.T = T.copy()
        self.v = np.zeros(6)
        self.P = np.zeros((12, 12))
        self.P[:6, :6] = C
        self.P[6:9, 6:9] = np.eye(3) * self.init_speed_mm_s ** 2
        self.P[9:, 9:] = np.eye(3) * self.init_rate_rad_s ** 2
        self._t = t_s
        self._rejects = 0
        self._count = 1
        return FilteredPose(status, self.T.copy(), C.copy(), self.v.copy(), math.nan, 1)

    def _predict(self, dt: float) -> None:
        if dt <= 0.0:
            return
        self.T = _apply(self.T, self.v * dt)
        P = self.P.copy()                      # F P Fᵀ with F = [[I, dt I], [0, I]], by blocks
        P[:6] += dt * self.P[6:]
        P[:, :6] += dt * P[:, 6:]
        a = self._accel2
        i = self._diag
        P[i, i] += a * dt ** 4 / 4
        P[i, i + 6] += a * dt ** 3 / 2
        P[i + 6, i] += a * dt ** 3 / 2
        P[i + 6, i + 6] += a * dt ** 2
        self.P = P

    def update(self, t_s: float, T_G_F, cov) -> FilteredPose:
        """Combine one estimate taken at ``t_s`` (s) and return the filtered pose.

        Parameters
        ----------
        t_s : float
            Time of the profile, s (any origin; only differences matter).
        T_G_F : array_like, shape (4, 4)
            Estimated pose of F in G, mm.
        cov : array_like, shape (6, 6)
            Its covariance ``[δt (mm), δθ (rad)]`` in G.

        Raises
        ------
        ConfigError
            If the shapes are wrong or a value is not finite.
        """
        T_m, C = _check_estimate(T_G_F, cov)
        t_s = float(t_s)
        if self.T is None:
            return self._start(t_s, T_m, C, "init")
        dt = t_s - self._t
        if not (math.isfinite(dt) and 0.0 <= dt <= self.max_gap_s):
            return self._start(t_s, T_m, C, "init")
        self._predict(dt)
        self._t = t_s
        y = _difference(T_m, self.T)
        S = self.P[:6, :6] + C
        try:
            L_inv = np.linalg.inv(np.linalg.cholesky(S))
        except np.linalg.LinAlgError:
            return self._start(t_s, T_m, C, "reset")
        w = L_inv @ y
        nis = float(w @ w)
        if nis > self.gate:
            self._rejects += 1
            if self._rejects >= self.max_rejects:
                return self._start(t_s, T_m, C, "reset")
            return FilteredPose("rejected", self.T.copy(), self.P[:6, :6].copy(), self.v.copy(), nis, self._count)
        self._rejects = 0
        K = self.P[:, :6] @ (L_inv.T @ L_inv)              # P Hᵀ S⁻¹ with H = [I6 0]
        dx = K @ y
        self.T = _apply(self.T, dx[:6])
        self.v = self.v + dx[6:]
        IKH = np.eye(12)
        IKH[:, :6] -= K
        P = IKH @ self.P @ IKH.T + K @ C @ K.T                  # Joseph form: stays symmetric PSD
        self.P = 0.5 * (P + P.T)
        self._count += 1
        return FilteredPose("ok", self.T.copy(), self.P[:6, :6].copy(), self.v.copy(), nis, self._count)

    def __repr__(self) -> str:
        return (f"ConstantVelocityFilter(accel_mm_s2={self.accel_mm_s2:g}, "
                f"angular_accel_rad_s2={self.angular_accel_rad_s2:g}, max_gap_s={self.max_gap_s:g})")


class WindowFusion:
    """Information-weighted mean of the last ``k`` estimates (a robot at rest).

    The estimates are expressed as left errors about the newest one, weighted by the inverse
    of their covariances and averaged: ``x̄ = (Σ Cᵢ⁻¹)⁻¹ Σ Cᵢ⁻¹ xᵢ``, covariance
    ``(Σ Cᵢ⁻¹)⁻¹``. When the newest estimate disagrees with an older one beyond the χ² gate
    (with both covariances), that one and every older one are dropped (status ``reset``).

    Parameters
    ----------
    k : int
        Estimates fused, 1 to 10,000.
    gate_probability : float
    max_gap_s : float
        Estimates older than this (s, against the newest) are dropped.

    Examples
    --------
    >>> import numpy as np
    >>> f = WindowFusion(k=4)
    >>> cov = np.diag([1e-6, 1e-2, 1e-6, 1e-6, 1e-6, 1e-6])
    >>> out = [f.update(0.012 * i, np.eye(4), cov) for i in range(6)]
    >>> out[-1].count, round(float(out[-1].std_t_um[1]), 1)              # σ / √4
    (4, 50.0)
    """

    def __init__(self, k: int = 10, *, gate_probability: float = _GATE_PROBABILITY, max_gap_s: float = 0.5):
        if not (isinstance(k, int) and 1 <= k <= 10_000):
            raise ConfigError(f"WindowFusion: k must be an integer in 1..10000, got {k!r}")
        if not (isinstance(gate_probability, float) and 0.0 < gate_probability < 1.0):
            raise ConfigError(f"WindowFusion: gate_probability must be in (0, 1), got {gate_probability!r}")
        self.k = k
        self.max_gap_s = _positive(max_gap_s, "WindowFusion: max_gap_s")
        self.gate = _chi2_gate(gate_probability)
        self.reset()

    def reset(self) -> None:
        """Forget every estimate."""
        self._window: deque = deque(maxlen=self.k)

    def update(self, t_s: float, T_G_F, cov) -> FilteredPose:
        """Add one estimate taken at ``t_s`` (s) and return the fused pose (see
        :meth:`ConstantVelocityFilter.update` for the parameters)."""
        T_m, C = _check_estimate(T_G_F, cov)
        t_s = float(t_s)
        try:
            info_m = np.linalg.inv(C)
        except np.linalg.LinAlgError:
            self.reset()
            return FilteredPose("reset", T_m, C, np.zeros(6), math.nan, 1)
        win = self._window
        status = "ok" if win else "init"
        if win and not (math.isfinite(t_s - win[-1][0]) and 0.0 <= t_s - win[-1][0]):
            win.clear()
            status = "init"
        keep = [item for item in win if t_s - item[0] <= self.max_gap_s]
        keep = keep[max(0, len(keep) - (self.k - 1)):]          # with the new one: k in all
        nis = math.nan
        if keep:
            Ts = np.stack([item[1] for item in keep])
            xs = np.empty((len(keep), 6))
            xs[:, :3] = Ts[:, :3, 3] - T_m[:3, 3]
            xs[:, 3:] = rotation_vector_from_matrix(Ts[:, :3, :3] @ T_m[:3, :3].T, check=False)
            Cs = np.stack([item[2] for item in keep]) + C
            d2 = np.einsum("ki,ki->k", xs, np.linalg.solve(Cs, xs[..., None])[..., 0])
            bad = np.flatnonzero(d2 > self.gate)
            nis = float(d2[-1])
            if len(bad):
                keep = keep[bad[-1] + 1:]
                xs = xs[bad[-1] + 1:]
                status = "reset"
        else:
            xs = np.empty((0, 6))
        info = info_m.copy()
        rhs = np.zeros(6)
        for item, x in zip(keep, xs):
            info += item[3]
            rhs += item[3] @ x
        cov_f = np.linalg.inv(info)
        cov_f = 0.5 * (cov_f + cov_f.T)
        T_f = _apply(T_m, cov_f @ rhs)
        win.clear()
        win.extend(keep)
        win.append((t_s, T_m, C, info_m))
        return FilteredPose(status, T_f, cov_f, np.zeros(6), nis, len(keep) + 1)

    def __repr__(self) -> str:
        return f"WindowFusion(k={self.k}, max_gap_s={self.max_gap_s:g})"


def make_filter(name: str, *, accel_mm_s2: float = 10.0, angular_accel_rad_s2: float = 0.025, window: int = 10):
    """A pose filter by name: ``cv`` (:class:`ConstantVelocityFilter`) or ``window``
    (:class:`WindowFusion` of ``window`` estimates).

    Raises
    ------
    ConfigError
        For an unknown name or a parameter out of range.
    """
    if name == "cv":
        return ConstantVelocityFilter(accel_mm_s2, angular_accel_rad_s2)
    if name == "window":
        return WindowFusion(window)
    raise ConfigError(f"unknown pose filter '{name}'; expected one of {', '.join(FILTERS)}")
