"""Accuracy of the ceiling system as in the paper's §V-B.

Two studies:

1. **Known points** (:func:`known_points_assessment`): the dot is placed at 36 known world
   points (a 6×6 grid over the ceiling rectangle), each frame is rendered, the dot is
   detected, mapped to the world with the calibration, and compared with its true position
   (the paper: mean error 14 mm over about 24 m²).
2. **Heading from two dots** (:func:`simulate_heading_error`): the paper's simulation of
   Fig. 7. Two dots D = 400 mm apart (the Pioneer 3); "as the average position estimation
   error is 14 mm, we assume that the actual positions of the laser points are uniformly
   distributed in two circles centred at the ideal positions with radius e = 14 mm"; the std
   of the angle between the estimated and the ideal line is 2.00°.

Why the error model matters (and which one the paper used). To first order the heading
error is the difference of the two dots' error components perpendicular to the line,
divided by D: ``δθ ≈ (e2⊥ − e1⊥) / D``. For an isotropic error the perpendicular component
has variance ``E|e|²/2``, so::

    std(δθ) ≈ sqrt((E|e1|² + E|e2|²) / 2) / D  =  e_rms / D       (same error law on both dots)

The heading std depends on the **rms** radial error of a dot, not its mean:

====================  =============  ============  ==================  ==============
error of each dot      mean |e|       rms |e|       std(δθ), closed     D=400, e=14
====================  =============  ============  ==================  ==============
on the circle |e|=e    e              e             e / D               2.005°
uniform in the disc    2e/3           e/√2          e / (√2 D)          1.418°
2D Gaussian σ          σ·√(π/2)       σ·√2          √2·σ / D            2.263° (*)
====================  =============  ============  ==================  ==============

(*) with σ = 14 mm / √(π/2) = 11.17 mm, i.e. a mean radial error of 14 mm.

Only errors **on the circle** of radius e reproduce both the paper's premise (the mean
position error is exactly e = 14 mm) and its result (2.00°): a dot uniformly spread in the
disc has a mean error of only 9.3 mm and gives 1.42°, and a Gaussian with a mean error of
14 mm has a larger rms (15.8 mm) and gives 2.26°. So "uniformly distributed in two circles
with radius e" means on the circumference, and :func:`simulate_heading_error` defaults to
``model="circle"``.
"""

from dataclasses import dataclass, replace

import numpy as np

from ...errors import ConfigError, GeometryError

__all__ = [
    "ERROR_MODELS",
    "PAPER_DOT_DISTANCE_MM",
    "PAPER_MEAN_ERROR_MM",
    "PAPER_HEADING_STD_DEG",
    "ErrorStats",
    "error_stats",
    "gaussian_sigma_for_mean_error",
    "sample_position_errors",
    "heading_std_closed_form",
    "HeadingSimulation",
    "simulate_heading_error",
    "known_points_grid",
    "KnownPointsResult",
    "known_points_assessment",
]

ERROR_MODELS = ("circle", "disc", "gaussian")
PAPER_DOT_DISTANCE_MM = 400.0
"""Distance between the two laser dots in §V-B (the Pioneer 3), mm."""
PAPER_MEAN_ERROR_MM = 14.0
"""Mean position error of the 36-point assessment of §V-B, mm."""
PAPER_HEADING_STD_DEG = 2.00
"""Std of the heading error of the §V-B simulation, degrees."""


# --- position errors -----------------------------------------------------------------------

@dataclass(frozen=True)
class ErrorStats:
    """Statistics of position errors (Euclidean distances), mm."""

    n: int
    mean_mm: float
    rms_mm: float
    p95_mm: float
    max_mm: float

    def __str__(self) -> str:
        return (f"n={self.n}: mean {self.mean_mm:.2f} mm, rms {self.rms_mm:.2f} mm, "
                f"p95 {self.p95_mm:.2f} mm, max {self.max_mm:.2f} mm")


