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
from dataclasses import replace
from pathlib import Path

import numpy as np

from ...errors import ConfigError, InputFileError
from .cameras import Camera, MultiCameraTracker, border_distance
from .results import TrackResult
from .setup import _as_calibration, _as_scenes, frame_groups, make_cameras, open_sources
from .types import TrackerConfig, TrackRow

__all__ = ["TRACK_COLUMNS", "parse_dots", "iter_track", "track_frames", "track_video",
           "write_track_csv", "read_track_csv"]

TRACK_COLUMNS = ("frame", "time_s", "x", "y", "heading_deg", "status", "std_mm", "std_heading_deg", "reason")
"""Columns of the track CSV: the contract's six, then ``std_mm`` (1σ of the position, mm),
``std_heading_deg`` (1σ of the heading, degrees; empty with one dot) and ``reason`` (why a row
is not ``ok``; empty when it is)."""
LEGACY_TRACK_COLUMNS = TRACK_COLUMNS[:6]
EARLIER_TRACK_COLUMNS = TRACK_COLUMNS[:7]
KNOWN_COLOURS = ("red", "green")
LINE_DOTS = ("line",)
"""``dots`` of case C: one laser line (:class:`~posekit.ceiling.detect.LineDetector` and
:class:`~posekit.ceiling.linetrack.LineTracker`)."""


def parse_dots(text: str | Sequence[str]) -> tuple[str, ...]:
    """``"red"`` or ``"red,green"`` → a tuple of colours, ``"line"`` → ``("line",)`` (one
    laser line, case C); ConfigError otherwise."""
    items = [t.strip() for t in (text.split(",") if isinstance(text, str) else text)]
    if items == ["line"]:
        return ("line",)
    if not items or any(c not in KNOWN_COLOURS for c in items) or len(set(items)) != len(items):
        raise ConfigError(f"--dots: expected 'red' or 'red,green', got {text!r} (or 'line' for a laser line)")
    return tuple(items)


def _dots_by_colour(dots) -> dict[str, np.ndarray]:
    out: dict[str, list] = {}
    for d in dots:
        out.setdefault(d.color, []).append((d.u, d.v))
    return {c: np.asarray(v, dtype=float) for c, v in out.items()}


