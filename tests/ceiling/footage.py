"""Real camera footage with a laser dot drawn on it: the generator the ceiling tracker is judged
by on frames nobody here rendered (shares no code with ``posekit.ceiling.sim``).

The frames are the first 300 of OpenCV's ``vtest.avi`` (``tests/data/ceiling/SOURCE.md``): a
fixed camera, people walking, brick, grass, orange cones, H.264 then MPEG-4 compression. The
"ceiling" is that image plane under a mild perspective homography (about 5 mm per pixel), so a
world path in mm becomes an image path in px.

What is drawn (in float, then clipped to 8 bits and passed through JPEG at quality 85, 4:2:0
chroma, like a compressed camera):

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

CLIP = Path(__file__).resolve().parent.parent / "data" / "ceiling" / "vtest_320x240.mp4"
FPS = 10.0
W, H = 320, 240
N_FRAMES = 300
# world (mm) -> image (px): about 5 mm per pixel, a mild perspective
H_IMAGE_WORLD = np.array([[0.2, 0.006, 8.0], [-0.004, 0.19, 10.0], [2.0e-6, 3.0e-6, 1.0]])


def to_image(xy, H_iw=H_IMAGE_WORLD):
    """World points (n, 2) mm -> image points (n, 2) px."""
    xy = np.atleast_2d(np.asarray(xy, float))
    q = np.c_[xy, np.ones(len(xy))] @ H_iw.T
    return q[:, :2] / q[:, 2:]


def calibration(rms_px: float = 0.2) -> Calibration:
    """The true homography as a calibration (as if clicked with ``rms_px`` of noise)."""
    Hwi = np.linalg.inv(H_IMAGE_WORLD)
    return Calibration(H_IMAGE_WORLD.copy(), Hwi / Hwi[2, 2], rms_px, rms_px * 5.0)


@lru_cache(maxsize=1)
def real_frames() -> tuple:
    """The 300 real frames (BGR uint8, 240×320×3), decoded once per test session."""
    import cv2
    cap = cv2.VideoCapture(str(CLIP))
    out = []
    while len(out) < N_FRAMES:
        ok, f = cap.read()
        if not ok:
            break
        f.setflags(write=False)
        out.append(f)
    cap.release()
    assert len(out) == N_FRAMES, f"{CLIP}: {len(out)} frames decoded"
    return tuple(out)


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
    occluded : tuple of (frame0, frame1)
        Frames in [frame0, frame1) where the dot is hidden.
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
    """

    dot: bool = True
    path: np.ndarray | None = None
    occluded: tuple = ((148, 156),)
    lamp_xy: tuple | None = None
    blink_xy: tuple | None = None
    lamp_jitter_px: float = 0.4
    decoy: np.ndarray | None = None
    green_offset_mm: float | None = None
    heading: np.ndarray | None = None
    jpeg_quality: int = 85
    seed: int = 0
    n: int = N_FRAMES
    amp: float = 500.0
    frames_: list = field(default_factory=list, repr=False)

    def __post_init__(self):
        self.truth = robot_path(self.n) if self.path is None else np.asarray(self.path, float)
        uv = to_image(self.truth)
        inside = (uv[:, 0] >= 2) & (uv[:, 0] <= W - 3) & (uv[:, 1] >= 2) & (uv[:, 1] <= H - 3)
        hidden = np.zeros(self.n, bool)
        for a, b in self.occluded:
            hidden[a:b] = True
        self.visible = inside & ~hidden & self.dot
        self.uv = uv

    def frames(self):
        """Yield ``(index, time_s, BGR frame)``."""
        import cv2
        rng = np.random.default_rng(self.seed)
        base = real_frames()
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
            if self.jpeg_quality:
                ok, buf = cv2.imencode(".jpg", out, [cv2.IMWRITE_JPEG_QUALITY, int(self.jpeg_quality)])
                out = cv2.imdecode(buf, cv2.IMREAD_COLOR)
            yield k, k / FPS, out


def judge(rows, scene: Overlay) -> dict:
    """Per-scene figures of a track against the overlay's truth.

    ``ok_rate``: ``ok`` rows among the frames where the dot is visible, from the first ``ok``
    row on; ``median_mm``: median error of the ``ok`` rows; ``cover_2s``: fraction of ``ok``
    errors within 2 × ``std_mm``; ``ok_far``: ``ok`` rows more than 50 mm off; ``ok_unseen``:
    ``ok`` rows while the dot is not visible; ``acquired_s``: time from the first motion to the
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
    moving = np.flatnonzero(np.hypot(*np.diff(truth, axis=0).T) > 0)
    t_move = moving[0] + 1 if moving.size else 0
    return {
        "ok": int(ok.sum()),
        "ok_rate": float(np.mean(ok[vis & after])) if np.any(vis & after) else float("nan"),
        "median_mm": float(np.median(err[ok])) if ok.any() else float("nan"),
        "cover_2s": float(np.mean(err[ok] <= 2 * std[ok])) if ok.any() else float("nan"),
        "ok_far": int(np.count_nonzero(ok & (err > 50))),
        "ok_unseen": int(np.count_nonzero(ok & ~vis)),
        "acquired_s": (first - t_move) / FPS if ok.any() else float("inf"),
        "pred_cover_3s": _pred_cover(st, err, std),
    }


def _pred_cover(st, err, std):
    p = st == "predicted"
    return float(np.mean(err[p] <= 3 * std[p])) if p.any() else float("nan")


def scenes() -> dict:
    """The scenes of ``test_real_footage.py`` by name (the figures of docs/notes/issue-25.md)."""
    lamps = {"lamp_xy": (700.0, 600.0), "blink_xy": (1200.0, 300.0)}
    decoy = np.full((N_FRAMES, 2), np.nan)
    k = np.arange(140, 220)
    decoy[k] = np.c_[800.0 + 15.0 * (k - 140), np.full(len(k), 1150.0)]
    return {
        "no dot": Overlay(dot=False),
        "no dot, steady + blinking red lamp": Overlay(dot=False, **lamps),
        "dot": Overlay(),
        "dot + lamps": Overlay(**lamps),
        "dot + moving decoy while hidden": Overlay(decoy=decoy),
        "dot, occluded 1.6 s": Overlay(occluded=((146, 162),)),
        "dot, JPEG q75": Overlay(jpeg_quality=75),
        "dot, JPEG q60": Overlay(jpeg_quality=60),
    }


def main() -> None:
    """Print the per-scene figures: ``PYTHONPATH=src python tests/ceiling/footage.py``."""
    import json
    import time

    from posekit.ceiling.track.cameras import Camera
    from posekit.ceiling.track.pipeline import track_frames

    for name, scene in scenes().items():
        t0 = time.perf_counter()
        res = track_frames(scene.frames(), [Camera(calibration(), (W, H))], ("red",))
        j = judge(res.rows, scene)
        c = res.counts()
        print(json.dumps({"scene": name, **c, **{k: round(float(v), 3) for k, v in j.items() if k != "ok"},
                          "rebuilds": res.stats["rebuilds"], "s": round(time.perf_counter() - t0, 1)}))


if __name__ == "__main__":
    main()