def error_stats(xy_est: np.ndarray, xy_true: np.ndarray) -> ErrorStats:
    """Mean, rms, 95th percentile and maximum of ``|xy_est - xy_true|``.

    Parameters
    ----------
    xy_est, xy_true : ndarray, shape (N, 2)
        Estimated and true positions in the world plane, mm. Rows with a NaN in
        either are ignored (a lost frame has no position).

    Returns
    -------
    ErrorStats
        All NaN with ``n=0`` if no row is finite.
    """
    a = np.asarray(xy_est, dtype=float).reshape(-1, 2)
    b = np.asarray(xy_true, dtype=float).reshape(-1, 2)
    if a.shape != b.shape:
        raise GeometryError(f"error_stats: estimated and true positions differ in shape: {a.shape} vs {b.shape}")
    ok = np.all(np.isfinite(a), axis=1) & np.all(np.isfinite(b), axis=1)
    d = np.hypot(*(a[ok] - b[ok]).T)
    if d.size == 0:
        return ErrorStats(0, *(4 * [float("nan")]))
    return ErrorStats(int(d.size), float(d.mean()), float(np.sqrt(np.mean(d ** 2))),
                      float(np.percentile(d, 95)), float(d.max()))


def known_points_grid(x_range_mm: tuple[float, float], y_range_mm: tuple[float, float],
                      n: int = 6, inset: float = 0.1) -> np.ndarray:
    """An ``n × n`` grid of known points over a rectangle of the ceiling (36 for ``n=6``).

    Parameters
    ----------
    x_range_mm, y_range_mm : (float, float)
        Extent of the rectangle in the world plane, mm.
    n : int
        Points per side.
    inset : float
        Fraction of each side left free at both ends (keeps the dot inside the image).

    Returns
    -------
    ndarray, shape (n*n, 2)
        World points, mm, row-major in y then x.
    """
    if n < 1 or not 0 <= inset < 0.5:
        raise ConfigError(f"known_points_grid: need n >= 1 and 0 <= inset < 0.5, got n={n}, inset={inset}")
    (x0, x1), (y0, y1) = x_range_mm, y_range_mm
    xs = np.linspace(x0 + inset * (x1 - x0), x1 - inset * (x1 - x0), n)
    ys = np.linspace(y0 + inset * (y1 - y0), y1 - inset * (y1 - y0), n)
    X, Y = np.meshgrid(xs, ys)
    return np.column_stack([X.ravel(), Y.ravel()])


# --- heading from two dots (Fig. 7) -------------------------------------------------------

def gaussian_sigma_for_mean_error(mean_error_mm: float) -> float:
    """Per-axis σ of an isotropic 2D Gaussian whose mean radial error is ``mean_error_mm``.

    The radial error of a 2D Gaussian is Rayleigh-distributed with mean ``σ·√(π/2)``,
    so ``σ = mean / √(π/2)`` (14 mm → 11.17 mm).
    """
    return float(mean_error_mm) / np.sqrt(np.pi / 2.0)


def _check_model(model: str, error_mm: float, distance_mm: float | None = None, dots_with_error: int = 2):
    if model not in ERROR_MODELS:
        raise ConfigError(f"heading simulation: error model must be one of {ERROR_MODELS}, got {model!r}")
    if not (np.isfinite(error_mm) and error_mm >= 0):
        raise ConfigError(f"heading simulation: error_mm must be >= 0, got {error_mm!r}")
    if distance_mm is not None and not (np.isfinite(distance_mm) and distance_mm > 0):
        raise ConfigError(f"heading simulation: distance_mm must be > 0, got {distance_mm!r}")
    if dots_with_error not in (1, 2):
        raise ConfigError(f"heading simulation: dots_with_error must be 1 or 2, got {dots_with_error!r}")


