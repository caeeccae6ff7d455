"""Video → track: detect the dot(s), map them to the ceiling plane, filter (the paper's §IV).

Per frame and camera: :class:`~posekit.ceiling.detect.DotDetector` finds the dots (in a
region of interest around the track's predicted image position when there is one), the
camera's calibration maps them to the world plane, and a
:class:`~posekit.ceiling.track.MultiCameraTracker` (one camera is the usual case A/B)
gates, filters and switches cameras. The result is one row per frame, written by
:func:`write_track_csv` as ``frame,time_s,x,y,heading_deg,status,std_mm``
(:func:`iter_track` yields each row as soon as its frame is done, for live use).

With a lens model (``Camera.lens``, ``--camera``) the dot centroids are undistorted before
the homography (only the few centroids, not the frame). Each candidate is verified before the
tracker sees it (see :func:`iter_track`); the detections that were not the track teach the
detector where the static lights are. A frame that could not be decoded is a ``lost`` row.

Camera switch (case D): while the track is confident and the active camera's predicted
dot lies well inside its image, only that camera is searched; the others are searched
again as soon as the dot nears the border or is not seen (the paper's "camera switch
module ... to save energy and computational cost").
"""

import csv
import time
from collections.abc import Iterable, Iterator, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ...errors import ConfigError, InputFileError
from .cameras import Camera, MultiCameraTracker, border_distance
from .tracker import TrackerConfig, TrackRow

__all__ = ["TRACK_COLUMNS", "TrackResult", "parse_dots", "iter_track", "track_frames", "track_video",
           "write_track_csv", "read_track_csv"]

TRACK_COLUMNS = ("frame", "time_s", "x", "y", "heading_deg", "status", "std_mm")
"""Columns of the track CSV: the contract's six, then ``std_mm`` (1σ of the position, mm)."""
LEGACY_TRACK_COLUMNS = TRACK_COLUMNS[:6]
KNOWN_COLOURS = ("red", "green")
LINE_DOTS = ("line",)
"""``dots`` of case C: one laser line (:class:`~posekit.ceiling.detect.LineDetector` and
:class:`~posekit.ceiling.linetrack.LineTracker`)."""


class _TimedRows:
    """What every per-frame track result shares: iteration over ``rows`` and the timings.

    Subclasses are dataclasses with ``rows``, ``seconds_total`` (s) and ``seconds_processing``
    (shape (N,), s per frame) fields; ``_n_frames`` gives the number of frames behind ``rows``.
    """

    def __iter__(self):
        return iter(self.rows)

    def __len__(self) -> int:
        return len(self.rows)

    def _n_frames(self) -> int:
        return len(self.rows)

    @property
    def fps(self) -> float:
        """Frames per second end to end (decode + detect + map + filter)."""
        return self._n_frames() / self.seconds_total if self.seconds_total > 0 else float("nan")

    @property
    def processing_ms(self) -> float:
        """Median processing time per frame without decoding, ms."""
        return float(np.median(self.seconds_processing) * 1e3) if len(self.seconds_processing) else float("nan")


