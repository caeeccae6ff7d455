"""Serial chains in the standard Denavit–Hartenberg convention: forward kinematics, Jacobian.

Each row ``i`` (joint ``i``, 1-based in prose, 0-based in arrays) gives the link transform

``T_{i-1}_i = Rot_z(theta_i) · Trans_z(d_i) · Trans_x(a_i) · Rot_x(alpha_i)``

which is eq. (24) of the long-reach manipulator paper::

    [[cθ, -sθ cα,  sθ sα, a cθ],
     [sθ,  cθ cα, -cθ sα, a sθ],
     [ 0,     sα,     cα,    d],
     [ 0,      0,      0,    1]]

with ``theta_i = theta_offset_i + q_i`` for a revolute joint and ``d_i = d_offset_i + q_i``
for a prismatic joint. The flange pose is the product of the rows (eq. 23),
``T_base_flange = T_0_1 · T_1_2 ··· T_{n-1}_n``, and ``T_base_tool = T_base_flange · T_flange_tool``.
Frame 0 is the base frame. Lengths are mm, angles rad.

A DH table is not computed row by row: it becomes the kinematic pack every chain shares
(:mod:`posekit.robots._kernels`). Row i factors as ``J_i(q_i) · F_i`` with ``J_i`` the joint's
motion about (or along) ``z_{i-1}`` and ``F_i = Rot_z(θ_i) Trans_z(d_i) Trans_x(a_i) Rot_x(α_i)``
the row at zero joint value (``Trans_z(q)`` commutes with ``Rot_z(θ_i) Trans_z(d_i)``), so the
origin of joint i is ``F_{i-1}`` (the identity for the first joint), the axis is z, and the
flange is ``F_n`` after the last joint.
"""

from dataclasses import dataclass, field

import numpy as np

from posekit.errors import ConfigError

from .chain import (
    PRISMATIC,
    REVOLUTE,
    KinematicChain,
    as_vector,
    check_rigid,
    joint_types_and_names,
    limits,
)

__all__ = ["PRISMATIC", "REVOLUTE", "DHChain", "dh_row_transform"]


def dh_row_transform(a, alpha, d, theta) -> np.ndarray:
    """The standard DH transform of eq. (24) for rows at fixed values.

    Parameters
    ----------
    a, alpha, d, theta : array_like, shape (...)
        Link length (mm), twist (rad), offset (mm) and angle (rad) of each row.

    Returns
    -------
    T : ndarray, shape (..., 4, 4)
        ``Rot_z(θ) Trans_z(d) Trans_x(a) Rot_x(α)``, translation in mm.
    """
    a, alpha, d, theta = np.broadcast_arrays(*(np.asarray(v, dtype=np.float64) for v in (a, alpha, d, theta)))
    ct, st = np.cos(theta), np.sin(theta)
    ca, sa = np.cos(alpha), np.sin(alpha)
    T = np.zeros(a.shape + (4, 4))
    T[..., 0, 0], T[..., 0, 1], T[..., 0, 2], T[..., 0, 3] = ct, -st * ca, st * sa, a * ct
    T[..., 1, 0], T[..., 1, 1], T[..., 1, 2], T[..., 1, 3] = st, ct * ca, -ct * sa, a * st
    T[..., 2, 1], T[..., 2, 2], T[..., 2, 3] = sa, ca, d
    T[..., 3, 3] = 1.0
    return T


