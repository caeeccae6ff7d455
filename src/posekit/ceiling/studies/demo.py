"""The ceiling system end to end on a synthetic video: the paper's §V in one call.

:func:`run_demo` renders a ceiling video (:mod:`posekit.ceiling.sim.video`), calibrates the
camera from the grid corners of the dot-free ``reference.png`` (the T-bar crossings found
by :func:`~posekit.ceiling.camera.grid.find_grid_corners` from four roughly "clicked" corners;
``calibration_points.csv`` when the reference image is missing:
:mod:`~posekit.ceiling.studies.rendered_calibration`), tracks the dot(s)
(:func:`~posekit.ceiling.track.pipeline.track_video`), compares the track with ``truth.csv``
(:mod:`~posekit.ceiling.studies.truth`), runs the 36-known-points assessment and the heading
simulation of §V-B, draws the paper's figures (:mod:`~posekit.ceiling.studies.figures`) and writes
``demo.json`` and ``report.html`` (:mod:`~posekit.ceiling.studies.demo_report`).
"""

import json
from pathlib import Path

import numpy as np

from ..._extras import require
from ...errors import ConfigError
from .demo_report import DemoReport, write_demo_report
from .figures import plot_trajectories
from .rendered_calibration import calibrate_rendered_points, lens_from_chessboards
from .truth import compare_with_truth, read_truth_csv

__all__ = ["run_demo"]


def _effects(cfg) -> str:
    on = [name for name, flag in (
        (f"lens k1={cfg.dist[0]:g}, k2={cfg.dist[1]:g}", any(cfg.dist)), (f"bloom {cfg.bloom:g}", cfg.bloom > 0),
        (f"exposure steps ~{cfg.exposure_step_s:g} s", cfg.exposure_step_s > 0),
        (f"{cfg.occluders} occluder(s)", cfg.occluders), (f"{cfg.shadows} shadow(s)", cfg.shadows),
        (f"{cfg.stray_lights} steady red light(s)", cfg.stray_lights),
        (f"{cfg.blinking_lights} blinking red light(s)", cfg.blinking_lights),
        (f"{cfg.reflections} reflection(s)", cfg.reflections),
        (f"{cfg.codec} video", cfg.codec != "mjpg")) if flag]
    return ", ".join(on) or "none (clean video)"