@dataclass
class TrackResult(_TimedRows):
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
    warnings : list of str
        What the sources reported (a video shorter than its header says, a stream that stopped).
    """

    rows: list[TrackRow]
    image_uv: np.ndarray
    seconds_total: float
    seconds_processing: np.ndarray
    fps_source: str = ""
    cameras: list = field(default_factory=list)
    warnings: list = field(default_factory=list)

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
        from ..camera.homography import load_calibration
        return load_calibration(cal)
    return cal


def _dots_by_colour(dots) -> dict[str, np.ndarray]:
    out: dict[str, list] = {}
    for d in dots:
        out.setdefault(d.color, []).append((d.u, d.v))
    return {c: np.asarray(v, dtype=float) for c, v in out.items()}


def iter_track(frames: Iterable, cameras: Sequence[Camera], dots: Sequence[str] = ("red",), *,
               config: TrackerConfig | None = None, detectors: Sequence | None = None,
               border_margin_px: float = 20.0, use_roi: bool = True, survey_every: int = 30,
               timings: list | None = None) -> Iterator[tuple[TrackRow, np.ndarray]]:
    """Track frame by frame, yielding each row as soon as its frame is done (live use).

    Per frame and camera: the detector searches a window around the predicted dot while the
    track is ``ok`` (and the whole frame every ``survey_every`` frames, and whenever the track
    is not ``ok``: re-acquisition is a whole-frame search); every candidate is verified —
    not where a static light was learned (:meth:`DotDetector.learn`), brightness and size like
    the tracked laser's (:class:`DotSignature`) — and the tracker accepts only a gated
    candidate or a lone verified one. After the step, the detections that were not the track
    teach the detector's mask of static lights.

    Parameters are those of :func:`track_frames`; ``images`` of a frame may be None (or a
    camera's entry None) for a frame that could not be decoded: its row is ``lost`` (the
    filter still advances in time). ``timings``, if given, receives the processing time of
    each frame (s, decoding excluded).

    Yields
    ------
    row : TrackRow
    uv : ndarray, shape (2,)
        The primary dot as detected in the camera used, px (NaN when not ``ok``).
    """
    from ..detect.dots import DotSignature

    dots = parse_dots(dots)
    cfg = TrackerConfig(dots=dots) if config is None else replace(config, dots=dots)
    if detectors is None:
        from ..detect.dots import DotDetector
        detectors = [DotDetector(colors=dots) for _ in cameras]
    if len(detectors) != len(cameras):
        raise ConfigError(f"track_frames: {len(detectors)} detectors for {len(cameras)} cameras")
    survey_every = max(int(survey_every), 1)
    signatures = [{c: DotSignature() for c in dots} for _ in cameras]     # per camera and colour
    mct = MultiCameraTracker(cameras, cfg, border_margin_px=border_margin_px)
    confident = False
    for index, t_s, images in frames:
        t0 = time.perf_counter()
        if images is None:
            images = [None] * len(cameras)
        elif len(cameras) == 1 and isinstance(images, np.ndarray):
            images = [images]
        pred = mct.predicted_uv(t_s)
        search = list(range(len(cameras)))
        a = mct.active
        if confident and a >= 0 and dots[0] in pred[a]:
            bd = border_distance(np.asarray(pred[a][dots[0]])[None], cameras[a].image_size)[0]
            if bd >= 2 * border_margin_px:
                search = [a]                        # camera switch: the others can sleep
        survey = index % survey_every == 0
        detections, eligible, stds, found = [], [], [], {}
        for i, (det, img) in enumerate(zip(detectors, images)):
            if i not in search or img is None:
                detections.append(None)
                eligible.append(None)
                stds.append(None)
                continue
            roi = pred[i] if (use_roi and confident and not survey and pred[i]) else None
            ds = det.detect(img, predicted_uv=roi)
            found[i] = ds
            by, el, sd = {}, {}, {}
            for d in ds:
                sig = signatures[i][d.color]
                by.setdefault(d.color, []).append((d.u, d.v))
                el.setdefault(d.color, []).append(not d.stray and sig.consistent(d))
                sd.setdefault(d.color, []).append(sig.std_px(d, cameras[i].detection_std_px))
            detections.append({c: np.asarray(v, dtype=float) for c, v in by.items()})
            eligible.append({c: np.asarray(v, dtype=bool) for c, v in el.items()})
            stds.append({c: np.asarray(v, dtype=float) for c, v in sd.items()})
        row = mct.step(t_s, detections, frame=index, eligible=eligible, std_px=stds)
        if all(img is None for img in images):
            row = replace(row, x=float("nan"), y=float("nan"), heading_deg=float("nan"), status="lost",
                          std_mm=float("nan"), camera=-1, measured={})
        uv = np.full(2, np.nan)
        watched = list(mct.tracker.pending().values())
        for i, ds in found.items():
            track_uv = cameras[i].to_image(np.array(watched)) if watched else None
            if row.camera == i and row.measured:
                track_uv = cameras[i].to_image(np.array(list(row.measured.values()) + watched))
                for j, c in enumerate(row.measured):
                    p = track_uv[j]
                    best = min((d for d in ds if d.color == c), key=lambda d: (d.u - p[0]) ** 2 + (d.v - p[1]) ** 2,
                               default=None)
                    if best is None:
                        continue
                    signatures[i][c].update(best)
                    if c == dots[0] and row.status == "ok":
                        uv = np.array([best.u, best.v])
            detectors[i].learn(ds, track_uv)
        confident = row.status == "ok"
        if timings is not None:
            timings.append(time.perf_counter() - t0)
        yield row, uv


def track_frames(frames: Iterable, cameras: Sequence[Camera], dots: Sequence[str] = ("red",), *,
                 config: TrackerConfig | None = None, detectors: Sequence | None = None,
                 border_margin_px: float = 20.0, use_roi: bool = True, progress=None,
                 on_row=None) -> TrackResult:
    """Track already-decoded frames of one or more synchronised cameras.

    Parameters
    ----------
    frames : iterable
        Yields ``(index, time_s, images)`` with ``images`` one BGR image (H, W, 3) per
        camera, or a single image when there is one camera; None (or a None entry) for a
        frame that could not be decoded (its row is ``lost``).
    cameras : sequence of Camera
        Calibration, image size and lens model of each camera.
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
    on_row : callable, optional
        Called with each :class:`TrackRow` as soon as its frame is done.

    Returns
    -------
    TrackResult
    """
    dots = parse_dots(dots)
    it = frames if progress is None else progress(frames)
    if dots == LINE_DOTS:
        return _track_line_frames(it, cameras, config=config, detectors=detectors,
                                  border_margin_px=border_margin_px, use_roi=use_roi, on_row=on_row)
    rows, uvs, proc = [], [], []
    t_start = time.perf_counter()
    for row, uv in iter_track(it, cameras, dots, config=config, detectors=detectors,
                              border_margin_px=border_margin_px, use_roi=use_roi, timings=proc):
        rows.append(row)
        uvs.append(uv)
        if on_row is not None:
            on_row(row)
    total = time.perf_counter() - t_start
    return TrackResult(rows=rows, image_uv=np.array(uvs, dtype=float).reshape(-1, 2), seconds_total=total,
                       seconds_processing=np.array(proc), cameras=[c.name for c in cameras])


def _track_line_frames(frames: Iterable, cameras: Sequence[Camera], *, config: TrackerConfig | None = None,
                       detectors: Sequence | None = None, border_margin_px: float = 20.0,
                       use_roi: bool = True, on_row=None) -> TrackResult:
    """:func:`track_frames` for ``dots=("line",)`` (case C): the longest segment of each
    camera, end points mapped to the world, :class:`~posekit.ceiling.linetrack.LineTracker`.
    With several cameras, the one whose segment centre is farthest from its image border is
    used (the previous one while it stays ``border_margin_px`` inside)."""
    from ..detect.lines import LineDetector
    from .linetrack import LineTracker, LineTrackerConfig, pick_line

    if detectors is None:
        detectors = [LineDetector() for _ in cameras]
    if len(detectors) != len(cameras):
        raise ConfigError(f"track_frames: {len(detectors)} detectors for {len(cameras)} cameras")
    lt = LineTracker(LineTrackerConfig(tracker=TrackerConfig() if config is None else config))
    rows, uvs, proc = [], [], []
    active = -1
    t_start = time.perf_counter()
    for index, t_s, images in frames:
        if images is None:
            images = [None] * len(cameras)
        elif len(cameras) == 1 and isinstance(images, np.ndarray):
            images = [images]
        t0 = time.perf_counter()
        pred = lt.tracker.predict(t_s).get("red")
        found = []
        for i, (det, img, cam) in enumerate(zip(detectors, images, cameras)):
            if img is None:
                continue
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
        if on_row is not None:
            on_row(row)
    total = time.perf_counter() - t_start
    return TrackResult(rows=rows, image_uv=np.array(uvs, dtype=float).reshape(-1, 2), seconds_total=total,
                       seconds_processing=np.array(proc), cameras=[c.name for c in cameras])


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
            out.append(open_frames(s, fps))
    return out


def frame_groups(streams) -> Iterator[tuple[int, float, list]]:
    """``(index, time_s, images)`` of synchronised sources (the shortest ends it); an image
    that could not be decoded is None."""
    for group in zip(*streams):
        f0 = group[0]
        yield f0.index, f0.time_s, [f.image for f in group]


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
        cams.append(Camera(_as_calibration(cal), st.image_size, name=str(st.path), lens=lens))
    return cams


def make_detectors(dots, n: int, detector_options: dict | None = None):
    """``n`` detectors for ``dots`` (None: the defaults of :func:`track_frames`)."""
    if detector_options is None:
        return None
    from ..detect.dots import DotDetector
    from ..detect.lines import LineDetector
    if dots == LINE_DOTS:
        if detector_options.get("method") == "dotted":          # the §III-C dotted line
            from .linetrack import DottedLineDetector
            rest = {k: v for k, v in detector_options.items() if k != "method"}
            return [DottedLineDetector(**rest) for _ in range(n)]
        return [LineDetector(**detector_options) for _ in range(n)]
    return [DotDetector(colors=dots, **detector_options) for _ in range(n)]


def track_video(sources, calibrations, dots: Sequence[str] | str = ("red",), *, fps: float | None = None,
                config: TrackerConfig | None = None, border_margin_px: float = 20.0, use_roi: bool = True,
                detector_options: dict | None = None, progress=None, camera=None, on_row=None,
                loop: int = 1, max_frames: int | None = None, live: bool = False) -> TrackResult:
    """Track the laser dot(s) in a video, a folder of images, a camera or a stream per calibrated camera.

    Parameters
    ----------
    sources : path, str, int, or a sequence of them
        Video file or image folder of each camera (case D: several, synchronised
        frame by frame; the shortest one ends the track), or a camera index (``0``), a
        device (``/dev/video0``) or a stream URL (``rtsp://``, ``http://``): live input,
        time-stamped with the capture clock.
    calibrations : Calibration, path, or sequence of them
        One per source (``load_calibration`` JSON or a ``Calibration``); with ``camera``, the
        homography maps undistorted pixels.
    dots : str or sequence of str
        ``"red"`` / ``("red",)`` (case A) or ``"red,green"`` (case B, heading).
    fps : float, optional
        Frame rate for the timestamps of files (default: from the container, else 15).
    config : TrackerConfig, optional
    border_margin_px, use_roi :
        As in :func:`track_frames`.
    detector_options : dict, optional
        Keyword arguments of every ``DotDetector``.
    progress : callable, optional
    camera : CameraModel, path, or sequence of them, optional
        Lens model(s) (``posekit ceiling camera``): dot centroids are undistorted before the
        homography.
    on_row : callable, optional
        Called with each row as soon as its frame is done.
    loop, max_frames, live :
        Live input: passes over a video file played live, a frame limit, and whether to
        read a file through the live path (:func:`~posekit.ceiling.video_io.open_live`).

    Returns
    -------
    TrackResult
        Iterable over its rows (:class:`~posekit.ceiling.track.TrackRow`); ``warnings``
        lists what the input sources reported (a video shorter than its header says).

    Raises
    ------
    InputFileError
        A source cannot be read (see :func:`~posekit.ceiling.video_io.open_frames`).
    CalibrationError or InputFileError
        A calibration or camera file is missing or malformed.
    ConfigError
        Sources and calibrations differ in number, bad ``dots`` or ``fps``.
    """
    dots = parse_dots(dots)
    if isinstance(sources, (str, Path, int)):
        sources = [sources]
    if not isinstance(calibrations, (list, tuple)):
        calibrations = [calibrations]
    if len(sources) != len(calibrations):
        raise ConfigError(f"track_video: {len(sources)} input(s) but {len(calibrations)} calibration(s); "
                          "give one calibration per camera")
    cals = [_as_calibration(c) for c in calibrations]
    streams = open_sources(sources, fps, loop=loop, max_frames=max_frames, live=live)
    cameras = make_cameras(streams, cals, camera)
    detectors = make_detectors(dots, len(cameras), detector_options)
    result = track_frames(frame_groups(streams), cameras, dots, config=config, detectors=detectors,
                          border_margin_px=border_margin_px, use_roi=use_roi, progress=progress, on_row=on_row)
    result.fps_source = streams[0].fps_source
    result.warnings = [w for st in streams for w in st.warnings]
    return result


def write_track_csv(rows: Iterable[TrackRow], path: str | Path) -> Path:
    """Write ``frame,time_s,x,y,heading_deg,status,std_mm`` (mm, s, degrees; NaN as empty)."""
    from ...io import atomic_file

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
        Missing file or header other than ``frame,time_s,x,y,heading_deg,status[,std_mm[,robot]]``
        (a file without ``std_mm`` reads it as NaN).
    """
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            reader = csv.reader(fh)
            header = next(reader, None)
            body = list(reader)
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read track CSV ({exc.strerror or exc})") from None
    names = tuple(h.strip() for h in header) if header is not None else ()
    if names not in (TRACK_COLUMNS, LEGACY_TRACK_COLUMNS, TRACK_COLUMNS + ("robot",)):
        raise InputFileError(f"{path}: expected header {','.join(TRACK_COLUMNS)}, got {','.join(header or [])!r}")
    bad = next((k for k, r in enumerate(body) if len(r) != len(names)), None)
    if bad is not None:
        raise InputFileError(f"{path}: line {bad + 2} has {len(body[bad])} fields, expected {len(names)}")
    cols = list(zip(*body)) if body else [()] * len(names)
    out = {}
    for name, col in zip(names, cols):
        if name == "status":
            out[name] = np.array(col, dtype=str)
        elif name in ("frame", "robot"):
            out[name] = np.array([int(v) for v in col], dtype=int)
        else:
            out[name] = np.array([float(v) if v.strip() else np.nan for v in col], dtype=float)
    if "std_mm" not in out:
        out["std_mm"] = np.full(len(body), np.nan)
    return out
