"""The integrity monitor's offset test: is the robot's kinematic error still what the profile was fitted on?

Along the axes the lasers see, the filter's estimate settles at some offset from the kinematic pose
``Fk(q + Cj(τ))``: the robot's own unmodelled error (a deflection the compliance model lacks, its geometry). The
profile's spread along the axes the lasers barely see (the roll about the travel) rests on that error being what
it was on the training episodes. An encoder offset, or a tool or mount that moved after the profile was fitted,
changes it: the lasers pull the estimate to another offset along the axes they see, while along the others the
estimate follows the kinematics and their new error.

The test averages the step's offset (:func:`kinematic_offset`, tool frame, mm and rad) over the monitor's long
window (:func:`offset_means`) and compares each axis with the profile's ``offset`` block (``seam tune`` measures
it on the training episodes: :mod:`posekit.seam.frontend.tune_offset`): beyond ``mean ± L · sd``, with ``L`` a
Student t prediction bound on the few independent windows the spread rests on (:func:`offset_limits`, at the
monitor's ``alpha_degraded`` split over six axes and two signs), the step is ``degraded`` and the reason names the
axis and both offsets.
"""

import math

import numpy as np

from posekit._student_t import t_isf
from posekit.seam.engine import _kernels as _k
from posekit.seam.engine.window_sum import WindowSum

__all__ = ["OFFSET_AXES", "OffsetTest", "kinematic_offset", "offset_limits", "offset_means"]

#: The offset test's axes as a reason names them, with the unit its values are printed in and that unit per mm
#: or rad.
OFFSET_AXES = (("x", "mm", 1.0), ("y", "mm", 1.0), ("z", "mm", 1.0), ("rx", "deg", math.degrees(1.0)),
               ("ry", "deg", math.degrees(1.0)), ("rz", "deg", math.degrees(1.0)))


def kinematic_offset(T_est: np.ndarray, T_kin: np.ndarray) -> np.ndarray:
    """The estimate's offset from the kinematic pose, in the kinematic tool frame.

    Parameters
    ----------
    T_est, T_kin : ndarray, shape (..., 4, 4)
        Estimated and kinematic (``Fk(q + Cj(τ))``) tool poses ``T_base_tool``, mm.

    Returns
    -------
    ndarray, shape (..., 6)
        ``R_kinᵀ (p_est - p_kin)`` (mm) and the rotation vector of ``R_kinᵀ R_est`` (rad); NaN where either pose
        is not finite.
    """
    T = np.ascontiguousarray(T_est, dtype=np.float64)
    K = np.ascontiguousarray(T_kin, dtype=np.float64)
    if T.shape != K.shape:
        T, K = (np.ascontiguousarray(x) for x in np.broadcast_arrays(T, K))
    shape = T.shape[:-2]
    T, K = T.reshape(-1, 4, 4), K.reshape(-1, 4, 4)
    out = np.empty((T.shape[0], 6))
    _k.relative_offset_kernel(T, K, out)          # compiled: ~1 µs a pose (NumPy's einsums took ~80 for one)
    out[~(np.isfinite(T).all(axis=(1, 2)) & np.isfinite(K).all(axis=(1, 2)))] = np.nan
    return out.reshape(shape + (6,))


def offset_means(offsets: np.ndarray, window_long: int, window: int) -> np.ndarray:
    """The offset test's statistic at every step of an episode, as the monitor computes it.

    Parameters
    ----------
    offsets : ndarray, shape (T, 6)
        Each step's :func:`kinematic_offset` (a row with a NaN: not counted).
    window_long : int
        Steps averaged over (the monitor's long window).
    window : int
        The short window: while the long one holds ``window`` or fewer counted steps it is not tested (NaN).

    Returns
    -------
    ndarray, shape (T, 6)
        At step ``t`` the mean of the counted offsets of steps ``t - window_long + 1 .. t``.
    """
    X = np.asarray(offsets, dtype=np.float64).reshape(-1, 6)
    seen = np.isfinite(X).all(axis=1)
    c = np.concatenate([np.zeros((1, 6)), np.cumsum(np.where(seen[:, None], X, 0.0), axis=0)])
    k = np.concatenate([[0], np.cumsum(seen)])
    t = np.arange(len(X))
    lo = np.maximum(0, t - max(1, int(window_long)) + 1)
    n = k[t + 1] - k[lo]
    with np.errstate(divide="ignore", invalid="ignore"):
        m = (c[t + 1] - c[lo]) / n[:, None]
    m[n <= int(window)] = np.nan
    return m


