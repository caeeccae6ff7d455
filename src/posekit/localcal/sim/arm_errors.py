"""The non-kinematic errors of the simulated long-reach arm (joint offsets, backlash, bending,
boom vibration; their physics in :mod:`posekit.localcal.sim.arm`) and a seeded sampler of a
HIAB033-sized crane's errors. rad, rad per metre of lever arm, Hz.
"""

from dataclasses import dataclass

import numpy as np

from posekit.errors import ConfigError

__all__ = ["NonKinematicErrors", "sample_nonkinematic_errors"]


def _vector(value, name: str, n: int) -> np.ndarray:
    try:
        a = np.broadcast_to(np.asarray(value, dtype=np.float64), (n,)).copy()
    except (TypeError, ValueError):
        raise ConfigError(
            f"{name}: expected a number or {n} numbers, got {value!r}"
        ) from None
    if not np.all(np.isfinite(a)):
        raise ConfigError(f"{name}: expected finite values, got {a.tolist()}")
    return a


@dataclass(frozen=True)
class NonKinematicErrors:
    """The true arm's deviations from its nominal DH model (joint offsets, backlash, bending, boom vibration: see :mod:`posekit.localcal.sim.arm`).

    Parameters
    ----------
    joint_offsets_rad : array_like, shape (n,)
        Encoder zero errors: true link angle = actuator angle + offset, rad.
    backlash_rad : array_like, shape (n,)
        Full width of each joint's dead band, rad, >= 0.
    bending_rad_per_m : array_like, shape (len(bending_joints),)
        Compliance of the bending joints: droop angle in rad per metre of TCP lever arm, >= 0.
    bending_joints : tuple of int
        Joint indices (0-based) that droop; (1, 2) = lift and tilt of the HIAB033 model.
    flex_hz : float
        Natural frequency of the boom vibration of the bending joints, Hz (0: rigid booms).
    flex_damping : float
        Its damping ratio ζ, in (0, 1].
    flex_gain : float
        Its participation ``g`` (>= 0): the deflection per unit joint acceleration is ``g / ω²``.
    """

    joint_offsets_rad: np.ndarray
    backlash_rad: np.ndarray
    bending_rad_per_m: np.ndarray
    bending_joints: tuple[int, ...] = (1, 2)
    flex_hz: float = 0.0
    flex_damping: float = 0.1
    flex_gain: float = 1.0

    def __post_init__(self):
        set_ = object.__setattr__
        off = np.asarray(self.joint_offsets_rad, dtype=np.float64)
        n = off.shape[0] if off.ndim == 1 else -1
        if n < 1 or not np.all(np.isfinite(off)):
            raise ConfigError(
                f"joint_offsets_rad: expected finite values of shape (n,), got {off.tolist()}"
            )
        back = np.asarray(self.backlash_rad, dtype=np.float64)
        if back.shape != (n,) or not np.all(np.isfinite(back)) or np.any(back < 0):
            raise ConfigError(
                f"backlash_rad: expected {n} finite values >= 0, got {back.tolist()}"
            )
        joints = tuple(int(j) for j in self.bending_joints)
        if any(j < 0 or j >= n for j in joints):
            raise ConfigError(
                f"bending_joints: expected joint indices in [0, {n - 1}], got {list(joints)}"
            )
        bend = np.asarray(self.bending_rad_per_m, dtype=np.float64)
        if bend.shape != (len(joints),) or not np.all(np.isfinite(bend)) or np.any(bend < 0):
            raise ConfigError(
                f"bending_rad_per_m: expected {len(joints)} finite values >= 0, got {bend.tolist()}"
            )
        for name, lo, hi in (("flex_hz", 0.0, 100.0), ("flex_damping", 1e-6, 1.0), ("flex_gain", 0.0, 100.0)):
            v = getattr(self, name)
            if not (np.ndim(v) == 0 and np.isfinite(v) and lo <= v <= hi):
                raise ConfigError(f"{name}: expected a number in {lo:g}..{hi:g}, got {v!r}")
            set_(self, name, float(v))
        set_(self, "joint_offsets_rad", off)
        set_(self, "backlash_rad", back)
        set_(self, "bending_rad_per_m", bend)
        set_(self, "bending_joints", joints)

    @property
    def n_joints(self) -> int:
        """Number of joints ``n``."""
        return self.joint_offsets_rad.shape[0]

    @classmethod
    def none(cls, n_joints: int = 6) -> "NonKinematicErrors":
        """No errors: the true arm equals the nominal model (except for encoder noise)."""
        return cls(np.zeros(n_joints), np.zeros(n_joints), np.zeros(2))


def sample_nonkinematic_errors(rng=None, scale: float = 1.0, n_joints: int = 6) -> NonKinematicErrors:
    """Draw plausible non-kinematic errors for the HIAB033-like crane.

    Sized so that the nominal model mis-predicts the true TCP position by ~2–6 cm at typical
    poses (``scale=1``): joint offsets N(0, 1.5 mrad) on the booms and slewing joint and
    N(0, 2 mrad) on the wrist; backlash widths U(1, 3) mrad on the booms and slewing joint,
    U(0.5, 1.5) mrad on the wrist; droop compliance U(0.8, 1.4) mrad/m on the lift joint and
    U(1.0, 1.8) mrad/m on the tilt joint (≈ 4 + 4 mrad of droop at ~4.5 m / ~2.5 m lever
    arms, i.e. ~2–3 cm at the tip); boom vibration at U(1.0, 2.0) Hz with U(5, 12) % damping
    (participation ``scale``; none when ``scale = 0``).

    Parameters
    ----------
    rng : numpy.random.Generator or int or None
        Random source or seed.
    scale : float
        Multiplies every error (>= 0); 0 gives no errors.
    n_joints : int
        Number of joints (>= 3; the first three are the slewing, lift and tilt joints).

    Returns
    -------
    NonKinematicErrors
    """
    if not (np.ndim(scale) == 0 and np.isfinite(scale) and scale >= 0):
        raise ConfigError(f"scale must be a finite number >= 0, got {scale!r}")
    if int(n_joints) != n_joints or n_joints < 3:
        raise ConfigError(f"n_joints must be an integer >= 3, got {n_joints!r}")
    rng = np.random.default_rng(rng)
    n = int(n_joints)
    big = np.arange(n) < 3
    offsets = rng.normal(0.0, np.where(big, 1.5e-3, 2.0e-3))
    backlash = np.where(big, rng.uniform(1.0e-3, 3.0e-3, n), rng.uniform(0.5e-3, 1.5e-3, n))
    bending = np.array([rng.uniform(0.8e-3, 1.4e-3), rng.uniform(1.0e-3, 1.8e-3)])
    flex_hz, flex_damping = rng.uniform(1.0, 2.0), rng.uniform(0.05, 0.12)   # drawn last: earlier draws unchanged
    return NonKinematicErrors(scale * offsets, scale * backlash, scale * bending,
                              flex_hz=flex_hz if scale > 0 else 0.0, flex_damping=flex_damping,
                              flex_gain=float(scale))