def sample_position_errors(n: int, error_mm: float, model: str = "circle",
                           rng: np.random.Generator | int | None = None) -> np.ndarray:
    """Random isotropic position errors of one dot.

    Parameters
    ----------
    n : int
        Number of samples.
    error_mm : float
        ``"circle"``: every error has length ``error_mm`` in a uniform direction;
        ``"disc"``: uniform in the disc of radius ``error_mm``;
        ``"gaussian"``: isotropic Gaussian whose **mean** radial error is ``error_mm``.
    model : {"circle", "disc", "gaussian"}
    rng : numpy Generator, int or None

    Returns
    -------
    ndarray, shape (n, 2)
        Errors in the world plane, mm.
    """
    _check_model(model, error_mm)
    rng = np.random.default_rng(rng)
    if model == "gaussian":
        return rng.normal(0.0, gaussian_sigma_for_mean_error(error_mm), size=(n, 2))
    angle = rng.uniform(0.0, 2.0 * np.pi, n)
    r = np.full(n, float(error_mm)) if model == "circle" else error_mm * np.sqrt(rng.uniform(0.0, 1.0, n))
    return np.column_stack([r * np.cos(angle), r * np.sin(angle)])


def _rms_error(error_mm: float, model: str) -> float:
    if model == "circle":
        return float(error_mm)
    if model == "disc":
        return float(error_mm) / np.sqrt(2.0)
    return np.sqrt(2.0) * gaussian_sigma_for_mean_error(error_mm)


def _mean_error(error_mm: float, model: str) -> float:
    return float(error_mm) * {"circle": 1.0, "disc": 2.0 / 3.0, "gaussian": 1.0}[model]


def heading_std_closed_form(distance_mm: float = PAPER_DOT_DISTANCE_MM, error_mm: float = PAPER_MEAN_ERROR_MM,
                            model: str = "circle", dots_with_error: int = 2) -> float:
    """Small-error std of the heading from two dots, degrees.

    ``std(δθ) ≈ e_rms · sqrt(k / 2) / D`` with ``e_rms`` the rms radial error of a dot
    under ``model`` (see the module docstring) and ``k`` the number of dots with error:
    ``e / D`` on the circle, ``e / (√2 D)`` in the disc, ``√2 σ / D`` for a Gaussian
    (``√2·σ/d`` of the brief). 400 mm and 14 mm on the circle: 2.005°.

    Parameters
    ----------
    distance_mm : float
        Distance D between the two dots, mm.
    error_mm : float
        Size of the position error, mm (its meaning per ``model`` as in
        :func:`sample_position_errors`).
    model : {"circle", "disc", "gaussian"}
    dots_with_error : {1, 2}
        Both dots err (the paper), or only one (the other is exact).
    """
    _check_model(model, error_mm, distance_mm, dots_with_error)
    return float(np.degrees(_rms_error(error_mm, model) * np.sqrt(dots_with_error / 2.0) / distance_mm))


@dataclass(frozen=True)
class HeadingSimulation:
    """Result of :func:`simulate_heading_error` (errors in degrees, lengths in mm)."""

    distance_mm: float
    error_mm: float
    model: str
    dots_with_error: int
    n: int
    mean_deg: float
    std_deg: float
    std_se_deg: float
    closed_form_deg: float
    mean_position_error_mm: float
    rms_position_error_mm: float

    def __str__(self) -> str:
        return (f"heading from two dots {self.distance_mm:g} mm apart, {self.model} error {self.error_mm:g} mm "
                f"on {self.dots_with_error} dot(s) (mean |e| {self.mean_position_error_mm:.2f} mm, "
                f"rms {self.rms_position_error_mm:.2f} mm): std {self.std_deg:.3f}° ± {self.std_se_deg:.3f}° "
                f"(Monte Carlo, n={self.n}), closed form {self.closed_form_deg:.3f}°, mean {self.mean_deg:+.4f}°")


