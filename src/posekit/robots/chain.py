"""Serial chains: one interface and one compiled kinematics for DH tables and URDF paths.

:class:`KinematicChain` holds everything a system needs from a robot — joint names, types and
limits, the tool, forward kinematics ``T_base_tool`` and the geometric Jacobian, single or
batched, validated or not — on top of the kinematic pack of :mod:`posekit.robots._kernels`.
:class:`SerialChain` is the general chain (a URDF path: fixed origin transform + joint axis per
joint); :class:`~posekit.robots.DHChain` builds the same pack from a DH table.

Conventions: mm and rad (mm for a prismatic joint's variable); ``T_a_b`` maps coordinates in
frame b into frame a; batches take leading axes, ``q`` of shape ``(..., n)``.
"""

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from posekit.errors import ConfigError
from posekit.geometry import matrix_from_rotation_vector

from . import _kernels as _k

__all__ = ["PRISMATIC", "REVOLUTE", "KinematicChain", "SerialChain"]

REVOLUTE = "revolute"
PRISMATIC = "prismatic"
JOINT_TYPES = (REVOLUTE, PRISMATIC)

#: Rotation blocks of given transforms must be orthonormal to this (max abs of RᵀR - I).
RIGID_TOL = 1e-6


def check_rigid(T, what: str) -> np.ndarray:
    """``T`` as a float64 (4, 4) rigid transform, or a ConfigError naming ``what``."""
    try:
        T = np.asarray(T, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{what}: expected a (4, 4) array of numbers, got {type(T).__name__}") from None
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ConfigError(f"{what}: expected a finite (4, 4) transform, got shape {T.shape}")
    R = T[:3, :3]
    if (np.max(np.abs(R.T @ R - np.eye(3))) > RIGID_TOL or np.linalg.det(R) <= 0
            or np.max(np.abs(T[3] - [0.0, 0.0, 0.0, 1.0])) > 1e-12):
        raise ConfigError(f"{what}: not a rigid transform (rotation block not orthonormal or last row not 0 0 0 1)")
    return T


def as_vector(x, name: str, n: int | None = None) -> np.ndarray:
    """Return ``x`` as a float64 1-D array (of length ``n``) or raise ConfigError."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(f"{name}: expected a sequence of numbers, got {type(x).__name__}") from None
    if a.ndim != 1 or (n is not None and a.shape[0] != n):
        want = f"({n},)" if n is not None else "(n,)"
        raise ConfigError(f"{name}: expected shape {want}, got shape {a.shape}")
    return a


def joint_types_and_names(types, names, n: int, name: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """Validated joint types (``"revolute"``/``"prismatic"``) and names (``joint_1`` … by default)."""
    types = tuple(types)
    if len(types) != n:
        raise ConfigError(f"{name}: expected {n} joint types, got {len(types)}")
    bad = [t for t in types if t not in JOINT_TYPES]
    if bad:
        raise ConfigError(f"{name}: unknown joint type {bad[0]!r}, expected one of {JOINT_TYPES}")
    names = tuple(f"joint_{i + 1}" for i in range(n)) if names is None else tuple(names)
    if len(names) != n:
        raise ConfigError(f"{name}: expected {n} joint names, got {len(names)}")
    return types, names


def limits(q_min, q_max, n: int, name: str) -> tuple[np.ndarray, np.ndarray]:
    """Validated joint limits ``(q_min, q_max)``, each (n,); None means unlimited."""
    lo = np.full(n, -np.inf) if q_min is None else as_vector(q_min, f"{name}: q_min", n)
    hi = np.full(n, np.inf) if q_max is None else as_vector(q_max, f"{name}: q_max", n)
    if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(lo > hi):
        raise ConfigError(f"{name}: expected q_min <= q_max, got q_min={lo.tolist()}, q_max={hi.tolist()}")
    return lo, hi


class KinematicChain:
    """The interface every chain offers (DH or URDF), on one compiled kinematics kernel.

    A subclass sets, in its constructor, ``_M_tool`` / ``_M_flange`` (n + 1, 4, 4) and ``_A``
    (n, 4), the kinematic packs with and without the tool (see :mod:`posekit.robots._kernels`),
    and the attributes ``name``, ``joint_types``, ``joint_names``, ``q_min``, ``q_max``,
    ``T_flange_tool``.
    """

    name: str
    joint_types: tuple[str, ...]
    joint_names: tuple[str, ...]
    q_min: np.ndarray
    q_max: np.ndarray
    T_flange_tool: np.ndarray

    # ------------------------------------------------------------------ basics
    @property
    def summary(self) -> str:
        """The chain in one line: ``name: base → tip, n joints (names)`` (what the CLI prints)."""
        base, tip = getattr(self, "base_link", "base"), getattr(self, "tip_link", "flange")
        names = ", ".join(self.joint_names)
        return f"{self.name}: {base} → {tip}, {self.n_joints} joints ({names})"

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.summary}>"

    @property
    def n_joints(self) -> int:
        """Number of joints ``n``."""
        return self._A.shape[0]

    @property
    def is_revolute(self) -> np.ndarray:
        """Boolean mask, shape (n,): True for revolute joints."""
        return self._A[:, 3] == 0.0

    @property
    def kinematic_pack(self) -> tuple[np.ndarray, np.ndarray]:
        """``(M (n + 1, 4, 4), A (n, 4))`` with the tool: the arrays a numba kernel passes to
        :func:`posekit.robots.fk_jacobian_into` (read-only)."""
        return self._M_tool, self._A

    def with_tool(self, T_flange_tool):
        """A copy of the chain with another tool ``T_flange_tool`` (4, 4), translation in mm."""
        return dataclasses.replace(self, T_flange_tool=T_flange_tool)

    def check_q(self, q, name: str = "q") -> np.ndarray:
        """Validate joint vectors and return them as float64.

        Parameters
        ----------
        q : array_like, shape (..., n)
            Joint variables (rad for revolute, mm for prismatic joints).

        Returns
        -------
        q : ndarray, shape (..., n)

        Raises
        ------
        ConfigError
            Wrong shape or non-finite values.
        """
        try:
            q = np.asarray(q, dtype=np.float64)
        except (TypeError, ValueError):
            raise ConfigError(f"{self.name}: {name} must be numeric, got {type(q).__name__}") from None
        n = self.n_joints
        if q.ndim < 1 or q.shape[-1] != n:
            raise ConfigError(
                f"{self.name}: {name} must have shape ({n},) or (..., {n}), got shape {q.shape}"
            )
        if not np.all(np.isfinite(q)):
            bad = np.argwhere(~np.isfinite(q))[0].tolist()
            raise ConfigError(f"{self.name}: {name} must be finite, found NaN or inf at index {bad}")
        return q

    def clamp(self, q) -> np.ndarray:
        """Clip joint vectors ``q`` (..., n) to ``[q_min, q_max]``."""
        return np.clip(q, self.q_min, self.q_max)

    def within_limits(self, q) -> np.ndarray:
        """True where every joint of ``q`` (..., n) lies within the limits; shape (...)."""
        q = np.asarray(q, dtype=np.float64)
        return np.all((q >= self.q_min) & (q <= self.q_max), axis=-1)

    # ------------------------------------------------------------------ kinematics
    def _q(self, q, check: bool) -> np.ndarray:
        if check:
            return self.check_q(q)
        if type(q) is not np.ndarray or q.dtype != np.float64:
            q = np.asarray(q, dtype=np.float64)
        return q

    def forward_kinematics(self, q, *, tool: bool = True, check: bool = True) -> np.ndarray:
        """Tool pose ``T_base_tool``, batched over the leading axes of ``q``.

        Parameters
        ----------
        q : array_like, shape (..., n)
            Joint variables (rad for revolute, mm for prismatic joints).
        tool : bool
            Apply ``T_flange_tool``; ``False`` returns the flange (tip link) pose.
        check : bool
            Validate ``q``; ``False`` is the unchecked hot path (``q`` must then be a finite
            float array of the right shape).

        Returns
        -------
        T_base_tool : ndarray, shape (..., 4, 4)
            Tool frame in the base frame, translation in mm.

        Raises
        ------
        ConfigError
            ``q`` has the wrong shape or non-finite values (with ``check``).
        """
        q = self._q(q, check)
        M = self._M_tool if tool else self._M_flange
        if q.ndim == 1:
            return _k.fk_single(q, M, self._A)
        Q = np.ascontiguousarray(q).reshape(-1, q.shape[-1])
        return _k.fk_batch(Q, M, self._A).reshape(q.shape[:-1] + (4, 4))

    def geometric_jacobian(self, q, *, check: bool = True) -> np.ndarray:
        """Geometric Jacobian of the tool frame, in the base frame.

        ``[v; ω] = J(q) q̇`` with ``v`` the velocity of the tool origin (mm/s) and ``ω`` the
        angular velocity of the tool frame (rad/s), both in the base frame. Column i is
        ``[w_i × (p_tool - o_i); w_i]`` for a revolute joint and ``[w_i; 0]`` for a prismatic
        joint (``w_i`` the joint axis through the point ``o_i``, base frame).

        Parameters
        ----------
        q : array_like, shape (..., n)
            Joint variables (rad / mm).
        check : bool
            Validate ``q``.

        Returns
        -------
        J : ndarray, shape (..., 6, n)
            Rows 0–2 linear (mm per rad, or mm per mm for prismatic joints), rows 3–5 angular
            (rad per rad, or 0 for prismatic joints).
        """
        return self.forward_kinematics_and_jacobian(q, check=check)[1]

    def forward_kinematics_and_jacobian(self, q, *, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """``(T_base_tool, J)`` in one pass of the kernel (see :meth:`forward_kinematics` and
        :meth:`geometric_jacobian`): shapes ``(..., 4, 4)`` and ``(..., 6, n)``."""
        q = self._q(q, check)
        if q.ndim == 1:
            return _k.fk_jacobian_single(q, self._M_tool, self._A)
        Q = np.ascontiguousarray(q).reshape(-1, q.shape[-1])
        T, J = _k.fk_jacobian_batch(Q, self._M_tool, self._A)
        return T.reshape(q.shape[:-1] + (4, 4)), J.reshape(q.shape[:-1] + J.shape[1:])

    def joint_axes(self, q, *, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Joint axes and a point on each, in the base frame.

        Parameters
        ----------
        q : array_like, shape (..., n)
            Joint variables (rad / mm).

        Returns
        -------
        axes : ndarray, shape (..., n, 3)
            Unit axis ``w_i`` of joint i (rotation axis or sliding direction), base frame.
        points : ndarray, shape (..., n, 3)
            A point ``o_i`` on that axis, base frame, mm.
        """
        q = self._q(q, check)
        Q = np.ascontiguousarray(q).reshape(-1, q.shape[-1])
        _, W = _k.joint_axes_batch(Q, self._M_tool, self._A)
        W = W.reshape(q.shape[:-1] + W.shape[1:])
        return W[..., :3], W[..., 3:]

    def _set_packs(self, origins: np.ndarray, axes: np.ndarray, prismatic: np.ndarray,
                   T_last_flange: np.ndarray, T_flange_tool: np.ndarray) -> None:
        """Build the read-only kinematic packs (frozen dataclasses call this in __post_init__)."""
        n = axes.shape[0]
        M = np.empty((n + 1, 4, 4))
        M[:n] = origins
        M[n] = T_last_flange
        M_tool = M.copy()
        M_tool[n] = T_last_flange @ T_flange_tool
        A = np.empty((n, 4))
        A[:, :3] = axes
        A[:, 3] = prismatic.astype(np.float64)
        for arr in (M, M_tool, A):
            arr.setflags(write=False)
        object.__setattr__(self, "_M_flange", M)
        object.__setattr__(self, "_M_tool", M_tool)
        object.__setattr__(self, "_A", A)


@dataclass(frozen=True, eq=False, repr=False)
class SerialChain(KinematicChain):
    """A serial chain given by a fixed origin transform and an axis per joint (a URDF path).

    ``T_base_flange(q) = O_0 J_0(q_0) O_1 J_1(q_1) ··· O_{n-1} J_{n-1}(q_{n-1}) T_last_flange``,
    ``J_i`` a rotation about (revolute) or a translation along (prismatic) ``axes[i]``.

    Parameters
    ----------
    origins : array_like, shape (n, 4, 4)
        ``O_i``: joint i's frame in the frame after joint i - 1 (the base for i = 0) at zero
        joint value, translation in mm (fixed joints between them folded in).
    axes : array_like, shape (n, 3)
        Joint axes in their joint frames (normalised here; a zero axis is an error).
    joint_types : sequence of str, length n
        ``"revolute"`` (rad) or ``"prismatic"`` (mm).
    T_last_flange : array_like, shape (4, 4), optional
        The tip link (flange) in the frame after the last joint, mm; identity by default.
    q_min, q_max : array_like, shape (n,), optional
        Joint limits (rad or mm); unlimited by default.
    T_flange_tool : array_like, shape (4, 4), optional
        Tool (TCP) in the flange frame, mm; identity by default.
    name : str
        Name used in messages.
    joint_names : sequence of str, optional
        One name per joint; ``joint_1`` … by default.
    base_link, tip_link : str
        Names of the base and tip frames (URDF links), for messages and plots.
    notes : tuple of str
        What a loader chose or assumed (how a default tip was found, limits read as
        unbounded); empty by default.

    Raises
    ------
    ConfigError
        Shapes that do not agree, non-finite values, a zero axis, an origin that is not a
        rigid transform, ``q_min > q_max``.
    """

    origins: np.ndarray
    axes: np.ndarray
    joint_types: tuple[str, ...]
    T_last_flange: np.ndarray | None = None
    q_min: np.ndarray | None = None
    q_max: np.ndarray | None = None
    T_flange_tool: np.ndarray | None = None
    name: str = "chain"
    joint_names: tuple[str, ...] | None = None
    base_link: str = "base"
    tip_link: str = "flange"
    notes: tuple[str, ...] = ()
    _M_tool: np.ndarray = field(init=False, repr=False)
    _M_flange: np.ndarray = field(init=False, repr=False)
    _A: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        set_ = object.__setattr__
        try:
            origins = np.asarray(self.origins, dtype=np.float64)
            ax = np.asarray(self.axes, dtype=np.float64)
        except (TypeError, ValueError):
            raise ConfigError(f"{self.name}: origins and axes must be numeric arrays") from None
        if origins.ndim != 3 or origins.shape[1:] != (4, 4) or origins.shape[0] == 0:
            raise ConfigError(f"{self.name}: origins: expected shape (n, 4, 4) with n >= 1, got {origins.shape}")
        n = origins.shape[0]
        if ax.shape != (n, 3):
            raise ConfigError(f"{self.name}: axes: expected shape ({n}, 3), got {ax.shape}")
        types, names = joint_types_and_names(self.joint_types, self.joint_names, n, self.name)
        for i in range(n):
            check_rigid(origins[i], f"{self.name}: joint '{names[i]}' origin")
        if not np.all(np.isfinite(ax)):
            raise ConfigError(f"{self.name}: axes must be finite, got {ax.tolist()}")
        norm = np.linalg.norm(ax, axis=1)
        if np.any(norm < 1e-12):
            i = int(np.argmax(norm < 1e-12))
            raise ConfigError(f"{self.name}: joint '{names[i]}' has a zero axis; expected a non-zero direction")
        ax = ax / norm[:, None]
        T_last = np.eye(4) if self.T_last_flange is None else check_rigid(self.T_last_flange, f"{self.name}: T_last_flange")
        T_tool = np.eye(4) if self.T_flange_tool is None else check_rigid(self.T_flange_tool, f"{self.name}: T_flange_tool")
        lo, hi = limits(self.q_min, self.q_max, n, self.name)
        for key, value in (("origins", origins), ("axes", ax), ("joint_types", types), ("joint_names", names),
                           ("T_last_flange", T_last), ("T_flange_tool", T_tool), ("q_min", lo), ("q_max", hi)):
            set_(self, key, value)
        self._set_packs(origins, ax, np.array([t == PRISMATIC for t in types]), T_last, T_tool)

    def perturbed(self, sigma_mm: float, sigma_rad: float, rng: np.random.Generator, name: str | None = None):
        """A copy whose joint origins (and flange) are off by random rigid offsets.

        Each of the n origins and ``T_last_flange`` is composed with an offset of translation
        ``N(0, sigma_mm² I)`` and rotation vector ``N(0, sigma_rad² I)``: a simulated real robot
        whose geometry differs from its model.

        Parameters
        ----------
        sigma_mm, sigma_rad : float
            Standard deviations per component, mm and rad.
        rng : numpy.random.Generator
        name : str, optional
            Name of the copy (default: the name plus ``" (true)"``).
        """
        fixed = np.concatenate([self.origins, self.T_last_flange[None]], axis=0)
        dt = sigma_mm * rng.standard_normal((fixed.shape[0], 3))
        dr = sigma_rad * rng.standard_normal((fixed.shape[0], 3))
        out = fixed.copy()
        for i in range(fixed.shape[0]):
            E = np.eye(4)
            E[:3, :3] = matrix_from_rotation_vector(dr[i])
            E[:3, 3] = dt[i]
            out[i] = fixed[i] @ E
        return dataclasses.replace(self, origins=out[:-1], T_last_flange=out[-1],
                                   name=name or self.name + " (true)")
