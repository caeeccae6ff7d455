"""Sets of simulated episodes: several runs of one configuration, and the grid of sensor
configurations × trajectories behind Fig. 8.

Run ``r`` of a set with seed ``s`` simulates with the episode seed drawn from
``task_seed(s, r)`` (:func:`posekit.sweep.task_seed`), so a set of R runs is the first R runs
of a larger one, and every configuration of a comparison sees the same seeds (common random
numbers: the differences between configurations are not noise between draws).
"""

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from posekit.errors import ConfigError
from posekit.sweep import task_seed

__all__ = [
    "resize_sensors",
    "FIG8_SENSORS",
    "FIG8_TRAJECTORIES",
    "ConfigurationSet",
    "compare_configurations",
    "episode_seeds",
    "run_episodes",
    "with_sensors",
]

#: The trajectories and sensor counts of the paper's Fig. 8.
FIG8_TRAJECTORIES = ("xy", "yz")
FIG8_SENSORS = (0, 1, 2)


def episode_seeds(seed: int, runs: int) -> list[int]:
    """Episode seeds of runs ``0 .. runs-1`` of a set with seed ``seed`` (ints >= 0)."""
    if int(runs) < 1:
        raise ConfigError(f"runs: expected >= 1, got {runs}")
    return [int(task_seed(seed, r).generate_state(1)[0]) for r in range(int(runs))]


def resize_sensors(data: dict, count: int) -> dict:
    """A configuration mapping (``SeamConfig.model_dump``) with ``count`` sensors, in place: the first ``count``
    distances, mounts and latencies when it lists at least that many (the defaults otherwise), and a per-sensor
    profile cut to its first entries (its first entry for all when it has fewer)."""
    ds = data["cell"]["sensors"]
    ok = isinstance(count, int) and not isinstance(count, bool) and count >= 0
    ds["count"] = count
    for key in ("distances_mm", "mounts", "latency_s"):
        v = ds.get(key)
        if v is not None:
            ds[key] = tuple(v[:count]) if ok and 0 < count <= len(v) else None
    prof = data.get("profile")
    if isinstance(prof, dict) and isinstance(prof.get("sensors"), (list, tuple)):
        entries = list(prof["sensors"])
        if ok and len(entries) > 1 and len(entries) != count:
            prof["sensors"] = entries[:count] if 0 < count <= len(entries) else entries[:1]
    return data


def with_sensors(cfg, count: int, source: str = "command line"):
    """``cfg`` with ``count`` sensors (:func:`resize_sensors`)."""
    from posekit.seam.frontend.config import config_from_dict

    data = cfg.model_dump(mode="python")
    data["profile"] = cfg.profile.model_dump(mode="python", exclude_none=True)
    return config_from_dict(resize_sensors(data, count), source)


def run_episodes(cfg, runs: int, *, seed: int | None = None, record_particles: int = 0,
                 progress=None, desc: str = "episodes") -> list:
    """Simulate ``runs`` episodes of one configuration, in this process.

    Parameters
    ----------
    cfg : SeamConfig
    runs : int
        Number of episodes (>= 1).
    seed : int, optional
        Seed of the set (default ``cfg.seed``); see :func:`episode_seeds`.
    record_particles : int
        Particles recorded per step in run 0 (for Fig. 5); 0 records none.
    progress : callable, optional
        Wraps the run iterator (e.g. a tqdm bar); default none.

    Returns
    -------
    list of EpisodeResult
    """
    from posekit.seam.frontend.episode import run_episode

    seeds = episode_seeds(cfg.seed if seed is None else seed, runs)
    it = range(len(seeds)) if progress is None else progress(range(len(seeds)), total=len(seeds), desc=desc)
    return [run_episode(cfg, seeds[r], record_particles=record_particles if r == 0 else 0) for r in it]


@dataclass
class ConfigurationSet:
    """Episodes of one configuration of a comparison."""

    label: str
    trajectory: str
    sensors: int
    config: object
    results: list
    metrics: dict

    def errors(self) -> np.ndarray:
        """(R*T, 6) filter errors of all runs, ``[x, y, z mm, rx, ry, rz rad]``."""
        return np.concatenate([r.error for r in self.results], axis=0)

    def kinematic_errors(self) -> np.ndarray:
        """(R*T, 6) errors of the kinematics-only pose of all runs, ``[x, y, z mm, rx, ry, rz rad]``."""
        return np.concatenate([r.kinematic_error for r in self.results], axis=0)


def compare_configurations(cfg, runs: int, *, trajectories: Sequence[str] = FIG8_TRAJECTORIES,
                           sensors: Sequence[int] = FIG8_SENSORS, seed: int | None = None,
                           record_particles: int = 0, progress=None,
                           reuse: tuple | None = None) -> list[ConfigurationSet]:
    """Fig. 8: the same filter on every trajectory × sensor count, ``runs`` episodes each.

    Every other parameter comes from ``cfg`` (the paper tunes the filter for xy and keeps it).
    ``reuse = (config, results)``: episodes already simulated for one configuration with the
    same runs and seed, taken as they are when a combination equals that configuration.
    Returns one :class:`ConfigurationSet` per combination, trajectories outermost.
    """
    from posekit.seam.frontend.config import apply_overrides
    from posekit.seam.frontend.episode_metrics import metrics

    out = []
    for kind in trajectories:
        base = apply_overrides(cfg, {"trajectory.kind": kind})
        for count in sensors:
            c = with_sensors(base, int(count))
            label = f"{kind}, {count} sensor{'s' if count != 1 else ''}"
            if reuse is not None and reuse[0] == c and len(reuse[1]) == runs:
                res = list(reuse[1])
            else:
                res = run_episodes(c, runs, seed=seed, record_particles=record_particles, progress=progress,
                                   desc=label)
            out.append(ConfigurationSet(label, kind, int(count), c, res, metrics(res)))
    return out
