"""A small independent frame generator for the ceiling tracker's tests (NumPy only; shares
no code with ``posekit.ceiling.sim.render``), and checks of the generator itself.

The scene: a grey ceiling with darker T-bars, a mild perspective homography (world mm ↔
image px), optional radial lens distortion (OpenCV's k1, k2 model written out here), sensor
noise, and a laser dot drawn as a Gaussian whose core saturates white with a red rim (bloom).
Stray light: a steady red LED and a blinking red light drawn *with the laser's own profile*
(the hardest case: only position, motion and persistence tell them apart), a white lamp, a
dark occluder (a person's shadow) that crosses the path and hides the dot, and a vent where
the dot vanishes. The path is a fast rectangle with sharp corners (no stop).
"""

from dataclasses import dataclass, field

import numpy as np

from posekit.ceiling.camera.homography import Calibration
from posekit.ceiling.track.cameras import Camera

W, H = 432, 240
FPS = 15.0
# world (mm) -> image (px, undistorted): a mild perspective
H_IMAGE_WORLD = np.array([[0.105, 0.004, 10.0], [-0.003, 0.102, 12.0], [1.0e-6, 2.0e-6, 1.0]])


def to_image(xy, H_iw=H_IMAGE_WORLD):
    xy = np.atleast_2d(np.asarray(xy, float))
    q = np.c_[xy, np.ones(len(xy))] @ H_iw.T
    return q[:, :2] / q[:, 2:]


def distort(uv, K, dist):
    """OpenCV's radial/tangential model (k1, k2, p1, p2, k3) applied to undistorted pixels."""
    k1, k2, p1, p2, k3 = dist
    x = (uv[:, 0] - K[0, 2]) / K[0, 0]
    y = (uv[:, 1] - K[1, 2]) / K[1, 1]
    r2 = x * x + y * y
    rad = 1 + k1 * r2 + k2 * r2 ** 2 + k3 * r2 ** 3
    xd = x * rad + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * rad + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return np.c_[K[0, 0] * xd + K[0, 2], K[1, 1] * yd + K[1, 2]]


def rectangle_path(n, speed_mm_s=600.0, rect=(300.0, 300.0, 3500.0, 1900.0)):
    """Positions (n, 2) mm along a rectangle at constant speed, sharp corners (no stop)."""
    x0, y0, x1, y1 = rect
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]])
    seg = np.hypot(*np.diff(corners, axis=0).T)
    s = (np.arange(n) / FPS * speed_mm_s) % seg.sum()
    cum = np.r_[0, np.cumsum(seg)]
    k = np.searchsorted(cum, s, side="right") - 1
    f = (s - cum[k]) / seg[k]
    return corners[k] + f[:, None] * (corners[k + 1] - corners[k])


