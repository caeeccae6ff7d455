"""Real camera footage with a laser dot drawn on it: the generator the ceiling tracker is judged
by on frames nobody here rendered (shares no code with ``posekit.ceiling.sim``).

Two real clips (``tests/data/ceiling/SOURCE.md``), each a fixed camera:

* ``vtest``: the first 300 frames of OpenCV's ``vtest.avi`` (10 frames/s, 320×240): people
  walking past brick, grass, orange cones and a striped barrier tape; H.264 then MPEG-4;
* ``parking``: 300 frames of Intel's ``car-detection.mp4`` (CC BY 4.0; 12.5 frames/s, 384×216):
  a parking lot seen from above, white and red cars driving through with their tail lights
  and specular glints, white specks on the asphalt, a camera that sways by a few pixels.

The "ceiling" is the clip's image plane under a mild perspective homography (about 5 mm per
pixel), so a world path in mm becomes an image path in px.

What is drawn (in float, then clipped to 8 bits and passed through JPEG at quality 85, 4:2:0
chroma, like a compressed camera; optionally a second lossy pass):

* the laser dot: a Gaussian of added light whose red channel saturates over the halo and whose
  core saturates in all three channels (a real red laser pointer's look), at a sub-pixel
  position, with a little brightness flicker;
* a steady red lamp and a blinking one (on 5 frames, off 5) drawn with the *laser's own
  profile*, each jittering by ``lamp_jitter_px`` (1σ per axis) from frame to frame — the hardest
  case: only motion tells them apart;
* the path (:func:`robot_path`): a stand-still start, a straight run, a stop, a sharp 90° turn,
  an occlusion (the dot not drawn), a run that leaves the image and comes back, a final stop.
"""

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np

from posekit.ceiling.camera.homography import Calibration

DATA = Path(__file__).resolve().parent.parent / "data" / "ceiling"


@dataclass(frozen=True)
class Clip:
    """A real clip of ``tests/data/ceiling``: file, frame rate, size (w, h) px, frames used."""

    file: str
    fps: float
    size: tuple
    n_frames: int = 300

    @property
    def path(self) -> Path:
        return DATA / self.file


CLIPS = {"vtest": Clip("vtest_320x240.mp4", 10.0, (320, 240)),
         "parking": Clip("parking_384x216.mp4", 12.5, (384, 216))}
CLIP = CLIPS["vtest"].path
FPS = CLIPS["vtest"].fps
W, H = CLIPS["vtest"].size
N_FRAMES = 300
# world (mm) -> image (px): about 5 mm per pixel, a mild perspective
H_IMAGE_WORLD = np.array([[0.2, 0.006, 8.0], [-0.004, 0.19, 10.0], [2.0e-6, 3.0e-6, 1.0]])


def to_image(xy, H_iw=H_IMAGE_WORLD):
    """World points (n, 2) mm -> image points (n, 2) px."""
    xy = np.atleast_2d(np.asarray(xy, float))
    q = np.c_[xy, np.ones(len(xy))] @ H_iw.T
    return q[:, :2] / q[:, 2:]


def calibration(rms_px: float = 0.2, clip: str = "vtest") -> Calibration:
    """The true homography as a calibration (as if clicked with ``rms_px`` of noise), for the
    frames of ``clip``."""
    Hwi = np.linalg.inv(H_IMAGE_WORLD)
    return Calibration(H_IMAGE_WORLD.copy(), Hwi / Hwi[2, 2], rms_px, rms_px * 5.0, image_size=CLIPS[clip].size)


@lru_cache(maxsize=2)
def real_frames(clip: str = "vtest") -> tuple:
    """The clip's real frames (BGR uint8, (h, w, 3)), decoded once per test session."""
    import cv2
    c = CLIPS[clip]
    cap = cv2.VideoCapture(str(c.path))
    out = []
    while len(out) < c.n_frames:
        ok, f = cap.read()
        if not ok:
            break
        f.setflags(write=False)
        out.append(f)
    cap.release()
    assert len(out) == c.n_frames, f"{c.path}: {len(out)} frames decoded"
    return tuple(out)


@lru_cache(maxsize=2)
def clip_background(clip: str = "vtest") -> np.ndarray:
    """The clip's empty scene: the per-pixel median of every fifth frame (float, (h, w, 3))."""
    return np.median(np.stack(real_frames(clip)[::5]), axis=0)


