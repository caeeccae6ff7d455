"""Where profiles come from: files, the simulator, the PKPF socket, a vendor SDK.

A **profile source** is anything iterable that yields ``(t_s, profile)``: the time of the
profile in seconds (any origin, non-decreasing) and the points, an array of shape (N, 2) of
``(x, z)`` in the profiler frame F, mm, in scan order, NaN where there was no return.
posekit implements it for files (:class:`FileSource`: CSV, ``.npy``, ``.npz``), arrays
(:class:`ArraySource`), the simulator (:class:`SimulatedSource`) and the receiving end of
the binary stream (:class:`SocketSource`). Whatever the source, the profiles go on the same
way: ``estimate_pose(profile, gauge)`` one at a time, ``SensorClient.send_source(source)``
to a :class:`~posekit.profiler.stream.server.PoseServer` over TCP, or ``server.submit(profile)``
into a server in the same process.

Plugging in a sensor's SDK (Keyence LJ-X, LMI Gocator, Micro-Epsilon scanCONTROL, ...)
means writing one small class; posekit holds no vendor code. SDKs typically deliver the
points as integers in a device unit (with a scale and an offset per axis), mark a missing
return with a sentinel value, and stamp profiles on the controller's clock: convert all three
at this edge, to mm, NaN and seconds. A fake SDK object stands in for the vendor's binding::

    >>> import numpy as np
    >>> class FakeSDK:                                # the vendor's Python binding
    ...     INVALID = -32768                          # its "no return" sentinel
    ...     def __init__(self):
    ...         self.k = 0
    ...     def grab(self):                           # -> stamp in µs, raw x and z counts
    ...         self.k += 1
    ...         x = np.arange(-4, 5) * 2500           # 2.5 µm per count -> ±10 mm
    ...         z = np.full(9, 160_000 + self.k)      # -> 400 mm
    ...         z[0] = self.INVALID
    ...         return 12_000 * self.k, x, z
    >>> class VendorSource:
    ...     '''ProfileSource over the SDK: counts -> mm, sentinel -> NaN, µs -> s.'''
    ...     def __init__(self, sdk, count, scale_mm=0.0025):
    ...         self.sdk, self.count, self.scale_mm = sdk, count, scale_mm
    ...     def __iter__(self):
    ...         for _ in range(self.count):
    ...             t_us, x, z = self.sdk.grab()
    ...             pts = np.column_stack([x, z]) * self.scale_mm
    ...             pts[z == self.sdk.INVALID] = np.nan
    ...             yield t_us * 1e-6, pts
    >>> source = VendorSource(FakeSDK(), count=2)
    >>> isinstance(source, ProfileSource)
    True
    >>> [(round(t, 3), p.shape, float(p[1, 1])) for t, p in source]
    [(0.012, (9, 2), 400.0025), (0.024, (9, 2), 400.005)]

Reading options (:class:`ReadOptions`, the ``--columns``, ``--delimiter``, ``--roi-x`` and
``--roi-z`` flags of ``posekit profiler estimate`` and ``replay``) apply to files; every file
goes through the safe readers of :mod:`posekit.io`. A profile whose every coordinate is below
2 in magnitude and that spans less than 1 is refused as one in metres (:func:`check_units`).
"""

import math
from collections.abc import Iterator
from pathlib import Path
from typing import Protocol, runtime_checkable

import numpy as np

from ...errors import ConfigError, InputFileError, ProfileError
from ...io import load_npz_member
from ..gauge.model import Gauge
from ..loop.robotsim import PERIOD_S
from ..sensor import LJ_X8400, NoiseModel, ProfilerModel
from ..sim.render import render_profiles
from .reading import ReadOptions, read_profile_file

__all__ = ["ProfileSource", "ArraySource", "FileSource", "SimulatedSource"]

_DEFAULT_RATE_HZ = 1.0 / PERIOD_S          # the paper's 12 ms control cycle


@runtime_checkable
class ProfileSource(Protocol):
    """An iterable of ``(t_s, profile)``: time in s (non-decreasing), points (N, 2) (x, z) in F, mm."""

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]: ...


# --------------------------------------------------------------------------- reading options


# --------------------------------------------------------------------------- sources


