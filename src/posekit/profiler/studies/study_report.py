"""Tables (CSV), figures (PNG, matplotlib Agg) and ``report.html`` of the design studies.

:func:`write_report` takes the result of :func:`~posekit.profiler.studies.study.corners_study`,
:func:`~posekit.profiler.studies.study_noise.noise_study` or
:func:`~posekit.profiler.studies.study_limits.limits_study` and writes everything into one folder;
the report embeds each figure (base64) and links its PNG file.
"""

import html
import math
from pathlib import Path

from ...errors import ConfigError
from ...io import check_out_folder, staged_folder
from ...report import html_figure as _figure
from ...report import html_table, pyplot, save_figure, write_csv, write_html
from ..sensor import LJ_X8400
from .study import (
    GAP_COLUMNS,
    METHODS,
    PAPER_TABLE1,
    PAPER_TABLE1_M,
    STATUS_NAMES,
    TABLE1_COLUMNS,
    CornersConfig,
    CornersStudy,
    corners_study,
)
from .study_limits import LimitsConfig, LimitsStudy, limits_study, range_summary, tilt_summary
from .study_noise import NoiseConfig, NoiseStudy, noise_study

__all__ = ["run_study", "write_report", "write_csv"]

LABEL = {"cf": "CF", "mle": "CF-Opt"}


def _num(v: float) -> str:
    """3 significant digits, without exponents between 1e-3 and 1e6."""
    if math.isnan(v):
        return "–"
    if v != 0 and not 1e-3 <= abs(v) < 1e6:
        return f"{v:.3g}"
    return f"{v:.0f}" if abs(v) >= 100 else f"{v:.3g}"


def _cell(v, column: str) -> str:
    return _num(v) if isinstance(v, float) else html.escape(str(v))


def _table(rows, columns, headers=None) -> str:
    return html_table(rows, columns, headers, cell=_cell)


def _failures(failures) -> str:
    if not failures:
        return "<p>No profile failed.</p>"
    rows = [{"method": LABEL[m], "reason": STATUS_NAMES[s], "count": c, "example": msg}
            for (m, s), (c, msg) in failures.items()]
    return _table(rows, ["method", "reason", "count", "example"])


def _config(study) -> str:
    cfg = study.config
    items = "".join(f"<li><code>{html.escape(k)}</code> = {html.escape(repr(v))}</li>"
                    for k, v in vars(cfg).items())
    return (f"<p>Wall time {study.wall_s:.1f} s; CPU time in the tasks {study.task_cpu_s:.1f} s.</p>"
            f"<details><summary>Configuration</summary><ul>{items}</ul></details>")


# --------------------------------------------------------------------------- corners

DIAG_COLUMNS = ("n", "method", "estimates", "beyond_fail_um", "t_err_median_um", "rmse_x_um", "rmse_y_um",
                "rmse_z_um", "eq17_mid_median_um_per_mm", "ridge_skew_mean", "beta_mean_deg")
#: The metrics of the side-by-side Table I: (label, mean key, std key).
SIDE_METRICS = (("reprojection (µm)", "reproj_mean_um", "reproj_std_um"),
                ("eq. (17) × 10³", "eq17_mean_um_per_mm", "eq17_std_um_per_mm"))


