"""Static lights of the scene: a spot whose motion its own centroid jitter explains.

A real ceiling has exit signs, smoke-detector LEDs, lamps and glints. Each is a spot that stays
where it is, but whose detected centroid jitters from frame to frame (sensor noise, flicker,
compression) — by a pixel or so, which is as far as a slow robot's dot moves in a frame. So a
static light is told from the laser by a statistical test, not a distance threshold:

* the candidates of each frame are chained into short image tracks (nearest neighbour within
  a gate of ``max(4 px, 4σ_scene)`` around the track's last position moved on by its last
  velocity, at most ``assoc_px``; a spot seen once is continued within ``assoc_px`` in the
  next frame, later only where it was; a track survives ``max_gap`` frames unseen, so a
  blinking light keeps its history);
* the jitter σ of a track is the larger of its own — from the second differences of
  consecutive sightings (``p₀ − 2p₁ + p₂`` has covariance ``6σ²I`` for a still point *and* for
  one moving at constant speed, so the motion does not inflate it;
  ``σ² = median |Δ²p|² / (12 ln 2)``) — and the scene's: the 90th percentile, over the tracks
  not found moving with at least ``min_frames`` sightings, of the spread of their sightings
  about a constant-velocity fit (what a
  compressed video's static spots really do: they sit still for a few frames and step by a
  fraction of a pixel when a key frame arrives, which second differences alone miss), never
  below ``jitter_floor_px``;
* the motion statistic is the distance between the mean positions of the first and the second
  half of the window: under "static" (independent jitter of σ) ``d ~ N(0, σ²(1/n₁ + 1/n₂) I)``,
  so ``T = |d|² / (2σ²(1/n₁ + 1/n₂))`` follows an F(2, ν) law: ν = n − 2 when σ is the track's
  own (the effective degrees of freedom of the median of the overlapping second differences:
  measured by Monte-Carlo, 0.8–1.2 × alpha rejections of independent Gaussian jitter for
  n = 8–20), ν = the residual degrees of freedom of all the static spots behind the scene's
  jitter when that is larger (then nearly χ²₂/2: a handful of sightings suffice). A track is
  **moving** when ``T`` exceeds the ``1 − alpha`` quantile (``alpha`` = 1e-3 by default: one
  lamp in a thousand windows reads as motion) **and** the motion is a robot's: a sign test —
  its last ``steady_frames`` (m) sightings, seen within 2 (m − 1) frames, each advance along
  their net displacement (the spots of a compressed real video step once at a key frame and
  sit, or hop back and forth between two stripes of a tape; steps in no order all advance
  with probability at most 2^-(m-1), 1/16 for m = 5, and only *after* the F test rejected).
  **Static** when it has at least ``min_frames`` sightings and the F test does not reject;
  otherwise **new**.

A scene learned beforehand (:func:`learn_scene`, ``posekit ceiling learn-scene``) seeds the
model: a candidate within ``max(4σ_j, 1 px)`` of a known light is static from its first
sighting. Without one, lights are learned online (:attr:`StaticLights.n_static`).
"""

import itertools
from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np

__all__ = ["NEW", "MOVING", "STATIC", "Light", "StaticLights", "f_quantile", "save_scene", "load_scene", "SCENE_KEYS"]

NEW, MOVING, STATIC = 0, 1, 2
"""States of a candidate (:meth:`StaticLights.update`)."""

_LN2x12 = 12.0 * np.log(2.0)


def f_quantile(q: float, d1: int, d2: float) -> float:
    """``q`` quantile of the F(d1, d2) law (scipy)."""
    from scipy.stats import f
    return float(f.ppf(q, d1, d2))


@dataclass
class Light:
    """A static light in the image.

    Attributes
    ----------
    u, v : float
        Mean centroid, px (pixel-centre convention).
    jitter_px : float
        1σ of its centroid per axis from frame to frame, px.
    colour : str
        Laser colour it was detected as.
    seen : int
        Frames it was seen in.
    x_mm, y_mm : float
        Its position on the ceiling, mm (NaN when not mapped).
    """

    u: float
    v: float
    jitter_px: float
    colour: str = "red"
    seen: int = 0
    x_mm: float = float("nan")
    y_mm: float = float("nan")


