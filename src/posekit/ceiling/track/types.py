"""What the ceiling tracker is tuned by, keeps per dot, and gives per frame.

:class:`TrackerConfig` (the tuning, mm, s, rad), :class:`DotState` and :class:`HeadingState`
(the Kalman states of :class:`~posekit.ceiling.track.Tracker`) and :class:`TrackRow` (one frame
of the track, a row of the track CSV). All are re-exported by :mod:`posekit.ceiling.track`.
"""

from dataclasses import dataclass, field

import numpy as np

from ...errors import ConfigError
from ...verdict import Verdict

__all__ = ["CHI2_2DOF_999", "STATUSES", "DotState", "HeadingState", "TrackRow", "TrackerConfig"]

STATUSES = ("ok", "suspect", "predicted", "lost")

CHI2_2DOF_999 = float(-2.0 * np.log(1e-3))
"""χ² quantile of 2 dof at 0.999 (13.8): the default gate on the squared Mahalanobis distance."""


@dataclass(frozen=True)
class TrackerConfig:
    """Tuning of :class:`~posekit.ceiling.track.Tracker` (mm, s, rad).

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
        prediction is no longer trusted: the dot is re-acquired like a lost one, on a
        candidate that is verified (not flagged ineligible: a learned static light, a
        signature unlike the laser's) and unambiguous (the only one); until then ``predicted``.
    init_speed_std_mm_s : float
        Std of the velocity of a freshly initialised filter, mm/s.
    heading_psd_rad2_s3 : float
        Spectral density of the white angular acceleration of the heading filter, rad²/s³.
    init_rate_std_rad_s : float
        Std of the turn rate of a freshly initialised heading filter, rad/s.
    max_speed_mm_s : float
        Fastest the dot can move, mm/s. The gate never reaches farther from the last accepted
        position than ``gate_floor_mm + max_speed_mm_s * (time since it)``, however long the
        prediction ran (a widening covariance must not accept noise), and a lone verified
        candidate within that reach but outside the χ² gate (a sharp turn, a stop at a
        corner) is re-acquired in the same frame.
    confirm_after_s : float
        After coasting longer than this (s), a candidate inside the gate resumes the track only
        when the next frame shows it moving as the track was.
    min_move_mm : float
        Without the caller's verdict on motion (``moving=`` of :meth:`Tracker.step`, the
        image-space test of :class:`~posekit.ceiling.detect.scene.StaticLights`), a lone
        candidate starts a track only once it has moved this far (mm) over its chained
        history. 0: a lone candidate starts the track at once (world measurements known to be
        the dot, no stray light possible).
    adapt_noise : bool
        Scale the measurement covariance by a running mean of the normalised innovation
        squared of accepted measurements (at least 1), so that ``std_mm`` stays honest when
        the detections are noisier than the calibration says (compression, bloom, residual
        lens distortion).
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
    max_speed_mm_s: float = 1000.0
    adapt_noise: bool = True
    confirm_after_s: float = 0.25
    min_move_mm: float = 8.0

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
        for name in ("min_meas_std_mm", "max_predict_s", "gate_floor_mm", "max_speed_mm_s", "confirm_after_s",
                     "min_move_mm"):
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
    z_meas : ndarray, shape (2,) or None
        Last accepted measurement, mm (the centre of the reach gate).
    noise_scale : float
        Factor (>= 1) on the measurement covariance learned from the innovations.
    noise_stats : dict or None
        The last accepted measurements and squared second differences behind ``noise_scale``.
    pending : tuple or None
        ``(t_s, xy)`` of a candidate seen once while coasting that may resume the track when
        it is seen again, moving as predicted.
    seen : list or None
        ``[(t_s, (K, 2) xy), ...]``: the verified candidates of the last second without a
        track, to tell which one moves.
    probation : tuple or None
        ``(until_s, jump_mm, conflicted)`` after a re-acquisition away from a live prediction:
        the rows are ``suspect`` until then, and for as long as the track lives once another
        moving laser-like spot (or the previous dot) was seen during that time.
    alt : Alternative or None
        The previous track while the identity is in doubt (:mod:`posekit.ceiling.track.verdicts`):
        the rows' ``std_mm`` spans both hypotheses.
    """

    x: np.ndarray | None = None
    P: np.ndarray | None = None
    t_s: float = float("nan")
    t_meas_s: float = float("nan")
    n_rejected: int = 0
    last_d2: float = float("nan")
    z_meas: np.ndarray | None = None
    noise_scale: float = 1.0
    noise_stats: dict | None = None
    pending: tuple | None = None
    seen: list | None = None
    probation: tuple | None = None
    alt: object = None


