"""``posekit seam tune --with-truth --cross-check``: how a profile fitted on these episodes does on an episode it
was not fitted on, measured on the user's own recordings.

A profile from a few episodes depends on which episodes (on the independent cell of the tests, held-out tracking
moved 79-93 % between four sets of three: ``benchmarks/seam_training_sets.py``), and its values' 1σ do not show
it. Here each episode in turn is left out: a profile is fitted on the others exactly as ``seam tune`` fits (same
base profile, same sensor sharing), the left-out episode is tracked with it (:func:`~.tracker.track_log`) and
scored against its ``truth.csv`` (:func:`~.tracker.track_metrics`): the 2σ coverage per axis, the share of
``tracking`` steps and the confident-wrong share (``tracking`` while more than 3σ off on some axis). Pooled over
the episodes, step-weighted, it is what a new episode of this cell may expect from a profile fitted on one
episode fewer than given.

The folds are independent fits: they run as a study on :func:`posekit.sweep.run_tasks` (a local Dask cluster, a
scheduler address, or this process), one task per left-out episode; every fit is deterministic, so the table is
the same wherever they run.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posekit.errors import ConfigError
from posekit.seam.frontend.seam_frame import AXES
from posekit.sweep import SERIAL, run_tasks

__all__ = ["CrossCheck", "check_cross_check", "cross_check", "cross_check_fold", "cross_check_report"]


@dataclass
class CrossCheck:
    """:func:`cross_check`'s result.

    Attributes
    ----------
    names : list of str
        The left-out episodes' folder names, in the order given.
    steps : ndarray of int, shape (E,)
    coverage : ndarray, shape (E, 6)
        Per left-out episode, the share of its steps whose error is within twice the reported spread, per axis
        ``x y z rx ry rz`` (seam frame).
    tracking, confident_wrong : ndarray, shape (E,)
        The share of its steps ``tracking``, and ``tracking`` while beyond 3 × the spread on some axis.
    """

    names: list
    steps: np.ndarray
    coverage: np.ndarray
    tracking: np.ndarray
    confident_wrong: np.ndarray

    @property
    def pooled(self) -> dict:
        """Step-weighted over the episodes: ``coverage_2sigma`` per axis, ``tracking``, ``confident_wrong``, and
        ``episodes_confident_wrong_over_5_percent``."""
        w = self.steps / self.steps.sum()
        return {"coverage_2sigma": dict(zip(AXES, (float(v) for v in w @ self.coverage))),
                "tracking": float(w @ self.tracking), "confident_wrong": float(w @ self.confident_wrong),
                "episodes_confident_wrong_over_5_percent": int(np.sum(self.confident_wrong > 0.05))}


def check_cross_check(logdirs) -> list:
    """The episode folders as paths, or a one-line ConfigError before anything is fitted: fewer than two
    episodes, or one without ``truth.csv``."""
    dirs = [Path(d) for d in logdirs]
    if len(dirs) < 2:
        raise ConfigError(f"--cross-check: needs at least 2 episodes (each is left out in turn), got {len(dirs)}")
    for d in dirs:
        if not (d / "truth.csv").is_file():
            raise ConfigError(f"--cross-check: {d} has no truth.csv; expected every episode to have one (each is "
                              "scored against it when left out)")
    return dirs


def cross_check(logdirs, *, base=None, share_sensors: bool = False, stage=None, scheduler=SERIAL,
                n_workers: int | None = None) -> CrossCheck:
    """Leave each episode out in turn: fit on the others (``seam tune --with-truth``), track it, score it.

    Parameters
    ----------
    logdirs : sequence of path-like
        At least two recorded episodes of one cell, each with ``truth.csv``.
    base, share_sensors
        As :func:`~.tune.tune_profile` (each fold gets them: a path or a profile model, both picklable).
    stage : callable, optional
        ``stage(text)``: as each fold starts in this process (``'serial'``), else once as the folds are sent out.
    scheduler, n_workers
        Where the folds run, as :func:`posekit.sweep.run_tasks`: ``'serial'`` (default) this process, None a
        local Dask cluster of ``n_workers`` processes (default one per core), or a scheduler address.

    Raises
    ------
    ConfigError
        Fewer than two episodes; a left-out episode without ``truth.csv``; a scheduler that cannot be reached.
    """
    dirs = check_cross_check(logdirs)
    tasks = [(i, [str(d) for d in dirs], base, bool(share_sensors)) for i in range(len(dirs))]
    others = f"the other {len(dirs) - 1} episode(s)"
    if scheduler == SERIAL:
        rows = []
        for i, d in enumerate(dirs):
            if stage is not None:
                stage(f"cross-check {i + 1}/{len(dirs)}: fitting on {others}, tracking {d.name}")
            rows.append(cross_check_fold(tasks[i]))
    else:
        if stage is not None:
            stage(f"cross-check: {len(dirs)} folds in parallel, each fitting on {others} and tracking the one left "
                  "out")
        rows = run_tasks(cross_check_fold, tasks, scheduler=scheduler, n_workers=n_workers, desc="cross-check")
    steps, cov, trk, cw = (np.array(c) for c in zip(*rows))
    names = [d.name for d in dirs]
    if len(set(names)) < len(names):   # folders of the same name in different places: the paths as given
        names = [str(d) for d in dirs]
    return CrossCheck(names, steps.astype(int), cov.astype(float), trk.astype(float),
                      cw.astype(float))


def cross_check_fold(task) -> tuple:
    """One fold of :func:`cross_check` (a study task: top level, picklable in and out).

    Parameters
    ----------
    task : tuple
        ``(i, dirs, base, share_sensors)``: the index of the left-out episode among the folders ``dirs`` (str),
        the base profile (a path, a profile model or None) and the sensor sharing, as ``seam tune``.

    Returns
    -------
    steps, coverage, tracking, confident_wrong : int, list of 6 float, float, float
        The left-out episode's steps, 2σ coverage per axis, ``tracking`` share and confident-wrong share.
    """
    from posekit.seam.frontend.logs import read_episode_log
    from posekit.seam.frontend.tracker import track_log, track_metrics
    from posekit.seam.frontend.tune import tune_profile

    i, dirs, base, share = task
    d = Path(dirs[i])
    fitted = tune_profile([Path(x) for k, x in enumerate(dirs) if k != i], with_truth=True, base=base,
                          share_sensors=share, command=f"cross-check without {d.name}").profile
    m = track_metrics(track_log(read_episode_log(d, profile=fitted)))
    steps = m["steps"]
    return (steps, [m["coverage_2sigma"][a] for a in AXES], m["status_counts"].get("tracking", 0) / steps,
            m["confident_wrong"])


def cross_check_report(check: CrossCheck) -> str:
    """The table ``seam tune --cross-check`` prints: one row per left-out episode and the pooled row."""
    width = max(8, *(len(n) for n in check.names))
    head = f"  {'episode':{width}s}  " + " ".join(f"{a:>6s}" for a in AXES) + "  tracking  confident-wrong"
    lines = ["cross-check: each episode tracked with a profile fitted on the others (2σ coverage per axis: an "
             "honest spread covers about 0.95)", head]

    def row(name, cov, trk, cw):
        return (f"  {name:{width}s}  " + " ".join(f"{v:6.3f}" for v in cov)
                + f"  {100 * trk:6.1f} %  {100 * cw:8.2f} %")

    for k, name in enumerate(check.names):
        lines.append(row(name, check.coverage[k], check.tracking[k], check.confident_wrong[k]))
    p = check.pooled
    lines.append(row("pooled", [p["coverage_2sigma"][a] for a in AXES], p["tracking"], p["confident_wrong"]))
    lines.append(f"  {p['episodes_confident_wrong_over_5_percent']} of {len(check.names)} episode(s) more than 5 % "
                 "confident-wrong (tracking while more than 3σ off on some axis)")
    return "\n".join(lines)
