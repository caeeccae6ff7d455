"""Benchmark behind ``posekit bench ceiling``.

Times, per 864×480 frame on one thread (``cv2.setNumThreads(1)`` for both sides; our kernels
are single-threaded numba), laser dot detection of posekit over >= 300 frames of a rendered
ceiling video (one red dot on the paper's 2.4 m × 4.4 m rectangle, vents where the dot
vanishes, illumination drift, sensor noise), and in the same run the pipelines a user would
write with OpenCV:

* MOG2 background subtraction (``createBackgroundSubtractorMOG2`` with its defaults) + HSV
  ``inRange`` for red (both hue ends) + ``cv2.moments`` of the mask, on the full frame;
* a lighter one: ``absdiff`` against a running average (``accumulateWeighted``) + HSV
  ``inRange`` + ``cv2.moments``, on the full frame.

Ours runs as a tracker would call it (the previous detection as the predicted position: a
window around it is searched, the whole frame when the dot was lost) and, in a second pass,
on the full frame every time. Frames are rendered in chunks, outside the timed region, and
each chunk goes through every method in turn. Medians and p99 are reported; the machines are
shared and noisy, so compare ratios. Accuracy: distance in px of each method's dot to the
true projection of the laser (frames where the dot is visible), detection rate, and dots
reported while the truth has none.

Then, on a realistic video (``SceneConfig.realistic``: lens distortion, bloom, exposure steps,
occluders, stray red lights, reflections): the whole verified per-frame path of ``ceiling
track`` (detection, undistortion of the candidates, verification and the learned mask of
static lights, gating, filter) beside today's detector alone and MOG2 on the same frames; and
live tracking end to end (decode through the live path + track + one JSON line per frame)
beside decode + MOG2.
"""

import os
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FRAME_PERIOD_MS = 1000.0 / 15.0        # the paper's camera: 15 fps
CHUNK = 60


class _Mog2Pipeline:
    """What a user would write first: MOG2 foreground & HSV red mask, moments of the mask."""

    name = "OpenCV MOG2 + HSV inRange + moments, full frame"

    def __init__(self):
        import cv2
        self.cv2 = cv2
        self.mog = cv2.createBackgroundSubtractorMOG2()

    def __call__(self, frame):
        cv2 = self.cv2
        fg = self.mog.apply(frame)
        hsv = cv2.cvtColor(frame, cv2.COLOR_BGR2HSV)
        red = cv2.bitwise_or(cv2.inRange(hsv, (0, 70, 150), (10, 255, 255)),
                             cv2.inRange(hsv, (170, 70, 150), (180, 255, 255)))
        m = cv2.moments(cv2.bitwise_and(red, fg), binaryImage=True)
        return (m["m10"] / m["m00"], m["m01"] / m["m00"]) if m["m00"] > 0 else None


class _AbsdiffPipeline:
    """A lighter user pipeline: difference to a running average, HSV red mask, moments."""

    name = "OpenCV absdiff(running average) + HSV inRange + moments, full frame"

    def __init__(self, learning_rate=0.05, threshold=20):
        import cv2
        self.cv2 = cv2
        self.acc = None
        self.rate = learning_rate
        self.threshold = threshold

    def __call__(self, frame):
        cv2 = self.cv2
        if self.acc is None:
            self.acc = frame.astype(np.float32)
        diff = cv2.cvtColor(cv2.absdiff(frame, cv2.convertScaleAbs(self.acc)), cv2.COLOR_BGR2GRAY)
        _, fg = cv2.threshold(diff, self.threshold, 255, cv2.THRESH_BINARY)
        hsv = cv2.cvtColor(frame, cv2.COLOR_BGR2HSV)
        red = cv2.bitwise_or(cv2.inRange(hsv, (0, 70, 150), (10, 255, 255)),
                             cv2.inRange(hsv, (170, 70, 150), (180, 255, 255)))
        m = cv2.moments(cv2.bitwise_and(red, fg), binaryImage=True)
        cv2.accumulateWeighted(frame, self.acc, self.rate)
        return (m["m10"] / m["m00"], m["m01"] / m["m00"]) if m["m00"] > 0 else None


class _Ours:
    def __init__(self, track: bool):
        from posekit.ceiling.detect.dots import DotDetector
        self.det = DotDetector(("red",))
        self.track = track
        self.last = None

    def __call__(self, frame):
        dots = self.det.detect(frame, self.last if self.track else None)
        self.last = (dots[0].u, dots[0].v) if dots else None
        return self.last


