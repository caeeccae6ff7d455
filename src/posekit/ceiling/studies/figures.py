"""The paper's figures of the ceiling system (§V): Fig. 5 (calibration check), Fig. 6 (accuracy at
known points), Fig. 7 (heading accuracy from two dots) and Fig. 8 and 9 (a track's trajectory in the
image and on the ceiling, with the truth), as PNG files via :mod:`posekit.report`.
World points in mm on the ceiling plane; image points in px of the real (distorted) image.
"""

from pathlib import Path

import numpy as np

from .accuracy import HeadingSimulation, KnownPointsResult, sample_position_errors
from .truth import SceneTruthTable

__all__ = ["plot_calibration_check", "plot_known_points", "plot_heading_simulation", "plot_trajectories"]


def plot_calibration_check(reference_bgr, world_xy, image_uv, calibration, path, *, lens=None,
                           inliers=None) -> Path:
    """Fig. 5: the calibration points (black crosses, where they were found in the image) and the
    world points back-projected by the calibration (red circles), over the reference image.

    Parameters
    ----------
    reference_bgr : ndarray, shape (H, W, 3) uint8, or None
    world_xy : ndarray, shape (N, 2)
        Calibration points on the ceiling, mm.
    image_uv : ndarray, shape (N, 2)
        Their pixels as seen (distorted), px.
    calibration : Calibration
        Maps world → undistorted pixels (``lens`` given) or pixels as seen.
    path : path
        PNG file to write.
    lens : CameraModel, optional
        Distorts the back-projections to the image as seen.
    inliers : ndarray of bool, shape (N,), optional
        Points used (others drawn in grey).
    """
    from ...report import pyplot, save_figure
    plt = pyplot()
    back = calibration.world_to_image(np.asarray(world_xy, float), invalid="nan")
    if lens is not None:
        back = lens.distort_points(back)
    image_uv = np.asarray(image_uv, float)
    used = np.ones(len(image_uv), bool) if inliers is None else np.asarray(inliers, bool)
    err = np.linalg.norm(back - image_uv, axis=1)
    fig, ax = plt.subplots(figsize=(9, 5.4))
    if reference_bgr is not None:
        ax.imshow(reference_bgr[..., ::-1])
    ax.plot(image_uv[used, 0], image_uv[used, 1], "k+", ms=9, mew=1.4, label="calibration points (image)")
    if (~used).any():
        ax.plot(image_uv[~used, 0], image_uv[~used, 1], "+", color="0.5", ms=9, label="rejected points")
    ax.plot(back[:, 0], back[:, 1], "o", mfc="none", mec="r", ms=9, mew=1.2,
            label=f"back-projected (rms {np.sqrt(np.nanmean(err[used] ** 2)):.2f} px)")
    ax.set_xlabel("u (px)")
    ax.set_ylabel("v (px)")
    ax.set_title("Camera calibration check (cf. Fig. 5)" + (" — pixels through the lens model" if lens else ""))
    ax.legend(loc="lower right", fontsize=8)
    return save_figure(fig, Path(path), dpi=120)


def plot_known_points(result: KnownPointsResult, path, *, paper_mean_mm: float = 14.0) -> Path:
    """Fig. 6: known positions (circles) and the positions estimated from the rendered dots
    (crosses) on the ceiling plane, with the errors magnified in an inset scale."""
    from ...report import pyplot, save_figure
    plt = pyplot()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.8), gridspec_kw={"width_ratios": [1.6, 1]})
    w, e = result.world_xy, result.estimated_xy
    ax.plot(w[:, 0], w[:, 1], "o", mfc="none", mec="k", ms=9, label="ground truth")
    ok = np.all(np.isfinite(e), axis=1)
    ax.plot(e[ok, 0], e[ok, 1], "rx", ms=7, label="estimated")
    if (~ok).any():
        ax.plot(w[~ok, 0], w[~ok, 1], "s", mfc="none", mec="0.6", ms=11, label="not detected")
    ax.set_aspect("equal")
    ax.set_xlabel("X (mm)")
    ax.set_ylabel("Y (mm)")
    ax.set_title(f"{len(w)} known points (cf. Fig. 6): mean error {result.stats.mean_mm:.2f} mm "
                 f"(paper {paper_mean_mm:g} mm)")
    ax.legend(loc="best", fontsize=8)
    d = e[ok] - w[ok]
    ax2.axhline(0, color="0.8", lw=0.8)
    ax2.axvline(0, color="0.8", lw=0.8)
    ax2.plot(d[:, 0], d[:, 1], "rx")
    lim = max(float(np.abs(d).max()) if d.size else 1.0, 1e-3) * 1.2
    ax2.set_xlim(-lim, lim)
    ax2.set_ylim(-lim, lim)
    ax2.set_aspect("equal")
    ax2.set_xlabel("error X (mm)")
    ax2.set_ylabel("error Y (mm)")
    ax2.set_title("estimated − true")
    return save_figure(fig, Path(path), dpi=120)


def plot_heading_simulation(sim: HeadingSimulation, path, *, n_lines: int = 60, rng=0) -> Path:
    """Fig. 7: the paper's heading simulation. Left: two dots ``D`` apart, each estimated on a
    circle of radius ``e`` about its ideal position, and some estimated lines (angle θ to the
    ideal line). Right: the distribution of θ with its std (Monte Carlo and closed form ``e/D``)."""
    from ...report import pyplot, save_figure
    plt = pyplot()
    rng = np.random.default_rng(rng)
    D, e = sim.distance_mm, sim.error_mm
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(11, 4.2), gridspec_kw={"width_ratios": [1.5, 1]})
    t = np.linspace(0, 2 * np.pi, 200)
    for cx in (0.0, D):
        ax.plot(cx + e * np.cos(t), e * np.sin(t), "k-", lw=0.8)
    ax.plot([0, D], [0, 0], "k-", lw=1.5, label="ideal line P1-P2")
    e1 = sample_position_errors(n_lines, e, sim.model, rng)
    e2 = sample_position_errors(n_lines, e, sim.model, rng)
    for a, b in zip(e1, e2):
        ax.plot([a[0], D + b[0]], [a[1], b[1]], "r-", lw=0.4, alpha=0.5)
    ax.plot([], [], "r-", lw=0.8, label="estimated lines")
    ax.set_aspect("equal")
    ax.set_ylim(-4 * e, 4 * e)
    ax.set_xlabel("mm")
    ax.set_title(f"dots D = {D:g} mm apart, errors on circles of radius e = {e:g} mm")
    ax.legend(loc="upper center", fontsize=8)
    e1 = sample_position_errors(50_000, e, sim.model, rng)
    e2 = sample_position_errors(50_000, e, sim.model, rng) if sim.dots_with_error == 2 else np.zeros((50_000, 2))
    d = np.array([D, 0.0]) + e2 - e1
    theta = np.degrees(np.arctan2(d[:, 1], d[:, 0]))
    ax2.hist(theta, bins=80, density=True, color="0.6")
    ax2.set_xlabel("heading error θ (deg)")
    ax2.set_ylabel("density")
    ax2.set_title(f"std {sim.std_deg:.2f}° (closed form {sim.closed_form_deg:.2f}°; paper 2.00°)")
    return save_figure(fig, Path(path), dpi=120)


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
