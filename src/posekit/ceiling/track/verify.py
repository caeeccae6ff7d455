"""Which detected spots may be the laser: the tests every candidate goes through before a tracker
sees it, shared by the single-robot pipeline (:func:`~posekit.ceiling.track.pipeline.iter_track`)
and the several-robot one (:func:`~posekit.ceiling.track.multitrack.iter_track_robots`).

A candidate is **eligible** (it may continue or resume a track) when it is not a static light
(:class:`~posekit.ceiling.detect.scene.StaticLights`: an F test at ``alpha`` of the spot's motion
against its centroid jitter, the jitter measured from the scene's static spots), its own channel
reaches the sensor's white level (:attr:`~posekit.ceiling.detect.spots.Dot.saturated`) and, once a
track has been followed, its brightness and size are like the tracked laser's
(:class:`~posekit.ceiling.detect.dots.DotSignature`).

It is **moving** (it may start or re-acquire a track, or make another track ``suspect`` as a
rival) when, besides, every test that could tell it is not the laser does not reject at its
stated significance level, each with its noise measured from the scene:

* *it moves like a robot*: the static-light model found it moving (the F test rejects "static"
  at ``alpha`` and the sign test of its last steps at 1/16: see :mod:`posekit.ceiling.detect.scene`);
* *on the ceiling*: the spot is light added to an unchanged background — the ring test of the
  detector (:attr:`~posekit.ceiling.detect.spots.Dot.background_p`: the surroundings' outliers
  against the scene's measured outlier rate, binomial) does not reject at
  ``alpha_background`` (a tail light sits on a car, a glint on a windscreen, a red sleeve on a
  person: none of them on the unchanged ceiling);
* *of the laser's colour*: its added light showed it, not washed out by compression and
  clipping (:attr:`~posekit.ceiling.detect.spots.Dot.colour_known`).

A candidate that lies on a settled spot other than the tracked dot's own (within its radius)
has a centroid pulled by that spot: its 1σ is at least half its radius.

A candidate is **another object** — dropped before any tracker sees it — when its image track in
the static-light model is not the one the tracker follows, has been seen in at least
``min_frames`` frames and was not found moving: a spot that has sat in view apart from the
track (a lamp, a cone, a glint, a stripe that hops between two places) is not the laser, even
when the track's gate reaches it (a track that coasts, a stop next to a lamp). The laser itself
keeps its image track, or starts a new one after a sharp turn.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...errors import ConfigError

__all__ = ["LaserTests", "Candidates", "verify_candidates"]


@dataclass(frozen=True)
class LaserTests:
    """Significance levels of the tests that a spot is the laser.

    Attributes
    ----------
    alpha_background : float
        Probability that the ring test rejects a spot that does lie on the unchanged
        background (a laser dot on the ceiling is then not eligible for that frame).
    """

    alpha_background: float = 1e-3

    def __post_init__(self):
        if not 0.0 < self.alpha_background < 0.5:
            raise ConfigError(f"LaserTests.alpha_background: expected a probability in (0, 0.5), "
                              f"got {self.alpha_background!r}")


@dataclass
class Candidates:
    """One camera's candidates of a frame, per colour (arrays in detection order).

    Attributes
    ----------
    uv : dict
        ``{colour: (K, 2) px}``.
    eligible, moving : dict
        ``{colour: (K,) bool}``.
    std_px : dict
        ``{colour: (K,) px}``: 1σ per axis of each centroid.
    dots : list
        The detections kept (:class:`~posekit.ceiling.detect.spots.Dot`), in the order of the
        arrays.
    states, ids : ndarray
        Their states and image-track identities in the static-light model.
    dropped : int
        Candidates dropped as another object.
    """

    uv: dict = field(default_factory=dict)
    eligible: dict = field(default_factory=dict)
    moving: dict = field(default_factory=dict)
    std_px: dict = field(default_factory=dict)
    dots: list = field(default_factory=list)
    states: np.ndarray = field(default_factory=lambda: np.zeros(0, int))
    ids: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    dropped: int = 0

    def associable(self, followed: dict) -> dict:
        """``{colour: (K,) bool}``: the candidate that continues the followed image track of each
        colour when it is in view (the only one the dot may then be associated with), else all."""
        out = {}
        for c, uv in self.uv.items():
            ids = np.array([i for d, i in zip(self.dots, self.ids) if d.color == c], np.int64)
            f = followed.get(c)
            out[c] = (ids == f) if f is not None and np.any(ids == f) else np.ones(len(uv), bool)
        return out

    def identity(self, colour: str, uv) -> int | None:
        """Image-track identity of the candidate of ``colour`` nearest to ``uv`` (px), or None."""
        best, d2 = None, np.inf
        for d, i in zip(self.dots, self.ids):
            if d.color == colour:
                e = (d.u - uv[0]) ** 2 + (d.v - uv[1]) ** 2
                if e < d2:
                    best, d2 = int(i), e
        return best


def verify_candidates(index: int, dots, lights, signatures: dict, std_floor_px: float,
                      tests: LaserTests | None = None, followed: dict | None = None) -> Candidates:
    """Run a frame's detections through the static-light model and the laser tests.

    Parameters
    ----------
    index : int
        Frame index.
    dots : list of Dot
        The frame's detections (one camera).
    lights : StaticLights
        That camera's model of static lights (updated here).
    signatures : dict
        ``{colour: DotSignature}`` of that camera.
    std_floor_px : float
        Least 1σ of a centroid, px (the camera's ``detection_std_px``).
    tests : LaserTests, optional
    followed : dict, optional
        ``{colour: identity}`` of the image track the tracker follows (None: none), or
        ``{colour: set of identities}`` when several robots carry that colour; the candidates of
        other, settled image tracks that are not moving are dropped.

    Returns
    -------
    Candidates
    """
    from ..detect.scene import MOVING, STATIC

    tests = LaserTests() if tests is None else tests
    states = lights.update(index, [(d.u, d.v) for d in dots], [d.color for d in dots])
    ids = lights.ids
    followed = followed or {}

    def own(colour, identity):
        f = followed.get(colour)
        return identity in f if isinstance(f, (set, frozenset)) else identity == f

    by, el, mv, sd, kept = {}, {}, {}, {}, []
    for k, (d, s) in enumerate(zip(dots, states)):
        if not own(d.color, ids[k]) and s == STATIC:
            continue                                   # another object: it sat in view apart from the track
        kept.append(k)
        sig = signatures[d.color]
        ok = s != STATIC and d.saturated and sig.consistent(d)
        by.setdefault(d.color, []).append((d.u, d.v))
        el.setdefault(d.color, []).append(ok)
        mv.setdefault(d.color, []).append(ok and s == MOVING and d.colour_known
                                          and d.background_p > tests.alpha_background)
        std = sig.std_px(d, std_floor_px)
        r = float(np.sqrt(max(d.area_px, 1) / np.pi))
        if lights.settled_near((d.u, d.v), r + 2.0, exclude=ids[k] if own(d.color, ids[k]) else None):
            std = max(std, 0.5 * r)                    # on a static light: the merged centroid is pulled by it
        sd.setdefault(d.color, []).append(std)
    return Candidates({c: np.asarray(v, dtype=float).reshape(-1, 2) for c, v in by.items()},
                      {c: np.asarray(v, dtype=bool) for c, v in el.items()},
                      {c: np.asarray(v, dtype=bool) for c, v in mv.items()},
                      {c: np.asarray(v, dtype=float) for c, v in sd.items()}, [dots[k] for k in kept],
                      np.asarray(states)[kept], np.asarray(ids)[kept], len(dots) - len(kept))