def _run(methods, scene, n_frames):
    """Time every method on every frame (chunk by chunk, methods in turn); returns per method
    the times (ms) and the detections ((n, 2), NaN where none)."""
    times = {k: np.empty(n_frames) for k in methods}
    uv = {k: np.full((n_frames, 2), np.nan) for k in methods}
    for start in range(0, n_frames, CHUNK):
        frames = list(scene.frames(start, min(start + CHUNK, n_frames)))
        for key, method in methods.items():
            for i, frame in enumerate(frames):
                t0 = time.perf_counter_ns()
                p = method(frame)
                times[key][start + i] = (time.perf_counter_ns() - t0) * 1e-6
                if p is not None:
                    uv[key][start + i] = p
    return times, uv


def _accuracy(uv, truth):
    vis = truth.visible[:, 0]
    found = np.all(np.isfinite(uv), axis=1)
    err = np.hypot(*(uv[vis & found] - truth.uv_red[vis & found]).T)
    return {"error_px_median": float(np.median(err)) if len(err) else float("nan"),
            "error_px_mean": float(np.mean(err)) if len(err) else float("nan"),
            "error_px_p95": float(np.percentile(err, 95)) if len(err) else float("nan"),
            "detection_rate": float(np.count_nonzero(vis & found) / max(np.count_nonzero(vis), 1)),
            "false_dots": int(np.count_nonzero(~vis & found))}


def _stats(a):
    return float(np.median(a)), float(np.percentile(a, 99))


def _realistic(n_frames):
    """Realistic frames (lens k1 = -0.2, bloom, exposure steps, a person, shadows, a steady and a
    blinking red LED, reflections), the camera (true homography on undistorted pixels + the
    lens model) and the truth."""
    from posekit.ceiling.camera.homography import Calibration
    from posekit.ceiling.sim.config import SceneConfig
    from posekit.ceiling.sim.render import CeilingScene
    from posekit.ceiling.track.cameras import Camera

    cfg = SceneConfig.realistic(duration_s=n_frames / 15.0, seed=0)
    scene = CeilingScene(cfg)
    H = scene.H_image_world
    cal = Calibration(H_image_world=H, H_world_image=np.linalg.inv(H), rms_px=0.1, rms_world=1.0)
    return cfg, scene, Camera(cal, (cfg.width_px, cfg.height_px), lens=scene.camera), scene.truth()


def _verified_run(frames, camera, n):
    """Per-frame processing time (ms) of the whole verified path of ``posekit ceiling track``
    (detection in the tracking window, undistortion, candidate verification, the mask of
    static lights, gating and the filter), and the rows."""
    from posekit.ceiling.track.pipeline import iter_track
    timings, rows = [], []
    for row, _ in iter_track(((k, k / 15.0, f) for k, f in enumerate(frames)), [camera], ("red",), timings=timings):
        rows.append(row)
    return np.array(timings[:n]) * 1e3, rows


def _live_run(video, cal_json, camera_json, n):
    """End to end through the live path (decode + track + one JSON line per frame): per-frame
    wall time (ms) between consecutive rows, and the rows."""
    import io
    import json

    from posekit.ceiling.track.pipeline import track_video
    sink, stamps = io.StringIO(), []

    def on_row(row):
        sink.write(json.dumps(row.json_record()) + "\n")
        stamps.append(time.perf_counter())
    t0 = time.perf_counter()
    res = track_video(video, cal_json, camera=camera_json, live=True, on_row=on_row, max_frames=n)
    return np.diff(np.r_[t0, stamps]) * 1e3, res.rows


def _decode_mog2_run(video, n):
    """The peer end to end: decode with cv2.VideoCapture + the MOG2 pipeline, per-frame wall time (ms)."""
    import cv2
    cap = cv2.VideoCapture(str(video))
    m = _Mog2Pipeline()
    out = []
    t = time.perf_counter()
    while len(out) < n:
        ok, f = cap.read()
        if not ok:
            break
        m(f)
        t1 = time.perf_counter()
        out.append((t1 - t) * 1e3)
        t = t1
    cap.release()
    return np.array(out)


