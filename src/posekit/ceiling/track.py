"""Motion filter for the laser dots on the ceiling (the filter of the paper's future work).

One constant-velocity Kalman filter per dot colour in the world (ceiling) plane, mm:
state ``[x, y, vx, vy]``, continuous white-noise acceleration of spectral density
``accel_psd_mm2_s3`` (a ground robot: smooth motion, turns of a few hundred mm/s²), a
measurement covariance per detection (from the calibration's reprojection rms pushed
through the local Jacobian of the image-to-world homography), and a Mahalanobis gate
(χ², 2 dof) that rejects outliers such as reflections. A detection that fails the gate
but lies within ``gate_floor_mm`` of the prediction is a manoeuvre (the robot stopped,
started or turned abruptly), not an outlier: the covariance is inflated and the filter
follows it at once. After ``reinit_after`` consecutive rejected frames the filter restarts
at the detection (the robot was carried elsewhere).

Status of a frame, for the primary dot (red; its x, y are the track):

``ok``
    a dot was measured **and accepted** this frame; x, y is the filtered estimate.
``predicted``
    no accepted dot this frame (the dot fell into an air-conditioning hole, was occluded
    or gated out) and the last accepted one is at most ``max_predict_s`` old; x, y is the
    constant-velocity prediction.
``lost``
    no accepted dot for longer than ``max_predict_s`` (or never): x, y are NaN
    (empty in the CSV). The next detection re-initialises the filter.

A row is never ``ok`` without a dot. Heading (case B of the paper) is the direction from
the red to the green dot, filtered by a circular constant-turn-rate filter on the unwrapped
angle (innovations wrapped to (-π, π]); NaN with one dot, or when the green or red dot has
not been seen for ``max_predict_s``.

:class:`Tracker` works on world measurements (no video needed). :class:`MultiCameraTracker`
(case D) takes image detections from several calibrated cameras, maps them to the world,
picks one camera per frame (the active one while its dot stays clear of the image border,
else the one whose dot is farthest from its border) and feeds one :class:`Tracker`.
"""

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, GeometryError, TrajectoryError

__all__ = [
    "STATUSES",
    "TrackerConfig",
    "TrackRow",
    "DotState",
    "HeadingState",
    "Tracker",
    "Camera",
    "MultiCameraTracker",
    "cv_predict",
    "kf_update",
    "homography_jacobian",
    "border_distance",
]

STATUSES = ("ok", "predicted", "lost")

CHI2_2DOF_999 = float(-2.0 * np.log(1e-3))
"""χ² quantile of 2 dof at 0.999 (13.8): the default gate on the squared Mahalanobis distance."""


