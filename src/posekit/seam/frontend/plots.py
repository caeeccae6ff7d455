"""Figures of the seam-tracking simulation framework (§III-A of the paper), PNG via matplotlib Agg.

* :func:`plot_particle_density` — Fig. 5: for each state dimension, the density of the
  particles over time as a heatmap with the true coordinate overlaid.
* :func:`plot_error_distributions` — Fig. 8: the distribution of the tool-pose error per
  axis for several sensor configurations and trajectories.
* :func:`plot_tool_paths` — Fig. 9: tool positions along x, y, z over the time step.
* :func:`plot_tracking_errors` — the per-step error of the filter and of the kinematics
  alone.
* :func:`plot_pvalue_heatmap` — Fig. 6: log10 p-values of the tuning study's linear models.

Plotting is kept out of the numerical modules; each function writes one PNG and returns its
path. The inputs are in the library's units (lengths in mm, angles in radians); the figures show
angles in degrees, lengths in mm (the conversion happens here, at the edge).
"""

import inspect
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from posekit.errors import ConfigError

__all__ = [
    "AXIS_LABELS",
    "particle_histogram",
    "plot_design_ranking",
    "plot_error_distributions",
    "plot_ess",
    "plot_measurement_hypotheses",
    "plot_tracking_errors",
    "plot_particle_density",
    "plot_pvalue_heatmap",
    "plot_tool_paths",
    "positions_in_frame",
]

#: Label of each of the six state/error dimensions (translations in mm, rotations in deg).
AXIS_LABELS = ("x (mm)", "y (mm)", "z (mm)", "rx (deg)", "ry (deg)", "rz (deg)")
DPI = 100


def _rad_to_deg(a: np.ndarray) -> np.ndarray:
    """A float copy of ``(..., 6)`` rows ``[mm, mm, mm, rad, rad, rad]`` with the rotations in degrees."""
    a = np.array(a, dtype=float, copy=True)
    if a.ndim >= 1 and a.shape[-1] == 6:
        a[..., 3:] = np.degrees(a[..., 3:])
    return a


def _plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def _save(fig, path) -> Path:
    path = Path(path)
    fig.tight_layout()
    fig.savefig(path, dpi=DPI)
    _plt().close(fig)
    return path


def _six_panels(t_s):
    """A 3×2 figure over time: the axes in state order (x, y, z left; rx, ry, rz right), the
    bottom row labelled with the time (s) or the step index."""
    fig, axes = _plt().subplots(3, 2, figsize=(11, 8), sharex=True)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)" if t_s is not None else "time step")
    return fig, axes.T.ravel()


def positions_in_frame(T_W_tool: np.ndarray, T_W_ref: np.ndarray | None = None) -> np.ndarray:
    """Tool positions expressed in a reference frame.

    Parameters
    ----------
    T_W_tool : ndarray, shape (T, 4, 4)
        Tool poses in the world frame W, mm.
    T_W_ref : ndarray, shape (4, 4), optional
        The reference frame in W (default: the first tool pose, so the path starts at 0 and
        its axes are the tool's: y along the travel, z along the tool axis).

    Returns
    -------
    ndarray, shape (T, 3)
        ``R_W_ref^T (p_W - t_W_ref)``, mm.
    """
    T = np.asarray(T_W_tool, dtype=float)
    ref = T[0] if T_W_ref is None else np.asarray(T_W_ref, dtype=float)
    return (T[:, :3, 3] - ref[:3, 3]) @ ref[:3, :3]


