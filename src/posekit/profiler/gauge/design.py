"""Random gauges within the paper's design limits (§III-D), for tests and design studies."""

import numpy as np

from ...errors import ConfigError, GaugeError
from ..sensor import LJ_X8400, ProfilerModel
from .model import Gauge, gauge_from_design

__all__ = ["random_gauge"]


def random_gauge(n_corners: int, rng=None, *, beta_min_deg: float = 50.0, width_mm: float | None = None,
                 y_half_mm: float = 15.0, min_gap_mm: float = 5.0, u_spread: float = 0.35,
                 min_y_half_mm: float = 8.0, strict_length: bool = False, model: ProfilerModel = LJ_X8400,
                 max_tries: int = 1000) -> Gauge:
    """A random multi-plane gauge that a profiler can measure in one profile.

    The block is at most as wide as the measuring range's near width minus margins (so all
    corners fit in view), and no face is steeper than ``90° - beta_min_deg`` (the paper's
    β: the sensor can tilt up to β before a face self-occludes). Neighbouring faces
    alternate in slope (a zig-zag cross-section with height steps of several mm), and the
    ridges are skewed in the x–y plane so that every pose component is observable.

    Parameters
    ----------
    n_corners : int
        Number of ridges, >= 4.
    rng : numpy.random.Generator or int or None
    beta_min_deg : float
        Smallest admissible angle between a face and the vertical, degrees.
    width_mm : float, optional
        Block width (default: uniform in 60 %–85 % of the near-range width).
    y_half_mm : float
        Largest half length of the block along the ridges, mm.
    min_gap_mm : float
        Smallest x gap between neighbouring ridges anywhere on the block, mm.
    u_spread : float
        Ridge skews ``u = dx/dy`` are uniform in ±``u_spread`` whatever ``n_corners``, so
        gauges with more corners are not worse at observing y; the block is shortened
        along y (down to ``min_y_half_mm``) where neighbouring ridges would meet.
    min_y_half_mm : float
        Shortest admissible half length, mm.
    strict_length : bool
        Insist on the full ``y_half_mm`` (draw again rather than shorten).
    model : ProfilerModel
    max_tries : int

    Returns
    -------
    Gauge
        Never an ambiguous one (:func:`~posekit.profiler.gauge.ambiguity.gauge_ambiguity`): a draw
        whose reversed reading fits the ridges is drawn again.

    Raises
    ------
    ConfigError
        If no draw in ``max_tries`` meets the limits; the message counts the draws refused
        as ambiguous.
    """
    if n_corners < 4:
        raise ConfigError(f"random_gauge: expected n_corners >= 4, got {n_corners}")
    if not 0 < beta_min_deg < 90:
        raise ConfigError(f"random_gauge: beta_min_deg must lie in (0, 90), got {beta_min_deg}")
    rng = np.random.default_rng(rng)
    max_slope = np.tan(np.radians(90.0 - beta_min_deg))
    ambiguous = 0
    for _ in range(max_tries):
        width = width_mm if width_mm is not None else rng.uniform(0.6, 0.85) * model.width_near
        span = 0.8 * width
        gaps = rng.uniform(1.0, 2.0, n_corners - 1)
        ridge_x = np.concatenate([[0.0], np.cumsum(gaps)])
        ridge_x = (ridge_x / ridge_x[-1] - 0.5) * span
        if np.min(np.diff(ridge_x)) < min_gap_mm + 2:
            continue
        signs = np.where(np.arange(n_corners + 1) % 2 == 0, 1.0, -1.0) * rng.choice([-1.0, 1.0])
        slopes_x = signs * rng.uniform(0.3, 0.85, n_corners + 1) * max_slope
        # Ridge skews from the same distribution whatever n (y is observed through them);
        # the block gets shorter along y where neighbouring ridges would come too close.
        ridge_u = rng.uniform(-u_spread, u_spread, n_corners)
        du = np.abs(np.diff(ridge_u))
        room = (np.diff(ridge_x) - min_gap_mm) / np.maximum(du, 1e-9)
        # ... and where an outer ridge would leave the block
        edge = np.array([ridge_x[0] + width / 2, width / 2 - ridge_x[-1]]) - min_gap_mm
        room_out = edge / np.maximum(np.abs(ridge_u[[0, -1]]), 1e-9)
        y_half = min(y_half_mm, float(np.min(room)), float(np.min(room_out)))
        if y_half < min_y_half_mm or (strict_length and y_half < y_half_mm):
            continue
        try:
            g = gauge_from_design(f"random-{n_corners}", ridge_x, slopes_x, ridge_u,
                                  y_slope0=rng.uniform(-0.1, 0.1) * max_slope,
                                  extent=((-width / 2, width / 2), (-y_half, y_half)), mounting="normal")
        except GaugeError:
            continue
        if g.ambiguity is not None:          # the design-rule check: profiles must tell the mounting
            ambiguous += 1
            continue
        # skewed ridges (a spread of u) make y and the tilt about x observable
        if g.beta_deg >= beta_min_deg and np.ptp(g.ridge_s[:, 0]) >= 0.5 * u_spread:
            return g
    note = f" ({ambiguous} refused as ambiguous: their reversed reading fits)" if ambiguous else ""
    raise ConfigError(f"random_gauge: no gauge with {n_corners} corners, beta >= {beta_min_deg} deg and "
                      f"ridge gaps >= {min_gap_mm} mm in {max_tries} tries{note}; relax the limits")
