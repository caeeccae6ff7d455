"""Video → track: detect the dot(s), map them to the ceiling plane, filter (the paper's §IV).

Per frame and camera: :class:`~posekit.ceiling.detect.DotDetector` finds the dots (in a
region of interest around the track's predicted image position when there is one), the
camera's calibration maps them to the world plane, and a
:class:`~posekit.ceiling.track.MultiCameraTracker` (one camera is the usual case A/B)
gates, filters and switches cameras. The result is one row per frame, written by
:func:`write_track_csv` as ``frame,time_s,x,y,heading_deg,status``.

Camera switch (case D): while the track is confident and the active camera's predicted
dot lies well inside its image, only that camera is searched; the others are searched
again as soon as the dot nears the border or is not seen (the paper's "camera switch
module ... to save energy and computational cost").
"""

import csv
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import ConfigError, InputFileError
from .track import Camera, MultiCameraTracker, TrackerConfig, TrackRow, border_distance

__all__ = ["TRACK_COLUMNS", "TrackResult", "parse_dots", "track_frames", "track_video",
           "write_track_csv", "read_track_csv"]

TRACK_COLUMNS = ("frame", "time_s", "x", "y", "heading_deg", "status")
KNOWN_COLOURS = ("red", "green")
LINE_DOTS = ("line",)
"""``dots`` of case C: one laser line (:class:`~posekit.ceiling.detect.LineDetector` and
:class:`~posekit.ceiling.linetrack.LineTracker`)."""


@dataclass
class TrackResult:
    """Track of a video, with what is needed to plot and time it.

    Attributes
    ----------
    rows : list of TrackRow
        One per frame (iterate the result directly for the rows).
    image_uv : ndarray, shape (N, 2)
        Primary dot detected in the camera used at each frame, px (NaN where none
        was accepted): the trajectory in the image (the paper's Fig. 8).
    seconds_total : float
        Wall time of the whole run, decoding included, s.
    seconds_processing : ndarray, shape (N,)
        Wall time of detection + mapping + filtering per frame, s (decoding excluded).
    fps_source : str
        Where the frame rate of the timestamps came from.
    cameras : list of str
        Camera names.
    """

    rows: list[TrackRow]
    image_uv: np.ndarray
    seconds_total: float
    seconds_processing: np.ndarray
    fps_source: str = ""
    cameras: list = field(default_factory=list)

    def __iter__(self):
        return iter(self.rows)

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def fps(self) -> float:
        """Frames per second end to end (decode + detect + map + filter)."""
        return len(self.rows) / self.seconds_total if self.seconds_total > 0 else float("nan")

    @property
    def processing_ms(self) -> float:
        """Median processing time per frame without decoding, ms."""
        return float(np.median(self.seconds_processing) * 1e3) if len(self.seconds_processing) else float("nan")

    def xy(self) -> np.ndarray:
        """(N, 2) track in the world plane, mm (NaN where lost)."""
        return np.array([[r.x, r.y] for r in self.rows], dtype=float).reshape(-1, 2)

    def heading_deg(self) -> np.ndarray:
        return np.array([r.heading_deg for r in self.rows], dtype=float)

    def status(self) -> np.ndarray:
        return np.array([r.status for r in self.rows])

    def counts(self) -> dict[str, int]:
        s = self.status()
        return {k: int(np.sum(s == k)) for k in ("ok", "predicted", "lost")}


