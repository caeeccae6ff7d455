"""``posekit seam tune``, ``study`` and ``design`` as library calls.

Each command is one function here with the command's arguments by the same names (the episode
configuration as :func:`~posekit.seam.frontend.commands.episode_config` makes it); the command
parses its flags, stages its output and prints.
"""

from __future__ import annotations

import shlex
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

from ...errors import ConfigError
from .config import SeamConfig
from .design import SensorDesign, design_configurations, distance_grid, sensor_design, write_design
from .profile import write_profile
from .study import SeamStudy, seam_study, write_study
from .study_factors import make_factors, study_base
from .tune import TuneResult, tune_profile, tune_simulated

__all__ = ["MAX_SIMULATED", "MAX_STUDY_EPISODES", "MAX_DESIGN_EPISODES", "StudyRun", "DesignRun", "tune_command",
           "tune_config", "tune", "check_study_size", "study", "check_design_size", "design"]

#: Most episodes ``tune(simulate=RUNS)`` makes.
MAX_SIMULATED = 100
#: Most episodes of one study (runs × episodes: 100,000 default episodes take about a day on 2 cores).
MAX_STUDY_EPISODES = 100_000
#: Most episodes of one design (configurations × runs).
MAX_DESIGN_EPISODES = 100_000


def _kinds(trajectory) -> list | None:
    if trajectory is None or not isinstance(trajectory, str):
        return None if trajectory is None else list(trajectory)
    return [k.strip() for k in trajectory.split(",")]


def tune_command(out, logdirs: Sequence = (), *, with_truth: bool = False, base=None, share_sensors: bool = False,
                 simulate: int | None = None, config=None, trajectory=None, seed: int | None = None) -> str:
    """The command line that reproduces a :func:`tune` run, as the profile file records it."""
    words = ["posekit", "seam", "tune", *logdirs]
    if simulate is not None:
        words += ["--simulate", simulate]
        words += ["--config", config] if config else []
        words += ["--trajectory", trajectory if isinstance(trajectory, str) else ",".join(trajectory)] if trajectory else []
        words += ["--seed", seed] if seed is not None else []
    words += ["--with-truth"] if with_truth else []
    words += ["--share-sensors"] if share_sensors else []
    words += ["--from", base] if base else []
    return " ".join(shlex.quote(str(a)) for a in words + ["--out", out])


def _check_tune_sources(logdirs, simulate, config, trajectory) -> None:
    """Recorded episodes or ``simulate`` episodes, not both; ``config``/``trajectory`` only with ``simulate``."""
    if simulate is None and not logdirs:
        raise ConfigError("seam tune: expected at least one LOGDIR (or --simulate RUNS)")
    if simulate is not None and logdirs:
        raise ConfigError("seam tune: expected LOGDIRs or --simulate RUNS, not both")
    if simulate is None and (config is not None or trajectory is not None):
        raise ConfigError("--config, --trajectory: only with --simulate (a recorded episode's setup.yaml describes "
                          "its cell)")