def _gap_text(study: CornersStudy) -> str:
    """What the closed-form gap to the paper is due to, with the study's own numbers."""
    rows = {r["n"]: r for r in study.gap}
    if not rows:
        return "<p>No closed-form estimates.</p>"
    n = 5 if 5 in rows and math.isfinite(rows[5]["reproj_mean_um"]) else max(
        (k for k, r in rows.items() if math.isfinite(r["reproj_mean_um"])), default=None)
    if n is None:
        return "<p>The closed form failed for every corner count studied (it needs n ≥ 5).</p>"
    r = rows[n]
    f = _num
    cfg = study.config
    z0 = LJ_X8400.z_mid if cfg.workspace.standoff_mm is None else cfg.workspace.standoff_mm
    trend = ", ".join(f"{f(rows[k]['eq17_mean_um_per_mm'])} (n = {k})" for k in sorted(rows)
                      if math.isfinite(rows[k]["eq17_mean_um_per_mm"]))
    opt = max((t["eq17_mean_um_per_mm"] for t in study.table
               if t["method"] == "mle" and math.isfinite(t["eq17_mean_um_per_mm"])), default=float("nan"))
    try:
        paper_mean = float(r["paper_cf"].split("/")[0])
    except ValueError:
        paper_mean = float("nan")
    compare = "" if not paper_mean > 0 else (
        f": in µm our mean is {r['reproj_mean_um'] / paper_mean:.1f}× the paper's, in its own metric "
        f"{r['eq17_mean_um_per_mm'] / paper_mean:.2f}×")
    return (
        f"<p><b>The metric.</b> The paper's Table I is its eq. (17), ‖s − ŝ‖: the difference between a ridge's "
        f"direction and the direction from the ridge's point q to the estimated corner, both scaled to a unit "
        f"y-component. That is dimensionless — the corner's offset from its ridge in the plane y = const divided "
        f"by its distance from q along the ridge — so the paper's numbers (labelled µm) are read here as eq. (17) "
        f"× 10³, µm of offset per mm along the ridge. Our reprojection error is the offset itself, in µm. On the "
        f"same closed-form (CF) estimates, n = {n}, all {max(cfg.gauges)} gauges: reprojection "
        f"{f(r['reproj_mean_um'])}/{f(r['reproj_std_um'])} µm, eq. (17) × 10³ {f(r['eq17_mean_um_per_mm'])}/"
        f"{f(r['eq17_std_um_per_mm'])} with q at the end of the block — the paper's {html.escape(r['paper_cf'])}"
        f"{compare}.</p>"
        f"<p><b>Where q is.</b> Eq. (17) divides by |y − y_q|, so it depends on where the frame puts q (the "
        f"paper: q_y = 0, its origin not given). With q at y = 0 of our gauge files, the middle of the block that "
        f"the laser line sweeps, the same estimates give a median of {f(r['eq17_mid_median_um_per_mm'])} but a "
        f"mean/std of {f(r['eq17_mid_mean_um_per_mm'])}/{f(r['eq17_mid_std_um_per_mm'])}: the mean is carried by "
        f"the profiles that pass near q. Table I therefore takes q at the block's end (y = y_min), where the "
        f"paper's mean ≈ std shape appears.</p>"
        f"<p><b>Where F's origin is.</b> The closed form is not invariant to it: eq. (13)–(14) replace the fitted "
        f"r1, r3 by the nearest rotation and rescale t, which moves each corner by the change of the rotation "
        f"times the corner's depth — here ≈ {z0:.0f} mm from the emitter. With F's origin moved along z to the "
        f"stand-off before the closed form (and back after), the same profiles give "
        f"{f(r['standoff_reproj_mean_um'])}/{f(r['standoff_reproj_std_um'])} µm reprojection and "
        f"{f(r['standoff_eq17_mean_um_per_mm'])}/{f(r['standoff_eq17_std_um_per_mm'])} in eq. (17) × 10³, while "
        f"the mean true translation error stays {f(r['t_err_mean_um'])} vs {f(r['standoff_t_err_mean_um'])} µm: a "
        f"smaller residual, not a better pose. The paper does not say where F's origin lies on the line of sight; "
        f"a profiler that reports heights about a reference distance near the gauge would put its CF residuals "
        f"in this range.</p>"
        f"<p><b>What is left.</b> Our CF in eq. (17) × 10³ by n: {trend}; the paper's falls from 10 (n = 5) to 2 "
        f"(n = 10). The paper gives neither its random-gauge distribution nor its pose ranges, nor whether its "
        f"5 µm noise is on the profile points (ours: the corners, fitted over hundreds of points, then scatter by "
        f"{f(r['corner_std_um'])} µm) or on the corners; these set the CF's level and its trend with n. "
        f"CF-Opt, the ML refinement, is invariant to both choices; its eq. (17) × 10³ is at most "
        f"{f(opt)} here (the paper: '*' below 1, or 1).</p>")


