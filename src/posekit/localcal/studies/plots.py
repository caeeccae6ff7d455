"""Figures (PNG, matplotlib Agg), CSV/JSON tables and ``report.html`` of localcal experiments.

Figures after the paper:

* Fig. 6-like (line method): the circular reference path vs the completed path (true and
  encoder TCP) and the move to the computed reference;
* Fig. 8-like (trajectory method): the reference path, the encoder-based TCP positions and
  the VO camera positions after the local calibration;
* Fig. 7/9-like: the image-based position errors between the tool marker and the OOI over
  time, with the look-then-move updates marked;
* Fig. 5-like: the image-based rotation errors (XYZ Euler angles) between the tool marker and
  the OOI over time, before and after the orientation adjustment.
"""

import html
import math
from pathlib import Path

import numpy as np

from posekit.localcal.methods.trajectory_method import STANDOFF_MM
from posekit.localcal.studies.experiments import (
    PAPER_TABLE2_MEAN,
    PAPER_TABLE3,
    PAPER_TABLE4_MEAN,
    ExperimentResult,
    format_table,
    table_columns,
)
from posekit.report import (
    html_figure,
    html_table,
    pyplot,
    save_figure,
    write_csv,
    write_html,
    write_json,
)

__all__ = [
    "TABLE_TITLES",
    "plot_circle_path",
    "plot_errors_over_time",
    "plot_orientation_errors",
    "plot_trajectory_matching",
    "tables_text",
    "write_experiment",
]

TABLE_TITLES = {
    "table2": "Table 2: line-equation method, image-based absolute rotation errors after the orientation "
              "adjustment and position errors after each update (#1 = eq. 16, #2.. = servo variant)",
    "table2_truth": "Table 2 (simulation truth): true rotation and position errors of the tool marker vs the OOI",
    "table3": "Table 3: mean and maximum absolute errors after point-set matching (calibrated VO vs encoder TCP), mm",
    "table4": "Table 4: image-based absolute position errors after each update (trajectory matching)",
    "table4_truth": "Table 4 (simulation truth): true position errors of the tool marker vs the OOI",
}


def _plane_coords(points, T_B_F):
    """Coordinates of base-frame points in the (n, s) plane of a TCP pose, mm."""
    d = np.asarray(points, float) - T_B_F[:3, 3]
    return d @ T_B_F[:3, 0], d @ T_B_F[:3, 1]


def plot_circle_path(episode, path):
    """Fig. 6-like figure of a line-method episode: reference circle vs completed path."""
    plt = pyplot()
    lg = episode.logs
    T0 = lg["T_B_F_centre"]
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.8))
    ref = lg["reference_path_B"]
    # the true TCP is off the model by centimetres: compare shapes from the same start
    shift = lg["path_true_B"][0] - lg["path_nominal_B"][0]
    true_path = lg["path_true_B"] - shift
    approach = lg["approach_true_B"] - shift
    for a, proj in zip(ax, ("plane", "side")):
        if proj == "plane":
            x, y = _plane_coords(ref, T0)
            a.plot(x, y, "k.-", label="reference path (waypoints)")
            x, y = _plane_coords(true_path, T0)
            a.plot(x, y, "r-", lw=1.2, label="completed path (true TCP, from the same start)")
            x, y = _plane_coords(lg["path_nominal_B"], T0)
            a.plot(x, y, "b:", lw=1, label="completed path (encoders)")
            x, y = _plane_coords(approach, T0)
            a.plot(x, y, "m-", lw=1.2, label="move to the reference (true TCP)")
            x, y = _plane_coords(np.asarray(lg["references_B"]), T0)
            a.plot(x, y, "g*", ms=12, label="reference positions (eq. 16)")
            x, y = _plane_coords(lg["ooi_target_B"][None], T0)
            a.plot(x, y, "kx", ms=10, mew=2, label="goal (tool marker on the OOI axis)")
            a.set(xlabel="n (mm)", ylabel="s (mm)", title="in the plane of the circle", aspect="equal")
        else:
            d_true = (true_path - T0[:3, 3]) @ T0[:3, 2]
            d_nom = (lg["path_nominal_B"] - T0[:3, 3]) @ T0[:3, 2]
            a.plot(d_true, "r-", label="true TCP, out of plane")
            a.plot(d_nom, "b:", label="encoder TCP, out of plane")
            a.set(xlabel="sample", ylabel="distance from the plane of the circle (mm)",
                  title="planarity of the completed path")
        a.grid(True, alpha=0.3)
        a.legend(fontsize=7)
    fig.suptitle(f"Line-equation range adjustment: circular path (r = {episode.config.radius_mm:.0f} mm)")
    return save_figure(fig, path)