@dataclass(frozen=True)
class TrackerConfig:
    """Tuning of :class:`Tracker` (mm, s, rad).

    Attributes
    ----------
    dots : tuple of str
        Dot colours to track; the first is the primary dot whose x, y form the track
        (``("red",)`` for case A, ``("red", "green")`` for case B).
    accel_psd_mm2_s3 : float
        Spectral density q of the white acceleration noise of each axis, mm²/s³; the
        velocity of the model wanders by ``sqrt(q·t)`` over ``t`` s. The default
        (141 mm/s/√s) suits a ground robot such as the paper's Pioneer 3: at 15 fps with
        3 mm measurement noise it lowers the mean error of the raw dots by ~20 % on a
        rectangle with rounded corners and still follows a 300 mm/s turn of 200 mm radius
        (450 mm/s²) within 10 mm, without gating the turn out.
    meas_std_mm : float
        Measurement std per axis used when a measurement comes without its covariance.
    min_meas_std_mm : float
        Floor of the measurement std per axis (a noiseless calibration has rms 0).
    gate_chi2 : float
        A measurement whose squared Mahalanobis distance to the prediction exceeds this
        is rejected (default: 2-dof χ² at 0.999) unless it is within ``gate_floor_mm``.
    gate_floor_mm : float
        A candidate at most this far from the prediction, mm, is never rejected: it is a
        manoeuvre (the robot stops, starts or turns abruptly; 300 mm/s lost in one frame
        is 20 mm at 15 fps) and the covariance is inflated by ``d² / gate_chi2`` so that the
        filter follows it at once. Reflections and other lights are farther away.
    max_predict_s : float
        Predict through a dropout for at most this long, then report ``lost``.
    reinit_after : int
        After this many consecutive frames whose every candidate was gated out, the
        filter restarts at the best candidate (the robot was moved by hand, or the
        filter diverged).
    init_speed_std_mm_s : float
        Std of the velocity of a freshly initialised filter, mm/s.
    heading_psd_rad2_s3 : float
        Spectral density of the white angular acceleration of the heading filter, rad²/s³.
    init_rate_std_rad_s : float
        Std of the turn rate of a freshly initialised heading filter, rad/s.
    """

    dots: tuple[str, ...] = ("red",)
    accel_psd_mm2_s3: float = 2.0e4
    meas_std_mm: float = 5.0
    min_meas_std_mm: float = 0.05
    gate_chi2: float = CHI2_2DOF_999
    gate_floor_mm: float = 40.0
    max_predict_s: float = 1.0
    reinit_after: int = 5
    init_speed_std_mm_s: float = 500.0
    heading_psd_rad2_s3: float = 1.0
    init_rate_std_rad_s: float = 1.0

    def __post_init__(self):
        dots = tuple(self.dots)
        object.__setattr__(self, "dots", dots)
        if not dots or len(set(dots)) != len(dots) or not all(isinstance(d, str) and d for d in dots):
            raise ConfigError(f"TrackerConfig.dots: expected distinct colour names such as ('red',) "
                              f"or ('red', 'green'), got {self.dots!r}")
        for name in ("accel_psd_mm2_s3", "meas_std_mm", "gate_chi2", "init_speed_std_mm_s",
                     "heading_psd_rad2_s3", "init_rate_std_rad_s"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v > 0):
                raise ConfigError(f"TrackerConfig.{name}: expected a positive number, got {v!r}")
        for name in ("min_meas_std_mm", "max_predict_s", "gate_floor_mm"):
            v = getattr(self, name)
            if not (np.isfinite(v) and v >= 0):
                raise ConfigError(f"TrackerConfig.{name}: expected a number >= 0, got {v!r}")
        if int(self.reinit_after) != self.reinit_after or self.reinit_after < 1:
            raise ConfigError(f"TrackerConfig.reinit_after: expected an integer >= 1, got {self.reinit_after!r}")


@dataclass
class DotState:
    """Kalman state of one dot in the world plane.

    Attributes
    ----------
    x : ndarray, shape (4,) or None
        ``[x, y, vx, vy]`` in mm and mm/s at ``t_s``; None before the first detection
        and after the dot was lost.
    P : ndarray, shape (4, 4) or None
        Its covariance (mm², mm²/s, mm²/s²).
    t_s : float
        Time of the state, s.
    t_meas_s : float
        Time of the last accepted measurement, s (NaN if none).
    n_rejected : int
        Consecutive frames whose every candidate was gated out.
    last_d2 : float
        Squared Mahalanobis distance of the last associated candidate (NaN if none).
    """

    x: np.ndarray | None = None
    P: np.ndarray | None = None
    t_s: float = float("nan")
    t_meas_s: float = float("nan")
    n_rejected: int = 0
    last_d2: float = float("nan")


@dataclass
class HeadingState:
    """Circular filter of the heading: ``[θ, ω]`` with θ unwrapped (rad, rad/s)."""

    x: np.ndarray | None = None
    P: np.ndarray | None = None
    t_s: float = float("nan")
    t_meas_s: float = float("nan")