def run_demo(out_dir, *, dots=("red", "green"), seconds: float | None = None, seed: int = 0,
             config=None, known_points: bool = True, progress=None, camera=None, realistic: bool = False,
             line_pattern: str = "dotted") -> DemoReport:
    """Render, calibrate, track and evaluate; write the figures, ``demo.json`` and ``report.html``.

    Parameters
    ----------
    out_dir : path
        Output folder (created): the render (``video.avi``, ``truth.csv``,
        ``calibration_points.csv``, ``reference.png``, ``camera.json``), ``calibration.json``,
        ``track.csv``, the figures ``fig5`` .. ``fig9``, ``demo.json``, ``report.html``; with a
        distorting lens and no ``camera``, ``chessboard/`` and ``camera_calibrated.json``.
    dots : tuple of str
        ``("red",)``, ``("red", "green")`` or ``("line",)`` (case C).
    seconds : float, optional
        Video length, s (default: the renderer's).
    seed : int
        Seed of the render.
    config : SceneConfig, optional
        Full scene configuration (``dots``, ``seconds`` and ``seed`` override it).
    known_points : bool
        Also run the 36-known-points assessment.
    progress : callable, optional
        Wraps the frame iterators (progress bars).
    camera : CameraModel or path, optional
        Lens model used for calibration and tracking. Default: none for a pinhole scene; for a
        distorting one, the lens is calibrated from rendered chessboard views
        (:func:`lens_from_chessboards`), as a user would.
    realistic : bool
        Start from :meth:`SceneConfig.realistic` instead of the clean defaults (ignored with
        ``config``).
    line_pattern : {"dotted", "solid"}
        With ``dots=("line",)``: the §III-C dotted line (default) or a solid line.

    Returns
    -------
    DemoReport
    """
    from dataclasses import replace

    cv2 = require("cv2", "vision", "posekit ceiling demo")

    from ..camera.lens import CameraModel, load_camera
    from ..sim.config import SceneConfig
    from ..sim.video import render_video
    from ..track.pipeline import track_video, write_track_csv
    from .accuracy import known_points_assessment, simulate_heading_error
    from .figures import plot_calibration_check, plot_heading_simulation, plot_known_points

    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {out}: cannot create folder ({exc.strerror or exc})") from None
    if seconds is not None and not (np.isfinite(seconds) and seconds > 0):
        raise ConfigError(f"--duration-s must be a positive number of seconds, got {seconds!r}")
    dots = tuple(dots)
    cfg = (SceneConfig.realistic() if realistic else SceneConfig()) if config is None else config
    extra = {"line_pattern": line_pattern} if dots == ("line",) else {}
    cfg = replace(cfg, dots=dots, seed=int(seed), **extra,
                  **({} if seconds is None else {"duration_s": float(seconds)}))
    rendered = render_video(cfg, out, progress=progress)

    lens, lens_method = None, "none (pinhole camera)"
    if camera is not None:
        lens = camera if isinstance(camera, CameraModel) else load_camera(camera)
        if tuple(lens.image_size) != (cfg.width_px, cfg.height_px):
            raise ConfigError(f"--camera: the model is for {lens.image_size[0]}x{lens.image_size[1]} px images; "
                              f"the demo renders {cfg.width_px}x{cfg.height_px}")
        lens_method = f"given ({camera if not isinstance(camera, CameraModel) else 'model'}; rms {lens.rms_px:.3f} px)"
    elif any(cfg.dist):
        from ..camera.lens import save_camera
        from ..sim.scene_geometry import lens_camera
        lc = lens_from_chessboards(lens_camera(cfg), out, seed=int(seed))
        lens = lc.camera
        save_camera(lens, out / "camera_calibrated.json")
        lens_method = (f"calibrated from {len(lc.used)} rendered chessboard views (rms {lens.rms_px:.3f} px, "
                       f"k1 {lens.dist[0]:+.4f}, k2 {lens.dist[1]:+.4f}; boards cover {100 * lc.coverage:.0f} % "
                       f"of the image); truth k1 {cfg.dist[0]:+.4f}, k2 {cfg.dist[1]:+.4f}")

    from ..camera.grid import CeilingGrid
    grid = CeilingGrid(spacing_mm=cfg.tile_size_mm, bar_width_mm=cfg.tbar_width_mm)
    cal, method, cal_world, cal_seen = calibrate_rendered_points(out, grid, lens)
    cal.to_json(out / "calibration.json")
    if dots == ("line",) and cfg.line_pattern == "dotted":
        result = _track_dotted_line(rendered.video, cal, lens, progress)
    else:
        result = track_video(rendered.video, cal, dots, progress=progress, camera=lens)
    write_track_csv(result.rows, out / "track.csv")
    truth = read_truth_csv(rendered.truth)
    errors = compare_with_truth(result, truth)
    kp = known_points_assessment(replace(cfg, holes=False), cal, camera=lens) if known_points else None
    hs = simulate_heading_error()
    reference = cv2.imread(str(rendered.reference))
    files = [rendered.video, out / "truth.csv", out / "calibration.json", out / "track.csv", out / "camera.json"]
    if (out / "camera_calibrated.json").exists():
        files.append(out / "camera_calibrated.json")
    files.append(plot_calibration_check(reference, cal_world, cal_seen, cal, out / "fig5_calibration_check.png",
                                        lens=lens, inliers=cal.inliers))
    if kp is not None:
        files.append(plot_known_points(kp, out / "fig6_known_points.png"))
    files.append(plot_heading_simulation(hs, out / "fig7_heading_simulation.png"))
    files += plot_trajectories(result, truth, cal, reference, out,
                               holes_mm=cfg.hole_rects_mm if cfg.holes else ())
    report = DemoReport(out_dir=out, n_frames=len(result), dots=tuple(dots), calibration_method=method,
                        calibration_rms_px=cal.rms_px, calibration_rms_world=cal.rms_world,
                        counts=result.counts(), fps=result.fps, processing_ms=result.processing_ms,
                        errors=errors, known_points=kp, heading_simulation=hs, files=files,
                        lens_method=lens_method, effects=_effects(cfg))
    (out / "demo.json").write_text(json.dumps(report.to_json(), indent=2) + "\n")
    report.files.append(out / "demo.json")
    report.files.append(write_demo_report(report))
    return report


def _track_dotted_line(video, cal, lens, progress):
    """Track the §III-C dotted line: :class:`~posekit.ceiling.track.linetrack.DottedLineDetector` in
    the line pipeline of :func:`~posekit.ceiling.track.pipeline.track_frames`."""
    from ..track.linetrack import DottedLineDetector
    from ..track.pipeline import track_frames
    from ..track.setup import frame_groups, make_cameras, open_sources

    streams = open_sources([video])
    cameras = make_cameras(streams, [cal], lens)
    return track_frames(frame_groups(streams), cameras, ("line",), detectors=[DottedLineDetector()],
                        progress=progress)