def _corners(study: CornersStudy, out: Path) -> Path:
    plt = pyplot()
    write_csv(out / "table1.csv", study.table, TABLE1_COLUMNS)
    write_csv(out / "table1_diagnostics.csv", study.diagnostics, DIAG_COLUMNS)
    write_csv(out / "table1_gap.csv", study.gap, GAP_COLUMNS)
    cfg = study.config
    row = {(r["method"], r["n"], r["m"]): r for r in study.table}
    fig, axes = plt.subplots(1, 2, figsize=(10, 4), sharey=True)
    for ax, method in zip(axes, METHODS):
        for i, n in enumerate(cfg.corners):
            rs = [row[(method, n, m)] for m in cfg.gauges]
            ax.plot(cfg.gauges, [r["reproj_mean_um"] for r in rs], "o-", color=f"C{i}", label=f"n = {n}: mean")
            ax.plot(cfg.gauges, [r["reproj_std_um"] for r in rs], "s--", color=f"C{i}", label=f"n = {n}: std")
        ax.set(xlabel="random gauges m", title=f"{LABEL[method]}", yscale="log")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("reprojection error (µm)")
    axes[1].legend(fontsize=8, ncol=2)
    f1 = save_figure(fig, out / "table1_reprojection.png")
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    m = max(cfg.gauges)
    for method in METHODS:
        rs = [row[(method, n, m)] for n in cfg.corners]
        axes[0].plot(cfg.corners, [r["t_err_mean_um"] for r in rs], "o-", label=LABEL[method])
        axes[1].plot(cfg.corners, [r["rot_err_mean_deg"] for r in rs], "o-", label=LABEL[method])
    diag = [d for d in study.diagnostics if d["method"] == "mle"]
    for axis in "xyz":
        axes[2].plot([d["n"] for d in diag], [d[f"rmse_{axis}_um"] for d in diag], "o-", label=f"RMSE {axis}")
    twin = axes[2].twinx()
    twin.plot([d["n"] for d in diag], [d["ridge_skew_mean"] for d in diag], "k:", label="ridge skew ptp(u)")
    twin.set_ylabel("mean ridge skew ptp(u)")
    axes[0].set(xlabel="corners n", ylabel="mean |translation error| (µm)", yscale="log", title=f"m = {m}")
    axes[1].set(xlabel="corners n", ylabel="mean rotation error (deg)", yscale="log", title=f"m = {m}")
    axes[2].set(xlabel="corners n", ylabel="CF-Opt translation RMSE in G (µm)", yscale="log",
                title="CF-Opt error per axis; y follows the ridge skew")
    for ax in axes:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=8, loc="upper left")
    twin.legend(fontsize=8, loc="lower right")
    f2 = save_figure(fig, out / "table1_pose_error.png")

    def cell(r, mean, std):
        if math.isnan(r[mean]):
            return "-/-"
        return f"{_num(r[mean])}/{_num(r[std])}"

    side = []
    for method in METHODS:
        for n in cfg.corners:
            for label, mean, std in SIDE_METRICS:
                entry = {"method": LABEL[method], "n": n, "metric": label}
                for m in cfg.gauges:
                    entry[f"ours m={m}"] = cell(row[(method, n, m)], mean, std)
                for i, m in enumerate(PAPER_TABLE1_M):       # the paper's numbers are eq. (17)
                    paper = PAPER_TABLE1[(method, n)][i] if (method, n) in PAPER_TABLE1 else ""
                    entry[f"paper m={m}"] = paper if mean.startswith("eq17") else ""
                side.append(entry)
    cols = (["method", "n", "metric"] + [f"ours m={m}" for m in cfg.gauges]
            + [f"paper m={m}" for m in PAPER_TABLE1_M])
    intro = (f"<p>Paper Table I by simulation: {len(cfg.corners)} corner counts × {max(cfg.gauges)} random "
             f"gauges × {cfg.poses} poses, noise {cfg.noise.sigma_z_um:g} µm in z and {cfg.noise.sigma_x_um:g} µm "
             f"in x; the row for m uses the first m gauges. A failure is a profile whose corners were not "
             f"found, an estimator error, or an error above 10³ µm (the paper's '-').</p>"
             + _config(study))
    sections = [
        ("Table I: mean/std of our reprojection error (µm) and of the paper's eq. (17) × 10³, beside the paper's",
         _table(side, cols) + "<p>Paper: '-' failure (error above 10³), '*' below 1. Eq. (17) with each ridge's "
                              "point q at the block's end (y = y_min of G); see below.</p>"),
        ("The closed-form gap to the paper (table1_gap.csv)",
         _gap_text(study) + _table(study.gap, list(GAP_COLUMNS))),
        ("All statistics (table1.csv)", _table(study.table, list(TABLE1_COLUMNS))),
        (f"Diagnostics over all {max(cfg.gauges)} gauges (every estimate returned, also those beyond 10³ µm)",
         _table(study.diagnostics, list(DIAG_COLUMNS))
         + "<p>y (along the ridges) is observed only through the skew of the ridges, ptp(u) of their "
           "directions [u, 1, w]; rmse_y follows it.</p>"),
        ("Figures", _figure(f1, "Reprojection error vs number of random gauges")
         + _figure(f2, "True pose error vs corner count")),
        ("Failures", _failures(study.failures)),
    ]
    return write_html(out, "posekit profiler study: corners (Table I)", intro, sections)