def simulate_heading_error(distance_mm: float = PAPER_DOT_DISTANCE_MM, error_mm: float = PAPER_MEAN_ERROR_MM,
                           model: str = "circle", n: int = 200_000, dots_with_error: int = 2,
                           rng: np.random.Generator | int | None = 0) -> HeadingSimulation:
    """Monte Carlo of the paper's Fig. 7: heading error of the line through two noisy dots.

    The ideal dots are ``P1 = (0, 0)`` and ``P2 = (D, 0)``; each estimated dot is its ideal
    position plus an error drawn by :func:`sample_position_errors`; the heading error is
    the angle of ``P2' − P1'`` (exact ``atan2``, no small-angle approximation).

    Parameters
    ----------
    distance_mm : float
        D, mm (the paper: 400).
    error_mm : float
        e, mm (the paper: 14).
    model : {"circle", "disc", "gaussian"}
        ``"circle"`` reproduces the paper (2.00°).
    n : int
        Number of Monte Carlo samples.
    dots_with_error : {1, 2}
        2: both dots err (the paper); 1: only ``P2``.
    rng : numpy Generator, int or None

    Returns
    -------
    HeadingSimulation
        ``std_deg`` with its standard error ``std_se_deg = std / sqrt(2 (n - 1))``, and the
        closed form of :func:`heading_std_closed_form`.
    """
    _check_model(model, error_mm, distance_mm, dots_with_error)
    if int(n) != n or n < 2:
        raise ConfigError(f"simulate_heading_error: n must be an integer >= 2, got {n!r}")
    rng = np.random.default_rng(rng)
    e2 = sample_position_errors(n, error_mm, model, rng)
    e1 = sample_position_errors(n, error_mm, model, rng) if dots_with_error == 2 else np.zeros((n, 2))
    d = np.array([distance_mm, 0.0]) + e2 - e1
    theta = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    std = float(theta.std(ddof=1))
    r = np.hypot(*e2.T)
    return HeadingSimulation(
        distance_mm=float(distance_mm), error_mm=float(error_mm), model=model,
        dots_with_error=int(dots_with_error), n=int(n), mean_deg=float(theta.mean()), std_deg=std,
        std_se_deg=std / np.sqrt(2.0 * (n - 1)),
        closed_form_deg=heading_std_closed_form(distance_mm, error_mm, model, dots_with_error),
        mean_position_error_mm=float(r.mean()), rms_position_error_mm=float(np.sqrt(np.mean(r ** 2))))


# --- 36 known points in rendered frames ---------------------------------------------------

@dataclass(frozen=True)
class KnownPointsResult:
    """Result of :func:`known_points_assessment`.

    Attributes
    ----------
    world_xy : ndarray, shape (n, 2)
        Known (true) dot positions on the ceiling, mm.
    image_uv : ndarray, shape (n, 2)
        Detected dot in the image, px (NaN where no dot was found).
    estimated_xy : ndarray, shape (n, 2)
        ``calibration.image_to_world(image_uv)``, mm (NaN where missed).
    true_uv : ndarray, shape (n, 2)
        Exact projection of ``world_xy`` by the renderer's camera, px.
    stats : ErrorStats
        Of ``|estimated_xy - world_xy|`` over the detected points, mm.
    detection_stats : ErrorStats
        Of ``|image_uv - true_uv|``, px (the detector's share of the error).
    n_missed : int
        Points where no dot was detected (a dot in a vent opening, out of view).
    """

    world_xy: np.ndarray
    image_uv: np.ndarray
    estimated_xy: np.ndarray
    true_uv: np.ndarray
    stats: ErrorStats
    detection_stats: ErrorStats
    n_missed: int

    def __str__(self) -> str:
        return (f"{len(self.world_xy)} known points ({self.n_missed} not detected): world error {self.stats}; "
                f"image error mean {self.detection_stats.mean_mm:.3f} px, max {self.detection_stats.max_mm:.3f} px")


