"""``posekit localcal simulate`` and ``demo`` as library calls: the episode settings from the
command's options, the runs, the files.

>>> from posekit.localcal.studies.simulate import episode_config, simulate
>>> config = episode_config(vo="isotropic", camera_hz=5)          # doctest: +SKIP
>>> result = simulate("line", runs=3, seed=0, config=config, out="run")  # doctest: +SKIP
>>> result.status_counts                                            # doctest: +SKIP
{'ok': 3, 'suspect': 0, 'error': 0}
"""

import math
from dataclasses import dataclass

from posekit.errors import ConfigError, EstimationError
from posekit.io import parse_number
from posekit.localcal.sim.vo import VONoise
from posekit.localcal.studies.episode_config import EpisodeConfig
from posekit.localcal.studies.experiments import ExperimentResult, run_experiment

__all__ = ["DEMO_METHODS", "DEMO_UPDATES", "MAX_START_Q", "VO_MODELS", "RobotOptions", "all_failed_error", "check_rates",
           "demo", "episode_config", "robot_options", "simulate", "view_hint"]

#: The VO error models: ``stereo`` (noise and drift grow with depth, ZED2-like baseline) and
#: ``isotropic`` (1 mm white noise, 3 mm per sqrt(m) drift: the first simulator's, :class:`VONoise`).
VO_MODELS = ("stereo", "isotropic")
#: Largest start joint value, deg (mm for a prismatic joint).
MAX_START_Q = 1e6
#: The demo: one episode of each method, two look-then-move updates each.
DEMO_METHODS, DEMO_UPDATES = ("line", "trajectory"), 2


@dataclass(frozen=True)
class RobotOptions:
    """The arm of an episode, loaded and checked (:func:`robot_options`).

    Attributes
    ----------
    config : dict
        ``robot``, ``base_link``, ``tip_link`` and, when given, ``start_q`` (rad, mm for a
        prismatic joint) for :class:`EpisodeConfig`.
    summary : str
        One line on the arm for a robot other than the bundled crane (empty for ``hiab033``).
    """

    config: dict
    summary: str = ""


def robot_options(robot: str = "hiab033", *, base_link: str | None = None, tip_link: str | None = None,
                  start_q_deg=None) -> RobotOptions:
    """The robot fields of :class:`EpisodeConfig`, with the robot loaded once here so that a bad
    file or link is a one-line error before any run.

    Parameters
    ----------
    robot : str
        A bundled model name or a URDF file.
    base_link, tip_link : str, optional
        The URDF chain's ends.
    start_q_deg : sequence of float or str, optional
        Start joint values, deg (mm for prismatic joints), or their comma-separated text; required for any robot but ``hiab033``
        (the crane's start pose fits only the crane).

    Raises
    ------
    ConfigError
        Non-finite or out-of-range values, the wrong number of them, none for another robot.
    """
    from posekit.robots import load_robot

    if start_q_deg is not None:
        shown = start_q_deg if isinstance(start_q_deg, str) else ",".join(map(str, start_q_deg))
        if isinstance(start_q_deg, str):
            try:
                values = [parse_number(v) for v in start_q_deg.split(",")]
            except ValueError:
                raise ConfigError(f"--start-q-deg: expected comma-separated numbers, got '{shown[:80]}'") from None
        else:
            values = [float(v) for v in start_q_deg]
        if not all(math.isfinite(v) for v in values):
            raise ConfigError(f"--start-q-deg: expected finite values, got '{shown[:80]}'")
        if not all(abs(v) <= MAX_START_Q for v in values):
            raise ConfigError(f"--start-q-deg: expected values in -{MAX_START_Q:.0e}..{MAX_START_Q:.0e} deg (mm for a "
                              f"prismatic joint), got '{shown[:80]}'")
    options = {"robot": robot, "base_link": base_link, "tip_link": tip_link}
    model = load_robot(robot, base_link, tip_link)
    if start_q_deg is not None:
        if len(values) != model.n_joints:
            raise ConfigError(f"--start-q-deg: expected {model.n_joints} values for {model.name}, got {len(values)}")
        options["start_q"] = tuple(math.radians(v) if r else v for v, r in zip(values, model.is_revolute))
    elif robot != "hiab033":
        raise ConfigError(f"--start-q-deg: required for --robot {robot} (the crane's start pose fits only "
                          f"the crane); give its {model.n_joints} start joint values in deg (chain "
                          f"{getattr(model, 'base_link', 'base')} → {getattr(model, 'tip_link', 'flange')})")
    summary = ("" if robot == "hiab033"
               else f"robot {model.summary}" + "".join(f"; {note}" for note in getattr(model, "notes", ())))
    return RobotOptions(options, summary)


def check_rates(camera_hz: float, plot_hz: float) -> None:
    """A one-line :class:`ConfigError` unless ``camera_hz > 0`` and ``plot_hz >= 0`` (finite, Hz)."""
    if not (math.isfinite(camera_hz) and camera_hz > 0):
        raise ConfigError(f"--camera-hz: expected a rate > 0, got {camera_hz:g}")
    if not (math.isfinite(plot_hz) and plot_hz >= 0):
        raise ConfigError(f"--plot-hz: expected a rate >= 0, got {plot_hz:g}")