@dataclass
class HeadingState:
    """Circular filter of the heading: ``[θ, ω]`` with θ unwrapped (rad, rad/s)."""

    x: np.ndarray | None = None
    P: np.ndarray | None = None
    t_s: float = float("nan")
    t_meas_s: float = float("nan")


@dataclass
class TrackRow:
    """One frame of the track (a row of :func:`~posekit.ceiling.track.pipeline.write_track_csv` and a little more).

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
        ``"ok"``, ``"suspect"``, ``"predicted"`` or ``"lost"`` (see
        :mod:`posekit.ceiling.track.tracker`).
    std_mm : float
        1σ of the position: square root of the largest eigenvalue of the position
        covariance, mm (NaN when lost); while coasting it grows with the process noise
        fitted from the track (:func:`~posekit.ceiling.track.motion_noise.fitted_accel_psd`).
    std_heading_deg : float
        1σ of the heading, degrees (NaN with one dot or without a heading).
    reasons : tuple of str
        Why the row is not ``ok`` (empty when it is).
    camera : int
        Index of the camera whose measurement was used this frame (-1 if none).
    measured : dict
        ``{colour: (x, y)}`` world measurements accepted this frame, mm.
    dots : dict
        ``{colour: (x, y, status)}`` estimate and status of every tracked dot.
    robot : int
        Which robot (0 with one robot; see :mod:`posekit.ceiling.multitrack`).
    """

    frame: int
    time_s: float
    x: float
    y: float
    heading_deg: float
    status: str
    std_mm: float = float("nan")
    std_heading_deg: float = float("nan")
    reasons: tuple = ()
    camera: int = -1
    measured: dict = field(default_factory=dict)
    dots: dict = field(default_factory=dict)
    robot: int = 0

    @property
    def reason(self) -> str:
        """The reasons joined by ``"; "`` (the CSV's ``reason`` field)."""
        return "; ".join(self.reasons)

    @property
    def verdict(self) -> Verdict:
        """The row as the shared :class:`posekit.verdict.Verdict` (std of x/y in mm, heading in degrees)."""
        std = None
        if np.isfinite(self.std_mm):
            std = {"xy_mm": float(self.std_mm)}
            if np.isfinite(self.std_heading_deg):
                std["heading_deg"] = float(self.std_heading_deg)
        return Verdict(self.status, self.reasons, std)

    def csv_fields(self) -> list[str]:
        """``frame,time_s,x,y,heading_deg,status,std_mm,std_heading_deg,reason`` as strings;
        NaN becomes an empty field."""
        def f(v, fmt):
            return "" if not np.isfinite(v) else format(v, fmt)
        return [str(self.frame), f"{self.time_s:.6f}", f(self.x, ".3f"), f(self.y, ".3f"),
                f(self.heading_deg, ".3f"), self.status, f(self.std_mm, ".3f"), f(self.std_heading_deg, ".3f"),
                self.reason]

    def json_record(self) -> dict:
        """``{"frame", "time_s", "x", "y", "heading_deg", "status", "std_mm", "std_heading_deg",
        "reason"}`` (NaN → None; ``reason`` None when ``ok``)."""
        def f(v):
            return float(v) if np.isfinite(v) else None
        return {"frame": int(self.frame), "time_s": f(self.time_s), "x": f(self.x), "y": f(self.y),
                "heading_deg": f(self.heading_deg), "status": self.status, "std_mm": f(self.std_mm),
                "std_heading_deg": f(self.std_heading_deg), "reason": self.reason or None}