def particle_histogram(values: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """Fraction of the particles in each bin, per time step.

    Parameters
    ----------
    values : ndarray, shape (T, K)
        One coordinate of K particles at each of T steps (NaN values are left out).
    edges : ndarray, shape (B + 1,)
        Increasing bin edges; values outside go to the first or last bin.

    Returns
    -------
    ndarray, shape (T, B)
        Each row sums to 1 (0 for a step without a finite value).
    """
    values = np.asarray(values, dtype=float)
    bins = len(edges) - 1
    idx = np.clip(np.searchsorted(edges, values, side="right") - 1, 0, bins - 1)
    ok = np.isfinite(values)
    counts = np.zeros((values.shape[0], bins))
    rows = np.broadcast_to(np.arange(values.shape[0])[:, None], values.shape)
    np.add.at(counts, (rows[ok], idx[ok]), 1.0)
    return counts / np.maximum(counts.sum(axis=1, keepdims=True), 1.0)


def plot_particle_density(particles: np.ndarray, truth: np.ndarray, path, *, t_s: np.ndarray | None = None,
                          bins: int = 60, title: str = "") -> Path:
    """Fig. 5: particle density over time per state dimension, the truth as a cyan line.

    Parameters
    ----------
    particles : ndarray, shape (T, K, 6)
        K recorded particles per time step, ``[x, y, z mm, rx, ry, rz rad]`` (the
        ``EpisodeResult.particles`` convention); the rotations are drawn in degrees.
    truth : ndarray, shape (T, 6)
        The true state in the same coordinates (``EpisodeResult.truth_coords``).
    path : path-like
        PNG file to write.
    t_s : ndarray, shape (T,), optional
        Time of each step, s (default: the step index on the x axis).
    bins : int
        Histogram bins along each state dimension.
    title : str
        Figure title.

    Returns
    -------
    pathlib.Path
    """
    particles = _rad_to_deg(particles)
    truth = _rad_to_deg(truth)
    if particles.ndim != 3 or particles.shape[2] != 6 or truth.shape != (particles.shape[0], 6):
        raise ConfigError(f"particle density plot: expected particles (T, K, 6) and truth (T, 6), "
                          f"got {particles.shape} and {truth.shape}")
    n_steps = particles.shape[0]
    x = np.arange(n_steps) if t_s is None else np.asarray(t_s, dtype=float)
    fig, panels = _six_panels(t_s)
    for d, ax in enumerate(panels):
        # range: the bulk of the particles (0.5-99.5 %) and all of the truth
        vals = particles[:, :, d][np.isfinite(particles[:, :, d])]
        tr = truth[np.isfinite(truth[:, d]), d]
        lo_hi = [*np.percentile(vals, [0.5, 99.5])] if len(vals) else []
        lo_hi += [tr.min(), tr.max()] if len(tr) else []
        lo, hi = (min(lo_hi), max(lo_hi)) if lo_hi else (-1.0, 1.0)
        pad = 0.05 * (hi - lo) if hi > lo else 1.0
        edges = np.linspace(lo - pad, hi + pad, bins + 1)
        density = particle_histogram(particles[:, :, d], edges)
        # each step scaled to its own peak: the shape of the density at that step is what matters
        shade = density / np.maximum(density.max(axis=1, keepdims=True), 1e-12)
        ax.imshow(shade.T, origin="lower", aspect="auto", cmap="magma", interpolation="nearest", vmin=0.0,
                  vmax=1.0, extent=(x[0], x[-1] if n_steps > 1 else x[0] + 1, edges[0], edges[-1]))
        ax.plot(x, truth[:, d], color="c", lw=1.2, label="truth")
        ax.set_ylabel(AXIS_LABELS[d])
    panels[0].legend(loc="upper right", fontsize=8)
    fig.suptitle(title or "Particle density per state dimension (heatmap, each step scaled to its peak) and the truth (cyan)")
    return _save(fig, path)


def plot_error_distributions(groups: Mapping[str, np.ndarray], path, *, title: str = "") -> Path:
    """Fig. 8: distribution of the tool-pose error per axis, one box per group.

    Parameters
    ----------
    groups : mapping of str to ndarray, shape (M, 6)
        Label (e.g. ``'xy, 2 sensors'``) -> per-step errors of all runs,
        ``[x, y, z mm, rx, ry, rz rad]`` in the seam frame (drawn in degrees). Non-finite rows are left out.
    path : path-like
        PNG file to write.
    title : str
        Figure title.

    Returns
    -------
    pathlib.Path
    """
    if not groups:
        raise ConfigError("error distribution plot: expected at least one group of errors, got none")
    labels = list(groups)
    data = []
    for k in labels:
        e = np.asarray(groups[k], dtype=float)
        if e.ndim != 2 or e.shape[1] != 6:
            raise ConfigError(f"error distribution plot: group '{k}' must be (M, 6), got {e.shape}")
        data.append(_rad_to_deg(e))
    plt = _plt()
    # Horizontal boxes, one row per group, the group names once on the left: the figure keeps
    # the report's width (11 in at DPI 100 = 1100 px, shown unscaled) whatever the number of
    # groups, and grows in height instead.
    n = len(labels)
    fig, axes = plt.subplots(2, 3, figsize=(11.0, 1.6 + 2 * (0.9 + 0.32 * n)), sharey=True)
    colors = [f"C{i % 10}" for i in range(n)]
    # matplotlib >= 3.10 says orientation=, older ones only vert= (deprecated since 3.11)
    horizontal = ({"orientation": "horizontal"} if "orientation" in inspect.signature(axes[0, 0].boxplot).parameters
                  else {"vert": False})
    for d, ax in enumerate(axes.ravel()):
        cols = [e[np.isfinite(e[:, d]), d] for e in data]
        cols = [c if len(c) else np.array([np.nan]) for c in cols]
        bp = ax.boxplot(cols, **horizontal, showfliers=False, whis=(2.5, 97.5), patch_artist=True, widths=0.6,
                        medianprops={"color": "k", "lw": 1.5})
        for patch, c in zip(bp["boxes"], colors):
            patch.set_facecolor(c)
            patch.set_alpha(0.6)
        ax.axvline(0.0, color="0.5", lw=0.8)
        ax.set_xlabel(f"error {AXIS_LABELS[d]}", fontsize=11)
        ax.tick_params(axis="x", labelsize=10)
        ax.grid(True, axis="x", alpha=0.3)
    for ax in axes[:, 0]:
        ax.set_yticks(range(1, n + 1), labels, fontsize=11)
    axes[0, 0].invert_yaxis()  # shared: the first group on top in every panel
    fig.suptitle(title or "Error distributions (boxes: quartiles, whiskers: 2.5–97.5 %)", fontsize=12)
    return _save(fig, path)


def plot_tool_paths(series: Mapping[str, np.ndarray], path, *, title: str = "",
                      styles: Mapping[str, str] | None = None) -> Path:
    """Fig. 9: distance along each axis (x, y, z) as a function of the time step.

    Parameters
    ----------
    series : mapping of str to ndarray, shape (T, 3)
        Label -> positions in mm (e.g. from :func:`positions_in_frame`).
    path : path-like
        PNG file to write.
    title : str
        Figure title.
    styles : mapping of str to str, optional
        Label -> matplotlib format string (default: solid, dashed, dotted, ... in turn).

    Returns
    -------
    pathlib.Path
    """
    if not series:
        raise ConfigError("trajectory plot: expected at least one trajectory, got none")
    plt = _plt()
    fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
    default = ["-", "--", ":", "-."]
    for i, (label, p) in enumerate(series.items()):
        p = np.asarray(p, dtype=float)
        if p.ndim != 2 or p.shape[1] != 3:
            raise ConfigError(f"trajectory plot: '{label}' must be (T, 3) positions, got {p.shape}")
        fmt = (styles or {}).get(label, default[i % len(default)])
        for d, ax in enumerate(axes):
            ax.plot(np.arange(len(p)), p[:, d], fmt, color=f"C{i % 10}", lw=1.4, label=label)
    for d, ax in enumerate(axes):
        ax.set_ylabel(AXIS_LABELS[d])
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8)
    axes[-1].set_xlabel("time step")
    fig.suptitle(title or "Trajectories")
    return _save(fig, path)


