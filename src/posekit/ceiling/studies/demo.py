"""The ceiling system end to end on a synthetic video: the paper's §V in one call.

:func:`run_demo` renders a ceiling video (:mod:`posekit.ceiling.sim.video`), calibrates the
camera from the grid corners of the dot-free ``reference.png`` (the T-bar crossings found
by :func:`~posekit.ceiling.grid.find_grid_corners` from four roughly "clicked" corners;
``calibration_points.csv`` when the reference image is missing), tracks the dot(s)
(:func:`~posekit.ceiling.track.pipeline.track_video`), compares the track with ``truth.csv``,
runs the 36-known-points assessment and the heading simulation of §V-B, draws the
trajectory in the image and on the ceiling with the truth (the paper's Fig. 8 and 9) and
writes ``report.html`` (:func:`write_demo_report`, through :mod:`posekit.report`).
"""

import csv
import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..._extras import require
from ...errors import ConfigError, InputFileError
from .accuracy import ErrorStats, HeadingSimulation, KnownPointsResult, error_stats

__all__ = ["SceneTruthTable", "DemoReport", "read_truth_csv", "calibrate_rendered", "calibrate_rendered_points",
           "lens_from_chessboards", "compare_with_truth", "plot_trajectories", "write_demo_report", "run_demo"]


@dataclass
class SceneTruthTable:
    """``truth.csv`` of a render: per frame, arrays with a leading frame axis (mm, degrees, px)."""

    frame: np.ndarray
    time_s: np.ndarray
    xy: np.ndarray
    heading_deg: np.ndarray
    red_visible: np.ndarray
    green_visible: np.ndarray
    uv: np.ndarray


def read_truth_csv(path) -> SceneTruthTable:
    """Read the renderer's ``truth.csv`` (``frame,time_s,x,y,heading_deg,red_visible,green_visible``
    and optionally ``red_u,red_v``)."""
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise InputFileError(f"{path}: cannot read the truth CSV ({exc.strerror or exc})") from None
    need = ("frame", "time_s", "x", "y", "heading_deg", "red_visible", "green_visible")
    if not rows or any(k not in rows[0] for k in need):
        raise InputFileError(f"{path}: expected the columns {','.join(need)}")

    def col(name, default=np.nan):
        return np.array([float(r[name]) if r.get(name, "") not in ("", None) else default for r in rows])

    return SceneTruthTable(frame=col("frame").astype(int), time_s=col("time_s"),
                           xy=np.column_stack([col("x"), col("y")]), heading_deg=col("heading_deg"),
                           red_visible=col("red_visible", 0).astype(bool),
                           green_visible=col("green_visible", 0).astype(bool),
                           uv=np.column_stack([col("red_u"), col("red_v")]))


def calibrate_rendered(render_dir, grid=None, lens=None):
    """Calibrate the camera of a rendered video folder; returns ``(calibration, method)``.
    See :func:`calibrate_rendered_points`."""
    cal, method, _, _ = calibrate_rendered_points(render_dir, grid, lens)
    return cal, method