def tune_config(logdirs: Sequence = (), *, base=None, simulate: int | None = None, config=None, trajectory=None,
                seed: int | None = None) -> SeamConfig:
    """The cell configuration ``posekit seam tune`` works with (``seam tune --dump-config``), loadable by
    ``--config`` of every seam verb.

    With ``simulate``: the configuration its episodes are simulated with (the file ``config`` or the
    defaults, ``trajectory.kind`` set to ``trajectory`` (one kind), ``seed`` to ``seed`` when given):
    ``posekit seam simulate --config FILE --runs RUNS`` then simulates the very episodes the tuner fits
    on. Otherwise the configuration the recorded episodes ``logdirs`` are tracked with while tuning
    (the first ``setup.yaml``'s; every episode must be of that cell). ``base`` (``--from``), when
    given, is its profile: the one the tuner starts from.

    Raises
    ------
    ConfigError
        The sources as :func:`tune` says; several trajectory kinds (one configuration holds one).
    """
    from .config import TRAJECTORY_KINDS, apply_overrides, config_from_dict, load_config

    _check_tune_sources(logdirs, simulate, config, trajectory)
    if simulate is not None:
        cfg = load_config(config) if config else config_from_dict({}, "defaults")
        kinds = _kinds(trajectory)
        if kinds is not None and len(kinds) != 1:
            raise ConfigError(f"--dump-config: --trajectory names {len(kinds)} kinds ({', '.join(kinds)}); a "
                              f"configuration holds one trajectory.kind: dump one kind at a time (the cell is the "
                              f"same)")
        if kinds is not None and kinds[0] not in TRAJECTORY_KINDS:
            raise ConfigError(f"--trajectory: expected kinds among {', '.join(TRAJECTORY_KINDS)}, got '{kinds[0]}'")
        if seed is not None and int(seed) < 0:
            raise ConfigError(f"--seed: expected an integer >= 0, got {seed}")
        cfg = apply_overrides(cfg, {"trajectory.kind": None if kinds is None else kinds[0], "seed": seed})
    else:
        from .logs import read_episode_log
        from .tune_fit import _check_same_cell

        logs = [read_episode_log(d) for d in logdirs]
        _check_same_cell(logs)
        cfg = logs[0].config
    if base is None:
        return cfg
    from .profile import resolve_profile

    data = cfg.model_dump(mode="python")
    data["profile"] = resolve_profile(base, None, "--from").model_dump(mode="python", exclude_none=True)
    return config_from_dict(data, "--from")


def tune(out, logdirs: Sequence = (), *, with_truth: bool = False, base=None, share_sensors: bool = False,
         simulate: int | None = None, config=None, trajectory=None, seed: int | None = None,
         overwrite: bool = False, stage=None) -> TuneResult:
    """``posekit seam tune``: fit a cell's profile and write it to the file ``out``.

    From the recorded episodes ``logdirs``, or from ``simulate`` episodes simulated now (of the
    configuration file ``config``, ``simulate`` episodes of each trajectory kind of ``trajectory``:
    ``'xy,yz'`` or a list; ``seed``, default the configuration's). ``with_truth``: fit from the errors
    against each episode's truth.csv; ``base``: the profile whose values are kept where the data do not
    pin them; ``share_sensors``: one laser noise and one latency for every sensor; ``stage(text)``: called as
    each step of the fit starts. The file's header records :func:`tune_command`. Returns the :class:`~posekit.seam.frontend.tune.TuneResult`.
    :func:`tune_config` is the cell configuration it works with.
    """
    given, out = out, Path(out)
    if out.exists() and not overwrite:
        raise ConfigError(f"--out {out}: exists; expected a new file (or --overwrite)")
    _check_tune_sources(logdirs, simulate, config, trajectory)
    command = tune_command(given, logdirs, with_truth=with_truth, base=base, share_sensors=share_sensors,
                           simulate=simulate, config=config, trajectory=trajectory, seed=seed)
    if simulate is None:
        result = tune_profile(list(logdirs), with_truth=with_truth, base=base, share_sensors=share_sensors,
                              command=command, stage=stage)
    else:
        result = tune_simulated(config, simulate, _kinds(trajectory), seed, with_truth=with_truth, base=base,
                                share_sensors=share_sensors, command=command, stage=stage)
    header = (f"posekit seam profile, fitted by: {command}\n"
              f"from {result.episodes} episode(s), {result.steps} samples "
              f"({'errors against truth.csv' if result.method == 'truth' else 'laser innovations'})")
    write_profile(out, result.profile, header)
    return result


def _failed(status) -> int:
    return sum(s != "ok" for s in status)


@dataclass
class StudyRun:
    """What :func:`study` made: the study, the files written, the failed runs and the exit code
    (1 when a run failed: every row is written, ``runs.csv`` says why)."""

    study: SeamStudy
    written: list
    failed: int

    @property
    def exit_code(self) -> int:
        return 1 if self.failed else 0