def parse_dots(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"red"`` or ``"red,green"`` → a tuple of colours, ``"line"`` → ``("line",)`` (one
    laser line, case C); ConfigError otherwise."""
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text)]
    if items == ["line"]:
        return ("line",)
    if not items or any(c not in KNOWN_COLOURS for c in items) or len(set(items)) != len(items):
        raise ConfigError(f"--dots: expected 'red' or 'red,green', got {text!r} (or 'line' for a laser line)")
    return tuple(items)


def _as_calibration(cal):
    if isinstance(cal, (str, Path)):
        from .calibration import load_calibration
        return load_calibration(cal)
    return cal


def _dots_by_colour(dots) -> dict[str, np.ndarray]:
    out: dict[str, list] = {}
    for d in dots:
        out.setdefault(d.color, []).append((d.u, d.v))
    return {c: np.asarray(v, dtype=float) for c, v in out.items()}


def track_frames(frames: Iterable, cameras: Sequence[Camera], dots: Sequence[str] = ("red",), *,
                 config: TrackerConfig | None = None, detectors: Sequence | None = None,
                 border_margin_px: float = 20.0, use_roi: bool = True, progress=None) -> TrackResult:
    """Track already-decoded frames of one or more synchronised cameras.

    Parameters
    ----------
    frames : iterable
        Yields ``(index, time_s, images)`` with ``images`` one BGR image (H, W, 3) per
        camera, or a single image when there is one camera.
    cameras : sequence of Camera
        Calibration and image size of each camera.
    dots : sequence of str
        Colours to track, primary first (``("red",)`` or ``("red", "green")``), or
        ``("line",)``: one laser line (case C, :func:`_track_line_frames`).
    config : TrackerConfig, optional
        Tracker tuning; its ``dots`` are replaced by ``dots``.
    detectors : sequence, optional
        One detector per camera (default ``DotDetector(colors=dots)`` each).
    border_margin_px : float
        Camera-switch hysteresis (see :class:`MultiCameraTracker`).
    use_roi : bool
        Pass the predicted image position to the detector (region of interest).
    progress : callable, optional
        Wraps the frame iterable (a progress bar).

    Returns
    -------
    TrackResult
    """
    dots = parse_dots(dots)
    if dots == LINE_DOTS:
        return _track_line_frames(frames, cameras, config=config, detectors=detectors,
                                  border_margin_px=border_margin_px, use_roi=use_roi, progress=progress)
    cfg = TrackerConfig(dots=dots) if config is None else replace(config, dots=dots)
    if detectors is None:
        from .detect import DotDetector
        detectors = [DotDetector(colors=dots) for _ in cameras]
    if len(detectors) != len(cameras):
        raise ConfigError(f"track_frames: {len(detectors)} detectors for {len(cameras)} cameras")
    mct = MultiCameraTracker(cameras, cfg, border_margin_px=border_margin_px)
    rows, uvs, proc = [], [], []
    t_start = time.perf_counter()
    it = frames if progress is None else progress(frames)
    for index, t_s, images in it:
        if len(cameras) == 1 and isinstance(images, np.ndarray):
            images = [images]
        t0 = time.perf_counter()
        pred = mct.predicted_uv(t_s)
        search = list(range(len(cameras)))
        a = mct.active
        if a >= 0 and dots[0] in pred[a]:
            bd = border_distance(np.asarray(pred[a][dots[0]])[None], cameras[a].image_size)[0]
            if bd >= 2 * border_margin_px:
                search = [a]                        # camera switch: the others can sleep
        detections = []
        for i, (det, img) in enumerate(zip(detectors, images)):
            if i not in search:
                detections.append(None)
                continue
            roi = pred[i] if (use_roi and pred[i]) else None
            detections.append(_dots_by_colour(det.detect(img, predicted_uv=roi)))
        row = mct.step(t_s, detections, frame=index)
        proc.append(time.perf_counter() - t0)
        uv = np.full(2, np.nan)
        if row.status == "ok" and row.camera >= 0:
            uv = np.asarray(cameras[row.camera].calibration.world_to_image(
                np.array([row.measured[dots[0]]])), dtype=float).reshape(2)
        rows.append(row)
        uvs.append(uv)
    total = time.perf_counter() - t_start
    return TrackResult(rows=rows, image_uv=np.array(uvs, dtype=float).reshape(-1, 2), seconds_total=total,
                       seconds_processing=np.array(proc), cameras=[c.name for c in cameras])


def _track_line_frames(frames: Iterable, cameras: Sequence[Camera], *, config: TrackerConfig | None = None,
                       detectors: Sequence | None = None, border_margin_px: float = 20.0,
                       use_roi: bool = True, progress=None) -> TrackResult:
    """:func:`track_frames` for ``dots=("line",)`` (case C): the longest segment of each
    camera, end points mapped to the world, :class:`~posekit.ceiling.linetrack.LineTracker`.
    With several cameras, the one whose segment centre is farthest from its image border is
    used (the previous one while it stays ``border_margin_px`` inside)."""
    from .detect import LineDetector
    from .linetrack import LineTracker, LineTrackerConfig, pick_line

    if detectors is None:
        detectors = [LineDetector() for _ in cameras]
    if len(detectors) != len(cameras):
        raise ConfigError(f"track_frames: {len(detectors)} detectors for {len(cameras)} cameras")
    lt = LineTracker(LineTrackerConfig(tracker=TrackerConfig() if config is None else config))
    rows, uvs, proc = [], [], []
    active = -1
    t_start = time.perf_counter()
    it = frames if progress is None else progress(frames)
    for index, t_s, images in it:
        if len(cameras) == 1 and isinstance(images, np.ndarray):
            images = [images]
        t0 = time.perf_counter()
        pred = lt.tracker.predict(t_s).get("red")
        found = []
        for i, (det, img, cam) in enumerate(zip(detectors, images, cameras)):
            roi = None
            if use_roi and pred is not None:
                uv = cam.to_image(pred[0])[0]
                if np.all(np.isfinite(uv)) and border_distance(uv[None], cam.image_size)[0] > 0:
                    roi = {det.colors[0]: uv}
            lines = det.detect(img, predicted_uv=roi)
            m = pick_line(lines, cam)
            if m is not None:
                bd = float(border_distance(np.array([[lines[0].u, lines[0].v]]), cam.image_size)[0])
                found.append((i, bd, m, lines[0]))
        choice = None
        if found:
            by_cam = {i: f for i, *f in found}
            if active in by_cam and by_cam[active][0] >= border_margin_px:
                choice = (active, *by_cam[active])
            else:
                choice = max(found, key=lambda f: f[1])
        if choice is None:
            row = lt.step(t_s, None, frame=index)
        else:
            active = choice[0]
            row = lt.step(t_s, choice[2][0], choice[2][1], frame=index, camera=active)
        proc.append(time.perf_counter() - t0)
        uv = np.full(2, np.nan)
        if row.status == "ok" and choice is not None:
            uv = np.array([choice[3].u, choice[3].v], dtype=float)
        rows.append(row)
        uvs.append(uv)
    total = time.perf_counter() - t_start
    return TrackResult(rows=rows, image_uv=np.array(uvs, dtype=float).reshape(-1, 2), seconds_total=total,
                       seconds_processing=np.array(proc), cameras=[c.name for c in cameras])


def track_video(sources, calibrations, dots: Sequence[str] | str = ("red",), *, fps: float | None = None,
                config: TrackerConfig | None = None, border_margin_px: float = 20.0, use_roi: bool = True,
                detector_options: dict | None = None, progress=None) -> TrackResult:
    """Track the laser dot(s) in a video (or folder of images) per calibrated camera.

    Parameters
    ----------
    sources : path or sequence of paths
        Video file or image folder of each camera (case D: several, synchronised
        frame by frame; the shortest one ends the track).
    calibrations : Calibration, path, or sequence of them
        One per source (``load_calibration`` JSON or a ``Calibration``).
    dots : str or sequence of str
        ``"red"`` / ``("red",)`` (case A) or ``"red,green"`` (case B, heading).
    fps : float, optional
        Frame rate for the timestamps (default: from the container, else 15).
    config : TrackerConfig, optional
    border_margin_px, use_roi :
        As in :func:`track_frames`.
    detector_options : dict, optional
        Keyword arguments of every ``DotDetector``.
    progress : callable, optional

    Returns
    -------
    TrackResult
        Iterable over its rows (:class:`~posekit.ceiling.track.TrackRow`).

    Raises
    ------
    InputFileError
        A source cannot be read (see :func:`~posekit.ceiling.video_io.open_frames`).
    CalibrationError or InputFileError
        A calibration file is missing or malformed.
    ConfigError
        Sources and calibrations differ in number, bad ``dots`` or ``fps``.
    """
    from .video_io import open_frames

    dots = parse_dots(dots)
    if isinstance(sources, (str, Path)):
        sources = [sources]
    if not isinstance(calibrations, (list, tuple)):
        calibrations = [calibrations]
    if len(sources) != len(calibrations):
        raise ConfigError(f"track_video: {len(sources)} input(s) but {len(calibrations)} calibration(s); "
                          "give one calibration per camera")
    cals = [_as_calibration(c) for c in calibrations]
    streams = [open_frames(s, fps) for s in sources]
    cameras = [Camera(cal, st.image_size, name=str(st.path)) for cal, st in zip(cals, streams)]
    if detector_options is None:
        detectors = None
    else:
        from .detect import DotDetector, LineDetector
        if dots == LINE_DOTS:
            detectors = [LineDetector(**detector_options) for _ in cameras]
        else:
            detectors = [DotDetector(colors=dots, **detector_options) for _ in cameras]

    def frames():
        for group in zip(*streams):
            f0 = group[0]
            yield f0.index, f0.time_s, [f.image for f in group]

    result = track_frames(frames(), cameras, dots, config=config, detectors=detectors,
                          border_margin_px=border_margin_px, use_roi=use_roi, progress=progress)
    result.fps_source = streams[0].fps_source
    return result


def write_track_csv(rows: Iterable[TrackRow], path: str | Path) -> Path:
    """Write ``frame,time_s,x,y,heading_deg,status`` (mm, s, degrees; NaN as empty)."""
    from ..io import atomic_file

    path = Path(path)
    with atomic_file(path, "w", newline="") as fh:  # complete or absent, never half-written
        w = csv.writer(fh)
        w.writerow(TRACK_COLUMNS)
        for r in rows:
            w.writerow(r.csv_fields())
    return path


def read_track_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Read a track CSV back: ``{column: array}`` (empty fields become NaN).

    Raises
    ------
    InputFileError
        Missing file or header other than ``frame,time_s,x,y,heading_deg,status``.
    """
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            body = list(reader)
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read track CSV ({exc.strerror or exc})") from None
    if header is None or tuple(h.strip() for h in header) != TRACK_COLUMNS:
        raise InputFileError(f"{path}: expected header {','.join(TRACK_COLUMNS)}, got {','.join(header or [])!r}")
    cols = list(zip(*body)) if body else [()] * len(TRACK_COLUMNS)
    out = {}
    for name, col in zip(TRACK_COLUMNS, cols):
        if name == "status":
            out[name] = np.array(col, dtype=str)
        elif name == "frame":
            out[name] = np.array([int(v) for v in col], dtype=int)
        else:
            out[name] = np.array([float(v) if v.strip() else np.nan for v in col], dtype=float)
    return out