_IDS = itertools.count(1)


@dataclass
class _Track:
    colour: str
    id: int = field(default_factory=lambda: next(_IDS))
    pts: list = field(default_factory=list)        # [(frame, u, v)], the last `window`
    last: int = 0
    seen: int = 0
    state: int = NEW
    known: Light | None = None


class StaticLights:
    """Online model of the static lights seen by one camera.

    Parameters
    ----------
    alpha : float
        Significance level of the motion test: the probability that a static light's jitter
        reads as motion in one window.
    window : int
        Sightings per track used by the test.
    min_frames : int
        Sightings before a track can be called static (a moving one is called moving as soon
        as the test rejects, from 4 sightings on).
    assoc_px : float
        A candidate continues the nearest track of its colour within this distance, px
        (a fast robot's dot moves this far between frames).
    max_gap : int
        Frames a track survives without a sighting (a blinking light).
    jitter_floor_px : float
        Smallest centroid jitter believed, px (quantisation and compression leave at least this).
    steady_frames : int
        A track found not static is called moving only when its last this many sightings
        (within twice as many frames) each advance along their net displacement.
    known : iterable of Light, optional
        Lights of a learned scene (static from their first sighting).
    """

    def __init__(self, *, alpha: float = 1e-3, window: int = 20, min_frames: int = 8, assoc_px: float = 25.0,
                 max_gap: int = 30, jitter_floor_px: float = 0.1, steady_frames: int = 5,
                 known: Iterable[Light] = ()):
        if not 0.0 < alpha < 0.5:
            raise ValueError(f"alpha: expected a probability in (0, 0.5), got {alpha}")
        self.alpha = float(alpha)
        self.window = max(int(window), 6)
        self.min_frames = max(int(min_frames), 4)
        self.assoc_px = float(assoc_px)
        self.max_gap = int(max_gap)
        self.jitter_floor_px = float(jitter_floor_px)
        self.steady_frames = max(int(steady_frames), 3)
        self.known = list(known)
        self.tracks: list[_Track] = []
        self._q = {}
        self._frame = -1
        self._scene_jitter = self.jitter_floor_px
        self._scene_dof = 0                  # residual degrees of freedom behind the scene's jitter
        self.ids = np.zeros(0, np.int64)
        self.seen = np.zeros(0, np.int64)

    # -- the test --------------------------------------------------------------------------
    def _threshold(self, nu: int) -> float:
        """``1 - alpha`` quantile of F(2, ν) (ν capped at 1000: the χ²₂/2 law beyond)."""
        nu = int(min(max(nu, 1), 1000))
        if nu not in self._q:
            self._q[nu] = f_quantile(1.0 - self.alpha, 2, nu)
        return self._q[nu]

    def scene_jitter_px(self) -> float:
        """The scene's centroid jitter, px: the 90th percentile of the spread (1σ per axis about
        a constant-velocity fit) of the sightings of the tracks not found moving with at least
        ``min_frames`` of them, and of the known lights' jitter; at least ``jitter_floor_px``."""
        return self._scene_jitter

    def _measure_scene_jitter(self) -> float:
        js = [lt.jitter_px for lt in self.known]
        dof = 1000 * len(self.known)
        for t in self.tracks:
            if len(t.pts) >= self.min_frames and t.state != MOVING:
                f = np.array([k for k, _, _ in t.pts], float)
                p = np.array([(u, v) for _, u, v in t.pts])
                A = np.column_stack([np.ones_like(f), f - f.mean()])
                r = p - A @ np.linalg.lstsq(A, p, rcond=None)[0]        # about a constant-velocity fit
                js.append(float(np.sqrt(np.sum(r * r) / (2.0 * max(len(f) - 2, 1)))))
                dof += 2 * (len(f) - 2)
        self._scene_dof = dof
        return max(float(np.percentile(js, 90)), self.jitter_floor_px) if js else self.jitter_floor_px

    @staticmethod
    def _jitter(t: _Track) -> float:
        p = np.array([(u, v) for _, u, v in t.pts])
        f = np.array([k for k, _, _ in t.pts])
        if len(p) < 3:
            return 0.0
        dd = (p[:-2] - 2.0 * p[1:-1] + p[2:])[(f[2:] - f[:-2]) == 2]
        return float(np.sqrt(np.median(np.sum(dd * dd, axis=1)) / _LN2x12)) if len(dd) else 0.0

    def test(self, pts: np.ndarray, floor_px: float | None = None, frames=None,
             floor_dof: int = 0) -> tuple[float, float, float]:
        """Motion statistic of sightings ``pts`` (n, 2) px: ``(T, threshold, jitter_px)``;
        moving when ``T > threshold``. ``frames`` (n,): their frame numbers; only second
        differences of three consecutive frames measure the jitter (across a gap the motion
        would count as jitter). The jitter is the track's own (ν = n − 2 degrees of freedom)
        or ``floor_px`` (the scene's, measured with ``floor_dof`` degrees of freedom),
        whichever is larger; the threshold is the F(2, ν) quantile of that estimate."""
        pts = np.asarray(pts, float).reshape(-1, 2)
        n = len(pts)
        dd = pts[:-2] - 2.0 * pts[1:-1] + pts[2:]
        if frames is not None and n >= 3:
            f = np.asarray(frames)
            dd = dd[(f[2:] - f[:-2]) == 2]
        s = float(np.sqrt(np.median(np.sum(dd * dd, axis=1)) / _LN2x12)) if len(dd) else 0.0
        floor = self.jitter_floor_px if floor_px is None else floor_px
        nu = n - 2
        if floor >= s:
            s, nu = floor, max(int(floor_dof), n - 2)
        n1 = n // 2
        d = pts[n1:].mean(axis=0) - pts[:n1].mean(axis=0)
        T = float(d @ d) / (2.0 * s * s * (1.0 / n1 + 1.0 / (n - n1)))
        return T, self._threshold(nu), s

    # -- one frame -------------------------------------------------------------------------
    def update(self, frame: int, uv, colours) -> np.ndarray:
        """Chain this frame's candidates into tracks and test each; returns their states (K,)
        (:data:`NEW`, :data:`MOVING` or :data:`STATIC`). Afterwards :attr:`ids` (K,) holds the
        identity of each candidate's track and :attr:`seen` (K,) how many frames it was seen in.

        Parameters
        ----------
        frame : int
            Frame index (increasing).
        uv : ndarray, shape (K, 2)
            Candidate centroids, px.
        colours : sequence of str, length K
        """
        uv = np.asarray(uv, float).reshape(-1, 2)
        self._frame = frame = int(frame)
        self.tracks = [t for t in self.tracks if frame - t.last <= self.max_gap]
        states = np.full(len(uv), NEW, int)
        taken = set()
        pairs = []
        base = max(4.0, 4.0 * self._scene_jitter)
        for j, t in enumerate(self.tracks):
            q = t.pts[-1]
            gap = frame - q[0]
            if len(t.pts) >= 2 and gap <= 3:        # moved on by its velocity over a short gap only
                q0 = t.pts[-2]
                vel = np.array([q[1] - q0[1], q[2] - q0[2]]) / max(q[0] - q0[0], 1)
                centre, radius = np.array(q[1:]) + vel * gap, min(base + 0.5 * float(np.hypot(*vel)) * gap, self.assoc_px)
            elif len(t.pts) >= 2 or gap > 1:          # no velocity to carry it over a gap: only where it was
                centre, radius = np.array(q[1:]), base
            else:
                centre, radius = np.array(q[1:]), self.assoc_px
            for k, (p, c) in enumerate(zip(uv, colours)):
                if t.colour == c and t.last < frame:
                    d = float(np.hypot(p[0] - centre[0], p[1] - centre[1]))
                    if d <= radius:
                        pairs.append((d, k, j))
        pairs.sort()
        match = {}
        for d, k, j in pairs:
            if k in match or j in taken:
                continue
            match[k] = j
            taken.add(j)
        floor = self._scene_jitter
        self.ids = np.zeros(len(uv), np.int64)
        self.seen = np.zeros(len(uv), np.int64)
        for k, (p, c) in enumerate(zip(uv, colours)):
            if k in match:
                t = self.tracks[match[k]]
            else:
                t = _Track(c)
                t.known = self._known_at(p, c)
                self.tracks.append(t)
            t.pts.append((frame, float(p[0]), float(p[1])))
            del t.pts[:-self.window]
            t.last = frame
            t.seen += 1
            t.state = self._state(t, floor)
            states[k] = t.state
            self.ids[k], self.seen[k] = t.id, t.seen
        if not frame % 5:                       # it changes slowly: every fifth frame
            self._scene_jitter = self._measure_scene_jitter()
        return states

    def _known_at(self, p, colour) -> Light | None:
        for lt in self.known:
            if lt.colour == colour and np.hypot(p[0] - lt.u, p[1] - lt.v) <= max(4.0 * lt.jitter_px, 1.0):
                return lt
        return None

    def _state(self, t: _Track, floor: float) -> int:
        n = len(t.pts)
        if t.known is not None:
            u, v = t.pts[-1][1:]
            lt = t.known
            if np.hypot(u - lt.u, v - lt.v) <= max(4.0 * lt.jitter_px, 1.0):
                return STATIC
            t.known = None                          # it left the known light: a moving spot
        if n < 4:
            return NEW
        P = np.array([(u, v) for _, u, v in t.pts])
        T, thr, _ = self.test(P, floor, [f for f, _, _ in t.pts], self._scene_dof)
        if T > thr:
            return MOVING if self._steady(t, P) else NEW
        return STATIC if n >= self.min_frames else NEW

    def _steady(self, t: _Track, P: np.ndarray) -> bool:
        """The last ``steady_frames`` (m) sightings, within ``2 (m - 1)`` frames, each advance
        along their net displacement: a sign test of a robot's progression against a spot
        whose steps come in no order (a compressed video's spot that steps once at a key frame
        and sits, or hops between two stripes), for which all m - 1 steps advance with
        probability at most 2^-(m-1) (1/16 for m = 5)."""
        m = self.steady_frames
        if len(P) < m or t.pts[-1][0] - t.pts[-m][0] > 2 * (m - 1):
            return False
        tail = P[-m:]
        net = tail[-1] - tail[0]
        return bool(np.all((tail[1:] - tail[:-1]) @ net > 0))

    # -- what it learned -------------------------------------------------------------------
    def settled_uv(self, keep=()) -> list:
        """Last sighting ``(u, v)`` px of every spot seen this frame that has settled — found
        static (known lights included), or seen in at least ``min_frames`` frames without being
        found moving (a spot that hops between two places) — except the tracks whose identity
        is in ``keep`` (the tracked dots). What a detector may absorb into its background: it
        is part of the scene."""
        return [t.pts[-1][1:] for t in self.tracks if t.last == self._frame and t.id not in keep
                and (t.state == STATIC or (t.seen >= self.min_frames and t.state != MOVING))]

    def settled_near(self, uv, radius_px: float, exclude=None) -> bool:
        """True if a settled spot (static, or seen in ``min_frames`` frames without moving; its
        mean position) other than the track ``exclude`` lies within ``radius_px`` of ``uv``."""
        for t in self.tracks:
            if t.id != exclude and (t.state == STATIC or (t.seen >= self.min_frames and t.state != MOVING)):
                u = sum(p[1] for p in t.pts) / len(t.pts)
                v = sum(p[2] for p in t.pts) / len(t.pts)
                if (u - uv[0]) ** 2 + (v - uv[1]) ** 2 <= radius_px * radius_px:
                    return True
        return False

    def last_uv(self, identity) -> tuple | None:
        """Last sighting ``(u, v)`` px of the track ``identity`` if it was seen this frame."""
        for t in self.tracks:
            if t.id == identity and t.last == self._frame:
                return t.pts[-1][1:]
        return None

    @property
    def n_static(self) -> int:
        """Static lights currently held (known ones included)."""
        return len(self.known) + sum(1 for t in self.tracks if t.state == STATIC and t.known is None)

    def lights(self, min_seen: int | None = None) -> list[Light]:
        """The static lights learned from the frames so far (image position, jitter, colour)."""
        min_seen = self.min_frames if min_seen is None else int(min_seen)
        out = []
        for t in self.tracks:
            if t.state == STATIC and t.seen >= min_seen:
                p = np.array([(u, v) for _, u, v in t.pts])
                out.append(Light(float(p[:, 0].mean()), float(p[:, 1].mean()),
                                 max(self._jitter(t), self.jitter_floor_px), t.colour, t.seen))
        return out