def offset_limits(samples, alpha: float) -> np.ndarray:
    """``(6,)``: per axis the offset test's limit in units of the spread of the training windows' means: the
    Student t prediction bound ``t_{n-1}(α / 12) √(1 + 1/n)`` for a new window, with ``n`` the effective number
    of independent windows the spread was estimated from (``α`` split over six axes and two signs); ``inf``
    where ``n`` is below 2 (no test)."""
    n = np.asarray(samples, dtype=np.float64).reshape(-1)
    return np.array([t_isf(alpha / 12.0, v - 1.0) * math.sqrt(1.0 + 1.0 / v) if v >= 2.0 else math.inf
                     for v in n])


class OffsetTest:
    """The offset test's window and verdict, one per integrity monitor.

    Parameters
    ----------
    mean, sd, samples : array_like, shape (6,)
        Per tool axis (mm, rad) the mean of :func:`offset_means` on the profile's training episodes, the spread of
        those window means, and the effective number of independent windows that spread rests on (``seam tune``).
    window_long : int
        Steps averaged over (the monitor's long window).
    window : int
        The monitor's short window: a long window of ``window`` or fewer counted steps is not tested.
    alpha : float
        The monitor's ``alpha_degraded``.
    """

    def __init__(self, mean, sd, samples, window_long: int, window: int, alpha: float):
        self.window_long = max(1, int(window_long))
        self.window = int(window)
        self.mean = np.asarray(mean, dtype=np.float64).reshape(6)
        self.sd = np.asarray(sd, dtype=np.float64).reshape(6)
        self.limit = np.where(self.sd > 0.0, offset_limits(samples, alpha), np.inf)
        self._win = WindowSum(self.window_long)   # the long window's offsets (a step without one: not seen)

    @property
    def active(self) -> bool:
        """Whether some axis can fail (a finite limit)."""
        return bool(np.isfinite(self.limit).any())

    def reset(self) -> None:
        """Forget the window (a new episode)."""
        self._win.clear()

    def add(self, offset) -> None:
        """Put one step's :func:`kinematic_offset` into the window (None or a NaN: a step without one)."""
        row = np.full(6, np.nan) if offset is None else np.asarray(offset, dtype=np.float64).reshape(6)
        self._win.add(row, np.full(6, bool(np.isfinite(row).all())))

    def test(self) -> str | None:
        """The reason the test fails (None: it passes, or the window is still too short)."""
        n = 0 if self._win.n is None else int(self._win.n[0])
        if n <= self.window:
            return None
        m = self._win.sum / n
        with np.errstate(divide="ignore", invalid="ignore"):
            ratio = np.where(self.sd > 0.0, np.abs(m - self.mean) / self.sd / self.limit, 0.0)
        a = int(np.argmax(ratio))
        if not ratio[a] > 1.0:
            return None
        name, unit, k = OFFSET_AXES[a]
        return (f"the estimate's offset from the kinematic pose along {name} over the last {n} steps "
                f"{m[a] * k:.3g} {unit}, the profile's episodes {self.mean[a] * k:.3g} ± {self.sd[a] * k:.2g} {unit} "
                f"(beyond {self.limit[a]:.3g}σ): the kinematics err otherwise than when the profile was fitted (an "
                "encoder offset? a tool or mount that moved?)")