def on_passing_object(clip: str, frames, uv, radius_px: int = 5, level: float = 40.0,
                      share: float = 0.25) -> np.ndarray:
    """Which of ``uv`` (n, 2) px in ``frames`` (n,) fall on something that is not the empty
    scene (a car, a person passing): more than ``share`` of the pixels within ``radius_px``
    differ from :func:`clip_background` by more than ``level`` grey levels in some channel.

    The "ceiling" is the empty scene; whatever moves in the clip is below it, between the
    camera and the ceiling: a laser dot there would land on that object, off the ceiling plane
    (its position through the ceiling's homography would be wrong), so the tracker must not
    call it ``ok`` on the strength of the background, and such frames do not count as frames
    where the dot is visible on the ceiling."""
    bg = clip_background(clip)
    imgs = real_frames(clip)
    out = np.zeros(len(frames), bool)
    for i, (k, p) in enumerate(zip(frames, uv)):
        u, v = int(round(p[0])), int(round(p[1]))
        img = imgs[k % len(imgs)]
        y0, y1, x0, x1 = max(v - radius_px, 0), v + radius_px + 1, max(u - radius_px, 0), u + radius_px + 1
        d = np.abs(img[y0:y1, x0:x1].astype(float) - bg[y0:y1, x0:x1]).max(axis=2)
        out[i] = d.size > 0 and float(np.mean(d > level)) > share
    return out


# (duration s, velocity mm/s (vx, vy)): the segments of the default path, from START_MM
START_MM = (400.0, 350.0)
SEGMENTS = (
    (3.0, (0.0, 0.0)),        # stand still: a dot at rest is not told from a lamp yet
    (4.0, (150.0, 0.0)),      # straight run
    (1.5, (0.0, 0.0)),        # stop
    (4.0, (0.0, 130.0)),      # sharp 90° turn, then on (occluded part of the way)
    (6.0, (-230.0, 0.0)),     # sharp turn, leaves the image on the left
    (5.0, (230.0, 0.0)),      # turns back and comes in again
    (6.5, (0.0, 0.0)),        # final stop
)


def robot_path(n: int = N_FRAMES, segments=SEGMENTS, start=START_MM, fps: float = FPS) -> np.ndarray:
    """Positions (n, 2) mm at frame times k / fps along the piecewise-constant-velocity path."""
    t = np.arange(n) / fps
    xy = np.empty((n, 2))
    p, t0 = np.asarray(start, float), 0.0
    for dur, v in segments:
        sel = (t >= t0) & (t < t0 + dur)
        xy[sel] = p + (t[sel] - t0)[:, None] * np.asarray(v)
        p = p + dur * np.asarray(v)
        t0 += dur
    xy[t >= t0] = p
    return xy


def draw_spot(img: np.ndarray, uv, amp: float, sigma_px: float = 1.5,
              colour=(0.25, 0.25, 1.0)) -> None:
    """Add a Gaussian spot of light (BGR weights ``colour``, peak ``amp`` grey levels) at
    sub-pixel ``uv`` (pixel centres at integers) to the float image ``img`` in place."""
    u, v = float(uv[0]), float(uv[1])
    r = int(np.ceil(4 * sigma_px))
    u0, v0 = int(round(u)), int(round(v))
    y0, y1, x0, x1 = max(v0 - r, 0), min(v0 + r + 1, img.shape[0]), max(u0 - r, 0), min(u0 + r + 1, img.shape[1])
    if y0 >= y1 or x0 >= x1:
        return
    yy, xx = np.mgrid[y0:y1, x0:x1]
    g = amp * np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma_px ** 2))
    img[y0:y1, x0:x1] += g[..., None] * np.asarray(colour)