#: Keys of a scene file (``posekit ceiling learn-scene --out``).
SCENE_KEYS = ("image_size", "frames", "jitter_px", "lights")
#: Most lights a scene file may hold.
MAX_LIGHTS = 10_000


def save_scene(path, lights: Iterable[Light], image_size, frames: int, jitter_px: float, source: str = ""):
    """Write a scene file: ``{"image_size": [w, h], "frames": n, "jitter_px": σ, "source": str,
    "lights": [{"u", "v", "x_mm", "y_mm", "colour", "jitter_px", "seen"}, ...]}`` (px, mm)."""
    import json

    from ...errors import InputFileError
    from ...io import write_text_atomic

    def num(v):
        return None if not np.isfinite(v) else round(float(v), 4)

    doc = {"image_size": [int(image_size[0]), int(image_size[1])], "frames": int(frames),
           "jitter_px": num(jitter_px), "source": str(source),
           "lights": [{"u": num(lt.u), "v": num(lt.v), "x_mm": num(lt.x_mm), "y_mm": num(lt.y_mm),
                       "colour": lt.colour, "jitter_px": num(lt.jitter_px), "seen": int(lt.seen)} for lt in lights]}
    return write_text_atomic(path, json.dumps(doc, indent=1) + "\n", flag="--out", error=InputFileError)