def plot_trajectory_matching(episode, path):
    """Fig. 8-like figure: reference path, encoder-based TCP and calibrated VO positions."""
    plt = pyplot()
    lg = episode.logs
    T0 = lg["T_B_F_start"]
    series = ((lg["reference_path_B"], "g.-", "reference path"),
              (lg["path_nominal_B"], "k-", "encoder-based TCP"),
              (lg["vo_calibrated_B"], "r-", "VO camera after local calibration"))
    fig, ax = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [3, 2]})
    for pts, style, label in series:
        x, y = _plane_coords(pts, T0)
        ax[0].plot(x, y, style, lw=1, label=label)
        depth = (np.asarray(pts, float) - T0[:3, 3]) @ T0[:3, 2]
        ax[1].plot(x, depth, style, lw=1, label=label)
    ax[0].set(xlabel="n (mm)", ylabel="s (mm)", title="in the plane of the path (base frame)", aspect="equal")
    ax[1].set(xlabel="n (mm)", ylabel="a (mm, out of the plane)", title="side view")
    for a in ax:
        a.grid(True, alpha=0.3)
        a.legend(fontsize=7)
    m = episode.matching
    fig.suptitle("Trajectory matching (VO vs kinematic model): mean |error| x/y/z = "
                 + "/".join(f"{v:.1f}" for v in m["mean_abs_err_mm"]) + " mm")
    return save_figure(fig, path)


def plot_errors_over_time(episode, path):
    """Fig. 7/9-like figure: image-based errors e_x, e_y, e_z over time with the updates."""
    plt = pyplot()
    tl = episode.timeline
    t, e = np.asarray(tl["t_s"]), np.asarray(tl["e_C_mm"])
    fig, ax = plt.subplots(2, 1, figsize=(10, 6), sharex=True)
    for i, axis in enumerate("xyz"):
        ax[0].plot(t, e[:, i], ".-", ms=2, lw=0.8, label=f"e_{axis}")
    for i, axis in enumerate("xy"):
        ax[1].plot(t, e[:, i], ".-", ms=2, lw=0.8, label=f"e_{axis}")
    for a in ax:
        for j, (t_ev, label) in enumerate(tl["events"]):
            a.axvline(t_ev, color="0.5", ls="--", lw=0.8)
            a.text(t_ev, 0.98 - 0.12 * (j % 2), " " + label, transform=a.get_xaxis_transform(), fontsize=7,
                   va="top", color="0.3")
        a.grid(True, alpha=0.3)
        a.legend(fontsize=8, loc="lower right")
    ax[1].axhspan(-5, 5, color="g", alpha=0.1)
    ax[1].set_ylim(-60, 60)
    ax[0].set(ylabel="image-based error (mm)",
              title=f"{episode.method} method: tool marker vs OOI in the camera frame (gaps: not seen)")
    ax[1].set(xlabel="time (s)", ylabel="XY error (mm), ±5 mm band")
    return save_figure(fig, path)


def plot_orientation_errors(episode, path):
    """Fig. 5-like figure: image-based rotation errors (signed XYZ Euler angles, deg) between
    the tool marker and the OOI over time, the orientation adjustment marked.

    The paper plots failed samples as zeros; here they are gaps (not seen by the camera).
    """
    plt = pyplot()
    tl = episode.timeline
    t = np.asarray(tl["t_s"])
    rot = np.asarray(tl.get("rot_deg", np.full((len(t), 3), np.nan))).reshape(-1, 3)
    fig, ax = plt.subplots(figsize=(10, 4))
    for i, axis in enumerate("xyz"):
        ax.plot(t, rot[:, i], ".-", ms=3, lw=0.8, label=f"e_θ{axis}")
    for j, (t_ev, label) in enumerate(tl["events"]):
        ax.axvline(t_ev, color="0.5", ls="--", lw=0.8)
        ax.text(t_ev, 0.98 - 0.1 * (j % 2), " " + label, transform=ax.get_xaxis_transform(), fontsize=7,
                va="top", color="0.3")
    ax.axhline(0.0, color="k", lw=0.5)
    after = ", ".join(f"{v:.2f}" for v in np.asarray(episode.rotation_after_deg, float))
    ax.set(xlabel="time (s)", ylabel="rotation error (deg)",
           title=f"Orientation adjustment: tool marker vs OOI, XYZ Euler (|after| = {after} deg; gaps: not seen)")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    return save_figure(fig, path)


# --------------------------------------------------------------------------- files