def calibrate_rendered_points(render_dir, grid=None, lens=None):
    """Calibrate the camera of a rendered video folder.

    With ``reference.png``: four grid corners of ``calibration_points.csv`` (the extreme
    ones, rounded to whole pixels as a user would click them) seed
    :func:`~posekit.ceiling.grid.find_grid_corners`, which finds every T-bar crossing to
    sub-pixel accuracy; the homography is fitted to those. Without it: to the points of
    ``calibration_points.csv``. With a ``lens``, the reference image is undistorted first
    (``cv2.undistort`` with the same K: straight T-bars again) and the seeds with it, so the
    homography maps undistorted pixels.

    Parameters
    ----------
    render_dir : path
        Folder written by :func:`~posekit.ceiling.sim.video.render_video`.
    grid : CeilingGrid, optional
        The ceiling lattice (default: the renderer's default tiles).
    lens : CameraModel, optional
        The camera's lens model.

    Returns
    -------
    calibration : Calibration
        ``camera`` set to ``lens``.
    method : str
        How it was obtained (for the report).
    world_xy : ndarray, shape (N, 2)
        The calibration points on the ceiling, mm.
    image_uv : ndarray, shape (N, 2)
        Their pixels as seen (distorted), px.
    """
    from ..camera.homography import calibrate
    from ..camera.points import read_points_csv, undistort_calibration_points

    render_dir = Path(render_dir)
    pts = read_points_csv(render_dir / "calibration_points.csv")
    ref = render_dir / "reference.png"
    lens_note = "" if lens is None else ", through the lens model"
    if ref.exists():
        cv2 = require("cv2", "vision", "posekit ceiling demo")

        from ..camera.grid import CeilingGrid, find_grid_corners
        if grid is None:
            from ..sim.config import SceneConfig
            c = SceneConfig()
            grid = CeilingGrid(spacing_mm=c.tile_size_mm, bar_width_mm=c.tbar_width_mm)
        image = cv2.imread(str(ref))
        if image is None:
            raise InputFileError(f"{ref}: cannot decode this file as an image")
        uv = pts.image_uv
        if lens is not None:
            image = cv2.undistort(image, lens.K, lens.dist, None, lens.K)
            uv = undistort_calibration_points(lens, uv, pts.lines)
        seeds = np.unique([np.argmin(uv.sum(1)), np.argmax(uv.sum(1)),
                           np.argmin(uv[:, 0] - uv[:, 1]), np.argmax(uv[:, 0] - uv[:, 1])])
        with np.errstate(invalid="ignore"):
            corners = find_grid_corners(image, grid, seed_world=pts.world_xy[seeds],
                                        seed_image=np.round(uv[seeds]))
        cal = calibrate(corners.world_xy, corners.image_uv)
        cal.camera = lens
        seen = corners.image_uv if lens is None else lens.distort_points(corners.image_uv)
        return (cal, f"{len(corners.world_xy)} grid corners found in reference.png{lens_note}",
                corners.world_xy, seen)
    image_uv = pts.image_uv if lens is None else undistort_calibration_points(lens, pts.image_uv, pts.lines)
    cal = calibrate(pts.world_xy, image_uv)
    cal.camera = lens
    return cal, f"{len(pts.world_xy)} points of calibration_points.csv{lens_note}", pts.world_xy, pts.image_uv


def lens_from_chessboards(camera, out_dir=None, *, n_views: int = 12, board=(9, 6), square_mm: float = 30.0,
                          seed: int = 0):
    """Calibrate a simulated lens the way a user would: render ``n_views`` chessboard images
    through ``camera`` (:mod:`~posekit.ceiling.render_chessboard`) and run
    :func:`~posekit.ceiling.camera.calibrate_camera` on them (k3 fixed at 0, as the CLI's
    default). Writes the views as ``chessboard/view_NN.png`` under ``out_dir`` if given.

    Returns
    -------
    LensCalibration
    """
    from ..camera.lens import calibrate_camera
    from ..sim.chessboard import chessboard_poses, render_board_view

    poses = chessboard_poses(camera, board, square_mm, n_views, rng=seed)
    views = [(f"view_{k:02d}", render_board_view(camera, T, board, square_mm, supersample=2, rng=[seed, k]))
             for k, T in enumerate(poses)]
    if out_dir is not None:
        cv2 = require("cv2", "vision", "posekit ceiling demo")
        folder = Path(out_dir) / "chessboard"
        folder.mkdir(parents=True, exist_ok=True)
        for name, img in views:
            cv2.imwrite(str(folder / f"{name}.png"), img)
    return calibrate_camera(views, board, square_mm, fix_k3=True)


def compare_with_truth(result, truth: SceneTruthTable) -> dict:
    """Errors of a track against the truth of its render.

    Returns
    -------
    dict
        ``ok``/``predicted`` : ErrorStats of the position (mm) over the rows of that status;
        ``raw`` : ErrorStats of the accepted measurements before filtering;
        ``heading`` : dict ``mean_deg, std_deg, rms_deg, max_abs_deg, n`` (rows with a heading);
        ``ok_without_dot`` : rows ``ok`` whose red dot was not visible (must be 0);
        ``visible_not_ok`` : rows whose red dot was visible but not ``ok`` (missed or gated).
    """
    n = min(len(result.rows), len(truth.frame))
    if n == 0:
        raise InputFileError("compare_with_truth: the track or the truth is empty")
    xy = result.xy()[:n]
    status = result.status()[:n]
    T = truth.xy[:n]
    raw = np.array([r.measured.get("red", (np.nan, np.nan)) for r in result.rows[:n]], dtype=float)
    out = {s: error_stats(np.where((status == s)[:, None], xy, np.nan), T) for s in ("ok", "predicted")}
    out["raw"] = error_stats(raw, T)
    h = result.heading_deg()[:n]
    dh = (h - truth.heading_deg[:n] + 180.0) % 360.0 - 180.0
    dh = dh[np.isfinite(dh)]
    out["heading"] = ({"n": int(dh.size), "mean_deg": float(dh.mean()), "std_deg": float(dh.std()),
                       "rms_deg": float(np.sqrt(np.mean(dh ** 2))), "max_abs_deg": float(np.abs(dh).max())}
                      if dh.size else {"n": 0})
    vis = truth.red_visible[:n]
    out["ok_without_dot"] = int(np.sum((status == "ok") & ~vis))
    out["visible_not_ok"] = int(np.sum(vis & (status != "ok")))
    return out