def load_scene(path) -> tuple[list[Light], tuple[int, int]]:
    """Read a scene file: (lights, image_size). One-line :class:`~posekit.errors.InputFileError`
    naming the file and the key on anything malformed."""
    from ...errors import InputFileError
    from ...io import load_json

    data = load_json(path, expected="a scene file (posekit ceiling learn-scene --out)", error=InputFileError)
    if not isinstance(data, dict) or any(k not in data for k in SCENE_KEYS):
        raise InputFileError(f"{path}: expected a JSON object with the keys {', '.join(SCENE_KEYS)}")
    size = data["image_size"]
    if not (isinstance(size, list) and len(size) == 2 and all(isinstance(s, int) and not isinstance(s, bool)
                                                               and 0 < s <= 100_000 for s in size)):
        raise InputFileError(f"{path}: image_size: expected [width, height] in px (two positive integers)")
    items = data["lights"]
    if not isinstance(items, list) or len(items) > MAX_LIGHTS:
        raise InputFileError(f"{path}: lights: expected a list of at most {MAX_LIGHTS} lights")
    lights = []
    for k, it in enumerate(items):
        if not isinstance(it, dict):
            raise InputFileError(f"{path}: lights[{k}]: expected an object with u, v, colour, jitter_px")
        vals = {}
        for key in ("u", "v", "jitter_px"):
            v = it.get(key)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not np.isfinite(v) or (key == "jitter_px"
                                                                                             and v < 0):
                raise InputFileError(f"{path}: lights[{k}].{key}: expected a finite number"
                                     + (" >= 0" if key == "jitter_px" else "") + f", got {str(v)[:30]}")
            vals[key] = float(v)
        colour = it.get("colour", "red")
        if not isinstance(colour, str) or not colour:
            raise InputFileError(f"{path}: lights[{k}].colour: expected a colour name such as 'red'")
        xm, ym = it.get("x_mm"), it.get("y_mm")
        lights.append(Light(vals["u"], vals["v"], vals["jitter_px"], colour, int(it.get("seen", 0) or 0),
                            float(xm) if isinstance(xm, (int, float)) else float("nan"),
                            float(ym) if isinstance(ym, (int, float)) else float("nan")))
    return lights, (size[0], size[1])