def _num(v, col):
    if isinstance(v, str):
        return html.escape(v)
    if math.isnan(v):
        return "–"
    return f"{v:.2f}" if col.endswith("_deg") else f"{v:.1f}"


def _html_table(rows, columns):
    cols = [c for c in columns if c != "error"]
    fails = "".join(f"<li>{html.escape(r['run'])}: {html.escape(r['error'])}</li>"
                    for r in rows if r["status"] == "error" and r["run"] != "mean")
    return html_table(rows, cols, cell=_num) + (f"<ul>{fails}</ul>" if fails else "")


def _paper_rows(method: str, updates: int) -> str:
    if method == "line":
        cols = ["e_θx (deg)", "e_θy (deg)", "e_θz (deg)", "e_x (mm)", "e_y (mm)", "e_z (mm)"]
        rows = [("paper mean (Table 2)", PAPER_TABLE2_MEAN)]
    else:
        cols = ["1st e_x", "1st e_y", "1st e_z", "2nd e_x", "2nd e_y", "2nd e_z"]
        rows = [("paper mean (Table 4)", PAPER_TABLE4_MEAN),
                ("paper Table 3 mean", PAPER_TABLE3["mean"] + (math.nan,) * 3),
                ("paper Table 3 max", PAPER_TABLE3["max"] + (math.nan,) * 3)]
    head = "<th></th>" + "".join(f"<th>{html.escape(c)}</th>" for c in cols)
    body = "".join("<tr><td>" + html.escape(name) + "</td>"
                   + "".join(f"<td>{'–' if math.isnan(v) else f'{v:g}'}</td>" for v in vals) + "</tr>"
                   for name, vals in rows)
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def _settings_html(settings: dict) -> str:
    if not settings:
        return ""
    st = settings.get("vo_stereo")
    vo = ("stereo VO (baseline {baseline_mm:g} mm, f {focal_px:g} px, σ_px {pixel_noise_px:g}, σ_d "
          "{disparity_noise_px:g} px, {features} features, drift {drift_mm_per_sqrt_m:g} mm/√m lateral)".format(**st)
          if st else "isotropic VO noise")
    return (f"<p>Simulated: robot {html.escape(str(settings['robot']))}; "
            f"{'lens distortion' if settings['lens_distortion'] else 'rectified images'}; {html.escape(vo)}; "
            f"trajectory matching {settings['matching']}.</p>")


def write_experiment(result: ExperimentResult, out, *, command: str = "") -> dict:
    """Write the tables (CSV), ``results.json``, the figures (PNG) and ``report.html``.

    Parameters
    ----------
    result : ExperimentResult
        From :func:`posekit.localcal.studies.experiments.run_experiment`.
    out : path
        Output folder (created).
    command : str
        The command line, quoted in the report.

    Returns
    -------
    dict
        Name -> path of every file written.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    files = {}
    for name, rows in result.tables.items():
        files[name] = write_csv(out / f"{name}.csv", rows, table_columns(name, result.updates))
    record = {
        "method": result.method, "seed": result.seed, "runs": len(result.episodes), "updates": result.updates,
        "wall_s": result.wall_s,
        "simulation": simulation_settings(result),
        "tables": result.tables,
        "matching": [ep.matching if ep is not None else None for ep in result.episodes]
        if result.method == "trajectory" else None,
    }
    files["results"] = write_json(out / "results.json", record)

    figures = []
    first = next((ep for ep in result.episodes if ep is not None), None)
    if first is not None:
        files["fig5"] = plot_orientation_errors(first, out / "fig5_orientation.png")
        figures.append((files["fig5"], "Fig. 5-like: image-based rotation errors before and after the orientation "
                                       "adjustment, run 1"))
        if result.method == "line":
            files["fig6"] = plot_circle_path(first, out / "fig6_circle_path.png")
            figures.append((files["fig6"], "Fig. 6-like: circular path, reference vs completed, run 1"))
            files["fig7"] = plot_errors_over_time(first, out / "fig7_errors.png")
            figures.append((files["fig7"], "Fig. 7-like: image-based position errors over time, run 1"))
        else:
            files["fig8"] = plot_trajectory_matching(first, out / "fig8_matching.png")
            figures.append((files["fig8"], "Fig. 8-like: reference path, encoder TCP and calibrated VO, run 1"))
            files["fig9"] = plot_errors_over_time(first, out / "fig9_errors.png")
            figures.append((files["fig9"], "Fig. 9-like: image-based position errors over time, run 1"))

    sections = []
    for name, rows in result.tables.items():
        sections.append((TABLE_TITLES.get(name, name),
                         _html_table(rows, table_columns(name, result.updates))))
    sections.append(("The paper's numbers (real HIAB033 crane)", _paper_rows(result.method, result.updates)))
    sections.append(("Figures", "".join(html_figure(p, c) for p, c in figures) or "<p>Every run failed.</p>"))
    title = f"posekit localcal simulate: {result.method} method"
    intro = (f"<p>{len(result.episodes)} simulated look-then-move episodes, seed {result.seed}, "
             f"{result.updates} update(s) each; wall time {result.wall_s:.1f} s."
             + (f" Command: <code>{html.escape(command)}</code>" if command else "") + "</p>"
             + _settings_html(simulation_settings(result)) +
             "<p>Errors are those the camera measures between the tool marker and the OOI (absolute, in "
             "the camera frame); the <em>truth</em> tables give the simulator's true errors.</p>")
    files["report"] = write_html(out, title, intro, sections)
    return files


def _paper_line(name: str) -> str:
    """The paper's numbers for a table, one line (empty for the truth tables)."""
    def fmt(vals, deg=0):
        return "  ".join((f"{v:.2f}" if i < deg else f"{v:.1f}") for i, v in enumerate(vals))
    if name == "table2":
        return "paper mean (Table 2): rot x/y/z [deg], e_x/e_y [mm], depth e_z [mm]: " + fmt(PAPER_TABLE2_MEAN, 3)
    if name == "table3":
        return ("paper (Table 3): mean x/y/z " + fmt(PAPER_TABLE3["mean"]) + " mm; max x/y/z "
                + fmt(PAPER_TABLE3["max"]) + " mm")
    if name == "table4":
        return "paper mean (Table 4): 1st input e_x/e_y/e_z, 2nd input e_x/e_y/e_z [mm]: " + fmt(PAPER_TABLE4_MEAN)
    return ""