# --------------------------------------------------------------------------- noise

NOISE_COLUMNS = ("noise_um", "method") + TABLE1_COLUMNS[3:]
COV_COLUMNS = ("noise_um", "axis", "predicted_std_um", "empirical_rmse_um", "normalized_rms")


def _noise(study: NoiseStudy, out: Path) -> Path:
    plt = pyplot()
    write_csv(out / "fig3.csv", study.table, NOISE_COLUMNS)
    write_csv(out / "noise_covariance.csv", study.covariance, COV_COLUMNS)
    cfg = study.config
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for ax, method, tag in zip(axes, METHODS, "ab"):
        rs = [r for r in study.table if r["method"] == method]
        ax.plot([r["noise_um"] for r in rs], [r["reproj_mean_um"] for r in rs], "o-", label="mean")
        ax.plot([r["noise_um"] for r in rs], [r["reproj_std_um"] for r in rs], "s--", label="std")
        ax.set(xlabel="noise σ_z (µm)", ylabel="reprojection error (µm)", title=f"({tag}) {LABEL[method]}")
        ax.grid(True, alpha=0.3)
        ax.legend()
    f1 = save_figure(fig, out / "fig3_reprojection.png")
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for axis, color in zip("xyz", ("C0", "C1", "C2")):
        rs = [r for r in study.covariance if r["axis"] == axis and r["noise_um"] > 0]
        x = [r["noise_um"] for r in rs]
        ax.plot(x, [r["empirical_rmse_um"] for r in rs], "o-", color=color, label=f"{axis}: empirical RMSE")
        ax.plot(x, [r["predicted_std_um"] for r in rs], "--", color=color, label=f"{axis}: predicted std")
    ax.set(xlabel="noise σ_z (µm)", ylabel="translation error in G (µm)", yscale="log",
           title="CF-Opt: predicted std (covariance) vs empirical RMSE")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    f2 = save_figure(fig, out / "noise_predicted_vs_empirical.png")
    intro = (f"<p>Paper Fig. 3 by simulation: n = {cfg.n_corners}, {cfg.gauges} random gauges × {cfg.poses} "
             f"poses at each noise level (σ in z; σ_x = {cfg.x_ratio:g} σ_z). The same gauges, poses and "
             f"standard-normal draws at every level.</p>" + _config(study))
    sections = [
        ("Reprojection and pose errors vs noise (fig3.csv)", _table(study.table, list(NOISE_COLUMNS))),
        ("Predicted vs empirical translation error, CF-Opt (noise_covariance.csv)",
         _table(study.covariance, list(COV_COLUMNS))
         + "<p>normalized_rms: RMS of error / predicted std (1 when the covariance is right).</p>"),
        ("Figures", _figure(f1, "Fig. 3: reprojection error vs noise, (a) CF, (b) CF-Opt")
         + _figure(f2, "Predicted standard deviation vs empirical RMSE per axis")),
        ("Failures", _failures(study.failures)),
    ]
    return write_html(out, "posekit profiler study: noise (Fig. 3)", intro, sections)


