"""What a track run is set up from: the frame sources (files, folders, cameras, streams), the
cameras with their calibrations (fitted to the frames' resolution) and lens models, and the
learned scenes."""

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from ...errors import ConfigError
from .cameras import Camera

__all__ = ["open_sources", "frame_groups", "make_cameras", "fit_calibration"]


def _as_calibration(cal):
    if isinstance(cal, (str, Path)):
        from ..camera.homography import load_calibration
        return load_calibration(cal)
    return cal


def _as_lens(lens):
    if lens is None:
        return None
    if isinstance(lens, (str, Path)):
        from ..camera.lens import load_camera
        return load_camera(lens)
    return lens


def open_sources(sources, fps: float | None = None, *, loop: int = 1, max_frames: int | None = None,
                 live: bool = False) -> list:
    """One frame source per input: :func:`~posekit.ceiling.video_io.open_live` for a camera
    index, device or URL (or any input when ``live``), else
    :func:`~posekit.ceiling.video_io.open_frames`."""
    from .sources import is_live_source, open_frames, open_live

    out = []
    for s in sources:
        if live or is_live_source(s):
            out.append(open_live(s, loop=loop, max_frames=max_frames, fps=fps))
        else:
            out.append(open_frames(s, fps, max_frames=max_frames))
    return out


def frame_groups(streams) -> Iterator[tuple[int, float, list, list]]:
    """``(index, time_s, images, errors)`` of synchronised sources (the shortest ends it); an
    image that could not be decoded is None and its error says why."""
    for group in zip(*streams):
        f0 = group[0]
        yield f0.index, f0.time_s, [f.image for f in group], [f.error for f in group]


def make_cameras(streams, calibrations, lenses=None) -> list[Camera]:
    """:class:`Camera` of each source from its calibration (object or JSON path) and lens
    model (``CameraModel``, camera JSON path, or None)."""
    if not isinstance(calibrations, (list, tuple)):
        calibrations = [calibrations]
    if len(streams) != len(calibrations):
        raise ConfigError(f"track_video: {len(streams)} input(s) but {len(calibrations)} calibration(s); "
                          "give one calibration per camera")
    if lenses is None or not isinstance(lenses, (list, tuple)):
        lenses = [lenses] * len(streams)
    if len(lenses) != len(streams):
        raise ConfigError(f"--camera given {len(lenses)} time(s) for {len(streams)} input(s); "
                          "give one camera model per input, or one for all")
    cams = []
    for cal, st, lens in zip(calibrations, streams, lenses):
        lens = _as_lens(lens)
        if lens is not None and tuple(lens.image_size) != tuple(st.image_size):
            raise ConfigError(f"{st.path}: frames are {st.image_size[0]}x{st.image_size[1]} px but the camera model "
                              f"is for {lens.image_size[0]}x{lens.image_size[1]} px; calibrate the lens at the "
                              "resolution of the video")
        cal = fit_calibration(_as_calibration(cal), st.image_size, str(st.path), notes=getattr(st, "warnings", None))
        cams.append(Camera(cal, st.image_size, name=str(st.path), lens=lens))
    return cams


def fit_calibration(cal, frame_size, source: str = "INPUT", notes: list | None = None):
    """The calibration for frames of ``frame_size`` (w, h) px.

    A calibration that knows its image size and matches is returned as is; one made at another
    resolution of the same shape (aspect within 0.5 %) gets its homography scaled (pixel
    centres: ``u' + ½ = s (u + ½)``) and a note in ``notes``; another shape is a one-line
    :class:`ConfigError`. Without a size, calibration points beyond the frame are a
    :class:`ConfigError` too (a calibration made for larger frames).
    """
    w, h = int(frame_size[0]), int(frame_size[1])
    size = getattr(cal, "image_size", None)
    if size is not None and tuple(size) != (w, h):
        cw, ch = size
        s = w / cw
        if abs(h / ch - s) > 0.005 * s:
            raise ConfigError(f"{source}: frames are {w}x{h} px but the calibration was made on {cw}x{ch} px "
                              "images of another shape; calibrate at the resolution of the video")
        from ..camera.homography import Calibration
        c = 0.5 / s - 0.5
        A = np.array([[1.0 / s, 0.0, c], [0.0, 1.0 / s, c], [0.0, 0.0, 1.0]])     # new px -> old px
        Hwi = cal.H_world_image @ A
        Hwi = Hwi / Hwi[2, 2]
        Hiw = np.linalg.inv(Hwi)
        ext = None if cal.points_extent is None else tuple(s * (v + 0.5) - 0.5 for v in cal.points_extent)
        if notes is not None:
            notes.append(f"{source}: the calibration was made on {cw}x{ch} px images, frames are {w}x{h} px: "
                         f"its homography is scaled by {s:g}")
        return Calibration(Hiw / Hiw[2, 2], Hwi, cal.rms_px * s, cal.rms_world, cal.inliers, cal.n_points, cal.camera,
                           (w, h), ext, cal.status, cal.reasons, cal.rms_all_px * s)
    ext = getattr(cal, "points_extent", None)
    if size is None and ext is not None and (ext[2] > w - 0.5 + 1.0 or ext[3] > h - 0.5 + 1.0):
        raise ConfigError(f"{source}: frames are {w}x{h} px but the calibration points reach u={ext[2]:.0f}, "
                          f"v={ext[3]:.0f} px; was the calibration made at another resolution?")
    return cal


def _as_scenes(scene, n: int) -> list:
    """Per source ``(lights or None, image_size or None, name)`` from ``track_video``'s ``scene``."""
    if scene is None:
        return [(None, None, "")] * n
    items = list(scene) if isinstance(scene, (list, tuple)) else [scene]
    if len(items) == 1:
        items = items * n
    if len(items) != n:
        raise ConfigError(f"--scene given {len(items)} time(s) for {n} input(s); give it once for all inputs or "
                          "once per input")
    from ..detect.scene import load_scene
    out = []
    for s in items:
        lights, size = load_scene(s)
        out.append((lights, size, str(s)))
    return out