def plot_tracking_errors(error: np.ndarray, kinematic_error: np.ndarray, path, *, t_s=None,
                          title: str = "", spread: np.ndarray | None = None) -> Path:
    """Per-step tool-pose error of the filter and of the kinematics alone, all runs.

    Parameters
    ----------
    error, kinematic_error : ndarray, shape (R, T, 6)
        Errors of the filter estimate and of the robot's FK-only pose for R runs,
        ``[x, y, z mm, rx, ry, rz rad]`` in the seam frame (drawn in degrees).
    path : path-like
        PNG file to write.
    t_s : ndarray, shape (T,), optional
        Time of each step, s.
    title : str
        Figure title.
    spread : ndarray, shape (R, T, 6), optional
        The filter's reported standard deviation (same units as ``error``): run 0's ±2σ band is
        drawn around zero (an honest spread keeps about 95 % of the error inside it).

    Returns
    -------
    pathlib.Path
    """
    e = _rad_to_deg(error)
    k = _rad_to_deg(kinematic_error)
    sp = None if spread is None else _rad_to_deg(spread)
    if e.ndim != 3 or e.shape[2] != 6 or k.shape != e.shape:
        raise ConfigError(f"error plot: expected two (R, T, 6) error arrays, got {e.shape} and {k.shape}")
    x = np.arange(e.shape[1]) if t_s is None else np.asarray(t_s, dtype=float)
    fig, panels = _six_panels(t_s)
    for d, ax in enumerate(panels):
        for r in range(e.shape[0]):
            ax.plot(x, k[r, :, d], color="C1", lw=0.7, alpha=0.5, label="kinematics only" if r == 0 else None)
            ax.plot(x, e[r, :, d], color="C0", lw=0.8, alpha=0.7, label="particle filter" if r == 0 else None)
        if sp is not None and sp.shape == e.shape:
            ax.fill_between(x, -2.0 * sp[0, :, d], 2.0 * sp[0, :, d], color="C0", alpha=0.15, lw=0,
                            label="±2σ reported (run 0)")
        ax.axhline(0.0, color="0.4", lw=0.6)
        ax.set_ylabel(f"error {AXIS_LABELS[d]}")
        ax.grid(True, alpha=0.3)
    panels[0].legend(fontsize=8)
    fig.suptitle(title or "Tool-pose error in the seam frame")
    return _save(fig, path)


