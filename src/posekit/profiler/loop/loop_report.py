"""Tables, figures and ``report.html`` of the closed-loop experiment (Fig. 5/6, Tables III/IV)."""

from pathlib import Path

import numpy as np

from ...report import html_figure, html_table, pyplot, save_figure, write_csv, write_html
from .loop import TABLE3_COLUMNS, TABLE4_COLUMNS, LoopExperiment
from .loop_sim import format_table4 as _format_table4
from .response import amplitude_spectrum

__all__ = ["write_loop_report", "PAPER_TABLE4", "PAPER_TABLE3", "format_table3", "format_table4", "server_rows",
           "table3_rows", "table4_rows"]

#: Table IV of the paper: (axis, step_mm, mode) -> (Mp %, ζ, Mf µm), means.
PAPER_TABLE4 = {
    ("x", 1.0, "open"): (5.39, 0.68, 8.30), ("x", 1.0, "closed"): (2.47, 0.76, 5.14),
    ("x", 2.0, "open"): (4.86, 0.70, 22.52), ("x", 2.0, "closed"): (3.07, 0.74, 5.46),
    ("y", 1.0, "open"): (65.88, 0.13, 9.69), ("y", 1.0, "closed"): (20.51, 0.45, 3.58),
    ("y", 2.0, "open"): (39.48, 0.28, 27.26), ("y", 2.0, "closed"): (1.46, 0.81, 3.49),
    ("z", 1.0, "open"): (13.98, 0.53, 29.86), ("z", 1.0, "closed"): (2.96, 0.75, 1.90),
    ("z", 2.0, "open"): (8.06, 0.63, 46.64), ("z", 2.0, "closed"): (1.07, 0.82, 1.70),
}
#: Table III of the paper (i9-12900KF): (system, stage) -> (mean, std, median, max, min) ms.
PAPER_TABLE3 = {
    ("camera", "DT"): (94.20, 0.07, 94.19, 94.38, 94.04), ("camera", "CD"): (21.64, 5.43, 20.85, 33.57, 13.51),
    ("camera", "PC"): (0.14, 0.04, 0.12, 0.27, 0.10), ("proposed", "DT"): (6.61, 0.56, 0.65, 7.78, 5.59),
    ("proposed", "CD"): (0.11, 0.05, 0.10, 0.20, 0.06), ("proposed", "PC"): (0.26, 0.14, 0.21, 0.68, 0.12),
}


def format_table4(exp: LoopExperiment) -> str:
    """Text Table IV of a loop experiment: measured mean ± std over repeats beside the paper's."""
    return _format_table4(exp.table4, PAPER_TABLE4)


def format_table3(exp: LoopExperiment) -> str:
    """Text table: measured Table III beside the paper's."""
    lines = [f"{'system':<9}{'stage':<20}{'mean/std ms':>18}{'median':>9}{'max':>9}{'min':>9}   paper mean/std"]
    for r in exp.table3:
        paper = PAPER_TABLE3.get((r["system"], r["stage"]))
        ptxt = "" if paper is None else f"{paper[0]:.2f} / {paper[1]:.2f}"
        lines.append(f"{r['system']:<9}{r['stage']:<20}{r['mean_ms']:>10.3f} /{r['std_ms']:>6.3f}"
                     f"{r['median_ms']:>9.3f}{r['max_ms']:>9.3f}{r['min_ms']:>9.3f}   {ptxt}")
    return "\n".join(lines)