# --------------------------------------------------------------------------- limits

RANGE_COLUMNS = ("axis", "size_mm", "gauge", "lower_tracked_mm", "upper_tracked_mm", "range_tracked_mm",
                 "lower_visible_mm", "upper_visible_mm", "range_visible_mm")
RANGE_SUMMARY_COLUMNS = ("axis", "size_mm", "range_tracked_mean_mm", "range_tracked_min_mm",
                         "range_tracked_max_mm", "range_visible_mean_mm", "margin_model_mm")
TILT_COLUMNS = ("beta_deg", "alpha_deg", "trials", "success_rate", "visible_rate")


def _limits(study: LimitsStudy, out: Path) -> Path:
    plt = pyplot()
    rng_rows = [{k: (float(v) if k in RANGE_COLUMNS[3:] else v) for k, v in r.items()} for r in study.ranges]
    write_csv(out / "limits_range.csv", rng_rows, RANGE_COLUMNS)
    summary = range_summary(study)
    write_csv(out / "limits_range_summary.csv", summary, RANGE_SUMMARY_COLUMNS)
    tilts = tilt_summary(study)
    write_csv(out / "limits_tilt.csv", tilts, TILT_COLUMNS)
    cfg = study.config
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for axis, color in (("x", "C0"), ("z", "C1"), ("y", "C2")):
        rs = [r for r in summary if r["axis"] == axis]
        ax = axes[1] if axis == "y" else axes[0]
        s = [r["size_mm"] for r in rs]
        ax.plot(s, [r["range_tracked_mean_mm"] for r in rs], "o-", color=color, label=f"along {axis}: tracked")
        ax.fill_between(s, [r["range_tracked_min_mm"] for r in rs], [r["range_tracked_max_mm"] for r in rs],
                        color=color, alpha=0.15)
        ax.plot(s, [r["range_visible_mean_mm"] for r in rs], "s--", color=color, label=f"along {axis}: visible")
        if axis == "x":
            ax.plot(s, [r["margin_model_mm"] for r in rs], ":", color="k", label="x: view width − gauge width")
    axes[0].set(xlabel="gauge width (mm)", ylabel="range of motion along F's axis (mm)",
                title="(a) x and z vs gauge width")
    axes[1].set(xlabel="gauge length along the ridges (mm)", ylabel="range of motion along F's y (mm)",
                title="(a) y vs gauge length")
    for ax in axes:
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=8)
    f1 = save_figure(fig, out / "fig4a_range.png")
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for i, beta in enumerate(cfg.betas_deg):
        rs = [r for r in tilts if r["beta_deg"] == beta]
        ax.plot([r["alpha_deg"] for r in rs], [r["success_rate"] for r in rs], "o-", ms=3, color=f"C{i}",
                label=f"β = {beta:g}°")
        for sgn in (-1, 1):
            ax.axvline(sgn * beta, color=f"C{i}", ls=":", lw=1)
    ax.set(xlabel="tilt α about F's y (deg)", ylabel="success rate", ylim=(-0.03, 1.03),
           title="(b) self-occlusion: tracked poses vs tilt (dotted: ±β)")
    ax.grid(True, alpha=0.3)
    ax.legend()
    f2 = save_figure(fig, out / "fig4b_tilt.png")
    intro = ("<p>Paper Fig. 4 by simulation. (a) From the nominal pose, the sensor is moved along F's x and z "
             "(gauges scaled in x–z to each width) or y (gauges cut to each length) until the pose is lost: "
             "<em>tracked</em> = all corners detected on a noisy rendered profile and a CF-Opt estimate that "
             "fits them; <em>visible</em> = posekit.profiler.sim.poses.visible_mask (3 mm margins). "
             f"{cfg.gauges} random gauges with {cfg.n_corners} corners per size (band: min–max). "
             f"(b) Gauges whose steepest faces make exactly β with the vertical, tilted by α about F's y "
             f"through the gauge, {cfg.tilt_poses} jittered poses per gauge and tilt.</p>"
             + _config(study))
    sections = [
        ("Range of motion (limits_range_summary.csv)", _table(summary, list(RANGE_SUMMARY_COLUMNS))),
        ("Figures", _figure(f1, "Fig. 4(a): range of motion vs gauge size")
         + _figure(f2, "Fig. 4(b): success rate vs tilt α for gauges of different β")),
        ("Success rate vs tilt (limits_tilt.csv)", _table(tilts, list(TILT_COLUMNS))),
    ]
    return write_html(out, "posekit profiler study: limits (Fig. 4)", intro, sections)