def plot_trajectories(result, truth: SceneTruthTable, calibration, reference_bgr, out_dir,
                      holes_mm=(), corners_uv=None) -> list[Path]:
    """Fig. 8 (trajectory in the image over the reference image) and Fig. 9 (on the ceiling
    plane, mm), each with the truth; PNG files in ``out_dir``."""
    from matplotlib.patches import Rectangle

    from ...report import pyplot, save_figure
    plt = pyplot()

    out_dir = Path(out_dir)
    n = min(len(result.rows), len(truth.frame))
    status = result.status()[:n]
    xy = result.xy()[:n]
    paths = []

    fig, ax = plt.subplots(figsize=(9, 5.4))
    if reference_bgr is not None:
        ax.imshow(reference_bgr[..., ::-1], alpha=0.8)
    uv = result.image_uv[:n]
    ax.plot(uv[:, 0], uv[:, 1], "r.", ms=3, label="detected laser dot")
    tuv = truth.uv[:n]
    if np.isfinite(tuv).any():
        ax.plot(tuv[:, 0], tuv[:, 1], "-", color="k", lw=0.6, label="truth", zorder=3)
    if corners_uv is not None:
        ax.plot(corners_uv[:, 0], corners_uv[:, 1], "k+", ms=8, label="calibration corners")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_title("Trajectory of the laser dot in the image plane (cf. Fig. 8)")
    ax.legend(loc="upper right", fontsize=8)
    paths.append(save_figure(fig, out_dir / "fig8_image_trajectory.png", dpi=120))

    fig, ax = plt.subplots(figsize=(9, 5.4))
    for x0, y0, x1, y1 in holes_mm:
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, color="0.85", zorder=0))
    for s, style, label in (("ok", "r.", "tracked (ok)"), ("predicted", "bx", "predicted (no dot)")):
        m = status == s
        ax.plot(xy[m, 0], xy[m, 1], style, ms=3, label=label)
    ax.plot(truth.xy[:n, 0], truth.xy[:n, 1], "-", color="k", lw=0.6, label="truth", zorder=3)
    ax.set_aspect("equal")
    ax.set_xlabel("X (mm)")
    ax.set_ylabel("Y (mm)")
    ax.set_title("Trajectory on the ceiling plane (cf. Fig. 9); grey: air-conditioning vents")
    ax.legend(loc="best", fontsize=8)
    paths.append(save_figure(fig, out_dir / "fig9_world_trajectory.png", dpi=120))
    return paths