def iter_track(frames: Iterable, cameras: Sequence[Camera], dots: Sequence[str] = ("red",), *,
               config: TrackerConfig | None = None, detectors: Sequence | None = None,
               border_margin_px: float = 20.0, use_roi: bool = True, survey_every: int = 30,
               timings: list | None = None, scenes: Sequence | None = None,
               stats: dict | None = None, tests=None) -> Iterator[tuple[TrackRow, np.ndarray]]:
    """Track frame by frame, yielding each row as soon as its frame is done (live use).

    Per frame and camera: the detector searches a window around the predicted dot while the
    track is ``ok`` (and the whole frame every ``survey_every`` frames, and whenever the track
    is not ``ok``: re-acquisition is a whole-frame search); every candidate goes through the
    camera's model of static lights (:class:`~posekit.ceiling.detect.scene.StaticLights`: a
    test over several frames of whether its motion is more than its own centroid jitter) and is
    verified — not a static light, a saturated core, brightness and size like the tracked
    laser's (:class:`DotSignature`). The tracker accepts only a gated candidate, or re-acquires
    on the one verified candidate the test found moving.

    Parameters are those of :func:`track_frames`; ``images`` of a frame may be None (or a
    camera's entry None) for a frame that could not be decoded: its row is ``lost`` with the
    reason (a fourth item of the frame tuple, a list of one string per camera, when given).
    ``timings``, if given, receives the processing time of each frame (s, decoding excluded).
    ``scenes``: per camera the static lights of a learned scene (a list of
    :class:`~posekit.ceiling.detect.scene.Light`, or None: learned online). ``stats``, if
    given, is filled with ``rebuilds``, ``relights`` (background), ``static_lights`` and
    ``scene`` (``"learned online"`` or ``"from the scene file"``) as the run goes.

    Yields
    ------
    row : TrackRow
    uv : ndarray, shape (2,)
        The primary dot as detected in the camera used, px (NaN when not ``ok``).
    """
    from ..detect.scene import StaticLights
    from ..detect.signature import DotSignature
    from .verify import LaserTests, verify_candidates

    dots = parse_dots(dots)
    cfg = TrackerConfig(dots=dots) if config is None else replace(config, dots=dots)
    if detectors is None:
        from ..detect.dots import DotDetector
        detectors = [DotDetector(colors=dots) for _ in cameras]
    if len(detectors) != len(cameras):
        raise ConfigError(f"track_frames: {len(detectors)} detectors for {len(cameras)} cameras")
    if scenes is None:
        scenes = [None] * len(cameras)
    lights = [StaticLights(known=s or (), jitter_floor_px=cam.detection_std_px) for s, cam in zip(scenes, cameras)]
    stats = {} if stats is None else stats
    stats.update(rebuilds=0, relights=0, static_lights=0,
                 scene="from the scene file" if any(s is not None for s in scenes) else "learned online")
    survey_every = max(int(survey_every), 1)
    signatures = [{c: DotSignature() for c in dots} for _ in cameras]     # per camera and colour
    absorb = [[] for _ in cameras]             # per camera: the static lights of the last frame
    followed = [{} for _ in cameras]           # per camera: image-track identity of each tracked dot
    protect = [[] for _ in cameras]            # per camera: where the tracked dots were last seen
    tests = LaserTests() if tests is None else tests
    mct = MultiCameraTracker(cameras, cfg, border_margin_px=border_margin_px)
    suspect_cal = [getattr(c.calibration, "status", "ok") == "suspect" for c in cameras]
    confident = False
    for item in frames:
        index, t_s, images = item[:3]
        errors = item[3] if len(item) > 3 else None
        t0 = time.perf_counter()
        if images is None:
            images = [None] * len(cameras)
        elif len(cameras) == 1 and isinstance(images, np.ndarray):
            images = [images]
        if errors is None or isinstance(errors, str):
            errors = [errors] * len(cameras)
        pred = mct.predicted_uv(t_s)
        search = list(range(len(cameras)))
        a = mct.active
        if confident and a >= 0 and dots[0] in pred[a]:
            bd = border_distance(np.asarray(pred[a][dots[0]])[None], cameras[a].image_size)[0]
            if bd >= 2 * border_margin_px:
                search = [a]                        # camera switch: the others can sleep
        survey = index % survey_every == 0
        detections, eligible, stds, moving, assoc, found = [], [], [], [], [], {}
        for i, (det, img) in enumerate(zip(detectors, images)):
            if i not in search or img is None:
                for lst in (detections, eligible, stds, moving, assoc):
                    lst.append(None)
                continue
            roi = pred[i] if (use_roi and confident and not survey and pred[i]) else None
            ds = det.detect(img, predicted_uv=roi, protect=list(pred[i].values()) + protect[i], absorb=absorb[i])
            cand = verify_candidates(index, ds, lights[i], signatures[i], cameras[i].detection_std_px, tests,
                                     followed[i])
            found[i] = cand
            detections.append(cand.uv)
            eligible.append(cand.eligible)
            moving.append(cand.moving)
            stds.append(cand.std_px)
            assoc.append(cand.associable(followed[i]))
        row = mct.step(t_s, detections, frame=index, eligible=eligible, std_px=stds, moving=moving, associable=assoc)
        if all(img is None for img in images):
            why = "; ".join(e for e in errors if e) or "the frame could not be decoded"
            row = replace(row, x=float("nan"), y=float("nan"), heading_deg=float("nan"), status="lost",
                          std_mm=float("nan"), std_heading_deg=float("nan"), camera=-1, measured={},
                          reasons=(why,))
        elif row.status in ("predicted", "lost"):
            row = _blind_reason(row, pred, detectors, images)
        elif row.camera >= 0 and suspect_cal[row.camera]:
            cal = cameras[row.camera].calibration
            why = "; ".join(getattr(cal, "reasons", ()) or ("the calibration is suspect",))
            row = replace(row, status="suspect", reasons=row.reasons + (f"calibration: {why}",))
        uv = np.full(2, np.nan)
        for i, cand in found.items():
            if row.camera == i and row.measured:
                track_uv = cameras[i].to_image(np.array(list(row.measured.values())))
                for j, c in enumerate(row.measured):
                    p = track_uv[j]
                    best = min((d for d in cand.dots if d.color == c),
                               key=lambda d: (d.u - p[0]) ** 2 + (d.v - p[1]) ** 2, default=None)
                    if best is None:
                        continue
                    signatures[i][c].update(best)
                    followed[i][c] = cand.identity(c, (best.u, best.v))
                    if c == dots[0] and row.status in ("ok", "suspect"):
                        uv = np.array([best.u, best.v])
        for i in range(len(cameras)):                   # a lost dot follows no image track any more
            for c, (_, _, status) in (row.dots or {}).items():
                if status == "lost":
                    followed[i].pop(c, None)
            keep = set(followed[i].values())
            absorb[i] = lights[i].settled_uv(keep)      # next frame: the scene's settled spots fade in,
            protect[i] = [p for p in (lights[i].last_uv(f) for f in keep) if p is not None]   # the tracked ones not
        confident = row.status == "ok"
        stats.update(rebuilds=sum(getattr(d, "rebuilds", 0) for d in detectors),
                     relights=sum(getattr(d, "relights", 0) for d in detectors),
                     static_lights=sum(lt.n_static for lt in lights))
        if timings is not None:
            timings.append(time.perf_counter() - t0)
        yield row, uv


def _blind_reason(row: TrackRow, pred, detectors, images) -> TrackRow:
    """Add to a row without a dot that the background at the predicted dot is saturated."""
    for i, (det, img) in enumerate(zip(detectors, images)):
        p = pred[i].get(row.dots and next(iter(row.dots)) or "red") if i < len(pred) else None
        if img is None or p is None or not hasattr(det, "blind_fraction"):
            continue
        if det.blind_fraction(p) > 0.5:
            return replace(row, reasons=row.reasons + ("the background at the predicted dot is saturated: a dot "
                                                       "there cannot be told from the scene",))
    return row


