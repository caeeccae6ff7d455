"""The closed-loop experiment of §IV-C as one call: ``posekit profiler loop`` and ``posekit demo``.

:func:`closed_loop` runs the open- and closed-loop step responses over loopback sockets
(:func:`~posekit.profiler.loop.loop.run_loop_experiment`) with the command's arguments, by the
same names, and writes Table III, Table IV, Fig. 5/6 and ``report.html`` into ``out``
(:func:`~posekit.profiler.loop.loop_report.write_loop_report`).
"""

import math
from collections.abc import Callable
from pathlib import Path

from ...errors import ConfigError
from ...io import check_out_folder, staged_folder
from ..gauge.model import resolve_gauge
from ..sensor import NoiseModel
from .loop import LoopExperiment, run_loop_experiment
from .loop_report import write_loop_report

__all__ = ["closed_loop", "MAX_STEP_MM"]

#: Largest step size, mm: the gauge must stay in the profiler's view through the response.
MAX_STEP_MM = 50.0


def closed_loop(gauge="demo-5", *, runs: int = 3, axes=("x", "y", "z", "xyz"), steps_mm=(1.0, 2.0),
                noise_um: float = 5.0, seed: int = 0, realtime: bool = False, linear: bool = False,
                camera: bool = True, out=None, overwrite: bool = False, replace_own: bool = False,
                progress: Callable | None = None) -> tuple[LoopExperiment, dict]:
    """Open vs closed loop step responses over loopback TCP, and Table III's timings.

    Parameters
    ----------
    gauge : Gauge or str or Path
        The gauge (a file or a bundled name).
    runs : int
        Runs per axis, step size and mode (Monte-Carlo repetitions, each with its own noise).
    axes : sequence of str
        Step directions (``x``, ``y``, ``z``, ``xyz``).
    steps_mm : sequence of float
        Step sizes, mm, each non-zero and within ±:data:`MAX_STEP_MM`.
    noise_um : float
        Profiler noise in z, µm (x: twice that, :meth:`NoiseModel.from_z_um
        <posekit.profiler.sensor.NoiseModel.from_z_um>`).
    seed : int
    realtime : bool
        Pace the cycles at 83.3 Hz instead of lock-step.
    linear : bool
        The linear robot model (no amplitude-dependent damping).
    camera : bool
        Also time the OpenCV camera pipeline of Table III (needs the ``vision`` extra).
    out : str or Path, optional
        Folder for ``table3.csv``, ``table4.csv``, the figures and ``report.html`` (checked
        before the runs, written whole or not at all).
    overwrite : bool
        Replace a non-empty ``out``.
    replace_own : bool
        Replace ``out`` while everything in it was written by posekit (a verb's default
        folder: its marker lists the files); a user's file there stops the run first.
    progress : callable, optional
        Wraps the list of runs.

    Returns
    -------
    experiment : LoopExperiment
    paths : dict
        The files written into ``out`` by name (empty without ``out``).
    """
    steps = tuple(float(s) for s in steps_mm)
    if not all(math.isfinite(s) and s != 0 for s in steps) or any(abs(s) > MAX_STEP_MM for s in steps):
        raise ConfigError(f"steps_mm: expected non-zero step sizes in -{MAX_STEP_MM:g}..{MAX_STEP_MM:g} mm, "
                          f"got {list(steps)}")
    gauge = resolve_gauge(gauge)
    if out is not None:
        check_out_folder(out, overwrite=overwrite, replace_own=replace_own)
    exp = run_loop_experiment(gauge, axes=tuple(axes), steps_mm=steps, repeats=runs,
                              noise=NoiseModel.from_z_um(noise_um), seed=seed, realtime=realtime,
                              nonlinear=not linear, camera=camera, progress=progress)
    paths = {}
    if out is not None:
        with staged_folder(out, overwrite=overwrite, replace_own=replace_own) as tmp:
            paths = write_loop_report(exp, tmp)
            paths = {k: Path(out) / Path(v).relative_to(tmp) for k, v in paths.items()}
    return exp, paths