def write_report(study, out) -> Path:
    """Write the study's CSV tables, PNG figures and ``report.html`` into folder ``out``.

    Parameters
    ----------
    study : CornersStudy, NoiseStudy or LimitsStudy
    out : str or Path
        Created if missing.

    Returns
    -------
    Path
        The ``report.html`` written.
    """
    out = Path(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError(f"--out {out}: cannot create folder ({exc.strerror or exc})") from None
    if isinstance(study, CornersStudy):
        return _corners(study, out)
    if isinstance(study, NoiseStudy):
        return _noise(study, out)
    if isinstance(study, LimitsStudy):
        return _limits(study, out)
    raise ConfigError(f"write_report: expected a study result, got {type(study).__name__}")


def run_study(config, out=None, *, scheduler=None, n_workers=None, overwrite: bool = False, replace_own: bool = False, progress=None):
    """Run a design study and write its report (``posekit profiler study corners|noise|limits``).

    Parameters
    ----------
    config : CornersConfig, NoiseConfig or LimitsConfig
        Which study (Table I, Fig. 3, Fig. 4) and its parameters.
    out : str or Path, optional
        Folder for the CSV tables, PNG figures and ``report.html`` (checked before the study
        runs; written whole or not at all).
    scheduler, n_workers
        As :func:`posekit.sweep.run_tasks` (``"serial"``, a Dask address, or a local cluster
        of ``n_workers`` processes).
    overwrite : bool
        Replace a non-empty ``out``.
    replace_own : bool
        Replace ``out`` while everything in it was written by posekit (a verb's default
        folder: its marker lists the files); a user's file there stops the run first.
    progress : callable, optional
        As :func:`posekit.sweep.run_tasks`.

    Returns
    -------
    CornersStudy, NoiseStudy or LimitsStudy
    """
    kinds = {CornersConfig: corners_study, NoiseConfig: noise_study, LimitsConfig: limits_study}
    fn = kinds.get(type(config))
    if fn is None:
        raise ConfigError(f"run_study: expected a CornersConfig, NoiseConfig or LimitsConfig, got "
                          f"{type(config).__name__}")
    if out is not None:
        check_out_folder(out, overwrite=overwrite, replace_own=replace_own)
    study = fn(config, scheduler=scheduler, n_workers=n_workers, progress=progress)
    if out is not None:
        with staged_folder(out, overwrite=overwrite, replace_own=replace_own) as tmp:
            write_report(study, tmp)
    return study