@dataclass
class Scene:
    n: int = 150
    seed: int = 0
    speed_mm_s: float = 600.0
    noise: float = 2.0
    led_xy: tuple | None = None             # steady red light, world mm
    blink_xy: tuple | None = None           # red light on 8 frames, off 8 frames
    lamp_xy: tuple | None = None            # white lamp
    occluder: bool = False                  # a dark band sweeping across the image
    vent: tuple | None = None               # (frame0, frame1): the dot vanishes
    dist: tuple = (0.0, 0.0, 0.0, 0.0, 0.0)
    path: np.ndarray | None = None          # (n, 2) world mm, or the fast rectangle
    extra_paths: list = field(default_factory=list)   # further dots (other robots), (n, 2) each
    dot_sigma_px: float = 1.4
    K: np.ndarray = field(default_factory=lambda: np.array([[300.0, 0, (W - 1) / 2], [0, 300.0, (H - 1) / 2],
                                                            [0, 0, 1.0]]))

    def __post_init__(self):
        self.truth = rectangle_path(self.n, self.speed_mm_s) if self.path is None else np.asarray(self.path, float)
        self.rng = np.random.default_rng(self.seed)
        yy, xx = np.mgrid[0:H, 0:W]
        base = np.full((H, W), 150.0)
        base[(xx % 60) < 3] = 110.0
        base[(yy % 60) < 3] = 110.0
        self.base = base
        self.base3 = np.repeat(base[:, :, None], 3, axis=2).astype(np.float32)
        self.noise_bank = self.rng.normal(0.0, self.noise, (12, H, W, 3)).astype(np.float32)
        self.visible = np.ones(self.n, bool)
        if self.vent is not None:
            self.visible[self.vent[0]:self.vent[1]] = False

    def uv(self, xy):
        """Observed (distorted) pixels of world points."""
        uv = to_image(xy)
        return distort(uv, self.K, self.dist) if any(self.dist) else uv

    def _blob(self, img, uv, gain_r, gain_gb, sigma):
        u, v = uv
        r = int(4 * sigma + 3)
        u0, v0 = int(round(u)), int(round(v))
        y0, y1, x0, x1 = max(v0 - r, 0), min(v0 + r + 1, H), max(u0 - r, 0), min(u0 + r + 1, W)
        if y0 >= y1 or x0 >= x1:
            return
        yy, xx = np.mgrid[y0:y1, x0:x1]
        g = np.exp(-((xx - u) ** 2 + (yy - v) ** 2) / (2 * sigma ** 2))
        img[y0:y1, x0:x1, 2] += gain_r * g
        img[y0:y1, x0:x1, 1] += gain_gb * g
        img[y0:y1, x0:x1, 0] += gain_gb * g

    def occluder_box(self, k):
        """Rows/cols of the shadow at frame k (a band 70 px wide sweeping left to right), or None."""
        if not self.occluder:
            return None
        x = int(-80 + (W + 160) * (k % 90) / 90)
        return 0, H, max(x, 0), min(x + 70, W)

    def dot_hidden(self, k):
        box = self.occluder_box(k)
        if box is None:
            return False
        u, v = self.uv(self.truth[k])[0]
        return box[2] - 4 <= u < box[3] + 4

    def frame(self, k):
        img = self.base3.copy()
        box = self.occluder_box(k)
        if box is not None:
            img[box[0]:box[1], box[2]:box[3]] *= 0.45
        if self.lamp_xy is not None:
            self._blob(img, self.uv(self.lamp_xy)[0], 500.0, 500.0, 4.0)
        if self.led_xy is not None:
            self._blob(img, self.uv(self.led_xy)[0], 420.0, 150.0, self.dot_sigma_px)
        if self.blink_xy is not None and (k // 8) % 2 == 0:
            self._blob(img, self.uv(self.blink_xy)[0], 420.0, 150.0, self.dot_sigma_px)
        if self.visible[k] and not self.dot_hidden(k):
            self._blob(img, self.uv(self.truth[k])[0], 420.0, 150.0, self.dot_sigma_px)
        for p in self.extra_paths:
            self._blob(img, self.uv(p[k])[0], 420.0, 150.0, self.dot_sigma_px)
        img += self.noise_bank[self.rng.integers(len(self.noise_bank))]   # a bank of noise frames: fast
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)

    def frames(self):
        for k in range(self.n):
            yield k, k / FPS, self.frame(k)

    def camera(self, lens=None, rms_px=0.3):
        cal = Calibration(H_image_world=H_IMAGE_WORLD, H_world_image=np.linalg.inv(H_IMAGE_WORLD),
                          rms_px=rms_px, rms_world=rms_px * 10.0)
        return Camera(cal, (W, H), name="gen", lens=lens)

    def lens(self):
        from posekit.ceiling.camera.lens import CameraModel
        return CameraModel(K=self.K, dist=np.asarray(self.dist, float), image_size=(W, H), rms_px=0.1)


def ok_errors(rows, truth):
    """Distances (mm) of the ok rows to the truth, and their std_mm."""
    ok = np.array([r.status == "ok" for r in rows])
    xy = np.array([[r.x, r.y] for r in rows])
    err = np.hypot(*(xy - truth).T)
    std = np.array([r.std_mm for r in rows])
    return ok, err, std


# --- checks of the generator itself --------------------------------------------------------------

def test_generator_dot_is_where_the_truth_says():
    sc = Scene(n=5, noise=0.0)
    for k, _, img in sc.frames():
        added = np.clip(img.astype(float) - np.repeat(sc.base[:, :, None], 3, axis=2), 0, None).sum(axis=2)
        added[added < 30] = 0
        yy, xx = np.mgrid[0:H, 0:W]
        u = (added * xx).sum() / added.sum()
        v = (added * yy).sum() / added.sum()
        np.testing.assert_allclose([u, v], sc.uv(sc.truth[k])[0], atol=0.25)   # saturation clips a little
        core = img[int(round(v)), int(round(u))]
        assert np.all(core == 255)                                           # a white core
        ring = (np.hypot(xx - u, yy - v) > 2.0) & (np.hypot(xx - u, yy - v) < 3.5)
        add = img[ring].astype(float) - sc.base[ring][:, None]
        assert add[:, 2].mean() > 2.5 * add[:, 1].mean() > 0                 # a red rim


def test_generator_distortion_against_opencv():
    import cv2
    sc = Scene(n=2, dist=(-0.2, 0.05, 0.001, -0.001, 0.0))
    uv = to_image(np.array([[300.0, 300.0], [3500.0, 1900.0], [2000.0, 1000.0]]))
    K = sc.K
    xy = np.c_[(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1], np.ones(3)]
    ref, _ = cv2.projectPoints(xy, np.zeros(3), np.zeros(3), K, np.array(sc.dist))
    np.testing.assert_allclose(distort(uv, K, sc.dist), ref.reshape(-1, 2), atol=1e-6)


def test_generator_path_is_a_fast_rectangle():
    p = rectangle_path(200, 600.0)
    step = np.hypot(*np.diff(p, axis=0).T)
    assert np.all(step <= 40.0 + 1e-9) and np.median(step) == np.float64(40.0)
