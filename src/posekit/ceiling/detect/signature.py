"""What the tracked laser dot looks like (:class:`DotSignature`), learned from the dots a tracker
accepted: its brightness and size, and the 1σ of a candidate's centroid."""

from __future__ import annotations

import math

from .spots import Dot

__all__ = ["DotSignature"]


class DotSignature:
    """What the tracked laser dot looks like, learned from the dots the tracker accepted.

    The laser's brightness above the background (``peak``) and blob size (``area_px``) stay
    within a factor of a few along a track (exposure steps, vignetting), while a lamp, a
    reflection or a dim LED differ. Running means of their logarithms over the accepted dots
    (a time constant of ``memory`` acceptances) give the reference; a candidate is
    consistent with it when its peak is at least ``min_peak_ratio`` of the reference and its
    area within a factor ``area_factor``. Until ``warmup`` dots were accepted everything
    passes. Used for eligibility (starting or re-acquiring a track), never to drop a dot the
    track follows.
    """

    def __init__(self, *, memory: float = 30.0, warmup: int = 5, min_peak_ratio: float = 0.35,
                 area_factor: float = 4.0):
        self.memory, self.warmup = float(memory), int(warmup)
        self.min_peak_ratio, self.area_factor = float(min_peak_ratio), float(area_factor)
        self.n = 0
        self.log_peak = 0.0
        self.log_area = 0.0
        self.recent_area = 0.0

    def update(self, dot: Dot) -> None:
        """Learn from a dot the tracker accepted."""
        lp, la = math.log(max(dot.peak, 1.0)), math.log(max(dot.area_px, 1))
        a = 1.0 / min(self.n + 1, self.memory)
        self.log_peak += a * (lp - self.log_peak)
        self.log_area += a * (la - self.log_area)
        b = 1.0 / min(self.n + 1, 10.0)
        self.recent_area += b * (dot.area_px - self.recent_area)
        self.n += 1

    def std_px(self, dot: Dot, floor_px: float = 0.1) -> float:
        """1σ per axis of the dot's centroid, px: ``0.04 sqrt(area)`` for a blooming or blurred
        blob, or the noise the background under it gives (``dot.noise_px``), whichever is
        larger (at least ``floor_px``); for a blob smaller than the recent ones (cut by an
        occluder's edge, a vent or the image border) up to the dot's radius in proportion to
        the missing area, since the centroid of a clipped dot moves away from the cut; for a
        blob larger than the recent ones (merged with a bright thing beside it: the halo on a
        white stripe saturates on that side) by ``extra/(1 + extra)`` of the radius, the shift
        of a centroid by an added area ``extra`` times the dot's at about a radius; for a spot
        partly on a background clipped at the white level (a lamp: its light is cut there) by
        the clipped share of its window times the radius."""
        s = max(floor_px, 0.04 * math.sqrt(max(dot.area_px, 1)), getattr(dot, "noise_px", 0.0))
        clipped = getattr(dot, "clipped_px", 0)
        if clipped:                                  # the spot lies partly on a clipped background
            r = math.sqrt(max(dot.area_px, 1) / math.pi)
            s = max(s, clipped / (clipped + dot.area_px) * r)
        if self.n >= self.warmup and self.recent_area > 0:
            r = math.sqrt(self.recent_area / math.pi)
            missing = 1.0 - dot.area_px / self.recent_area
            if missing > 0.15:
                s = max(s, missing * r)
            extra = dot.area_px / self.recent_area - 1.0
            if extra > 0.15:                         # merged with something bright beside it
                s = max(s, extra / (1.0 + extra) * r)
        return s

    def consistent(self, dot: Dot) -> bool:
        """True if ``dot`` could be the laser that was tracked."""
        if self.n < self.warmup:
            return True
        if math.log(max(dot.peak, 1.0)) < self.log_peak + math.log(self.min_peak_ratio):
            return False
        return abs(math.log(max(dot.area_px, 1)) - self.log_area) <= math.log(self.area_factor)