def track_frames(frames: Iterable, cameras: Sequence[Camera], dots: Sequence[str] = ("red",), *,
                 config: TrackerConfig | None = None, detectors: Sequence | None = None,
                 border_margin_px: float = 20.0, use_roi: bool = True, progress=None,
                 on_row=None, scenes: Sequence | None = None) -> TrackResult:
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
    scenes : sequence, optional
        Per camera the static lights of a learned scene (:func:`~posekit.ceiling.detect.scene.load_scene`),
        or None: learned online.

    Returns
    -------
    TrackResult
    """
    dots = parse_dots(dots)
    it = frames if progress is None else progress(frames)
    if dots == LINE_DOTS:
        return _track_line_frames(it, cameras, config=config, detectors=detectors,
                                  border_margin_px=border_margin_px, use_roi=use_roi, on_row=on_row)
    rows, uvs, proc, stats = [], [], [], {}
    t_start = time.perf_counter()
    for row, uv in iter_track(it, cameras, dots, config=config, detectors=detectors,
                              border_margin_px=border_margin_px, use_roi=use_roi, timings=proc, scenes=scenes,
                              stats=stats):
        rows.append(row)
        uvs.append(uv)
        if on_row is not None:
            on_row(row)
    total = time.perf_counter() - t_start
    return TrackResult(rows=rows, image_uv=np.array(uvs, dtype=float).reshape(-1, 2), seconds_total=total,
                       seconds_processing=np.array(proc), cameras=[c.name for c in cameras], stats=stats)


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
    for item in frames:
        index, t_s, images = item[:3]
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
                loop: int = 1, max_frames: int | None = None, live: bool = False, scene=None) -> TrackResult:
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
        Passes over a video file played live, a frame limit (every kind of source), and
        whether to read a file through the live path (:func:`~posekit.ceiling.track.sources.open_live`).
    scene : path, or a sequence of them (one per source), optional
        Scene file(s) of ``posekit ceiling learn-scene``: the static lights, known from the
        first frame. Default: learned online.

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
    scenes = _as_scenes(scene, len(sources))
    streams = open_sources(sources, fps, loop=loop, max_frames=max_frames, live=live)
    cameras = make_cameras(streams, cals, camera)
    for (lights, size, name), st in zip(scenes, streams):
        if size is not None and tuple(size) != tuple(st.image_size):
            raise ConfigError(f"{name}: the scene was learned on {size[0]}x{size[1]} px frames, {st.path} has "
                              f"{st.image_size[0]}x{st.image_size[1]} px; learn it from this camera at this resolution")
    detectors = make_detectors(dots, len(cameras), detector_options)
    result = track_frames(frame_groups(streams), cameras, dots, config=config, detectors=detectors,
                          border_margin_px=border_margin_px, use_roi=use_roi, progress=progress, on_row=on_row,
                          scenes=None if scene is None else [s[0] for s in scenes])
    result.fps_source = streams[0].fps_source
    result.warnings = [w for st in streams for w in st.warnings]
    return result


def write_track_csv(rows: Iterable[TrackRow], path: str | Path) -> Path:
    """Write ``frame,time_s,x,y,heading_deg,status,std_mm,std_heading_deg,reason`` (mm, s,
    degrees; NaN as empty)."""
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
        Missing file or header other than
        ``frame,time_s,x,y,heading_deg,status[,std_mm[,std_heading_deg,reason]][,robot]``
        (a column a file lacks reads as NaN, or "" for ``reason``).
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
    if names not in (TRACK_COLUMNS, LEGACY_TRACK_COLUMNS, EARLIER_TRACK_COLUMNS, TRACK_COLUMNS + ("robot",),
                     EARLIER_TRACK_COLUMNS + ("robot",)):
        raise InputFileError(f"{path}: expected header {','.join(TRACK_COLUMNS)}, got {','.join(header or [])!r}")
    bad = next((k for k, r in enumerate(body) if len(r) != len(names)), None)
    if bad is not None:
        raise InputFileError(f"{path}: line {bad + 2} has {len(body[bad])} fields, expected {len(names)}")
    cols = list(zip(*body)) if body else [()] * len(names)
    out = {}
    for name, col in zip(names, cols):
        if name in ("status", "reason"):
            out[name] = np.array(col, dtype=str)
        elif name in ("frame", "robot"):
            out[name] = np.array([int(v) for v in col], dtype=int)
        else:
            out[name] = np.array([float(v) if v.strip() else np.nan for v in col], dtype=float)
    for name in ("std_mm", "std_heading_deg"):
        if name not in out:
            out[name] = np.full(len(body), np.nan)
    if "reason" not in out:
        out["reason"] = np.full(len(body), "", dtype=str)
    return out