def _run_realistic(n_frames, verbose):
    """Rows for the realistic video: verified detection vs today's detector vs MOG2 on the same
    frames, and live tracking end to end vs decode + MOG2."""
    import tempfile

    from posekit.ceiling.sim.video import render_video

    cfg, scene, camera, truth = _realistic(n_frames)
    frames = list(scene.frames(0, n_frames))
    # warm-up of the verified path (numba kernels, the lens)
    _verified_run(frames[:30], camera, 30)
    ours_ms, rows = _verified_run(frames, camera, n_frames)
    today = _Ours(True)
    mog = _Mog2Pipeline()
    t_today, t_mog = np.empty(n_frames), np.empty(n_frames)
    for k, f in enumerate(frames):
        t0 = time.perf_counter_ns()
        today(f)
        t_today[k] = (time.perf_counter_ns() - t0) * 1e-6
        t0 = time.perf_counter_ns()
        mog(f)
        t_mog[k] = (time.perf_counter_ns() - t0) * 1e-6
    st = np.array([r.status for r in rows])
    xy = np.array([[r.x, r.y] for r in rows])
    err = np.hypot(*(xy - truth.xy_red[:len(rows)]).T)
    ok = st == "ok"
    vis = truth.visible[:len(rows), 0]
    std = np.array([r.std_mm for r in rows])
    quality = {"ok": int(ok.sum()), "ok_off_20mm": int(np.count_nonzero(ok & (err > 20))),
               "ok_without_dot": int(np.count_nonzero(ok & ~vis)),
               "coverage_2p5std": float(np.mean(err[ok] <= 2.5 * std[ok])) if ok.any() else float("nan"),
               "error_ok_median_mm": float(np.median(err[ok])) if ok.any() else float("nan")}
    out_rows = []
    m, p99 = _stats(ours_ms)
    b = float(np.median(t_mog))
    out_rows.append({"name": "ceiling.detect.realistic_verified", "ours_ms": m, "ours_p99_ms": p99,
                     "baseline": _Mog2Pipeline.name, "baseline_ms": b, "speedup": b / m,
                     "realtime_factor": FRAME_PERIOD_MS / m, "samples": int(n_frames), "ours_fps": 1000.0 / m,
                     "today_detector_ms": float(np.median(t_today)), "today_detector_fps": 1000.0 / float(np.median(t_today)),
                     **quality})
    with tempfile.TemporaryDirectory() as tmp:
        paths = render_video(cfg, tmp)
        from json import dumps
        cal = f"{tmp}/cal.json"
        with open(cal, "w") as fh:
            fh.write(dumps({"H_image_world": scene.H_image_world.tolist(),
                            "H_world_image": np.linalg.inv(scene.H_image_world).tolist(), "rms_px": 0.1,
                            "rms_world": 1.0}))
        _live_run(paths.video, cal, paths.camera, 30)                    # warm-up
        live_ms, _ = _live_run(paths.video, cal, paths.camera, n_frames)
        peer_ms = _decode_mog2_run(paths.video, n_frames)
        codec = cfg.codec
    m, p99 = _stats(live_ms)
    b = float(np.median(peer_ms))
    out_rows.append({"name": "ceiling.track.live_end_to_end", "ours_ms": m, "ours_p99_ms": p99,
                     "baseline": f"cv2.VideoCapture decode ({codec}) + {_Mog2Pipeline.name}", "baseline_ms": b,
                     "speedup": b / m, "realtime_factor": FRAME_PERIOD_MS / m, "samples": int(len(live_ms)),
                     "ours_fps": 1000.0 / m, "baseline_fps": 1000.0 / b})
    if verbose:
        r0, r1 = out_rows
        print(f"realistic video ({n_frames} frames 864x480: lens k1 = -0.2, bloom, exposure steps, a person, shadows, "
              f"a steady and a blinking red LED, reflections):")
        print(f"  verified detection + undistortion + stray-light rejection + filter: median {r0['ours_ms']:.3f} ms "
              f"({r0['ours_fps']:.0f} frames/s, p99 {r0['ours_p99_ms']:.3f} ms); today's detector alone on the same "
              f"frames {r0['today_detector_ms']:.3f} ms ({r0['today_detector_fps']:.0f} frames/s); MOG2 "
              f"{r0['baseline_ms']:.3f} ms -> {r0['speedup']:.1f}x; target >= 450 frames/s")
        print(f"  track quality: {r0['ok']} ok, {r0['ok_off_20mm']} ok rows > 20 mm off, {r0['ok_without_dot']} ok "
              f"without the dot, {100 * r0['coverage_2p5std']:.1f} % of ok errors within 2.5 std_mm, median "
              f"error {r0['error_ok_median_mm']:.2f} mm")
        print(f"  live end to end (decode {codec} + track + JSON line): median {r1['ours_ms']:.3f} ms per frame "
              f"({r1['ours_fps']:.0f} frames/s, p99 {r1['ours_p99_ms']:.3f} ms); decode + MOG2 {r1['baseline_ms']:.3f} ms "
              f"({r1['baseline_fps']:.0f} frames/s) -> {r1['speedup']:.1f}x; target >= 30 frames/s")
    return out_rows