@dataclass
class Overlay:
    """One test scene: real frames, the laser dot(s) on a known path, lamps.

    Attributes
    ----------
    dot : bool
        Draw the red laser dot.
    path : ndarray (n, 2) mm, optional
        The dot's world path (default :func:`robot_path`).
    occluded : tuple of (frame0, frame1), optional
        Frames in [frame0, frame1) where the dot is hidden (default: :data:`OCCLUSION_S`).
    lamp_xy, blink_xy : (x, y) mm, optional
        A steady / blinking red lamp drawn with the laser's profile.
    lamp_jitter_px : float
        1σ per axis of the lamps' centroid jitter from frame to frame, px.
    decoy : ndarray (n, 2) mm, optional
        A second, laser-like red spot moving on its own path (NaN rows: not drawn).
    green_offset_mm : float
        With a value, a green dot this far ahead of the red one along ``heading`` (case B).
    heading : ndarray (n,) rad, optional
        Heading of the robot (red -> green) per frame.
    jpeg_quality : int
        JPEG round trip of every frame (0: none).
    second_pass : int
        A second JPEG round trip at this quality (0: none): video re-encoded once more, as a
        recorder or a stream relay does.
    clip : str
        Which real clip (:data:`CLIPS`).
    """

    dot: bool = True
    path: np.ndarray | None = None
    occluded: tuple | None = None
    lamp_xy: tuple | None = None
    blink_xy: tuple | None = None
    lamp_jitter_px: float = 0.4
    decoy: np.ndarray | None = None
    green_offset_mm: float | None = None
    heading: np.ndarray | None = None
    jpeg_quality: int = 85
    second_pass: int = 0
    clip: str = "vtest"
    seed: int = 0
    n: int = N_FRAMES
    amp: float = 500.0
    frames_: list = field(default_factory=list, repr=False)

    def __post_init__(self):
        c = CLIPS[self.clip]
        self.fps, self.size = c.fps, c.size
        if self.occluded is None:
            self.occluded = frames_of(self.clip, OCCLUSION_S)
        w, h = c.size
        self.truth = robot_path(self.n, fps=c.fps) if self.path is None else np.asarray(self.path, float)
        uv = to_image(self.truth)
        inside = (uv[:, 0] >= 2) & (uv[:, 0] <= w - 3) & (uv[:, 1] >= 2) & (uv[:, 1] <= h - 3)
        hidden = np.zeros(self.n, bool)
        for a, b in self.occluded:
            hidden[a:b] = True
        self.uv = uv
        self.on_object = np.zeros(self.n, bool)
        self.on_object[inside] = on_passing_object(self.clip, np.flatnonzero(inside), uv[inside])
        self.drawn = inside & ~hidden & self.dot
        self.visible = self.drawn & ~self.on_object

    def frames(self):
        """Yield ``(index, time_s, BGR frame)``."""
        import cv2
        rng = np.random.default_rng(self.seed)
        base = real_frames(self.clip)
        lamp_uv = None if self.lamp_xy is None else to_image(self.lamp_xy)[0]
        blink_uv = None if self.blink_xy is None else to_image(self.blink_xy)[0]
        decoy_uv = None if self.decoy is None else to_image(self.decoy)
        green_uv = None
        if self.green_offset_mm is not None:
            d = self.green_offset_mm * np.c_[np.cos(self.heading), np.sin(self.heading)]
            green_uv = to_image(self.truth + d)
        for k in range(self.n):
            img = base[k % len(base)].astype(np.float32)
            flicker = 1.0 + 0.05 * rng.standard_normal()
            if self.visible[k]:
                draw_spot(img, self.uv[k], self.amp * flicker)
            if green_uv is not None and self.visible[k]:
                draw_spot(img, green_uv[k], self.amp * flicker, colour=(0.25, 1.0, 0.25))
            for p, on in ((lamp_uv, True), (blink_uv, (k // 5) % 2 == 0)):
                if p is not None and on:
                    j = self.lamp_jitter_px * rng.standard_normal(2)
                    draw_spot(img, p + j, self.amp * (1.0 + 0.1 * rng.standard_normal()))
            if decoy_uv is not None and np.all(np.isfinite(decoy_uv[k])):
                draw_spot(img, decoy_uv[k], self.amp * flicker)
            out = np.clip(img, 0, 255).astype(np.uint8)
            for q in (self.jpeg_quality, self.second_pass):
                if q:
                    ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(q)])
                    out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
            yield k, k / self.fps, out


def judge(rows, scene: Overlay) -> dict:
    """Per-scene figures of a track against the overlay's truth.

    ``ok_rate``: ``ok`` rows among the frames where the dot is visible on the ceiling (in the
    image, not occluded, not on a passing object: :func:`on_passing_object`), from the first
    ``ok`` row on; ``median_mm``: median error of the ``ok`` rows; ``cover_2s``: fraction of ``ok``
    errors within 2 × ``std_mm``; ``ok_far``: ``ok`` rows more than 50 mm off; ``ok_unseen``:
    ``ok`` rows while the dot is not drawn; ``ok_on_object``: ``ok`` rows while it is drawn on a
    passing object; ``acquired_s``: time from the first motion seen on the ceiling to the
    first ``ok`` row.
    """
    st = np.array([r.status for r in rows])
    xy = np.array([[r.x, r.y] for r in rows], float)
    std = np.array([r.std_mm for r in rows], float)
    n = len(rows)
    truth, vis = scene.truth[:n], scene.visible[:n]
    err = np.hypot(*(xy - truth).T)
    ok = st == "ok"
    first = int(np.argmax(ok)) if ok.any() else n
    after = np.arange(n) >= first
    moving = np.flatnonzero((np.hypot(*np.diff(truth, axis=0).T) > 0) & vis[1:])
    t_move = moving[0] + 1 if moving.size else 0
    return {
        "ok": int(ok.sum()),
        "ok_rate": float(np.mean(ok[vis & after])) if np.any(vis & after) else float("nan"),
        "median_mm": float(np.median(err[ok])) if ok.any() else float("nan"),
        "cover_2s": float(np.mean(err[ok] <= 2 * std[ok])) if ok.any() else float("nan"),
        "ok_far": int(np.count_nonzero(ok & (err > 50))),
        "ok_unseen": int(np.count_nonzero(ok & ~scene.drawn[:n])),
        "ok_on_object": int(np.count_nonzero(ok & scene.drawn[:n] & scene.on_object[:n])),
        "acquired_s": (first - t_move) / scene.fps if ok.any() else float("inf"),
        "pred_cover_3s": _pred_cover(st, err, std),
    }


def _pred_cover(st, err, std):
    p = st == "predicted"
    return float(np.mean(err[p] <= 3 * std[p])) if p.any() else float("nan")


#: y (mm) of the decoy's run, in view on each clip
DECOY_Y_MM = {"vtest": 1150.0, "parking": 1000.0}


def decoy_path(clip: str = "vtest", t0_s: float = 14.0, t1_s: float = 22.0) -> np.ndarray:
    """A laser-like decoy's world path (n, 2) mm: from ``t0_s`` to ``t1_s`` it runs at 150 mm/s
    along y = :data:`DECOY_Y_MM` from x = 800 mm, 0.3-0.8 m from the dot, while the dot is
    hidden and after (NaN rows: not drawn)."""
    c = CLIPS[clip]
    t = np.arange(c.n_frames) / c.fps
    out = np.full((c.n_frames, 2), np.nan)
    on = (t >= t0_s) & (t < t1_s)
    out[on] = np.c_[800.0 + 150.0 * (t[on] - t0_s), np.full(int(on.sum()), DECOY_Y_MM[clip])]
    return out


def frames_of(clip: str, *spans_s) -> tuple:
    """Frame ranges ``((f0, f1), ...)`` of time spans ``(t0_s, t1_s)`` in ``clip``."""
    fps = CLIPS[clip].fps
    return tuple((int(round(a * fps)), int(round(b * fps))) for a, b in spans_s)


LAMPS = {"lamp_xy": (700.0, 600.0), "blink_xy": (1200.0, 300.0)}
OCCLUSION_S = (14.8, 15.6)


def scenes(clip: str = "vtest") -> dict:
    """The scenes of ``test_real_footage.py`` on ``clip`` by name (the figures of
    docs/notes/issue-25.md)."""
    occ = frames_of(clip, OCCLUSION_S)
    kw = {"clip": clip, "occluded": occ}
    return {
        "no dot": Overlay(dot=False, **kw),
        "no dot, steady + blinking red lamp": Overlay(dot=False, **kw, **LAMPS),
        "dot": Overlay(**kw),
        "dot + lamps": Overlay(**kw, **LAMPS),
        "dot + moving decoy while hidden": Overlay(decoy=decoy_path(clip), **kw),
        "dot, occluded 1.6 s": Overlay(clip=clip, occluded=frames_of(clip, (14.6, 16.2))),
        "dot, JPEG q75": Overlay(jpeg_quality=75, **kw),
        "dot, JPEG q60": Overlay(jpeg_quality=60, **kw),
        "dot, JPEG q60 twice": Overlay(jpeg_quality=60, second_pass=60, **kw),
    }


def main(argv=None) -> None:
    """Print the per-scene figures: ``PYTHONPATH=src python tests/ceiling/footage.py [CLIP ...]``
    (default: every clip)."""
    import json
    import sys
    import time

    from posekit.ceiling.track.cameras import Camera
    from posekit.ceiling.track.pipeline import track_frames

    for clip in (argv if argv is not None else sys.argv[1:]) or list(CLIPS):
        for name, scene in scenes(clip).items():
            t0 = time.perf_counter()
            res = track_frames(scene.frames(), [Camera(calibration(clip=clip), scene.size)], ("red",))
            j = judge(res.rows, scene)
            c = res.counts()
            print(json.dumps({"clip": clip, "scene": name, **c,
                              **{k: round(float(v), 3) for k, v in j.items() if k != "ok"},
                              "rebuilds": res.stats["rebuilds"], "s": round(time.perf_counter() - t0, 1)}),
                  flush=True)


if __name__ == "__main__":
    main()