def check_study_size(runs: int, episodes: int) -> None:
    """A one-line ConfigError unless 1 <= runs, 1 <= episodes and runs × episodes <= :data:`MAX_STUDY_EPISODES`."""
    for flag, v in (("--runs", runs), ("--episodes", episodes)):
        if v < 1:
            raise ConfigError(f"{flag}: expected an integer >= 1, got {v}")
    if runs * episodes > MAX_STUDY_EPISODES:
        raise ConfigError(f"--runs {runs} × --episodes {episodes} = {runs * episodes:,} episodes; "
                          f"expected at most {MAX_STUDY_EPISODES:,} (about a day on 2 cores)")


def study(cfg, out, *, runs: int = 100, episodes: int = 1, parameters: Sequence[str] | None = None,
          ranges: Mapping[str, tuple[float, float]] | None = None, spread: float = 0.5, seed: int = 0,
          scheduler=None, n_workers: int | None = None) -> StudyRun:
    """``posekit seam study``: ``runs`` random draws of the filter parameters around ``cfg``, ``episodes``
    episodes each, OLS of each error RMSE, written into the folder ``out`` (fig6_pvalues.png,
    parameters_ranked.csv, runs.csv, report.html).

    ``parameters``: dotted keys to perturb (default the profile's walk and plateau, the kernel
    bandwidth and ESS threshold), ``ranges`` their (low, high) where given, else ± ``spread`` × the
    base value; ``scheduler``/``n_workers`` as :func:`posekit.sweep.run_tasks`.
    """
    check_study_size(runs, episodes)
    factors = make_factors(study_base(cfg), parameters, spread=spread, ranges=dict(ranges or {}))
    result = seam_study(cfg, runs=runs, factors=factors, episodes=episodes, seed=seed, scheduler=scheduler,
                        n_workers=n_workers)
    Path(out).mkdir(parents=True, exist_ok=True)
    report = write_study(result, out)
    written = [n for n in ("fig6_pvalues.png", "parameters_ranked.csv", "runs.csv", "report.html")
               if (report.parent / n).exists()]
    return StudyRun(result, written, _failed(result.status))


@dataclass
class DesignRun:
    """What :func:`design` made: the ranked design, the files written, the failed configurations and
    the exit code (1 when a configuration failed: its row in ranking.csv says why)."""

    design: SensorDesign
    paths: dict
    failed: int

    @property
    def exit_code(self) -> int:
        return 1 if self.failed else 0


def check_design_size(sensors: Sequence[int], distances_mm, angle: str, runs: int) -> None:
    """A one-line ConfigError when configurations × runs exceed :data:`MAX_DESIGN_EPISODES`."""
    n = len(design_configurations(sensors, distances_mm, angle))
    if n * runs > MAX_DESIGN_EPISODES:
        raise ConfigError(f"{n} configurations × --runs {runs} = {n * runs:,} episodes; expected at most "
                          f"{MAX_DESIGN_EPISODES:,}")


def design(cfg, out, *, sensors: Sequence[int] = (0, 1, 2), distances_mm="20:80:20", angle: str = "off",
           runs: int = 3, seed: int = 0, lever_mm: float = 100.0, scheduler=None,
           n_workers: int | None = None) -> DesignRun:
    """``posekit seam design``: every sensor count × distance (× angle) of ``cfg`` simulated ``runs``
    times, ranked by the tool-pose RMSE score, written into the folder ``out`` (ranking.csv,
    ranking.png, report.html). ``distances_mm``: ``'A:B:STEP'``, ``'20,35,50'`` or a sequence (mm)."""
    grid = distance_grid(distances_mm) if isinstance(distances_mm, str) else tuple(distances_mm)
    check_design_size(sensors, grid, angle, runs)
    result = sensor_design(cfg, counts=tuple(sensors), distances_mm=grid, angle=angle, runs=runs, seed=seed,
                           lever_mm=lever_mm, scheduler=scheduler, n_workers=n_workers)
    Path(out).mkdir(parents=True, exist_ok=True)
    paths = write_design(result, out)
    return DesignRun(result, paths, sum(r["status"] != "ok" for r in result.rows()))