def run(count=None, verbose=True):
    """Run the benchmark; returns the JSON rows (DESIGN.md ``posekit bench`` contract)."""
    import cv2

    from posekit.ceiling.sim.config import SceneConfig
    from posekit.ceiling.sim.render import CeilingScene

    cv2.setNumThreads(1)
    n_frames = 600 if count is None else max(int(count), 300)
    config = SceneConfig(dots=("red",), duration_s=n_frames / 15.0, seed=0)
    scene = CeilingScene(config)
    truth = scene.truth()
    # Warm-up: compile/load the kernels, then keep the core busy for ~2 s (a VM's vCPU runs at
    # half speed for the first calls after an idle spell).
    warm = list(scene.frames(0, 30))
    t_end = time.perf_counter() + 2.0
    while time.perf_counter() < t_end:
        for make in (lambda: _Ours(True), lambda: _Ours(False), _Mog2Pipeline, _AbsdiffPipeline):
            m = make()
            for f in warm:
                m(f)
    del warm
    methods = {"ours_track": _Ours(True), "ours_full": _Ours(False), "mog2": _Mog2Pipeline(),
               "absdiff": _AbsdiffPipeline()}
    times, uv = _run(methods, scene, n_frames)
    acc = {k: _accuracy(uv[k], truth) for k in methods}

    rows = []

    def row(name, ours, peer):
        m, p99 = _stats(times[ours])
        b = float(np.median(times[peer]))
        r = {"name": name, "ours_ms": m, "ours_p99_ms": p99, "baseline": methods[peer].name, "baseline_ms": b,
             "speedup": b / m, "realtime_factor": FRAME_PERIOD_MS / m, "samples": int(n_frames),
             "baseline_p99_ms": _stats(times[peer])[1], "ours_fps": 1000.0 / m, "baseline_fps": 1000.0 / b}
        r.update({f"ours_{k}": v for k, v in acc[ours].items()})
        r.update({f"baseline_{k}": v for k, v in acc[peer].items()})
        rows.append(r)

    row("ceiling.detect", "ours_track", "mog2")
    row("ceiling.detect.full_frame", "ours_full", "mog2")
    row("ceiling.detect.vs_absdiff", "ours_track", "absdiff")
    row("ceiling.detect.full_frame.vs_absdiff", "ours_full", "absdiff")

    if verbose:
        vis = int(np.count_nonzero(truth.visible[:, 0]))
        print(f"posekit bench ceiling: {n_frames} rendered frames 864x480 (one red dot, visible in {vis}; "
              f"vents, illumination drift, noise σ = {config.noise_std} levels), one thread "
              f"(cv2.setNumThreads(1); numba kernels single-threaded)")
        print(f"{'method':<34}{'median':>9}{'p99':>9}{'fps':>8}   {'err med':>8}{'err p95':>8}{'found':>7}{'false':>6}")
        labels = {"ours_track": "posekit DotDetector, tracking ROI", "ours_full": "posekit DotDetector, full frame",
                  "mog2": "OpenCV MOG2 + HSV + moments", "absdiff": "OpenCV absdiff + HSV + moments"}
        for k in methods:
            m, p99 = _stats(times[k])
            a = acc[k]
            print(f"{labels[k]:<34}{m:>7.3f}ms{p99:>7.3f}ms{1000 / m:>8.0f}   {a['error_px_median']:>6.3f}px"
                  f"{a['error_px_p95']:>6.3f}px{100 * a['detection_rate']:>6.1f}%{a['false_dots']:>6d}")
        print(f"ratios: tracking {rows[0]['speedup']:.1f}x, full frame {rows[1]['speedup']:.1f}x faster than MOG2; "
              f"{rows[2]['speedup']:.1f}x / {rows[3]['speedup']:.1f}x than absdiff")
        print(f"target: >= 450 frames/s (<= 2.2 ms) -> measured {rows[0]['ours_fps']:.0f} frames/s tracking, "
              f"{rows[1]['ours_fps']:.0f} full frame (paper: 26 ms per frame, 27 Hz); "
              f"real-time factor at 15 fps: {rows[0]['realtime_factor']:.0f}x")
    rows += _run_realistic(min(n_frames, 450), verbose)
    return rows


if __name__ == "__main__":  # pragma: no cover
    sys.path.insert(0, str(HERE.parent / "src"))
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")
    run()
