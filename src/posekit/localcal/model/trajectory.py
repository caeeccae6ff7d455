"""A pose trajectory: the timed sequence of rigid poses that every localcal part exchanges.

The VO camera, the robot's kinematic TCP log and the simulator's motions are all a
:class:`Trajectory` (s, mm, 4x4 poses); the file formats that read and write it are in
:mod:`posekit.localcal.registration.formats`.
"""

from dataclasses import dataclass

import numpy as np

from posekit.errors import TrajectoryError

__all__ = ["Trajectory"]


@dataclass(frozen=True)
class Trajectory:
    """A timed sequence of rigid poses of one body.

    Attributes
    ----------
    t_s : ndarray, shape (N,)
        Timestamps, s, non-decreasing.
    T : ndarray, shape (N, 4, 4)
        Poses ``T_world_body``: the body frame expressed in the trajectory's world frame, mm.
    """

    t_s: np.ndarray
    T: np.ndarray

    def __post_init__(self):
        t = np.asarray(self.t_s, dtype=np.float64)
        T = np.asarray(self.T, dtype=np.float64)
        if t.ndim != 1 or T.shape != (t.size, 4, 4):
            raise TrajectoryError(f"a trajectory needs t_s of shape (N,) and T of shape (N, 4, 4), "
                                  f"got {t.shape} and {T.shape}")
        if not (np.isfinite(t).all() and np.isfinite(T).all()):
            raise TrajectoryError("a trajectory must be finite: found NaN or infinite timestamps or poses")
        if t.size > 1 and np.any(np.diff(t) < 0):
            k = int(np.flatnonzero(np.diff(t) < 0)[0]) + 1
            raise TrajectoryError(f"trajectory timestamps must not decrease: pose {k} has "
                                  f"t={t[k]:.6f} s after t={t[k - 1]:.6f} s")
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "T", T)

    def __len__(self) -> int:
        return self.t_s.size

    @property
    def positions(self) -> np.ndarray:
        """Body origins in the world frame, shape (N, 3), mm."""
        return self.T[:, :3, 3]

    @property
    def rotations(self) -> np.ndarray:
        """Body orientations ``R_world_body``, shape (N, 3, 3)."""
        return self.T[:, :3, :3]