class ArraySource:
    """Profiles held in memory.

    Parameters
    ----------
    profiles : array_like, shape (K, N, 2)
        (x, z) in F, mm; NaN = no return.
    t_s : array_like, shape (K,), optional
        Times, s, non-decreasing; default ``k / rate_hz``.
    rate_hz : float
        Rate that sets the default times (default 83.3 Hz, the paper's 12 ms cycle).
    """

    def __init__(self, profiles, t_s=None, rate_hz: float = _DEFAULT_RATE_HZ):
        arr = np.asarray(profiles, dtype=np.float64)
        if arr.ndim != 3 or arr.shape[2] != 2 or arr.shape[0] == 0:
            raise ProfileError(f"profile source: expected profiles of shape (K, N, 2) with K >= 1, got {arr.shape}")
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ConfigError(f"profile source: rate_hz must be > 0, got {rate_hz!r}")
        if t_s is None:
            t = np.arange(arr.shape[0]) / rate_hz
        else:
            t = np.asarray(t_s, dtype=np.float64).reshape(-1)
            if t.shape != (arr.shape[0],) or not np.all(np.isfinite(t)) or np.any(np.diff(t) < 0):
                raise ProfileError(f"profile source: t_s must be {arr.shape[0]} finite, non-decreasing times in s")
        self.profiles = arr
        self.t_s = t

    def __len__(self) -> int:
        return self.profiles.shape[0]

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        for t, p in zip(self.t_s, self.profiles):
            yield float(t), p


class FileSource(ArraySource):
    """The profiles of a file (:func:`read_profile_file`); an ``.npz`` may add ``t_s`` (K,), s.

    Parameters
    ----------
    path : str or Path
    options : ReadOptions
    rate_hz : float
        Times ``k / rate_hz`` when the file holds none.
    """

    def __init__(self, path, options: ReadOptions = ReadOptions(), rate_hz: float = _DEFAULT_RATE_HZ):
        self.path = Path(path)
        profiles = read_profile_file(self.path, options)
        t_s = None
        if self.path.suffix.lower() == ".npz":
            t_s = load_npz_member(self.path, "t_s")
            if t_s is not None:
                t_s = np.asarray(t_s)
                if (not np.issubdtype(t_s.dtype, np.number) or t_s.shape != (profiles.shape[0],)
                        or not np.all(np.isfinite(t_s)) or np.any(np.diff(t_s) < 0)):
                    raise InputFileError(f"{self.path}: 't_s' must hold {profiles.shape[0]} finite, non-decreasing "
                                         f"times in s (one per profile), got shape {t_s.shape}")
        super().__init__(profiles, t_s, rate_hz)


class SimulatedSource:
    """Simulated profiles of a gauge at given sensor poses (:func:`~posekit.profiler.sim.render.render_profiles`).

    Parameters
    ----------
    gauge : Gauge
    Ts_G_F : array_like, shape (K, 4, 4)
        Sensor poses in G, mm (the truth).
    noise : NoiseModel
    rng : numpy.random.Generator or int or None
    rate_hz : float
        Times ``k / rate_hz``, s.
    model : ProfilerModel
    """

    def __init__(self, gauge: Gauge, Ts_G_F, noise: NoiseModel = NoiseModel(), rng=None,
                 rate_hz: float = _DEFAULT_RATE_HZ, model: ProfilerModel = LJ_X8400):
        Ts = np.asarray(Ts_G_F, dtype=np.float64)
        if Ts.ndim != 3 or Ts.shape[1:] != (4, 4):
            raise ConfigError(f"SimulatedSource: Ts_G_F must have shape (K, 4, 4), got {Ts.shape}")
        if not (math.isfinite(rate_hz) and rate_hz > 0):
            raise ConfigError(f"SimulatedSource: rate_hz must be > 0, got {rate_hz!r}")
        self.gauge, self.Ts_G_F, self.noise, self.model = gauge, Ts, noise, model
        self.rate_hz = float(rate_hz)
        self._rng = np.random.default_rng(rng)

    def __len__(self) -> int:
        return self.Ts_G_F.shape[0]

    def __iter__(self) -> Iterator[tuple[float, np.ndarray]]:
        for k, T in enumerate(self.Ts_G_F):
            yield k / self.rate_hz, render_profiles(self.gauge, T, self.noise, self._rng, self.model)
