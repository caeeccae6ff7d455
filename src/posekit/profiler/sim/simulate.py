"""Simulated profiles of a gauge at random poses, with their truth: ``posekit profiler simulate``.

:func:`simulate` draws ``count`` sensor poses ``T_G_F`` in a workspace around the nominal pose
(:func:`~posekit.profiler.sim.poses.sample_poses`) and renders what the sensor measures there
(:func:`~posekit.profiler.sim.render.render_profiles`, ideal or with every defect of a real cell);
with ``out`` it writes the folder of DESIGN.md's contract: ``profiles.npz`` (``profiles`` (K, N, 2),
``T_G_F`` (K, 4, 4)) and ``truth.csv`` (``index,tx,ty,tz,qw,qx,qy,qz``, mm, the pose of F in G).
The same seed gives the same files.

Examples
--------
>>> from posekit.profiler import simulate
>>> sim = simulate("demo-5", count=3, noise_um=5.0, seed=0)
>>> sim.profiles.shape, sim.T_G_F.shape
((3, 3200, 2), (3, 4, 4))
"""

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...errors import InputFileError
from ...geometry import quaternion_from_matrix
from ...io import check_out_folder, staged_folder
from ..gauge.model import Gauge, resolve_gauge
from ..sensor import NoiseModel
from .poses import Workspace, sample_poses
from .realism import RealismModel
from .render import render_profiles

__all__ = ["Simulation", "simulate", "write_simulation", "write_truth_csv", "read_truth_csv", "TRUTH_COLUMNS"]

TRUTH_COLUMNS = ["index", "tx", "ty", "tz", "qw", "qx", "qy", "qz"]


@dataclass(frozen=True)
class Simulation:
    """Result of :func:`simulate`.

    Attributes
    ----------
    gauge : Gauge
    profiles : ndarray, shape (K, N, 2)
        Points (x, z) in F, mm, scan order; NaN = no return.
    T_G_F : ndarray, shape (K, 4, 4)
        The true pose of F in G of each profile, mm.
    realistic : bool
        Rendered with :meth:`RealismModel.realistic <posekit.profiler.sim.realism.RealismModel.realistic>`.
    """

    gauge: Gauge
    profiles: np.ndarray
    T_G_F: np.ndarray
    realistic: bool = False

    @property
    def returns(self) -> float:
        """Fraction of the rays with a return."""
        return float(np.isfinite(self.profiles[..., 0]).mean())


def simulate(gauge, count: int = 100, *, noise_um: float = 5.0, noise_x_um: float | None = None,
             outliers: float = 0.0, dropouts: float = 0.0, translation_mm=(10.0, 10.0, 40.0),
             rotation_deg=(4.0, 4.0, 8.0), standoff_mm: float | None = None, realistic: bool = False,
             seed: int = 0, out=None, overwrite: bool = False, replace_own: bool = False) -> Simulation:
    """Simulate ``count`` profiles of a gauge at random poses (``posekit profiler simulate``).

    Parameters
    ----------
    gauge : Gauge or str or Path
        A gauge, a gauge YAML file or a bundled name (:func:`~posekit.profiler.gauge.model.resolve_gauge`).
    count : int
        Number of profiles K.
    noise_um, noise_x_um : float
        1σ of the Gaussian noise in z and x of F, µm; x defaults to twice z
        (:meth:`NoiseModel.from_z_um <posekit.profiler.sensor.NoiseModel.from_z_um>`).
    outliers : float
        Fraction of returns that are spikes, 0..0.5.
    dropouts : float
        Mean number of dropout runs per profile.
    translation_mm, rotation_deg : 3 floats
        Workspace half-ranges (:class:`~posekit.profiler.sim.poses.Workspace`): translation along
        x, y, z of G, mm; rotation about x, y, z of F, degrees.
    standoff_mm : float, optional
        Depth of the gauge below the sensor at the nominal pose, mm (default: mid-range).
    realistic : bool
        Render one as-built gauge with every defect of a real cell (``RealismModel.realistic()``).
    seed : int
        Random seed: the same seed gives the same profiles.
    out : str or Path, optional
        Write ``profiles.npz`` and ``truth.csv`` into this folder (:func:`write_simulation`).
    overwrite : bool
        Replace a non-empty ``out`` folder.
    replace_own : bool
        Replace ``out`` while everything in it was written by posekit (a verb's default
        folder: its marker lists the files); a user's file there stops the run first.

    Returns
    -------
    Simulation

    Raises
    ------
    GaugeError, ConfigError
        For a bad gauge, noise or workspace, or an ``out`` folder that exists and is not empty
        (checked before simulating).
    """
    gauge = resolve_gauge(gauge)
    noise = NoiseModel.from_z_um(noise_um, noise_x_um, outlier_rate=outliers, dropouts_per_profile=dropouts)
    workspace = Workspace(translation_mm=tuple(translation_mm), rotation_deg=tuple(rotation_deg),
                          standoff_mm=standoff_mm)
    if out is not None:
        check_out_folder(out, overwrite=overwrite, replace_own=replace_own)
    rng = np.random.default_rng(seed)
    Ts = sample_poses(gauge, count, rng, workspace)
    profiles = render_profiles(gauge, Ts, noise, rng, realism=RealismModel.realistic() if realistic else None)
    sim = Simulation(gauge=gauge, profiles=profiles, T_G_F=Ts, realistic=bool(realistic))
    if out is not None:
        write_simulation(sim, out, overwrite=overwrite, replace_own=replace_own)
    return sim


def write_simulation(sim: Simulation, out, overwrite: bool = False, replace_own: bool = False) -> dict:
    """Write ``profiles.npz`` and ``truth.csv`` into the folder ``out`` (whole or not at all).

    Returns
    -------
    dict
        ``{"profiles": Path, "truth": Path}`` in ``out``.
    """
    with staged_folder(out, overwrite=overwrite, replace_own=replace_own) as tmp:
        np.savez_compressed(tmp / "profiles.npz", profiles=sim.profiles.astype(np.float64), T_G_F=sim.T_G_F)
        write_truth_csv(tmp / "truth.csv", sim.T_G_F, quaternion_from_matrix(sim.T_G_F[:, :3, :3]))
    return {"profiles": Path(out) / "profiles.npz", "truth": Path(out) / "truth.csv"}


def write_truth_csv(path, Ts_G_F, q_wxyz):
    """Write ``index,tx,ty,tz,qw,qx,qy,qz`` for poses ``T_G_F`` (mm)."""
    with open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(TRUTH_COLUMNS)
        for i, (T, q) in enumerate(zip(Ts_G_F, q_wxyz)):
            w.writerow([i, *(repr(float(v)) for v in T[:3, 3]), *(repr(float(v)) for v in q)])


def read_truth_csv(path):
    """Read a truth CSV; returns (index (K,), t (K, 3) mm, q_wxyz (K, 4))."""
    path = Path(path)
    try:
        data = np.genfromtxt(path, delimiter=",", names=True)
    except (OSError, ValueError) as exc:
        raise InputFileError(f"{path}: cannot read truth CSV ({exc})") from None
    if data.dtype.names is None or list(data.dtype.names) != TRUTH_COLUMNS:
        raise InputFileError(f"{path}: expected columns {','.join(TRUTH_COLUMNS)}")
    data = np.atleast_1d(data)
    return (data["index"].astype(int), np.stack([data["tx"], data["ty"], data["tz"]], 1),
            np.stack([data["qw"], data["qx"], data["qy"], data["qz"]], 1))