@dataclass
class TrackRow:
    """One frame of the track (a row of :func:`~posekit.ceiling.pipeline.write_track_csv` and a little more).

    Attributes
    ----------
    frame : int
        Frame index.
    time_s : float
        Frame time, s.
    x, y : float
        Primary (red) dot in the world plane, mm; NaN when ``status == "lost"``.
    heading_deg : float
        Direction from the red to the green dot, degrees in (-180, 180]; NaN with one dot
        or when either dot is lost.
    status : str
        ``"ok"``, ``"predicted"`` or ``"lost"`` (see the module docstring).
    std_mm : float
        Square root of the largest eigenvalue of the position covariance, mm (NaN when lost).
    camera : int
        Index of the camera whose measurement was used this frame (-1 if none).
    measured : dict
        ``{colour: (x, y)}`` world measurements accepted this frame, mm.
    dots : dict
        ``{colour: (x, y, status)}`` estimate and status of every tracked dot.
    """

    frame: int
    time_s: float
    x: float
    y: float
    heading_deg: float
    status: str
    std_mm: float = float("nan")
    camera: int = -1
    measured: dict = field(default_factory=dict)
    dots: dict = field(default_factory=dict)

    def csv_fields(self) -> list[str]:
        """``frame,time_s,x,y,heading_deg,status`` as strings; NaN becomes an empty field."""
        def f(v, fmt):
            return "" if not np.isfinite(v) else format(v, fmt)
        return [str(self.frame), f"{self.time_s:.6f}", f(self.x, ".3f"), f(self.y, ".3f"),
                f(self.heading_deg, ".3f"), self.status]


# --- Kalman kernels -----------------------------------------------------------------------

