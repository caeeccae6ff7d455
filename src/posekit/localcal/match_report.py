"""What ``posekit localcal match`` writes beside its JSON: the residual of every pose pair (CSV) and
evo-style figures of the match (PNG, matplotlib Agg).

* ``--residuals FILE.csv`` — one row per pair: :data:`RESIDUAL_COLUMNS`;
* ``--plot DIR`` — ``trajectories.png`` (the kinematic path and the camera path mapped into the
  base frame, top and side views) and ``error.png`` (the position error of every pair over time,
  kept and dropped pairs, with the RMSE over all and over the kept pairs).
"""

from pathlib import Path

import numpy as np

from posekit.localcal.model.trajectory import Trajectory
from posekit.localcal.registration.match import Registration
from posekit.report import pyplot, save_figure, write_csv

__all__ = ["RESIDUAL_COLUMNS", "plot_match", "residual_rows", "write_residuals"]

#: Columns of the residuals CSV: pair number, the two stamps (s), the pair's indices in the two
#: inputs (0-based; ``i_dst`` -1 for a dst pose interpolated at the src stamp), the residual
#: ``p_dst - (s R p_src + t)`` along the base axes and its length (mm), and whether the outlier
#: gate kept the pair (1) or dropped it (0).
RESIDUAL_COLUMNS = ("pair", "t_src_s", "t_dst_s", "i_src", "i_dst", "ex_mm", "ey_mm", "ez_mm", "error_mm", "kept")


def residual_rows(reg: Registration) -> list[dict]:
    """One dict per pose pair of ``reg``, keys :data:`RESIDUAL_COLUMNS`."""
    e = reg.residuals_mm
    err = np.linalg.norm(e, axis=1)
    return [{"pair": k, "t_src_s": f"{reg.pair_t_s[k, 0]:.9f}", "t_dst_s": f"{reg.pair_t_s[k, 1]:.9f}",
             "i_src": int(reg.pairs[k, 0]), "i_dst": int(reg.pairs[k, 1]),
             "ex_mm": f"{e[k, 0]:.4f}", "ey_mm": f"{e[k, 1]:.4f}", "ez_mm": f"{e[k, 2]:.4f}",
             "error_mm": f"{err[k]:.4f}", "kept": int(reg.inliers[k])} for k in range(reg.n_pairs)]


def write_residuals(reg: Registration, path) -> Path:
    """Write the residuals CSV (atomically) and return its path."""
    return write_csv(path, residual_rows(reg), RESIDUAL_COLUMNS)


def plot_match(reg: Registration, src: Trajectory, dst: Trajectory, folder, *, names=("camera", "kinematic")) -> list:
    """Write ``trajectories.png`` and ``error.png`` of a match into ``folder``; return their paths.

    Parameters
    ----------
    reg : Registration
        The match (``src`` mapped by ``reg.T``).
    src, dst : Trajectory
        The matched trajectories as read (mm).
    folder : str or Path
        An existing folder.
    names : (str, str)
        Legend names of src and dst.
    """
    plt = pyplot()
    folder = Path(folder)
    p_src = reg.scale * src.positions @ reg.R.T + reg.t_mm
    out = []
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    for ax, (i, j), label in zip(axes, ((0, 1), (0, 2)), ("top (x-y)", "side (x-z)")):
        ax.plot(dst.positions[:, i], dst.positions[:, j], "-", color="0.3", lw=1.2, label=f"{names[1]} (base frame)")
        ax.plot(p_src[:, i], p_src[:, j], "-", color="tab:blue", lw=1.0, alpha=0.85, label=f"{names[0]} mapped")
        ax.set_xlabel(f"{'xyz'[i]} (mm)")
        ax.set_ylabel(f"{'xyz'[j]} (mm)")
        ax.set_title(label)
        ax.set_aspect("equal", adjustable="datalim")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="best", fontsize=8)
    fig.suptitle(f"match: {reg.status}, rmse {reg.rmse_mm:.2f} mm over {reg.pairs_used} kept pairs"
                 + (f", scale {reg.scale:.5f}" if reg.scale != 1.0 else ""))
    fig.tight_layout()
    out.append(save_figure(fig, folder / "trajectories.png"))
    plt.close(fig)

    err = np.linalg.norm(reg.residuals_mm, axis=1)
    t = reg.pair_t_s[:, 0] - (reg.pair_t_s[0, 0] if reg.n_pairs else 0.0)
    fig, ax = plt.subplots(figsize=(11, 4))
    kept = reg.inliers
    ax.plot(t[kept], err[kept], ".", ms=3, color="tab:blue", label=f"kept ({int(kept.sum())})")
    if (~kept).any():
        ax.plot(t[~kept], err[~kept], "x", ms=5, color="tab:red", label=f"dropped ({int((~kept).sum())})")
    ax.axhline(reg.rmse_mm, color="tab:blue", ls="--", lw=1, label=f"rmse kept {reg.rmse_mm:.2f} mm")
    if np.isfinite(reg.rmse_all_mm):
        ax.axhline(reg.rmse_all_mm, color="0.4", ls=":", lw=1, label=f"rmse all {reg.rmse_all_mm:.2f} mm")
    ax.set_xlabel(f"time since the first pair (s, {names[0]} clock)")
    ax.set_ylabel("position error (mm)")
    ax.set_title("position error of every pose pair after the match")
    ax.grid(alpha=0.3)
    ax.legend(loc="upper right", fontsize=8)
    fig.tight_layout()
    out.append(save_figure(fig, folder / "error.png"))
    plt.close(fig)
    return out