@dataclass
class DemoReport:
    """What :func:`run_demo` measured (mm, degrees, s) and where it wrote it."""

    out_dir: Path
    n_frames: int
    dots: tuple
    calibration_method: str
    calibration_rms_px: float
    calibration_rms_world: float
    counts: dict
    fps: float
    processing_ms: float
    errors: dict
    known_points: KnownPointsResult | None
    heading_simulation: HeadingSimulation
    files: list = field(default_factory=list)
    lens_method: str = "none (pinhole camera)"
    effects: str = "none"

    def summary(self) -> str:
        e = self.errors
        lines = [
            f"posekit ceiling demo: {self.n_frames} frames, dots {','.join(self.dots)}, written to {self.out_dir}",
            f"scene effects: {self.effects}",
            f"lens: {self.lens_method}",
            (f"calibration: {self.calibration_method}; rms {self.calibration_rms_px:.3f} px, "
             f"{self.calibration_rms_world:.2f} mm"),
            (f"track: {self.counts['ok']} ok, {self.counts['predicted']} predicted, {self.counts['lost']} lost; "
             f"ok rows without a visible dot: {e['ok_without_dot']}; visible dot not ok: {e['visible_not_ok']}"),
            f"position error (ok rows):        {_fmt(e['ok'])}",
            f"position error (predicted rows): {_fmt(e['predicted'])}",
            f"raw measurements (unfiltered):   {_fmt(e['raw'])}",
        ]
        h = e["heading"]
        if h.get("n"):
            lines.append(f"heading error: std {h['std_deg']:.3f}°, mean {h['mean_deg']:+.3f}°, "
                         f"max |err| {h['max_abs_deg']:.2f}° over {h['n']} frames")
        lines.append(f"speed: {self.fps:.0f} frames/s end to end (decode + detect + map + filter), "
                     f"{self.processing_ms:.2f} ms/frame without decoding (paper: 26 ms, 27 Hz)")
        if self.known_points is not None:
            k = self.known_points
            lines.append(f"36 known points (§V-B): mean {k.stats.mean_mm:.2f} mm, p95 {k.stats.p95_mm:.2f} mm, "
                         f"max {k.stats.max_mm:.2f} mm ({k.n_missed} not detected; paper: mean 14 mm)")
        hs = self.heading_simulation
        lines.append(f"heading simulation (§V-B): {hs.distance_mm:g} mm apart, errors on circles of radius "
                     f"{hs.error_mm:g} mm: std {hs.std_deg:.3f}° (closed form e/D = {hs.closed_form_deg:.3f}°; "
                     "paper: 2.00°)")
        lines.append("figures: " + ", ".join(p.name for p in self.files if p.suffix == ".png"))
        lines += [f"report: {p}" for p in self.files if p.name == "report.html"]
        return "\n".join(lines)

    def to_json(self) -> dict:
        def stats(s: ErrorStats):
            return {"n": s.n, "mean_mm": s.mean_mm, "rms_mm": s.rms_mm, "p95_mm": s.p95_mm, "max_mm": s.max_mm}
        e = self.errors
        out = {"n_frames": self.n_frames, "dots": list(self.dots), "effects": self.effects, "lens": self.lens_method,
               "calibration": self.calibration_method,
               "calibration_rms_px": self.calibration_rms_px, "calibration_rms_mm": self.calibration_rms_world,
               "counts": self.counts, "fps": self.fps, "processing_ms": self.processing_ms,
               "error_ok": stats(e["ok"]), "error_predicted": stats(e["predicted"]), "error_raw": stats(e["raw"]),
               "heading": e["heading"], "ok_without_dot": e["ok_without_dot"],
               "visible_not_ok": e["visible_not_ok"],
               "heading_simulation_std_deg": self.heading_simulation.std_deg,
               "heading_simulation_closed_form_deg": self.heading_simulation.closed_form_deg}
        if self.known_points is not None:
            out["known_points"] = {**stats(self.known_points.stats), "n_missed": self.known_points.n_missed}
        return json.loads(json.dumps(out, default=float).replace("NaN", "null"))


def _fmt(s: ErrorStats) -> str:
    if s.n == 0:
        return "no rows"
    return f"mean {s.mean_mm:.2f} mm, p95 {s.p95_mm:.2f} mm, max {s.max_mm:.2f} mm (n={s.n})"


def _stats_row(name: str, s: ErrorStats, paper: str = "") -> dict:
    return {"rows": name, "n": s.n, "mean": s.mean_mm, "rms": s.rms_mm, "p95": s.p95_mm, "max": s.max_mm,
            "paper": paper}