def cv_predict(x: np.ndarray, P: np.ndarray, dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity prediction of ``[p_1..p_n, v_1..v_n]`` over ``dt``.

    Parameters
    ----------
    x : ndarray, shape (2n,)
        Positions then velocities (any unit u; velocities in u/s).
    P : ndarray, shape (2n, 2n)
        Covariance of ``x``.
    dt : float
        Time step, s (>= 0).
    q : float
        Spectral density of the white acceleration of each axis, u²/s³.

    Returns
    -------
    x, P : ndarray
        Predicted state and covariance (new arrays).
    """
    n = x.shape[0] // 2
    x = x.copy()
    x[:n] += dt * x[n:]
    # F P Fᵀ with F = [[I, dt I], [0, I]], block-wise (cheaper than two matmuls)
    P = P.copy()
    P[:n, :] += dt * P[n:, :]
    P[:, :n] += dt * P[:, n:]
    a, b, c = dt ** 3 / 3.0 * q, dt ** 2 / 2.0 * q, dt * q      # continuous white-noise acceleration
    for i in range(n):
        P[i, i] += a
        P[i, i + n] += b
        P[i + n, i] += b
        P[i + n, i + n] += c
    return x, P


def kf_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray,
              innovation: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with a measurement of the first ``m`` state components (Joseph form).

    Parameters
    ----------
    x : ndarray, shape (k,)
        Prior state.
    P : ndarray, shape (k, k)
        Prior covariance.
    z : ndarray, shape (m,)
        Measurement of ``x[:m]``.
    R : ndarray, shape (m, m)
        Measurement covariance.
    innovation : ndarray, shape (m,), optional
        Use this instead of ``z - x[:m]`` (a wrapped angle difference).

    Returns
    -------
    x, P : ndarray
        Posterior state and covariance.
    """
    m = z.shape[0]
    nu = z - x[:m] if innovation is None else innovation
    S = P[:m, :m] + R
    K = (_inv_sym(S) @ P[:m, :]).T                # P Hᵀ S⁻¹ with H = [I 0]
    x = x + K @ nu
    IKH = np.eye(x.shape[0])
    IKH[:, :m] -= K
    P = IKH @ P @ IKH.T + K @ R @ K.T
    return x, 0.5 * (P + P.T)


def _inv_sym(S: np.ndarray) -> np.ndarray:
    """Inverse of symmetric positive-definite matrices (..., m, m); closed form for m <= 2
    (a general solver costs more than the whole filter step at this size)."""
    m = S.shape[-1]
    if m == 1:
        return 1.0 / S
    if m == 2:
        a, b, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
        det = a * d - b * b
        inv = np.empty_like(S)
        inv[..., 0, 0] = d / det
        inv[..., 1, 1] = a / det
        inv[..., 0, 1] = inv[..., 1, 0] = -b / det
        return inv
    return np.linalg.inv(S)


def _mahalanobis2(nu: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distances of innovations ``nu`` (K, m) under covariances ``S`` (K, m, m)."""
    return np.einsum("ki,kij,kj->k", nu, _inv_sym(S), nu)


def _wrap(a):
    """Angle(s) wrapped to (-π, π]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2.0 * np.pi)


# --- the world-plane tracker ---------------------------------------------------------------

def _as_candidates(value, colour: str) -> np.ndarray:
    """(K, 2) float array of candidate world positions (K may be 0)."""
    if value is None:
        return np.zeros((0, 2))
    z = np.asarray(value, dtype=float)
    if z.ndim == 1 and z.shape == (2,):
        z = z[None, :]
    if z.ndim != 2 or z.shape[1] != 2:
        raise GeometryError(f"Tracker.step: dots_world[{colour!r}] must have shape (2,) or (K, 2) "
                            f"(x, y in mm), got shape {np.shape(value)}")
    return z[np.all(np.isfinite(z), axis=1)]


def _as_covariances(value, k: int, colour: str, default_std: float, floor: float) -> np.ndarray:
    """(K, 2, 2) measurement covariances (default isotropic), floored at ``floor²``."""
    if value is None:
        R = np.broadcast_to(default_std ** 2 * np.eye(2), (k, 2, 2)).copy()
    else:
        R = np.asarray(value, dtype=float)
        if R.shape == (2, 2):
            R = np.broadcast_to(R, (k, 2, 2)).copy()
        if R.shape != (k, 2, 2) or not np.all(np.isfinite(R)):
            raise GeometryError(f"Tracker.step: meas_cov[{colour!r}] must be finite with shape (2, 2) "
                                f"or ({k}, 2, 2) (mm²), got shape {np.shape(value)}")
    return R + floor ** 2 * np.eye(2)


class Tracker:
    """Constant-velocity Kalman tracking of the laser dot(s) in the world plane.

    Parameters
    ----------
    config : TrackerConfig, optional
        Tuning; ``config.dots`` names the tracked colours, the first is the track.

    Examples
    --------
    >>> tr = Tracker(TrackerConfig(dots=("red",)))
    >>> tr.step(0.0, {"red": [100.0, 200.0]}).status
    'ok'
    >>> tr.step(0.1, {}).status              # dropout: constant-velocity prediction
    'predicted'
    >>> tr.step(1.2, None).status            # longer than max_predict_s
    'lost'
    """

    def __init__(self, config: TrackerConfig | None = None):
        self.config = TrackerConfig() if config is None else config
        self.reset()

    def reset(self) -> None:
        """Forget every dot and the heading (the next detection re-initialises)."""
        self.states = {c: DotState() for c in self.config.dots}
        self.heading = HeadingState()
        self.frame = 0
        self.t_s = float("nan")
        self._pred_cache = None

    # -- queries ---------------------------------------------------------------------------
    def _alive(self, st: DotState, t_s: float) -> bool:
        return st.x is not None and t_s - st.t_meas_s <= self.config.max_predict_s + 1e-9

    def predict(self, t_s: float) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """Predicted position of each live dot at ``t_s`` without changing the state.

        Returns
        -------
        dict
            ``{colour: (xy, cov)}`` with ``xy`` shape (2,) in mm and ``cov`` shape (2, 2)
            in mm², for every dot that is not lost at ``t_s`` (used to place the
            detector's region of interest and to choose a camera).
        """
        if self._pred_cache is not None and self._pred_cache[0] == t_s:
            return dict(self._pred_cache[1])
        out = {}
        for c, st in self.states.items():
            if self._alive(st, t_s):
                x, P = cv_predict(st.x, st.P, max(t_s - st.t_s, 0.0), self.config.accel_psd_mm2_s3)
                out[c] = (x[:2], P[:2, :2])
        self._pred_cache = (t_s, out)
        return dict(out)

    # -- one frame -------------------------------------------------------------------------
    def step(self, t_s: float, dots_world: Mapping | np.ndarray | None,
             meas_cov: Mapping | None = None, *, frame: int | None = None,
             camera: int = -1) -> TrackRow:
        """Advance to ``t_s`` and fuse this frame's detections.

        Parameters
        ----------
        t_s : float
            Frame time, s; must not decrease from one call to the next.
        dots_world : mapping, ndarray or None
            ``{colour: xy}`` with ``xy`` shape (2,) or (K, 2): candidate positions of that
            dot in the world plane, mm (K candidates: the one closest to the prediction
            in Mahalanobis distance is used; before the first fix, the first one). A bare
            array means the primary colour; None or ``{}`` means no dot this frame.
        meas_cov : mapping, optional
            ``{colour: R}`` with ``R`` shape (2, 2) or (K, 2, 2): measurement covariance
            of each candidate, mm². Default ``config.meas_std_mm²·I``.
        frame : int, optional
            Frame index of the row (default: a counter starting at 0).
        camera : int
            Recorded in the row.

        Returns
        -------
        TrackRow
            ``ok`` only if a primary dot was measured and accepted this frame.

        Raises
        ------
        TrajectoryError
            ``t_s`` is not finite or goes back in time.
        GeometryError
            A candidate array or covariance has the wrong shape.
        """
        cfg = self.config
        t_s = float(t_s)
        if not np.isfinite(t_s):
            raise TrajectoryError(f"Tracker.step: frame time must be finite, got {t_s}")
        if np.isfinite(self.t_s) and t_s < self.t_s:
            raise TrajectoryError(f"Tracker.step: frame time went back from {self.t_s:.6f} s to {t_s:.6f} s")
        if dots_world is None:
            dots_world = {}
        elif not isinstance(dots_world, Mapping):
            dots_world = {cfg.dots[0]: dots_world}
        unknown = set(dots_world) - set(cfg.dots)
        if unknown:
            raise GeometryError(f"Tracker.step: dot colour(s) {sorted(unknown)} are not tracked; "
                                f"tracked: {list(cfg.dots)}")
        meas_cov = {} if meas_cov is None else meas_cov
        self.t_s = t_s
        self._pred_cache = None
        frame = self.frame if frame is None else int(frame)
        self.frame = frame + 1

        measured, dots = {}, {}
        for c in cfg.dots:
            z = _as_candidates(dots_world.get(c), c)
            R = _as_covariances(meas_cov.get(c), len(z), c, cfg.meas_std_mm, cfg.min_meas_std_mm)
            accepted = self._update_dot(self.states[c], t_s, z, R)
            if accepted is not None:
                measured[c] = accepted
        for c in cfg.dots:
            st = self.states[c]
            if c in measured:
                status = "ok"
            elif self._alive(st, t_s):
                status = "predicted"
            else:
                status = "lost"
                st.x = st.P = None
            xy = st.x[:2].copy() if st.x is not None else np.full(2, np.nan)
            dots[c] = (float(xy[0]), float(xy[1]), status)

        heading = self._update_heading(t_s, measured)
        main = self.states[cfg.dots[0]]
        x, y, status = dots[cfg.dots[0]]
        std = float(np.sqrt(np.linalg.eigvalsh(main.P[:2, :2])[-1])) if main.x is not None else float("nan")
        return TrackRow(frame=frame, time_s=t_s, x=x, y=y, heading_deg=heading, status=status, std_mm=std,
                        camera=camera if measured else -1,
                        measured={c: (float(v[0]), float(v[1])) for c, (v, _) in measured.items()},
                        dots=dots)

    def _update_dot(self, st: DotState, t_s: float, z: np.ndarray, R: np.ndarray):
        """Predict ``st`` to ``t_s`` and fuse the best gated candidate; returns (z, R) or None."""
        cfg = self.config
        if st.x is not None and not self._alive(st, t_s):
            st.x = st.P = None                      # lost: the next detection starts afresh
        if st.x is not None:
            st.x, st.P = cv_predict(st.x, st.P, max(t_s - st.t_s, 0.0), cfg.accel_psd_mm2_s3)
        st.t_s = t_s
        if len(z) == 0:
            st.last_d2 = float("nan")
            return None
        if st.x is None:                            # first fix (or after lost): take the first candidate
            st.x = np.array([z[0, 0], z[0, 1], 0.0, 0.0])
            st.P = np.zeros((4, 4))
            st.P[:2, :2] = R[0]
            st.P[2:, 2:] = cfg.init_speed_std_mm_s ** 2 * np.eye(2)
            st.t_meas_s, st.n_rejected, st.last_d2 = t_s, 0, 0.0
            return z[0], R[0]
        d2 = _mahalanobis2(z - st.x[:2], st.P[:2, :2] + R)
        k = int(np.argmin(d2))
        st.last_d2 = float(d2[k])
        if d2[k] > cfg.gate_chi2 and np.hypot(*(z[k] - st.x[:2])) <= cfg.gate_floor_mm:
            # a manoeuvre (the robot stopped, started or turned abruptly), not an outlier:
            # inflate the covariance until the innovation is consistent, then update
            st.P = st.P * (d2[k] / cfg.gate_chi2)
            d2[k] = cfg.gate_chi2
        if d2[k] > cfg.gate_chi2:
            st.n_rejected += 1
            if st.n_rejected < cfg.reinit_after:
                return None
            st.x = np.array([z[k, 0], z[k, 1], 0.0, 0.0])     # consistently elsewhere: restart there
            st.P = np.zeros((4, 4))
            st.P[:2, :2] = R[k]
            st.P[2:, 2:] = cfg.init_speed_std_mm_s ** 2 * np.eye(2)
        else:
            st.x, st.P = kf_update(st.x, st.P, z[k], R[k])
        st.t_meas_s, st.n_rejected = t_s, 0
        return z[k], R[k]

    def _update_heading(self, t_s: float, measured: dict) -> float:
        """Circular filter of the red→green direction; returns degrees in (-180, 180] or NaN."""
        cfg = self.config
        if len(cfg.dots) < 2:
            return float("nan")
        h = self.heading
        c0, c1 = cfg.dots[0], cfg.dots[1]
        if h.x is not None and t_s - h.t_meas_s > cfg.max_predict_s + 1e-9:
            h.x = h.P = None
        if h.x is not None:
            h.x, h.P = cv_predict(h.x, h.P, max(t_s - h.t_s, 0.0), cfg.heading_psd_rad2_s3)
        h.t_s = t_s
        if c0 in measured and c1 in measured:
            (z0, R0), (z1, R1) = measured[c0], measured[c1]
            d = z1 - z0
            dist = float(np.hypot(*d))
            if dist > 0:
                theta = float(np.arctan2(d[1], d[0]))
                n = np.array([-d[1], d[0]]) / dist          # perpendicular: the direction of angle error
                var = float(n @ (R0 + R1) @ n) / dist ** 2   # small-angle law: σθ² = σ⊥² / d²
                if h.x is None:
                    h.x = np.array([theta, 0.0])
                    h.P = np.diag([var, cfg.init_rate_std_rad_s ** 2])
                else:
                    nu = _wrap(theta - h.x[0])
                    h.x, h.P = kf_update(h.x, h.P, np.array([h.x[0] + nu]), np.array([[var]]),
                                         innovation=np.array([nu]))
                h.t_meas_s = t_s
        if h.x is None or any(self.states[c].x is None for c in (c0, c1)):
            return float("nan")
        deg = float(np.degrees(_wrap(h.x[0])))
        return 180.0 if deg == -180.0 else deg


# --- several cameras (case D) --------------------------------------------------------------

def homography_jacobian(to_world, uv: np.ndarray, step_px: float = 0.5) -> np.ndarray:
    """Jacobian of an image-to-world map at image points, by central differences.

    Parameters
    ----------
    to_world : callable
        ``(N, 2) px -> (N, 2) mm`` (``Calibration.image_to_world``).
    uv : ndarray, shape (K, 2)
        Image points, px.
    step_px : float
        Half step of the differences, px (exact to O(step²) for a homography).

    Returns
    -------
    ndarray, shape (K, 2, 2)
        ``d(x, y)/d(u, v)`` in mm/px.
    """
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    e = step_px * np.eye(2)
    pts = np.concatenate([uv + e[0], uv - e[0], uv + e[1], uv - e[1]])
    w = np.asarray(to_world(pts), dtype=float).reshape(4, -1, 2)
    J = np.empty((uv.shape[0], 2, 2))
    J[:, :, 0] = (w[0] - w[1]) / (2 * step_px)
    J[:, :, 1] = (w[2] - w[3]) / (2 * step_px)
    return J


def border_distance(uv: np.ndarray, image_size: tuple[int, int]) -> np.ndarray:
    """Distance of image points to the nearest image border, px (negative outside).

    Parameters
    ----------
    uv : ndarray, shape (K, 2)
        Pixel coordinates (u right, v down; pixel centres at integers).
    image_size : (int, int)
        ``(width, height)``, px.
    """
    uv = np.asarray(uv, dtype=float).reshape(-1, 2)
    w, h = image_size
    return np.minimum.reduce([uv[:, 0] + 0.5, w - 0.5 - uv[:, 0], uv[:, 1] + 0.5, h - 0.5 - uv[:, 1]])


@dataclass
class Camera:
    """One fixed camera of case D.

    Attributes
    ----------
    calibration : object
        Has ``image_to_world((N, 2) px) -> (N, 2) mm``, ``world_to_image`` and ``rms_px``
        (a :class:`posekit.ceiling.calibration.Calibration`).
    image_size : (int, int)
        ``(width, height)`` of its frames, px.
    name : str
        For messages and reports.
    detection_std_px : float
        Floor of the per-axis std of a dot detection, px; the measurement std is
        ``max(calibration.rms_px, detection_std_px)`` pushed through the homography.
    """

    calibration: object
    image_size: tuple[int, int]
    name: str = ""
    detection_std_px: float = 0.1

    def __post_init__(self):
        cal = self.calibration
        H = getattr(cal, "H_world_image", None)
        self._H_wi = None if H is None else np.asarray(H, dtype=float)
        H = getattr(cal, "H_image_world", None)
        self._H_iw = None if H is None else np.asarray(H, dtype=float)
        self._std_px = max(float(getattr(cal, "rms_px", 0.0) or 0.0), self.detection_std_px)

    def measurement(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """World positions (K, 2) mm and covariances (K, 2, 2) mm² of image points (K, 2) px.

        The covariance is ``s² J Jᵀ`` with ``s = max(calibration.rms_px, detection_std_px)``
        and ``J`` the Jacobian of the image-to-world homography at the point (analytic when
        the calibration exposes ``H_world_image``, central differences otherwise).
        """
        uv = np.asarray(uv, dtype=float).reshape(-1, 2)
        if self._H_wi is not None:
            H = self._H_wi
            q = uv @ H[:, :2].T + H[:, 2]
            w = q[:, 2:3]
            xy = q[:, :2] / w
            J = (H[None, :2, :2] - xy[:, :, None] * H[None, 2:3, :2]) / w[:, :, None]
        else:
            xy = np.asarray(self.calibration.image_to_world(uv), dtype=float).reshape(-1, 2)
            J = homography_jacobian(self.calibration.image_to_world, uv)
        return xy, self._std_px ** 2 * J @ np.swapaxes(J, 1, 2)

    def to_image(self, xy: np.ndarray) -> np.ndarray:
        """Image points (K, 2) px of world points (K, 2) mm (NaN behind the camera)."""
        xy = np.asarray(xy, dtype=float).reshape(-1, 2)
        if self._H_iw is None:
            try:
                return np.asarray(self.calibration.world_to_image(xy), dtype=float).reshape(-1, 2)
            except GeometryError:                 # beyond this camera's horizon
                return np.full_like(xy, np.nan)
        H = self._H_iw
        q = xy @ H[:, :2].T + H[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(q[:, 2:3] > 0, q[:, :2] / q[:, 2:3], np.nan)


class MultiCameraTracker:
    """One world track from several calibrated cameras that each see part of the ceiling.

    Each frame every camera reports its detections (image pixels). Detections are mapped
    to the world plane with that camera's calibration; the primary dot of each camera is
    gated against the track's prediction. The camera used is the previous one while its
    accepted dot stays at least ``border_margin_px`` from its image border; otherwise the
    camera whose accepted dot is farthest from its border (ties: smallest measurement
    covariance). Only that camera's dots update the :class:`Tracker`; with one camera this
    is the single-camera tracker with a position-dependent measurement covariance.

    Parameters
    ----------
    cameras : sequence of Camera
    config : TrackerConfig, optional
    border_margin_px : float
        Keep the active camera while its dot is at least this far from the border.
    """

    def __init__(self, cameras: Sequence[Camera], config: TrackerConfig | None = None,
                 border_margin_px: float = 20.0):
        if len(cameras) == 0:
            raise ConfigError("MultiCameraTracker: expected at least one camera")
        self.cameras = list(cameras)
        self.tracker = Tracker(config)
        self.border_margin_px = float(border_margin_px)
        self.active = -1

    @property
    def config(self) -> TrackerConfig:
        return self.tracker.config

    def reset(self) -> None:
        self.tracker.reset()
        self.active = -1

    def predicted_uv(self, t_s: float) -> list[dict[str, tuple[float, float]]]:
        """Predicted image position of each live dot in each camera at ``t_s``.

        Returns
        -------
        list of dict
            Per camera ``{colour: (u, v)}`` px, only for dots whose prediction falls inside
            that camera's image (the detector's region of interest); empty when lost.
        """
        pred = self.tracker.predict(t_s)
        if not pred:
            return [{} for _ in self.cameras]
        colours = list(pred)
        xy = np.array([pred[c][0] for c in colours])
        out = []
        for cam in self.cameras:
            uv = cam.to_image(xy)
            inside = np.all(np.isfinite(uv), axis=1)
            inside[inside] = border_distance(uv[inside], cam.image_size) > 0
            out.append({c: (float(uv[k, 0]), float(uv[k, 1])) for k, c in enumerate(colours) if inside[k]})
        return out

    def step(self, t_s: float, dots_image: Sequence[Mapping | None], *,
             frame: int | None = None) -> TrackRow:
        """Fuse one frame of detections from every camera.

        Parameters
        ----------
        t_s : float
            Frame time, s (the cameras are assumed synchronised).
        dots_image : sequence of mapping or None
            One entry per camera: ``{colour: uv}`` with ``uv`` shape (2,) or (K, 2),
            image pixels; None when that camera was not read or saw nothing.

        Returns
        -------
        TrackRow
            With ``camera`` the index of the camera used (-1 if none).
        """
        if len(dots_image) != len(self.cameras):
            raise ConfigError(f"MultiCameraTracker.step: expected detections of {len(self.cameras)} "
                              f"camera(s), got {len(dots_image)}")
        cfg = self.tracker.config
        primary = cfg.dots[0]
        pred = self.tracker.predict(t_s)
        seen = {}                                # camera -> {colour: (xy (K, 2), R (K, 2, 2), border (K,))}
        views = []                               # (camera, primary seen, border distance, trace R)
        for i, (cam, det) in enumerate(zip(self.cameras, dots_image)):
            if not det:
                continue
            meas = {}
            for c, uv in det.items():
                if c not in cfg.dots:
                    continue
                uv = np.asarray(uv, dtype=float).reshape(-1, 2)
                uv = uv[np.all(np.isfinite(uv), axis=1)]
                if len(uv):
                    xy, R = cam.measurement(uv)
                    meas[c] = (xy, R, border_distance(uv, cam.image_size))
            if not meas:
                continue
            seen[i] = meas
            key = primary if primary in meas else next(iter(meas))
            xy, R, bd = meas[key]
            if key in pred:                      # keep only candidates that pass the gate
                p, Pp = pred[key]
                d2 = _mahalanobis2(xy - p, Pp + cfg.min_meas_std_mm ** 2 * np.eye(2) + R)
                ok = (d2 <= cfg.gate_chi2) | (np.hypot(*(xy - p).T) <= cfg.gate_floor_mm)
                if not ok.any():
                    continue
                k = int(np.argmin(np.where(ok, d2, np.inf)))
            else:
                k = 0
            views.append((i, key == primary, float(bd[k]), float(R[k, 0, 0] + R[k, 1, 1])))
        if not views:
            if not seen:
                return self.tracker.step(t_s, None, frame=frame)
            # nothing passed the gate: give the tracker the detections of the active (or the
            # first seeing) camera so that its outlier and re-initialisation logic runs
            chosen = self.active if self.active in seen else next(iter(seen))
        else:
            views.sort(key=lambda v: (not v[1], -v[2], v[3]))   # primary seen, far from border, small R
            chosen = views[0][0]
            for i, has_primary, bd, _ in views:
                if i == self.active and has_primary and bd >= self.border_margin_px:
                    chosen = i
                    break
            self.active = chosen
        meas = seen[chosen]
        return self.tracker.step(t_s, {c: m[0] for c, m in meas.items()}, {c: m[1] for c, m in meas.items()},
                                 frame=frame, camera=chosen)