def known_points_assessment(config, calibration, *, n: int = 6, rect_mm=None, inset: float = 0.0,
                            empty_first: bool = True, detector_options: dict | None = None,
                            camera=None) -> KnownPointsResult:
    """The paper's §V-B accuracy experiment on rendered frames.

    The red dot is placed, still, at each of the ``n × n`` points of
    :func:`known_points_grid` over ``rect_mm`` (default: the robot's rectangle
    ``config.path_rect_mm``); one frame per point is rendered (its own noise and
    illumination), a fresh :class:`~posekit.ceiling.detect.DotDetector` finds the dot,
    and the calibration maps it to the ceiling. With ``empty_first`` the detector first
    sees a frame without the dot (other noise, same illumination: the robot drove in);
    otherwise it starts its background from the frame with the dot (the robot stood
    there when the video started), which costs about 0.1 px of bias.

    Parameters
    ----------
    config : posekit.ceiling.sim.config.SceneConfig
        The scene (camera, ceiling, noise). Its dots and path are replaced.
    calibration : Calibration
        ``image_to_world`` of the camera (e.g. from the grid corners of ``reference.png``).
    n : int
        Points per side (6: the paper's 36 points).
    rect_mm : (x0, y0, x1, y1), optional
        World rectangle of the grid, mm.
    inset : float
        Fraction of each side left free at both ends.
    empty_first : bool
        Show the detector a frame without the dot first (see above).
    detector_options : dict, optional
        Keyword arguments of the detector.
    camera : CameraModel, optional
        Lens model: detected dots are undistorted with it before ``calibration`` (which then
        maps undistorted pixels). The scene's own stray lights, people and exposure steps are
        left out (the experiment measures the geometry).

    Returns
    -------
    KnownPointsResult
    """
    from ..detect.dots import DotDetector
    from ..sim.render import CeilingScene

    x0, y0, x1, y1 = config.path_rect_mm if rect_mm is None else rect_mm
    pts = known_points_grid((x0, x1), (y0, y1), n=n, inset=inset)
    eps = 1e-3                                   # a degenerate rectangle: the robot stands at its corner

    clean = {k: 0 for k in ("occluders", "shadows", "stray_lights", "blinking_lights", "reflections")
             if hasattr(config, k)}
    if hasattr(config, "exposure_step_s"):
        clean["exposure_step_s"] = 0.0
    if hasattr(config, "stray_light_xy_mm"):
        clean["stray_light_xy_mm"] = ()

    def still_at(p):
        return replace(config, dots=("red",), path_rect_mm=(p[0], p[1], p[0] + eps, p[1] + eps),
                       path_phase_s=0.0, duration_s=1.0 / config.fps, **clean)

    scene = CeilingScene(still_at(pts[0]))       # the background is rendered once
    uv = np.full((len(pts), 2), np.nan)
    true_uv = np.asarray(scene.project(pts), dtype=float)
    for i, p in enumerate(pts):
        scene.config = still_at(p)
        truth = scene.truth()
        if np.hypot(*(truth.xy_red[0] - p)) > 10 * eps:
            raise RuntimeError("known_points_assessment: the renderer did not place the dot where asked "
                               "(CeilingScene changed?)")
        frame = scene.render_frame(2 * i + 1)
        det = DotDetector(colors=("red",), **(detector_options or {}))
        if empty_first:
            scene.config = still_at((-1e5, -1e5))         # off the ceiling: no dot in view
            det.detect(scene.render_frame(2 * i))
        dots = [d for d in det.detect(frame) if d.color == "red" and d.saturated]     # the laser drives its channel to white
        if dots:
            uv[i] = (dots[0].u, dots[0].v)
    est = np.full_like(uv, np.nan)
    ok = np.all(np.isfinite(uv), axis=1)
    if ok.any():
        seen = uv[ok] if camera is None else camera.undistort_points(uv[ok])
        est[ok] = calibration.image_to_world(seen, invalid="nan")
    return KnownPointsResult(world_xy=pts, image_uv=uv, estimated_xy=est, true_uv=true_uv,
                             stats=error_stats(est, pts), detection_stats=error_stats(uv, true_uv),
                             n_missed=int((~ok).sum()))
