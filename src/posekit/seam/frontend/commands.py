"""``posekit seam simulate``, ``demo`` and ``track`` as library calls.

Each command is one function here with the command's arguments by the same names; the command
parses its flags, stages its output folder and prints. The configuration of an episode is
:func:`episode_config` (defaults < the ``config`` file < the arguments given), as ``--config`` and
the flags of ``seam simulate`` / ``study`` / ``design``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from ...errors import ConfigError
from .compare import compare_configurations, run_episodes, with_sensors
from .config import SeamConfig, apply_overrides, config_from_dict, dump_config, load_config
from .episode_metrics import metrics
from .logs import EpisodeLog, read_episode_log, write_episode_log
from .profile import load_profile
from .report import write_simulation
from .simulate import simulate_data
from .tracker import step_record, track_log, write_track

__all__ = ["DEMO_PARTICLES", "DEMO_STEPS", "MAX_KEPT_STEPS", "MAX_RECORDED", "RECORD_DEFAULT", "SeamSimulation",
           "SeamDemo", "SeamTrackRun", "episode_config", "with_profile", "record_count", "check_kept",
           "simulate_episodes", "demo", "two_sensor_wins", "track_episode"]

#: The demo's episode: shorter and with fewer particles than the paper's 500 steps × 500.
DEMO_STEPS = 300
DEMO_PARTICLES = 300
#: Most episode-steps kept in memory for the metrics and figures (runs × steps, × 6 with
#: --compare or in the demo): about 1 KB each, so 1 GiB at the limit.
MAX_KEPT_STEPS = 1_000_000
#: Most recorded particle poses for Fig. 5 (steps × --record-particles, 48 bytes each: 96 MB).
MAX_RECORDED = 2_000_000
#: Particles recorded per step by default (fewer on a long episode, within MAX_RECORDED).
RECORD_DEFAULT = 200


def with_profile(cfg: SeamConfig, path) -> SeamConfig:
    """``cfg`` with the profile file ``path`` (``--profile``) in place of its own; unchanged for None."""
    if path is None:
        return cfg
    data = cfg.model_dump(mode="python")
    data["profile"] = load_profile(path).model_dump(mode="python", exclude_none=True)
    return config_from_dict(data, "--profile")


def episode_config(config=None, *, profile=None, trajectory: str | None = None, sensors: int | None = None,
                   particles: int | None = None, steps: int | None = None, seed: int | None = None) -> SeamConfig:
    """The effective configuration of an episode: defaults < the ``config`` YAML file < the arguments.

    ``profile``: a profile file (``posekit seam tune``) in place of the configuration's;
    ``trajectory``, ``particles``, ``steps``, ``seed`` override ``trajectory.kind``, ``filter.particles``,
    ``trajectory.steps``, ``seed``; ``sensors`` (0..4) the sensor count. A layout note of an old
    configuration file is a :class:`~posekit.seam.frontend.config.LayoutNote` warning.
    """
    cfg = load_config(config) if config else config_from_dict({}, "defaults")
    cfg = with_profile(cfg, profile)
    for flag, value, low in (("--particles", particles, 1), ("--steps", steps, 2), ("--seed", seed, 0)):
        if value is not None and value < low:
            raise ConfigError(f"{flag}: expected an integer >= {low}, got {value}")
    cfg = apply_overrides(cfg, {"trajectory.kind": trajectory, "filter.particles": particles,
                                "trajectory.steps": steps, "seed": seed})
    return cfg if sensors is None else with_sensors(cfg, sensors)


def check_kept(runs: int, steps: int, configurations: int = 1) -> None:
    """At most :data:`MAX_KEPT_STEPS` episode-steps held for the metrics and figures; ``runs`` >= 1."""
    if runs < 1:
        raise ConfigError(f"--runs: expected an integer >= 1, got {runs}")
    kept = runs * steps * configurations
    if kept > MAX_KEPT_STEPS:
        times = f" × {configurations} configurations" if configurations > 1 else ""
        raise ConfigError(f"--runs {runs} × {steps} steps{times} = {kept:,} episode-steps kept for the metrics and "
                          f"figures; expected at most {MAX_KEPT_STEPS:,} (1 GiB): fewer --runs or --steps")


def record_count(record_particles: int | None, steps: int) -> int:
    """Particles recorded per step for Fig. 5: ``record_particles``, or its default within
    :data:`MAX_RECORDED`; a one-line error for a given value over it."""
    if record_particles is None:
        return min(RECORD_DEFAULT, MAX_RECORDED // steps)
    if record_particles < 0:
        raise ConfigError(f"--record-particles: expected an integer >= 0, got {record_particles}")
    if steps * record_particles > MAX_RECORDED:
        raise ConfigError(f"--record-particles {record_particles} × {steps} steps = "
                          f"{steps * record_particles:,} recorded particle poses; expected at most "
                          f"{MAX_RECORDED:,} (96 MB): at most {MAX_RECORDED // steps} per step, or 0 (no Fig. 5)")
    return record_particles


@dataclass
class SeamSimulation:
    """What :func:`simulate_episodes` made: the episodes, their metrics (metrics.json), the Fig. 8
    comparison (or None) and the files written (name → path)."""

    config: SeamConfig
    results: list
    metrics: dict
    comparison: list | None
    paths: dict


def simulate_episodes(cfg: SeamConfig, out, *, runs: int = 1, compare: bool = False,
                      record_particles: int | None = None, save_log=None, progress: Callable | None = None
                      ) -> SeamSimulation:
    """``posekit seam simulate``: ``runs`` episodes of ``cfg`` (:func:`episode_config`), their metrics,
    estimates and figures written into the folder ``out``.

    ``compare``: also the trajectories xy, yz with 0, 1, 2 sensors (Fig. 8); ``record_particles``:
    particles per step recorded in run 0 for Fig. 5 (default :func:`record_count`'s); ``save_log``: a
    folder that receives run 0 as a recorded episode (setup.yaml, seam.csv, log.csv, truth.csv) for
    :func:`track_episode`.
    """
    check_kept(runs, cfg.trajectory.steps, 6 if compare else 1)
    record = record_count(record_particles, cfg.trajectory.steps)
    results = run_episodes(cfg, runs, record_particles=record, progress=progress, desc="episodes")
    m = metrics(results)
    comparison = (compare_configurations(cfg, runs, progress=progress, reuse=(cfg, results)) if compare else None)
    Path(out).mkdir(parents=True, exist_ok=True)
    paths = write_simulation(out, results, m, dump_config(cfg), comparison=comparison)
    if save_log is not None:
        Path(save_log).mkdir(parents=True, exist_ok=True)
        seed0 = results[0].seed
        write_episode_log(save_log, cfg, simulate_data(cfg, seed0), seed0)
    return SeamSimulation(cfg, results, m, comparison, paths)


@dataclass
class SeamDemo:
    """What :func:`demo` ran: the six configurations (0, 1, 2 sensors on xy and yz), the main one
    (xy, 2 sensors), its wall time (s) and the files written (empty without ``out``)."""

    sets: list
    main: object
    wall_s: float
    paths: dict


def demo(*, seed: int = 0, runs: int = 1, steps: int = DEMO_STEPS, particles: int = DEMO_PARTICLES,
         out=None, progress: Callable | None = None) -> SeamDemo:
    """``posekit seam demo``: 0, 1, 2 sensors on the xy and yz seams, ``runs`` episodes each of
    ``steps`` steps with ``particles`` particles; with ``out``, the figures, metrics.json and
    report.html of the xy seam with two sensors written into that folder."""
    for flag, value, low in (("--particles", particles, 1), ("--steps", steps, 2), ("--seed", seed, 0)):
        if value < low:
            raise ConfigError(f"{flag}: expected an integer >= {low}, got {value}")
    check_kept(runs, steps, 6)
    cfg = apply_overrides(config_from_dict({}, "defaults"),
                          {"trajectory.steps": steps, "filter.particles": particles, "seed": seed})
    t0 = time.perf_counter()
    record = min(RECORD_DEFAULT, MAX_RECORDED // steps) if out else 0
    sets = compare_configurations(cfg, runs, record_particles=record, progress=progress)
    wall = time.perf_counter() - t0
    main = next(s for s in sets if s.trajectory == "xy" and s.sensors == 2)
    paths = {}
    if out:
        Path(out).mkdir(parents=True, exist_ok=True)
        paths = write_simulation(out, main.results, main.metrics, dump_config(main.config), comparison=sets,
                                 title="Seam tracking demo")
    return SeamDemo(sets, main, wall, paths)


def _rmse_values(m, prefix: str = "") -> list[float]:
    return [m[f"{prefix}rmse_mm"][a] for a in "xyz"] + [m[f"{prefix}rmse_deg"][a] for a in ("rx", "ry", "rz")]


def two_sensor_wins(sets) -> dict[str, int]:
    """On each seam of ``sets``, on how many of the six axes (x, y, z, rx, ry, rz) two sensors beat the
    robot's kinematics (the paper's Fig. 8: two sensors give the smallest error; expected 6)."""
    wins = {}
    for kind in dict.fromkeys(s.trajectory for s in sets):
        two = next((s for s in sets if s.trajectory == kind and s.sensors == 2), None)
        if two is not None:
            ours, fk = _rmse_values(two.metrics), _rmse_values(two.metrics, "kinematic_")
            wins[kind] = sum(a < b for a, b in zip(ours, fk))
    return wins


@dataclass
class SeamTrackRun:
    """What :func:`track_episode` did: the recorded episode read, the filter's result and the
    metrics written (metrics.json)."""

    log: object
    result: object
    metrics: dict

    @property
    def exit_code(self) -> int:
        """0: the episode was read whole (:func:`~posekit.verdict.track_exit_code`; a partial read raises)."""
        from ...verdict import track_exit_code
        return track_exit_code(read_whole=True)


def track_episode(logdir, out, *, profile=None, jsonl=None, progress: Callable | None = None) -> SeamTrackRun:
    """``posekit seam track``: the filter on the recorded episode ``logdir``, estimates.csv,
    metrics.json and figures written into the folder ``out``.

    ``logdir`` may also be the episode already read (:func:`~posekit.seam.frontend.logs.read_episode_log`);
    ``profile``: a profile file in place of the setup's; ``jsonl``: a file, or ``'-'`` for stdout, that
    receives one JSON object per step as it is produced (:func:`~posekit.seam.frontend.tracker.step_record`).
    """
    import sys

    log = logdir if isinstance(logdir, EpisodeLog) else read_episode_log(logdir, profile=profile)
    stream = None
    if jsonl == "-":
        stream = sys.stdout
    elif jsonl:
        from ...io import open_stream
        stream = open_stream(jsonl, flag="--jsonl")  # closed below, flushed per step

    def emit(k, est):
        stream.write(json.dumps(step_record(k, est)) + "\n")
        stream.flush()

    try:
        result = track_log(log, progress=None if stream is sys.stdout else progress,
                           on_step=emit if stream is not None else None)
    except BaseException:
        if stream is not None and stream is not sys.stdout:
            stream.close(discard=True)
        raise
    if stream is not None and stream is not sys.stdout:
        stream.close()
    Path(out).mkdir(parents=True, exist_ok=True)
    return SeamTrackRun(log, result, write_track(Path(out), result))