def plot_pvalue_heatmap(log10_p: np.ndarray, parameters: Sequence[str], errors: Sequence[str], path, *,
                        title: str = "") -> Path:
    """Fig. 6: log10 p-values of each parameter (x axis) in the linear model of each error (y axis).

    Parameters
    ----------
    log10_p : ndarray, shape (E, P)
        log10 of the OLS p-value of parameter p in the model of error e (NaN where the model
        could not be fitted).
    parameters : sequence of str, length P
        Parameter names (the factors).
    errors : sequence of str, length E
        Error names (the responses).
    path : path-like
        PNG file to write.
    title : str
        Figure title.

    Returns
    -------
    pathlib.Path
    """
    lp = np.asarray(log10_p, dtype=float)
    if lp.shape != (len(errors), len(parameters)):
        raise ConfigError(f"p-value heatmap: expected log10_p of shape ({len(errors)}, {len(parameters)}), "
                          f"got {lp.shape}")
    plt = _plt()
    fig, ax = plt.subplots(figsize=(max(6, 0.9 * len(parameters) + 2.5), 0.5 * len(errors) + 2.8))
    finite = lp[np.isfinite(lp)]
    vmin = min(-4.0, float(finite.min())) if len(finite) else -4.0
    im = ax.imshow(lp, cmap="viridis", vmin=vmin, vmax=0.0, aspect="auto")
    for (i, j), v in np.ndenumerate(lp):
        if np.isfinite(v):
            ax.text(j, i, f"{v:.1f}", ha="center", va="center", fontsize=7,
                    color="w" if v < 0.6 * vmin else "k")
    ax.set_xticks(range(len(parameters)), parameters, rotation=45, ha="right", fontsize=8)
    ax.set_yticks(range(len(errors)), errors)
    ax.set_xlabel("filter parameter (factor)")
    ax.set_ylabel("error RMSE (response)")
    fig.colorbar(im, ax=ax, label="log10 p-value")
    ax.set_title(title or "Significance of the filter parameters (OLS, log10 p)")
    return _save(fig, path)


def plot_ess(ess: np.ndarray, resampled: np.ndarray, n_particles: int, path, *, t_s=None,
             status: Sequence[str] | None = None, title: str = "") -> Path:
    """Effective sample size over time with the resampling steps (and the integrity status).

    Parameters
    ----------
    ess : ndarray, shape (T,)
        ESS after each update, in [1, N].
    resampled : ndarray of bool, shape (T,)
        Steps at which the particles were resampled (ticks at the bottom).
    n_particles : int
        N (the ESS is drawn as a fraction of it).
    path : path-like
    t_s : ndarray, shape (T,), optional
    status : sequence of str, optional
        ``tracking``/``degraded``/``lost`` per step: shaded behind the curve.
    """
    plt = _plt()
    ess = np.asarray(ess, dtype=float)
    x = np.arange(ess.shape[0]) if t_s is None else np.asarray(t_s, dtype=float)
    fig, ax = plt.subplots(figsize=(10, 3.6))
    ax.plot(x, ess / float(n_particles), color="C0", lw=0.9, label="ESS / N")
    r = np.asarray(resampled, dtype=bool)
    ax.plot(x[r], np.full(r.sum(), 0.0), "|", color="C3", ms=8, label=f"resampled ({int(r.sum())} steps)")
    if status is not None:
        colours = {"degraded": "orange", "lost": "red"}
        st = np.asarray(list(status))
        for name, colour in colours.items():
            m = st == name
            if m.any():
                ax.fill_between(x, 0, 1, where=m, color=colour, alpha=0.15, step="mid", label=name)
    ax.set_ylim(-0.05, 1.05)
    ax.set_xlabel("time (s)" if t_s is not None else "time step")
    ax.set_ylabel("effective sample size / N")
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    ax.set_title(title or "Effective sample size and resampling")
    return _save(fig, path)