def episode_config(*, vo: str = "stereo", camera_hz: float = 10.0, plot_hz: float = 2.0,
                   lens_distortion: bool = True, **fields) -> EpisodeConfig:
    """The :class:`EpisodeConfig` of the ``simulate``/``demo`` options.

    Parameters
    ----------
    vo : {'stereo', 'isotropic'}
        The VO error model (:data:`VO_MODELS`): ``isotropic`` replaces the stereo model by
        :class:`~posekit.localcal.sim.vo.VONoise`'s white noise and drift.
    camera_hz : float
        Camera images per second along the circular path, > 0 Hz.
    plot_hz : float
        Camera images per second along the other motions (error plots), >= 0 Hz.
    lens_distortion : bool
        Render and undistort the lens distortion (False: rectified images).
    **fields
        Any other :class:`EpisodeConfig` field (``robot_options(...).config`` among them).

    Raises
    ------
    ConfigError
        A rate out of its range or an unknown VO model.
    """
    check_rates(camera_hz, plot_hz)
    noise = {}
    if vo == "isotropic":
        noise = {"vo_stereo": None, "vo_noise_mm": VONoise.noise_mm, "vo_noise_rad": VONoise.noise_rad,
                 "vo_drift_mm_per_sqrt_m": VONoise.drift_mm_per_sqrt_m,
                 "vo_drift_rad_per_sqrt_m": VONoise.drift_rad_per_sqrt_m}
    elif vo != "stereo":
        raise ConfigError(f"--vo: expected stereo or isotropic, got '{vo}'")
    return EpisodeConfig(camera_hz=camera_hz, plot_hz=plot_hz, lens_distortion=lens_distortion, **noise, **fields)


def all_failed_error(result: ExperimentResult) -> EstimationError | None:
    """The one-line error when every run of ``result`` failed (naming the first reason), else None."""
    if all(ep is None for ep in result.episodes):
        n = len(result.episodes)
        return EstimationError(f"{result.method} method: all {n} run(s) failed; run 1: {result.failures[0]}")
    return None


def view_hint(result: ExperimentResult, robot: str) -> str:
    """One line for a robot whose runs lost the markers from view: which options move them (else empty)."""
    lost = [f for f in result.failures if f and "not seen by the camera" in f]
    if not lost or robot == "hiab033":
        return ""
    return (f"posekit: hint: {len(lost)} run(s) lost the markers from view; the scene is sized for the 5 m crane: "
            "bring the object closer (--ooi-distance-mm 500), start with free reach along the camera axis "
            "(--start-q-deg) or shrink the errors (--error-scale)")


def _write(result, out, command):
    """``write_experiment`` with a write failure as a one-line ConfigError."""
    from posekit.localcal.studies.plots import write_experiment
    try:
        return write_experiment(result, out, command=command)
    except OSError as exc:
        raise ConfigError(f"--out {out}: cannot write the results ({exc.strerror or exc})") from None


def simulate(method: str, *, runs: int = 10, seed: int = 0, updates: int = 2, config: EpisodeConfig | None = None,
             scheduler="serial", n_workers: int | None = None, progress: bool | None = None, out=None,
             command: str = "") -> tuple[ExperimentResult, dict]:
    """``posekit localcal simulate``: ``runs`` episodes of one method, written to ``out``.

    Parameters
    ----------
    method : {'line', 'trajectory'}
        Range adjustment method.
    runs, seed, updates, config, scheduler, n_workers, progress
        As :func:`~posekit.localcal.studies.experiments.run_experiment`.
    out : path, optional
        Folder for the tables (CSV), ``results.json``, the figures and ``report.html``; every run
        has its row, failed ones with ``status=error``. Nothing is written when None.
    command : str
        The command line, quoted in the report.

    Returns
    -------
    result : ExperimentResult
    files : dict
        What was written (empty without ``out``).
    """
    result = run_experiment(method, runs, seed, updates=updates, config=config, scheduler=scheduler,
                            progress=progress, n_workers=n_workers)
    files = _write(result, out, command) if out is not None else {}
    return result, files


def demo(seed: int = 0, *, config: EpisodeConfig | None = None, out=None,
         progress: bool | None = None) -> tuple[dict, EstimationError | None]:
    """``posekit localcal demo``: one episode of each method (:data:`DEMO_METHODS`), two updates each.

    Parameters
    ----------
    seed : int
        Seed of both episodes.
    config : EpisodeConfig, optional
        Episode settings (:func:`episode_config`).
    out : path, optional
        Folder: ``OUT/line`` and ``OUT/trajectory`` get :func:`simulate`'s files.
    progress : bool, optional
        Progress bar; default only on a terminal.

    Returns
    -------
    results : dict of str to ExperimentResult
        By method, in order, up to and including the first method whose episode failed (what
        ran is still written).
    failure : EstimationError or None
        That failure (:func:`all_failed_error`), None when both episodes ran.
    """
    from pathlib import Path

    results = {}
    for method in DEMO_METHODS:
        result, _ = simulate(method, runs=1, seed=seed, updates=DEMO_UPDATES, config=config, scheduler="serial",
                             progress=progress, out=None if out is None else Path(out) / method,
                             command=f"posekit localcal demo --seed {seed}")
        results[method] = result
        failure = all_failed_error(result)
        if failure is not None:
            return results, failure
    return results, None