def _fig_open_loop(exp, path):
    plt = pyplot()
    fig, ax = plt.subplots(2, 2, figsize=(11, 7))
    opens = [r for r in exp.runs if r.mode == "open"]
    run = next((r for r in opens if r.axis == "y"), opens[0])
    for src, style, label in (("truth", "-", "truth (250 Hz, 'VICON')"), ("measured", ".", "posekit (83.3 Hz)")):
        t, y = run.signal(src)
        ax[0, 0].plot(t, y, style, ms=3, label=label)
        t, y = run.filled_signal(src)              # the spectrum needs the uniform grid: gaps filled
        ok = np.isfinite(y) & (t >= run.t_step_s)
        f, a = amplitude_spectrum(t[ok], y[ok] - np.mean(y[ok][-20:]))
        ax[0, 1].plot(f, a * 1e3, style, ms=2, label=label)
    ax[0, 0].set(title=f"(a) open-loop {run.step_mm:g} mm step along {run.axis}", xlabel="t (s)",
                 ylabel="position (mm)")
    ax[0, 1].set(title="(b) spectrum", xlabel="f (Hz)", ylabel="amplitude (µm)", xlim=(0, 40))
    imp = exp.impulse
    for src, style, label in (("truth", "-", "truth"), ("measured", ".", "posekit")):
        t, y = imp.signal(src)
        ax[1, 0].plot(t, y, style, ms=3, label=label)
        t, y = imp.filled_signal(src)
        ok = np.isfinite(y) & (t > imp.t_step_s)
        f, a = amplitude_spectrum(t[ok], y[ok] - np.mean(y[ok][-20:]))
        ax[1, 1].plot(f, a * 1e3, style, ms=2, label=label)
    res = exp.resonance or {}
    ax[1, 0].set(title=f"(c) impulse along y (resonance {res.get('f_natural_hz', float('nan')):.1f} Hz)",
                 xlabel="t (s)", ylabel="y (mm)")
    ax[1, 1].set(title="(d) spectrum", xlabel="f (Hz)", ylabel="amplitude (µm)", xlim=(0, 40))
    for a in ax.ravel():
        a.grid(alpha=0.3)
        a.legend(fontsize=8)
    save_figure(fig, path)


def _fig_steps(exp, path):
    plt = pyplot()
    axes = [a for a in ("x", "y", "z", "xyz") if any(r.axis == a for r in exp.runs)]
    fig, ax = plt.subplots(1, len(axes), figsize=(4 * len(axes), 3.6), squeeze=False)
    for i, axis in enumerate(axes):
        for r in exp.runs:
            if r.axis != axis or r.repeat != 0:
                continue
            t, y = r.signal("truth")
            ax[0, i].plot(t, y, "-" if r.mode == "closed" else "--",
                          label=f"{'CL' if r.mode == 'closed' else 'OL'} {r.step_mm:g} mm")
        ax[0, i].set(title=f"step along {axis}", xlabel="t (s)", ylabel="position (mm)")
        ax[0, i].grid(alpha=0.3)
        ax[0, i].legend(fontsize=8)
    save_figure(fig, path)


#: What each counter of :meth:`posekit.profiler.stream.server.PoseServer.stats` means (report table).
SERVER_COUNTERS = {
    "received": "well-formed frames decoded",
    "processed": "frames that went through corner detection and pose (ok or not)",
    "ok": "frames with a pose",
    "errors": "processed frames whose profile or controller failed",
    "dropped": "oldest frames pushed out of the full buffer",
    "rejected": "malformed stretches of the stream and NaN storms",
    "disconnects": "sensor disconnections",
    "connections": "sensor connections",
    "cold_restarts": "warm starts that fell back to the closed form",
    "sent": "records sent to the robot interface",
    "unsent": "records that could not be sent",
    "robot_connects": "connections to the robot interface",
    "robot_failures": "failed connections to the robot interface",
    "queued": "frames still in the buffer at the end",
}


def _fmt(v: float, digits: int = 2) -> str:
    return "–" if v is None or not np.isfinite(v) else f"{v:.{digits}f}"


def server_rows(stats: dict | None) -> list[dict]:
    """The server's counters as table rows ``{"counter", "value", "meaning"}`` (rejection reasons
    one row each)."""
    rows = []
    for key, value in (stats or {}).items():
        if key == "reasons":
            continue
        rows.append({"counter": key, "value": value, "meaning": SERVER_COUNTERS.get(key, "")})
    for reason, count in sorted(((stats or {}).get("reasons") or {}).items()):
        rows.append({"counter": f"rejected: {reason}", "value": count, "meaning": "rejections for this reason"})
    return rows