def plot_design_ranking(rows: Sequence[Mapping], path, *, title: str = "", top: int = 30) -> Path:
    """The sensor-placement design: the score of each configuration, best first, with its
    translation and rotation parts (``ranking.csv`` rows of :mod:`posekit.seam.frontend.design`).

    Parameters
    ----------
    rows : sequence of mapping
        Ranked rows with ``sensors``, ``distances_mm``, ``angle``, ``score``, ``rmse_*``.
    path : path-like
    top : int
        At most this many configurations are drawn (the best ones).
    """
    plt = _plt()
    rows = [r for r in rows if np.isfinite(r["score"])][:top]
    labels = [f"{r['sensors']} @ {r['distances_mm'] or '-'}{' +angle' if r.get('angle') else ''}" for r in rows]
    t = np.array([np.linalg.norm([r["rmse_x_mm"], r["rmse_y_mm"], r["rmse_z_mm"]]) for r in rows])
    score = np.array([r["score"] for r in rows])
    fig, ax = plt.subplots(figsize=(9, 0.32 * len(rows) + 1.6))
    y = np.arange(len(rows))[::-1]
    colours = [f"C{int(r['sensors'])}" for r in rows]
    ax.barh(y, t, color=colours, alpha=0.9, label="translation ‖RMSE‖ (mm)")
    ax.barh(y, score - t, left=t, color=colours, alpha=0.4, hatch="//", label="rotation part (mm at the lever)")
    kin = rows[0].get("kinematic_score") if rows else None
    if kin is not None and np.isfinite(kin):
        ax.axvline(kin, color="0.3", ls="--", lw=1.0, label=f"kinematics only ({kin:.2f})")
    ax.set_yticks(y, labels, fontsize=8)
    ax.set_xlabel("score (mm), lower is better")
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend(fontsize=8, loc="lower right")
    ax.set_title(title or "Sensor configurations ranked")
    return _save(fig, path)


def plot_measurement_hypotheses(snapshot: Mapping, seam: np.ndarray, path, *, title: str = "",
                                max_points: int = 2000) -> Path:
    """Fig. 5 of the paper as the authors' framework draws it: at one time step, each particle's
    hypothesis of the seam point its sensor saw (``m̂``), coloured by the laser likelihood, beside
    the seam and the point the true pose implies; top view (x–y) and side view (y–z) of the
    nominal tool frame at that step.

    Parameters
    ----------
    snapshot : mapping
        ``EpisodeResult.snapshot``: ``step``, ``sensor``, ``hypotheses`` (N, 3) base frame mm,
        ``loglik`` (N,), ``prior_w`` (N,), ``T_nominal`` (4, 4), ``truth_point`` (3,),
        ``sensor_origin`` (3,).
    seam : ndarray, shape (K, 3)
        The seam polyline, base frame, mm.
    path : path-like
    """
    plt = _plt()
    T = np.asarray(snapshot["T_nominal"], dtype=float)
    R, t = T[:3, :3], T[:3, 3]

    def local(p):
        return (np.asarray(p, dtype=float).reshape(-1, 3) - t) @ R

    h = local(snapshot["hypotheses"])
    ll = np.asarray(snapshot["loglik"], dtype=float)
    w = np.asarray(snapshot["prior_w"], dtype=float)
    post = np.log(np.maximum(w, 1e-300)) + ll
    post = np.exp(post - post.max())
    order = np.argsort(post)[-max_points:]
    truth = local(snapshot["truth_point"])[0]
    sl = local(seam)
    near = np.linalg.norm(sl - truth, axis=1) < max(15.0, 3.0 * float(np.ptp(h, axis=0).max()))
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.6))
    for ax, (a, b), names in zip(axes, ((0, 1), (1, 2)), (("x (mm)", "y (mm)"), ("y (mm)", "z (mm)"))):
        ax.plot(sl[near, a], sl[near, b], color="0.3", lw=1.2, label="seam")
        sc = ax.scatter(h[order, a], h[order, b], c=post[order], cmap="viridis", s=6, vmin=0.0, vmax=1.0,
                        label="hypotheses m̂ (particles)")
        ax.plot(*truth[[a, b]], "r+", ms=14, mew=2, label="from the true pose")
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
        # zoom on the cloud: ±4 of its spread (at least ±1 mm) about the true point
        half = max(1.0, 4.0 * float(np.std(h[:, [a, b]], axis=0).max()))
        ax.set_xlim(truth[a] - half, truth[a] + half)
        ax.set_ylim(truth[b] - half, truth[b] + half)
        ax.set_aspect("equal")
        ax.grid(True, alpha=0.3)
    fig.colorbar(sc, ax=axes, shrink=0.8, label="posterior weight (relative)")
    axes[0].legend(fontsize=7, loc="best")
    fig.suptitle(title or f"Measurement hypotheses of sensor {snapshot['sensor'] + 1} at step {snapshot['step']} "
                          "(nominal tool frame)")
    path = Path(path)
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    return path
