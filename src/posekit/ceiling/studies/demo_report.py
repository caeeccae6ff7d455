"""What ``posekit ceiling demo`` measured (:class:`DemoReport`): the summary it prints, ``demo.json``
and ``report.html`` (:func:`write_demo_report`, through :mod:`posekit.report`).

Errors in mm on the ceiling plane, headings in degrees, times in s.
"""

import json
from dataclasses import dataclass, field
from pathlib import Path

from .accuracy import ErrorStats, HeadingSimulation, KnownPointsResult

__all__ = ["DemoReport", "write_demo_report"]


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