def table4_rows(exp: LoopExperiment) -> list[dict]:
    """Table IV as display rows: measured mean (± std over repeats when there are several) beside the
    paper's, and after each closed-loop row the improvement over the open loop (positive: better)."""
    means = {(r["axis"], r["step_mm"], r["mode"]): r for r in exp.table4}
    repeats = 1 + max((r.repeat for r in exp.runs), default=0)
    keys = ("Mp_pct", "zeta", "Mf_um")

    def improvement(o, c):
        return [100 * (o[0] - c[0]) / o[0], 100 * (c[1] - o[1]) / o[1], 100 * (o[2] - c[2]) / o[2]]

    rows = []
    for (axis, step, mode), r in means.items():
        paper = PAPER_TABLE4.get((axis, step, mode))
        row = {"axis": axis, "step": f"{step:g}", "mode": mode}
        for k in keys:
            row[k] = _fmt(r[k]) + (f" ± {_fmt(r.get(k + '_std', np.nan))}" if repeats > 1 else "")
            row[f"paper_{k}"] = "" if paper is None else _fmt(paper[keys.index(k)])
        rows.append(row)
        if mode == "closed" and (axis, step, "open") in means:
            o = means[(axis, step, "open")]
            imp = improvement([o[k] for k in keys], [r[k] for k in keys])
            po, pc = PAPER_TABLE4.get((axis, step, "open")), paper
            pimp = improvement(po, pc) if po and pc else None
            row = {"axis": "", "step": "", "mode": "improvement"}
            for i, k in enumerate(keys):
                row[k] = f"{imp[i]:+.1f} %"
                row[f"paper_{k}"] = "" if pimp is None else f"{pimp[i]:+.1f} %"
            rows.append(row)
    return rows


TABLE4_HEADERS = ("axis", "step (mm)", "mode", "Mp (%)", "ζ", "Mf (µm)", "paper Mp (%)", "paper ζ", "paper Mf (µm)")
TABLE3_HEADERS = ("system", "stage", "mean (ms)", "std (ms)", "median (ms)", "max (ms)", "min (ms)", "samples",
                  "paper mean (ms)", "paper std (ms)")


def table3_rows(exp: LoopExperiment) -> list[dict]:
    """Table III as display rows: the measured stage times beside the paper's mean and std."""
    rows = []
    for r in exp.table3:
        paper = PAPER_TABLE3.get((r["system"], r["stage"]))
        row = {k: (_fmt(v, 3) if k.endswith("_ms") else v) for k, v in r.items()}
        row["paper_mean_ms"] = "" if paper is None else _fmt(paper[0])
        row["paper_std_ms"] = "" if paper is None else _fmt(paper[1])
        rows.append(row)
    return rows


def write_loop_report(exp: LoopExperiment, out) -> dict:
    """Write ``table3.csv``, ``table4.csv``, ``fig5_open_loop.png``, ``fig6_steps.png``, ``report.html``.

    Returns the paths written, by name.
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = {"table3": out / "table3.csv", "table4": out / "table4.csv", "fig5": out / "fig5_open_loop.png",
             "fig6": out / "fig6_steps.png", "report": out / "report.html"}
    write_csv(paths["table3"], exp.table3, TABLE3_COLUMNS)
    write_csv(paths["table4"], exp.table4, TABLE4_COLUMNS)
    _fig_open_loop(exp, paths["fig5"])
    _fig_steps(exp, paths["fig6"])
    res = exp.resonance or {}
    missed = sum(r.missed for r in exp.runs)
    intro = (f"<p>{len(exp.runs)} step runs + 1 impulse run; {missed} missed cycles; resonance from the "
             f"impulse {_fmt(res.get('f_natural_hz', np.nan))} Hz; wall time {exp.wall_s:.1f} s. "
             "Files: <a href='table4.csv'>table4.csv</a>, <a href='table3.csv'>table3.csv</a>.</p>"
             "<h3>Pose server</h3>" + html_table(server_rows(exp.server_stats), ["counter", "value", "meaning"]))
    t4_cols = ["axis", "step", "mode", "Mp_pct", "zeta", "Mf_um", "paper_Mp_pct", "paper_zeta", "paper_Mf_um"]
    t3_cols = [*TABLE3_COLUMNS, "paper_mean_ms", "paper_std_ms"]
    sections = [
        ("Table IV — step responses (measured by posekit, mean over repeats) beside the paper's",
         html_table(table4_rows(exp), t4_cols, TABLE4_HEADERS)
         + "<p>Mp: overshoot; ζ: damping ratio; Mf: magnitude at the 10 Hz mode. Improvement of the closed "
           "loop over the open loop: less overshoot, more damping, less 10 Hz magnitude (positive: better).</p>"),
        ("Table III — stage times beside the paper's",
         html_table(table3_rows(exp), t3_cols, TABLE3_HEADERS)
         + "<p>DT: data transmission; CD: corner detection; PC: posture computation.</p>"),
        ("Fig. 5 — open loop and impulse", html_figure(paths["fig5"], "Open loop and impulse response")),
        ("Fig. 6 — open vs closed loop", html_figure(paths["fig6"], "Step responses, open vs closed loop")),
    ]
    write_html(out, "Real-time closed loop (paper §IV-C), simulated over loopback sockets", intro, sections)
    return paths