def write_demo_report(report: DemoReport) -> Path:
    """Write ``report.html`` into ``report.out_dir``: what :meth:`DemoReport.summary` prints, as tables,
    and the figures of ``report.files`` (Fig. 8 and 9), embedded."""
    from ...report import html_figure, html_table, write_html

    e = report.errors
    overview = [
        {"item": "video", "value": f"{report.n_frames} frames, dots {', '.join(report.dots)}"},
        {"item": "scene effects", "value": report.effects},
        {"item": "lens model", "value": report.lens_method},
        {"item": "calibration", "value": report.calibration_method},
        {"item": "calibration rms", "value": f"{report.calibration_rms_px:.3f} px, "
                                             f"{report.calibration_rms_world:.2f} mm"},
        {"item": "speed, end to end (decode + detect + map + filter)", "value": f"{report.fps:.0f} frames/s"},
        {"item": "speed without decoding", "value": f"{report.processing_ms:.2f} ms/frame (paper: 26 ms, 27 Hz)"},
    ]
    intro = ("<p>The ceiling system of the paper's §V on a synthetic video: rendered, calibrated from the "
             "ceiling grid, tracked and compared with the renderer's truth. Files: "
             + ", ".join(f"<a href='{p.name}'>{p.name}</a>" for p in report.files
                         if p.suffix in (".csv", ".json", ".avi"))
             + ".</p>" + html_table(overview, ["item", "value"]))
    counts = report.counts
    track = [{"status": "ok (a dot measured)", "frames": counts.get("ok", 0)},
             {"status": "predicted (no dot, Kalman prediction)", "frames": counts.get("predicted", 0)},
             {"status": "lost", "frames": counts.get("lost", 0)},
             {"status": "ok without a visible dot (must be 0)", "frames": e["ok_without_dot"]},
             {"status": "visible dot, not ok (missed or gated)", "frames": e["visible_not_ok"]}]
    errors = [_stats_row("tracked (ok)", e["ok"]), _stats_row("predicted", e["predicted"]),
              _stats_row("raw measurements (unfiltered)", e["raw"])]
    if report.known_points is not None:
        k = report.known_points
        errors.append(_stats_row(f"36 known points (§V-B; {k.n_missed} not detected)", k.stats, "mean 14"))
    heading = []
    h = e["heading"]
    if h.get("n"):
        heading.append({"heading error": f"tracked, two dots ({h['n']} frames)", "std": h["std_deg"],
                        "mean": h["mean_deg"], "max |err|": h["max_abs_deg"], "paper": ""})
    hs = report.heading_simulation
    heading.append({"heading error": (f"simulation (§V-B): dots {hs.distance_mm:g} mm apart, errors on circles of "
                                      f"radius {hs.error_mm:g} mm; closed form e/D = {hs.closed_form_deg:.3f}°"),
                    "std": hs.std_deg, "mean": hs.mean_deg, "max |err|": float("nan"), "paper": "std 2.00"})
    figures = "".join(html_figure(p, caption) for p, caption in (
        (report.out_dir / "fig5_calibration_check.png",
         "Fig. 5: calibration points (black crosses) and the world points back-projected by the calibration "
         "(red circles)"),
        (report.out_dir / "fig6_known_points.png",
         "Fig. 6: accuracy assessment: known positions (circles) and the positions estimated from rendered "
         "dots (crosses)"),
        (report.out_dir / "fig7_heading_simulation.png",
         "Fig. 7: heading accuracy from the localisation accuracy: two dots D apart, each on a circle of radius "
         "e; the angle θ between the estimated and the ideal line"),
        (report.out_dir / "fig8_image_trajectory.png", "Fig. 8: trajectory of the laser dot in the image"),
        (report.out_dir / "fig9_world_trajectory.png", "Fig. 9: trajectory on the ceiling plane, with the truth"),
    ) if p in report.files)
    sections = [
        ("Track", html_table(track, ["status", "frames"])),
        ("Position error against the truth",
         html_table(errors, ["rows", "n", "mean", "rms", "p95", "max", "paper"],
                    ["", "n", "mean (mm)", "rms (mm)", "p95 (mm)", "max (mm)", "paper (mm)"])),
        ("Heading", html_table(heading, ["heading error", "std", "mean", "max |err|", "paper"],
                                     ["", "std (deg)", "mean (deg)", "max |err| (deg)", "paper (deg)"])),
        ("Figures", figures),
    ]
    return write_html(report.out_dir, "posekit ceiling demo: laser dots on the ceiling (paper §V)", intro,
                      sections)


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
    """Track the §III-C dotted line: :class:`~posekit.ceiling.linetrack.DottedLineDetector` in
    the line pipeline of :func:`~posekit.ceiling.track.pipeline.track_frames`."""
    from ..track.linetrack import DottedLineDetector
    from ..track.pipeline import track_frames
    from ..track.setup import frame_groups, make_cameras, open_sources

    streams = open_sources([video])
    cameras = make_cameras(streams, [cal], lens)
    return track_frames(frame_groups(streams), cameras, ("line",), detectors=[DottedLineDetector()],
                        progress=progress)