#: What the paper's methods aim at, the expected range of the verdict lines: the line method brings x, y to
#: "a few centimeters" (§4.1; depth is not controlled), the trajectory method to sub-centimetre x, y after its
#: second update with the depth at the designed stand-off b = 100 mm (eq. 21) "allowed more tolerance" (§4.2).
LINE_XY_MM = 50.0
TRAJECTORY_XY_MM = 10.0
TRAJECTORY_DEPTH_MM = 20.0


def verdict_line(name: str, rows: list[dict], updates: int, standoff_mm: float = STANDOFF_MM) -> str:
    """One line under a table: what its depth column means and whether the mean is in the expected range.

    Parameters
    ----------
    name : str
        ``table2``, ``table3`` or ``table4`` (the ``_truth`` tables get none).
    rows : list of dict
        The table's rows (the mean row included).
    updates : int
        Look-then-move updates per episode.
    standoff_mm : float
        The designed stand-off ``b`` of the trajectory method (eq. 21), mm.

    Returns
    -------
    str
        The line, or ``""``.
    """
    mean = next((r for r in rows if str(r.get("run")) == "mean"), None)
    if mean is None:
        return ""
    last = updates

    def within(value, limit):
        return "within" if math.isfinite(value) and value <= limit else "OUTSIDE"
    if name == "table2":                 # the paper's Table 2 is the line equation's update (#1, eq. 16)
        xy = max(mean["ex_1_mm"], mean["ey_1_mm"])
        return (f"verdict: x/y after the update (#1) {mean['ex_1_mm']:.1f} / {mean['ey_1_mm']:.1f} mm, "
                f"{within(xy, LINE_XY_MM)} the paper's few centimetres (< {LINE_XY_MM:g} mm); e_z is the depth to the "
                f"OOI, which this method does not control (paper {PAPER_TABLE2_MEAN[5]:g} mm), not an error")
    if name == "table3":
        worst = max(mean[f"mean_{a}_mm"] - PAPER_TABLE3["max"][i] for i, a in enumerate("xyz"))
        errs = " / ".join(f"{mean['mean_' + a + '_mm']:.1f}" for a in "xyz")
        return (f"verdict: mean matching errors {errs} mm, "
                f"{within(worst, 0.0)} the paper's largest errors ({' / '.join(f'{v:g}' for v in PAPER_TABLE3['max'])} mm)")
    if name == "table4":
        xy = max(mean[f"ex_{last}_mm"], mean[f"ey_{last}_mm"])
        depth = [mean[f"ez_{k}_mm"] - standoff_mm for k in range(1, last + 1)]
        paper = [PAPER_TABLE4_MEAN[2] - standoff_mm, PAPER_TABLE4_MEAN[5] - standoff_mm]
        ok = within(max(xy - TRAJECTORY_XY_MM, max(abs(d) for d in depth) - TRAJECTORY_DEPTH_MM), 0.0)
        return (f"verdict: e_z includes the designed stand-off b = {standoff_mm:g} mm (eq. 21), so the depth error is "
                f"e_z - {standoff_mm:g}: {' / '.join(f'{d:+.1f}' for d in depth)} mm (paper "
                f"{' / '.join(f'{d:+.1f}' for d in paper)}); x/y after update {last} {mean[f'ex_{last}_mm']:.1f} / "
                f"{mean[f'ey_{last}_mm']:.1f} mm; {ok} the expected sub-centimetre x/y and depth within "
                f"±{TRAJECTORY_DEPTH_MM:g} mm")
    return ""


