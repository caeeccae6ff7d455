"""A detected spot (:class:`Dot`) and the lasers' colours (:class:`LaserColor`,
:data:`LASER_COLORS`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Dot", "LaserColor", "LASER_COLORS"]


@dataclass(frozen=True)
class LaserColor:
    """Colour thresholds of one laser.

    ``hue_deg = (lo, hi)`` is the accepted hue range in degrees on [0, 360); ``lo > hi`` wraps
    through 0° (red). ``min_saturation`` applies to the light a blob adds, summed over the
    blob (on [0, 1]); ``channel``: the laser's own channel in BGR order (2: red, 1: green),
    which it drives to the sensor's white level.
    """

    name: str
    hue_deg: tuple[float, float]
    min_saturation: float = 0.45
    channel: int = 2

    def hue_mask(self, hue_deg: np.ndarray) -> np.ndarray:
        """Which hues (degrees) are this laser's."""
        lo, hi = self.hue_deg
        return (hue_deg >= lo) & (hue_deg <= hi) if lo <= hi else (hue_deg >= lo) | (hue_deg <= hi)


#: Red ~650 nm and green ~532 nm laser pointers as an RGB camera sees them. Summed over the
#: spot (as shares of each channel's headroom), the light a red dot adds keeps a hue within
#: 330°-30° and a saturation >= 0.15 in all but the worst compression; where it does not
#: (JPEG q60 applied twice on a bright pavement: the test generator's dot turns magenta-white,
#: hue 310°, saturation 0.18), the spot is saturated and its colour unknown (see
#: :meth:`DotDetector._colour`).
LASER_COLORS = {
    "red": LaserColor("red", (330.0, 30.0), min_saturation=0.15, channel=2),
    "green": LaserColor("green", (75.0, 170.0), min_saturation=0.3, channel=1),
}


@dataclass(frozen=True)
class Dot:
    """A detected laser dot.

    ``u, v``: sub-pixel position in px (pixel-centre convention: the top-left pixel's centre
    is (0, 0)); ``area_px``: pixels in its blob; ``peak``: the largest background difference
    in the blob, summed over the three channels (grey levels, 0-765); ``stray``: the blob is a
    static light (:class:`~posekit.ceiling.detect.scene.StaticLights`; set by the caller, never
    by the detector), so it must not start or re-acquire a track; ``saturated``: some pixel of
    the blob reaches ``core_level`` in a channel — a laser pointer is far brighter than the
    room it lights, so its core saturates a camera exposed for the room (only such blobs may
    start a track; a dim reflection or a person's red shirt does not); ``noise_px``: 1σ per
    axis of the centroid that the background's measured noise under the blob's window gives
    (px; a dot on flickering tape or a compressed, textured background moves by this much);
    ``background_p``: p-value of "the spot's surroundings are the unchanged background" (the
    ring test of :class:`DotDetector`; small: the spot sits on something that moved in, such
    as a car or a person); ``bbox``: its blob's rows y0:y1 and columns x0:x1, px;
    ``colour_known``: its added light showed the laser's colour (False: a saturated spot whose
    colour compression and clipping washed out, taken for the laser's colour because its own
    channel took the largest share); ``clipped_px``: pixels of its window whose background is at
    the white level (a lamp under the dot: the spot's light is cut there, its centroid pulled away).
    """

    color: str
    u: float
    v: float
    area_px: int
    peak: float
    stray: bool = False
    saturated: bool = False
    noise_px: float = 0.0
    background_p: float = 1.0
    bbox: tuple = (0, 0, 0, 0)
    colour_known: bool = True
    clipped_px: int = 0
