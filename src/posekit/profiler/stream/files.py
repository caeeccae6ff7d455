"""Profile files in, result files out: the library behind ``posekit profiler estimate`` and
``posekit profiler calibrate-gauge``.

:func:`estimate_file` reads a profile file (:func:`~posekit.profiler.stream.reading.read_profile_file`),
estimates every profile with its verdict and tests the gauge file against the batch
(:func:`~posekit.profiler.estimate.pipeline.estimate_profiles`), and writes one record per profile
(:class:`~posekit.profiler.stream.records.RecordWriter`: JSON lines or CSV, DESIGN.md's contract).
:func:`calibrate_gauge_file` measures the as-built gauge from a profile file and writes it as a
gauge YAML file. Both take the arguments of their command, by the same names.
"""

from collections.abc import Callable
from pathlib import Path

from ...io import write_text_atomic
from ..estimate.consistency import DEFAULT_SIGNIFICANCE, check_noise
from ..estimate.pipeline import BatchResult, estimate_profiles
from ..gauge.calibration import GaugeCalibration, as_built_yaml, calibrate_gauge
from ..gauge.model import resolve_gauge
from ..sensor import NoiseModel
from .reading import ReadOptions, read_profile_file, read_profiles
from .records import RecordWriter

__all__ = ["estimate_file", "calibrate_gauge_file", "assumed_noise"]


def assumed_noise(noise_um: float = 5.0, noise_x_um: float | None = None,
                  scale_sigma_ppm: float | None = None) -> NoiseModel:
    """The noise the estimator assumes from a command's ``--noise-um``, ``--noise-x-um`` and
    ``--scale-sigma-ppm``: x twice z unless given (:meth:`NoiseModel.from_z_um
    <posekit.profiler.sensor.NoiseModel.from_z_um>`), the default scale allowance unless given."""
    if scale_sigma_ppm is None:
        return NoiseModel.from_z_um(noise_um, noise_x_um)
    return NoiseModel.from_z_um(noise_um, noise_x_um, scale_sigma_ppm=scale_sigma_ppm)


def estimate_file(input, gauge, *, method: str = "mle", mounting: str = "auto", rotation: str = "quat",
                  noise_um: float = 5.0, noise_x_um: float | None = None, significance: float | None = None,
                  scale_sigma_ppm: float | None = None, read: ReadOptions = ReadOptions(), out=None,
                  stream=None, progress: Callable | None = None) -> BatchResult:
    """Estimate the pose of every profile of a file and write one record per profile.

    Parameters
    ----------
    input : str or Path
        CSV ``x,z`` (mm; or the columns of ``read``), ``.npy`` (N, 2) or ``.npz`` with
        ``profiles`` (K, N, 2).
    gauge : Gauge or str or Path
        The gauge (a file or a bundled name), loaded for ``mounting``.
    method, mounting, rotation
        As :func:`~posekit.profiler.estimate.pipeline.estimate_profiles`.
    noise_um, noise_x_um, scale_sigma_ppm : float
        The noise the estimator assumes (:func:`assumed_noise`): z and x, µm (x: twice z unless
        given), and the sensor's scale allowance, ppm (default 100).
    significance : float, optional
        α of the consistency tests (default :data:`~posekit.profiler.estimate.consistency.DEFAULT_SIGNIFICANCE`).
    read : ReadOptions
        How to read a CSV (columns, delimiter) and the region of interest.
    out : str or Path, optional
        ``FILE.jsonl`` or ``FILE.csv``, written to a temporary name and renamed into place;
        None: JSON lines on ``stream`` (if given).
    stream : text stream, optional
    progress : callable, optional
        Wraps the iterable of profile indices (a progress bar).

    Returns
    -------
    BatchResult
        Its ``verdicts``, ``status_counts()`` and ``exit_code`` (0 only if every profile is 'ok').
    """
    noise = assumed_noise(noise_um, noise_x_um, scale_sigma_ppm)
    check_noise(noise)
    significance = DEFAULT_SIGNIFICANCE if significance is None else significance
    gauge = resolve_gauge(gauge, mounting)          # an ambiguous gauge needs the mounting at load
    profiles = read_profile_file(input, read)
    res = estimate_profiles(profiles, gauge, method, mounting, noise=noise, significance=significance,
                            rotation=rotation, progress=progress)
    if out is not None or stream is not None:
        with RecordWriter(out, stream=stream, rotation=rotation) as writer:
            for rec in res.records:
                writer.write(rec)
    return res


def calibrate_gauge_file(input, gauge, *, mounting: str = "auto", out=None) -> GaugeCalibration:
    """The as-built gauge from a profile file, written as a gauge YAML file (with ``tolerance_um``).

    Parameters
    ----------
    input : str or Path
        ``.npz`` with ``profiles`` (K, N, 2), K >= 50, taken at unknown, varied poses.
    gauge : Gauge or str or Path
        The nominal gauge (the drawing), loaded for ``mounting``.
    mounting : {'auto', 'normal', 'reversed'}
    out : str or Path, optional
        ``ASBUILT.yaml``, written atomically.

    Returns
    -------
    GaugeCalibration
    """
    nominal = resolve_gauge(gauge, mounting)
    cal = calibrate_gauge(read_profiles(input), nominal, mounting=mounting, source=str(input))
    if out is not None:
        write_text_atomic(Path(out), as_built_yaml(cal, Path(input).name))
    return cal