def simulation_settings(result: ExperimentResult) -> dict:
    """What the simulated episodes modelled (camera, VO, matching), from the first episode's config."""
    ep = next((e for e in result.episodes if e is not None), None)
    if ep is None:
        return {}
    c = ep.config
    st = c.vo_stereo
    return {
        "robot": c.robot,
        "lens_distortion": bool(c.lens_distortion),
        "matching": "timestamps" if c.use_timestamps else f"correspondence-free ({c.matcher})",
        "vo_model": "stereo" if st is not None else "isotropic",
        "vo_stereo": None if st is None else {
            "baseline_mm": st.baseline_mm, "focal_px": st.focal_px, "pixel_noise_px": st.pixel_noise_px,
            "disparity_noise_px": st.disparity_noise_px, "features": st.features, "corr_s": st.corr_s,
            "drift_mm_per_sqrt_m": st.drift_mm_per_sqrt_m, "disparity_bias_px": st.disparity_bias_px},
        "vo_noise_mm": c.vo_noise_mm, "vo_drift_mm_per_sqrt_m": c.vo_drift_mm_per_sqrt_m,
    }


def tables_text(result: ExperimentResult, *, truth: bool = False) -> str:
    """The experiment's tables as text, each followed by the paper's numbers (the CLI prints this)."""
    parts = []
    for name, rows in result.tables.items():
        if name.endswith("_truth") and not truth:
            continue
        text = format_table(rows, table_columns(name, result.updates), TABLE_TITLES.get(name, name))
        paper = _paper_line(name)
        ep = next((e for e in result.episodes if e is not None), None)
        verdict = verdict_line(name, rows, result.updates, STANDOFF_MM if ep is None else ep.config.b_mm)
        parts.append(text + ("\n" + paper if paper else "") + ("\n" + verdict if verdict else ""))
    verdicts = registration_verdicts(result)
    if verdicts:
        parts.append(verdicts)
    settings = simulation_settings(result)
    if settings:
        st = settings["vo_stereo"]
        vo = (f"stereo VO (baseline {st['baseline_mm']:g} mm, depth error {_depth_sigmas(st)})" if st
              else "isotropic VO")
        parts.append(f"simulated: {'lens distortion' if settings['lens_distortion'] else 'rectified images'}, {vo}, "
                     f"matching {settings['matching']}")
    return "\n\n".join(parts)


def _depth_sigmas(st: dict) -> str:
    """Per-frame depth sigma of the stereo VO at 0.5, 1 and 2 m, e.g. '0.4/1.6/6.3 mm at 0.5/1/2 m'."""
    from posekit.localcal.sim.vo import StereoNoise

    model = StereoNoise(**{k: st[k] for k in ("baseline_mm", "focal_px", "pixel_noise_px", "disparity_noise_px",
                                              "features")})
    z = model.sigma_mm([500.0, 1000.0, 2000.0])[:, 2]
    return "/".join(f"{v:.1f}" for v in z) + " mm at 0.5/1/2 m"


def registration_verdicts(result: ExperimentResult) -> str:
    """One line: how many runs' registrations (match or hand-eye) were ``ok`` / ``suspect``, with
    the first reason; empty for the line method or when the registration gives no verdict."""
    if result.method != "trajectory":
        return ""
    recs = [ep.matching for ep in result.episodes if ep is not None and ep.matching]
    statuses = [r.get("status") for r in recs if r.get("status")]
    if not statuses:
        return ""
    mode = recs[0].get("mode", "timestamps")
    line = (f"registration verdict ({mode}): {statuses.count('ok')} ok, {statuses.count('suspect')} suspect "
            f"of {len(statuses)}")
    first = next((r["reasons"][0] for r in recs if r.get("status") == "suspect" and r.get("reasons")), None)
    return line + (f"; e.g. {first}" if first else "")

