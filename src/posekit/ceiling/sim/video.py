"""The files of a synthetic ceiling video: :func:`render_video` renders a :class:`SceneConfig` into a
folder — the video (Motion-JPEG or the config's codec), ``truth.csv``, ``calibration_points.csv``,
``reference.png``, ``camera.json`` and ``stray_lights.csv`` — and checks that the video holds every
frame (a full disk is a one-line error, never a short video).

Units: mm on the ceiling (world frame W of :mod:`posekit.ceiling.sim.render`), px in the image, s.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..._extras import require
from ...errors import ConfigError, InputFileError
from .config import CODECS, SceneConfig
from .render import CeilingScene, SceneTruth

__all__ = ["TRUTH_HEADER", "RenderedVideo", "render_video", "write_truth_csv", "write_calibration_csv",
           "write_lights_csv"]

TRUTH_HEADER = ("frame", "time_s", "x", "y", "heading_deg", "red_visible", "green_visible",
                "red_u", "red_v", "green_x", "green_y", "green_u", "green_v")


@dataclass(frozen=True)
class RenderedVideo:
    """Paths written by :func:`render_video`."""

    video: Path
    truth: Path
    calibration_points: Path
    reference: Path
    frames_dir: Path | None
    n_frames: int
    camera: Path | None = None
    stray_lights: Path | None = None


def write_truth_csv(path: Path, truth: SceneTruth) -> None:
    """``truth.csv``: the columns of :data:`TRUTH_HEADER`; x, y, green_x, green_y in mm,
    heading_deg from the first to the second dot (the robot's heading with one dot), u, v in px;
    ``green_*`` empty when there is no second dot."""
    two = not np.all(np.isnan(truth.xy_green))

    def fmt(value, spec):
        return "" if not np.isfinite(value) else format(value, spec)

    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(TRUTH_HEADER)
        for k in range(len(truth.frame)):
            x, y = truth.xy_red[k]
            gx, gy = truth.xy_green[k]
            w.writerow([int(truth.frame[k]), f"{truth.time_s[k]:.6f}", f"{x:.3f}", f"{y:.3f}",
                        f"{math.degrees(truth.heading_rad[k]):.4f}", int(truth.visible[k, 0]),
                        int(truth.visible[k, 1]) if two else "",
                        f"{truth.uv_red[k, 0]:.4f}", f"{truth.uv_red[k, 1]:.4f}",
                        fmt(gx, ".3f"), fmt(gy, ".3f"), fmt(truth.uv_green[k, 0], ".4f"),
                        fmt(truth.uv_green[k, 1], ".4f")])


def write_calibration_csv(path: Path, points: np.ndarray) -> None:
    """``X,Y,u,v`` per line (the calibration-points CSV of :mod:`posekit.ceiling.camera.points`), mm and px."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["X", "Y", "u", "v"])
        for X, Y, u, v in points:
            w.writerow([f"{X:.3f}", f"{Y:.3f}", f"{u:.4f}", f"{v:.4f}"])


def write_lights_csv(path: Path, lights) -> None:
    """``stray_lights.csv``: ``kind,x,y,u,v,period_s,phase_s`` per stray light (mm, px, s); a
    blinking light is on during ``[phase_s + k·period_s, phase_s + (k + ½)·period_s)``."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["kind", "x", "y", "u", "v", "period_s", "phase_s"])
        for light in lights:
            w.writerow([light.kind, f"{light.xy[0]:.3f}", f"{light.xy[1]:.3f}", f"{light.uv[0]:.4f}",
                        f"{light.uv[1]:.4f}", f"{light.period_s:g}", f"{light.phase_s:.6f}"])


def _can_write(cv2, codec, folder: Path) -> bool:
    fourcc, suffix = codec
    probe = folder / f".codec-probe{suffix}"
    w = cv2.VideoWriter(str(probe), cv2.VideoWriter_fourcc(*fourcc), 15.0, (64, 64))
    ok = w.isOpened()
    w.release()
    probe.unlink(missing_ok=True)
    return ok


def render_video(config: SceneConfig, out_dir, *, frames_png: bool = False,
                 progress: Callable | None = None) -> RenderedVideo:
    """Render the video of ``config`` into ``out_dir`` (created if needed).

    Writes ``video.avi`` (``fps`` frames per second; Motion-JPEG, or the ``codec`` of the config:
    ``video.mp4`` for mp4v/h264), ``truth.csv``, ``calibration_points.csv`` (every grid corner in
    view, at least 18, where the real lens shows it), ``reference.png`` (the ceiling without dots,
    lights or people), ``camera.json`` (the simulated lens, :func:`lens_camera`),
    ``stray_lights.csv`` (``kind,x,y,u,v,period_s,phase_s``, mm, px, s; header only without lights) and,
    with ``frames_png``, ``frames/000000.png`` ... (lossless).
    ``progress`` wraps the frame iterator (a progress bar), if given.
    """
    cv2 = require("cv2", "vision", "the ceiling video renderer")

    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputFileError(f"{out}: cannot create the output folder ({exc.strerror})") from None
    scene = CeilingScene(config)
    points = scene.calibration_points()
    if len(points) < 18:
        raise ConfigError(f"camera sees only {len(points)} grid corners (calibration needs at least 18): "
                          "widen the view (focal_px) or move the camera")
    fourcc, suffix = CODECS[config.codec]
    paths = RenderedVideo(video=out / f"video{suffix}", truth=out / "truth.csv",
                          calibration_points=out / "calibration_points.csv", reference=out / "reference.png",
                          frames_dir=(out / "frames") if frames_png else None, n_frames=scene.n_frames,
                          camera=out / "camera.json", stray_lights=out / "stray_lights.csv")
    writer = cv2.VideoWriter(str(paths.video), cv2.VideoWriter_fourcc(*fourcc), config.fps,
                             (config.width_px, config.height_px))
    if not writer.isOpened():
        writer.release()
        can = [k for k in CODECS if k != config.codec and _can_write(cv2, CODECS[k], out)]
        raise ConfigError(f"codec {config.codec}: OpenCV here cannot write {fourcc} video; "
                          f"expected one of {', '.join(can) or 'none'}")
    if config.codec == "mjpg":
        writer.set(cv2.VIDEOWRITER_PROP_QUALITY, 95)
    try:
        write_calibration_csv(paths.calibration_points, points)
        write_truth_csv(paths.truth, scene.truth())
        write_lights_csv(paths.stray_lights, scene.lights)
        from ..camera.lens import save_camera
        save_camera(scene.camera, paths.camera)
        _imwrite(cv2, paths.reference, scene.reference_image())
        if paths.frames_dir is not None:
            paths.frames_dir.mkdir(exist_ok=True)
        try:
            frames = scene.frames()
            for k, frame in enumerate(progress(frames, total=scene.n_frames) if progress else frames):
                writer.write(frame)
                if paths.frames_dir is not None:
                    _imwrite(cv2, paths.frames_dir / f"{k:06d}.png", frame)
        finally:
            writer.release()
    except OSError as exc:
        raise InputFileError(_write_failure(out, getattr(exc, "filename", None) or out, exc)) from None
    _check_video(cv2, paths.video, scene.n_frames, out)
    return paths


def _write_failure(out: Path, name, exc: OSError | None = None, need_bytes: int = 1 << 20) -> str:
    """One line: what could not be written, and why (no space left when that is the cause: the
    error says so, or less than ``need_bytes`` is free where it was written — OpenCV's writers
    give no reason and remove what they could not finish)."""
    import errno
    import os
    full = exc is not None and exc.errno == errno.ENOSPC
    if not full:
        try:
            st = os.statvfs(out)
            full = st.f_bavail * st.f_frsize < need_bytes
        except OSError:
            pass
    why = "no space left on device" if full else (getattr(exc, "strerror", None) or "the write failed")
    return f"{name}: cannot write ({why}); nothing was installed at the output folder"


def _imwrite(cv2, path: Path, image) -> None:
    """``cv2.imwrite`` that fails loudly (OpenCV returns False on a full disk)."""
    if not cv2.imwrite(str(path), image):
        raise InputFileError(_write_failure(path.parent, path, need_bytes=max(image.nbytes, 1 << 20)))


def _check_video(cv2, path: Path, n_frames: int, out: Path) -> None:
    """The written video holds ``n_frames`` readable frames (``cv2.VideoWriter`` says nothing when
    the disk fills up: the container comes out short or without its index)."""
    cap = cv2.VideoCapture(str(path))
    try:
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT) or 0) if cap.isOpened() else 0
        ok = n == n_frames
        if ok and n_frames > 0:
            cap.set(cv2.CAP_PROP_POS_FRAMES, n_frames - 1)
            ok, _ = cap.read()
    finally:
        cap.release()
    if not ok:
        raise InputFileError(_write_failure(out, path) + f" (the video holds {n} of {n_frames} frames)")