@dataclass(frozen=True, eq=False, repr=False)
class DHChain(KinematicChain):
    """A serial chain given by standard DH rows, joint types, joint limits and a tool.

    Parameters
    ----------
    a : array_like, shape (n,)
        Link lengths ``a_i`` along ``x_i``, in mm.
    alpha : array_like, shape (n,)
        Link twists ``alpha_i`` about ``x_i``, in rad.
    d : array_like, shape (n,)
        Link offsets ``d_i`` along ``z_{i-1}``, in mm (for a prismatic joint: the offset added
        to the joint variable).
    theta : array_like, shape (n,)
        Joint angle offsets ``theta_i`` about ``z_{i-1}``, in rad (for a revolute joint: the
        offset added to the joint variable).
    joint_types : sequence of str, length n
        ``"revolute"`` (joint variable in rad) or ``"prismatic"`` (joint variable in mm).
    q_min, q_max : array_like, shape (n,), optional
        Joint limits (rad or mm per joint); ``-inf``/``inf`` (the default) means unlimited.
    T_flange_tool : array_like, shape (4, 4), optional
        Tool (TCP) frame in the flange frame n, translation in mm; identity by default.
    name : str
        Name used in messages.
    joint_names : sequence of str, optional
        One name per joint; ``joint_1`` … by default.

    Raises
    ------
    ConfigError
        Rows of different lengths, non-finite DH values, an unknown joint type,
        ``q_min > q_max``, or a tool transform that is not a rigid transform.

    Examples
    --------
    >>> chain = DHChain(a=[300.0, 200.0], alpha=[0.0, 0.0], d=[0.0, 0.0], theta=[0.0, 0.0],
    ...                 joint_types=("revolute", "revolute"), name="planar-2")
    >>> chain.forward_kinematics([0.0, np.pi / 2])[:3, 3].round(9) + 0.0  # elbow at 90 deg
    array([300., 200.,   0.])
    """

    a: np.ndarray
    alpha: np.ndarray
    d: np.ndarray
    theta: np.ndarray
    joint_types: tuple[str, ...]
    q_min: np.ndarray | None = None
    q_max: np.ndarray | None = None
    T_flange_tool: np.ndarray | None = None
    name: str = "chain"
    joint_names: tuple[str, ...] | None = None
    _M_tool: np.ndarray = field(init=False, repr=False)
    _M_flange: np.ndarray = field(init=False, repr=False)
    _A: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        set_ = object.__setattr__
        a = as_vector(self.a, f"{self.name}: a")
        n = a.shape[0]
        if n == 0:
            raise ConfigError(f"{self.name}: expected at least one DH row, got 0")
        if not np.all(np.isfinite(a)):
            raise ConfigError(f"{self.name}: a must be finite, got {a.tolist()}")
        set_(self, "a", a)
        for key in ("alpha", "d", "theta"):
            v = as_vector(getattr(self, key), f"{self.name}: {key}", n)
            if not np.all(np.isfinite(v)):
                raise ConfigError(f"{self.name}: {key} must be finite, got {v.tolist()}")
            set_(self, key, v)
        types, names = joint_types_and_names(self.joint_types, self.joint_names, n, self.name)
        set_(self, "joint_types", types)
        set_(self, "joint_names", names)
        lo, hi = limits(self.q_min, self.q_max, n, self.name)
        set_(self, "q_min", lo)
        set_(self, "q_max", hi)
        T_tool = np.eye(4) if self.T_flange_tool is None else check_rigid(self.T_flange_tool, f"{self.name}: T_flange_tool")
        set_(self, "T_flange_tool", T_tool)
        # the kinematic pack: origin of joint i = row i-1 at zero joint value, axis z
        F = dh_row_transform(self.a, self.alpha, self.d, self.theta)
        origins = np.concatenate([np.eye(4)[None], F[:-1]], axis=0)
        axes = np.tile([0.0, 0.0, 1.0], (n, 1))
        self._set_packs(origins, axes, np.array([t == PRISMATIC for t in types]), F[-1], T_tool)

    def perturbed(self, sigma_mm: float, sigma_rad: float, rng: np.random.Generator, name: str | None = None):
        """A copy with every DH parameter off by Gaussian noise: a simulated real robot.

        ``a`` and ``d`` get ``N(0, sigma_mm²)``, ``alpha`` and ``theta`` ``N(0, sigma_rad²)``,
        drawn in the order a, alpha, d, theta; the copy has no joint limits.

        Parameters
        ----------
        sigma_mm, sigma_rad : float
            Standard deviations, mm and rad.
        rng : numpy.random.Generator
        name : str, optional
            Name of the copy (default: the name plus ``" (true)"``).
        """
        n = self.n_joints
        return DHChain(
            self.a + sigma_mm * rng.standard_normal(n), self.alpha + sigma_rad * rng.standard_normal(n),
            self.d + sigma_mm * rng.standard_normal(n), self.theta + sigma_rad * rng.standard_normal(n),
            self.joint_types, None, None, self.T_flange_tool, name or self.name + " (true)", self.joint_names,
        )
