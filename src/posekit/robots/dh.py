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
"""

from dataclasses import dataclass, field

import numpy as np

from posekit.errors import ConfigError

__all__ = ["PRISMATIC", "REVOLUTE", "DHChain"]

REVOLUTE = "revolute"
PRISMATIC = "prismatic"
_JOINT_TYPES = (REVOLUTE, PRISMATIC)


def _as_vector(x, name: str, n: int | None = None) -> np.ndarray:
    """Return ``x`` as a float64 1-D array (of length ``n``) or raise ConfigError."""
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise ConfigError(
            f"{name}: expected a sequence of numbers, got {type(x).__name__}"
        ) from None
    if a.ndim != 1 or (n is not None and a.shape[0] != n):
        want = f"({n},)" if n is not None else "(n,)"
        raise ConfigError(f"{name}: expected shape {want}, got shape {a.shape}")
    return a


@dataclass(frozen=True, eq=False)
class DHChain:
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

    Raises
    ------
    ConfigError
        Rows of different lengths, non-finite DH values, an unknown joint type,
        ``q_min > q_max``, or a tool transform that is not a rigid transform.
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
    _revolute: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        set_ = object.__setattr__
        a = _as_vector(self.a, f"{self.name}: a")
        n = a.shape[0]
        if n == 0:
            raise ConfigError(f"{self.name}: expected at least one DH row, got 0")
        set_(self, "a", a)
        for key in ("alpha", "d", "theta"):
            v = _as_vector(getattr(self, key), f"{self.name}: {key}", n)
            if not np.all(np.isfinite(v)):
                raise ConfigError(
                    f"{self.name}: {key} must be finite, got {v.tolist()}"
                )
            set_(self, key, v)
        if not np.all(np.isfinite(a)):
            raise ConfigError(f"{self.name}: a must be finite, got {a.tolist()}")
        types = tuple(self.joint_types)
        if len(types) != n:
            raise ConfigError(
                f"{self.name}: expected {n} joint types, got {len(types)}"
            )
        bad = [t for t in types if t not in _JOINT_TYPES]
        if bad:
            raise ConfigError(
                f"{self.name}: unknown joint type {bad[0]!r}, expected one of {_JOINT_TYPES}"
            )
        set_(self, "joint_types", types)
        set_(self, "_revolute", np.array([t == REVOLUTE for t in types]))
        lo = (
            np.full(n, -np.inf)
            if self.q_min is None
            else _as_vector(self.q_min, f"{self.name}: q_min", n)
        )
        hi = (
            np.full(n, np.inf)
            if self.q_max is None
            else _as_vector(self.q_max, f"{self.name}: q_max", n)
        )
        if np.any(np.isnan(lo)) or np.any(np.isnan(hi)) or np.any(lo > hi):
            raise ConfigError(
                f"{self.name}: expected q_min <= q_max, got q_min={lo.tolist()}, q_max={hi.tolist()}"
            )
        set_(self, "q_min", lo)
        set_(self, "q_max", hi)
        T = (
            np.eye(4)
            if self.T_flange_tool is None
            else np.asarray(self.T_flange_tool, dtype=np.float64)
        )
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise ConfigError(
                f"{self.name}: T_flange_tool must be a finite (4, 4) array, got shape {T.shape}"
            )
        R = T[:3, :3]
        if (
            np.max(np.abs(R.T @ R - np.eye(3))) > 1e-6
            or np.linalg.det(R) <= 0
            or np.max(np.abs(T[3] - [0, 0, 0, 1])) > 1e-12
        ):
            raise ConfigError(f"{self.name}: T_flange_tool is not a rigid transform")
        set_(self, "T_flange_tool", T)

    # ------------------------------------------------------------------ basics
    @property
    def n_joints(self) -> int:
        """Number of joints ``n``."""
        return self.a.shape[0]

    @property
    def is_revolute(self) -> np.ndarray:
        """Boolean mask, shape (n,): True for revolute joints."""
        return self._revolute.copy()

    def with_tool(self, T_flange_tool) -> "DHChain":
        """A copy of the chain with another tool ``T_flange_tool`` (4, 4), translation in mm."""
        return DHChain(
            self.a,
            self.alpha,
            self.d,
            self.theta,
            self.joint_types,
            self.q_min,
            self.q_max,
            T_flange_tool,
            self.name,
        )

    def check_q(self, q, name: str = "q") -> np.ndarray:
        """Validate joint vectors and return them as float64.

        Parameters
        ----------
        q : array_like, shape (n,) or (N, n)
            Joint variables (rad for revolute, mm for prismatic joints).

        Returns
        -------
        q : ndarray, shape (n,) or (N, n)

        Raises
        ------
        ConfigError
            Wrong shape or non-finite values.
        """
        try:
            q = np.asarray(q, dtype=np.float64)
        except (TypeError, ValueError):
            raise ConfigError(
                f"{self.name}: {name} must be numeric, got {type(q).__name__}"
            ) from None
        n = self.n_joints
        if q.ndim not in (1, 2) or q.shape[-1] != n:
            raise ConfigError(
                f"{self.name}: {name} must have shape ({n},) or (N, {n}), got shape {q.shape}"
            )
        if not np.all(np.isfinite(q)):
            bad = np.argwhere(~np.isfinite(q))[0].tolist()
            raise ConfigError(
                f"{self.name}: {name} must be finite, found NaN or inf at index {bad}"
            )
        return q

    def clamp(self, q) -> np.ndarray:
        """Clip joint vectors ``q`` (..., n) to ``[q_min, q_max]``."""
        return np.clip(q, self.q_min, self.q_max)

    def within_limits(self, q) -> np.ndarray:
        """True where every joint of ``q`` (..., n) lies within the limits; shape (...)."""
        q = np.asarray(q, dtype=np.float64)
        return np.all((q >= self.q_min) & (q <= self.q_max), axis=-1)

    # ------------------------------------------------------------------ kinematics
    def link_transforms(self, q, *, check: bool = True) -> np.ndarray:
        """Per-row DH transforms ``T_{i-1}_i`` (eq. 24).

        Parameters
        ----------
        q : array_like, shape (..., n)
            Joint variables (rad / mm).
        check : bool
            Validate ``q`` (shape (n,) or (N, n), finite); ``False`` is the unchecked hot path.

        Returns
        -------
        T : ndarray, shape (..., n, 4, 4)
            ``T[..., i]`` maps frame i+1 into frame i, translation in mm.
        """
        q = self.check_q(q) if check else np.asarray(q, dtype=np.float64)
        theta = self.theta + np.where(self._revolute, q, 0.0)
        d = self.d + np.where(self._revolute, 0.0, q)
        ct, st = np.cos(theta), np.sin(theta)
        ca, sa = np.cos(self.alpha), np.sin(self.alpha)
        ca, sa, a = (np.broadcast_to(v, theta.shape) for v in (ca, sa, self.a))
        T = np.zeros(theta.shape + (4, 4))
        T[..., 0, 0] = ct
        T[..., 0, 1] = -st * ca
        T[..., 0, 2] = st * sa
        T[..., 0, 3] = a * ct
        T[..., 1, 0] = st
        T[..., 1, 1] = ct * ca
        T[..., 1, 2] = -ct * sa
        T[..., 1, 3] = a * st
        T[..., 2, 1] = sa
        T[..., 2, 2] = ca
        T[..., 2, 3] = d
        T[..., 3, 3] = 1.0
        return T

    def link_frames(self, q, *, check: bool = True) -> np.ndarray:
        """All link frames in the base frame, ``T_base_i`` for i = 0..n (no tool).

        Parameters
        ----------
        q : array_like, shape (..., n)
            Joint variables (rad / mm).

        Returns
        -------
        Ts_base_link : ndarray, shape (..., n + 1, 4, 4)
            ``[..., 0]`` is the identity (base frame 0), ``[..., n]`` is the flange frame n;
            translations in mm.
        """
        A = self.link_transforms(q, check=check)
        n = self.n_joints
        out = np.empty(A.shape[:-3] + (n + 1, 4, 4))
        out[..., 0, :, :] = np.eye(4)
        # Loop over the n joints (a handful), never over the batch axis.
        for i in range(n):
            out[..., i + 1, :, :] = out[..., i, :, :] @ A[..., i, :, :]
        return out

    def forward_kinematics(
        self, q, *, all_frames: bool = False, tool: bool = True, check: bool = True
    ) -> np.ndarray:
        """Tool pose ``T_base_tool`` (eq. 23), batched over a leading axis of ``q``.

        Parameters
        ----------
        q : array_like, shape (n,) or (N, n)
            Joint variables (rad for revolute, mm for prismatic joints).
        all_frames : bool
            Also return every link frame ``T_base_i``, i = 0..n (see :meth:`link_frames`).
        tool : bool
            Apply ``T_flange_tool``; ``False`` returns the flange pose ``T_base_flange``.
        check : bool
            Validate ``q``; ``False`` skips validation (hot path).

        Returns
        -------
        T_base_tool : ndarray, shape (4, 4) or (N, 4, 4)
            Tool frame in the base frame, translation in mm.
        Ts_base_link : ndarray, shape (n + 1, 4, 4) or (N, n + 1, 4, 4)
            Only with ``all_frames=True``: the link frames in the base frame.

        Raises
        ------
        ConfigError
            ``q`` has the wrong length or non-finite values.
        """
        frames = self.link_frames(q, check=check)
        T = frames[..., -1, :, :]
        if tool:
            T = T @ self.T_flange_tool
        return (T, frames) if all_frames else T

    def geometric_jacobian(self, q, *, check: bool = True) -> np.ndarray:
        """Geometric Jacobian of the tool frame, expressed in the base frame.

        ``[v; ω] = J(q) q̇`` with ``v`` the velocity of the tool origin (mm/s) and ``ω`` the
        angular velocity of the tool frame (rad/s), both in the base frame. Column i is
        ``[z_{i-1} × (p_tool - o_{i-1}); z_{i-1}]`` for a revolute joint and ``[z_{i-1}; 0]``
        for a prismatic joint.

        Parameters
        ----------
        q : array_like, shape (n,) or (N, n)
            Joint variables (rad / mm).
        check : bool
            Validate ``q``.

        Returns
        -------
        J : ndarray, shape (6, n) or (N, 6, n)
            Rows 0–2 linear (mm per rad, or unitless for prismatic joints), rows 3–5 angular
            (rad per rad, or rad per mm = 0 for prismatic joints).
        """
        T, frames = self.forward_kinematics(q, all_frames=True, check=check)
        z = frames[..., :-1, :3, 2]  # (..., n, 3) joint axes z_{i-1}
        o = frames[..., :-1, :3, 3]  # (..., n, 3) joint origins o_{i-1}
        p = T[..., None, :3, 3]
        rev = self._revolute[:, None]
        lin = np.where(rev, np.cross(z, p - o), z)
        ang = np.where(rev, z, 0.0)
        return np.concatenate([lin, ang], axis=-1).swapaxes(-1, -2)
