"""Simulated heavy-duty long-reach (hydraulic) manipulator with non-kinematic errors.

The controller knows only the **nominal** rigid-body DH model (``posekit.robots.hiab033()``
by default). The simulated "true" arm differs from it the way the paper says long-reach
hydraulic cranes do (Sec. 1, ref. [9]):

joint offsets
    The encoder zero of joint i is off by ``joint_offsets_rad[i]``: the true link angle is
    the actuator angle plus this offset.
backlash
    The link follows the actuator through a dead band of full width ``backlash_rad[i]``
    (play operator): on reversal the link stays put until the play is taken up, so the
    error depends on the direction of the last motion.
bending
    Link droop under gravity and payload: the lift and tilt joints (``bending_joints``,
    by default indices 1 and 2) get an extra rotation about their own axes
    ``δ_i = c_i · τ_i / 1000``, where ``τ_i = z_i · ((p_TCP - o_i) × (-e_z))`` is the lever
    arm (mm) of a unit load at the TCP about joint axis i in the base frame (``e_z`` up) and
    ``c_i = bending_rad_per_m[i]`` the compliance in rad per metre of lever arm. The droop is
    therefore largest with the booms stretched out horizontally and vanishes with the load
    straight above/below the joint.
boom vibration
    A long hydraulic boom is a lightly damped spring: each bending joint gets a further
    deflection ``δ`` obeying ``δ̈ + 2ζω δ̇ + ω² δ = -g α`` with ``α`` that joint's angular
    acceleration (``flex_hz = ω / 2π``, ``flex_damping = ζ``, ``flex_gain = g``): accelerating
    a boom bends it back, and it rings on after the move (~1–2 Hz, a few % damping for a crane
    of this size — an assumption). The encoders do not see it; the camera and VO do.

Motion (eq. 4–6, 25): a move is a quintic point-to-point Cartesian path (position and
orientation about a fixed axis) sampled every ``dt_s``; resolved-rate control on the nominal
model integrates the commanded joints ``q_d``; a joint P servo ``u = K_v (q_d - q_meas)``
drives first-order-lag (PT-1) hydraulic joints ``τ v̇ + v = u``, ``q̇ = v`` with a velocity
limit. The loop is closed only at the joints (open loop in Cartesian space, as in the paper),
so after a move the *nominal* pose at the encoder readings reaches the reference to ~1 mm
while the *true* tool is off by centimetres.

Frames: B robot base, F the TCP frame at the end of the DH chain. mm and rad.
"""

from dataclasses import KW_ONLY, dataclass, field
from typing import NamedTuple

import numpy as np

from posekit.errors import ConfigError, GeometryError
from posekit.geometry import check_transform, matrix_from_rotation_vector, rotation_vector_from_matrix
from posekit.localcal.sim._arm_kernel import simulate_moves
from posekit.localcal.sim.arm_errors import NonKinematicErrors, _vector, sample_nonkinematic_errors
from posekit.robots import KinematicChain, hiab033, quintic_trajectory

__all__ = ["DEFAULT_Q0", "ArmLog", "LongReachArm"]

#: Default start configuration of the HIAB033-like crane (rad): lift boom up 46°, tilt boom
#: folded down, wrist 2 at 0.2 rad (clear of the wrist singularity at 0); the TCP is 4.42 m
#: from the slewing axis and 2.52 m high, the last joint's torsion axis (and the camera)
#: points forward and 31.6° down. From here the tool can move ~0.65 m forward along that
#: axis (an OOI ~1 m in front of the camera) and ±0.25 m sideways within reach.
DEFAULT_Q0 = np.array([0.0, 0.8, -1.15, 0.0, 0.2, 0.0])

_UP = np.array([0.0, 0.0, 1.0])


class ArmLog(NamedTuple):
    """Samples of one move, one row per controller period (the start state first).

    t_s : ndarray, shape (T,)
        Time since the arm was created, s.
    q_measured : ndarray, shape (T, n)
        Encoder readings, rad.
    T_B_F_nominal : ndarray, shape (T, 4, 4)
        TCP pose by the nominal DH model at the encoder readings, base frame, mm.
    T_B_F_true : ndarray, shape (T, 4, 4)
        True TCP pose (offsets, backlash, bending), base frame, mm.
    """

    t_s: np.ndarray
    q_measured: np.ndarray
    T_B_F_nominal: np.ndarray
    T_B_F_true: np.ndarray


def _flex_discretisation(errors: NonKinematicErrors, dt: float):
    """Exact zero-order-hold step ``x ← Φ x + Γ α`` of ``δ̈ + 2ζω δ̇ + ω² δ = -g α``; None when rigid."""
    if errors.flex_hz <= 0 or errors.flex_gain <= 0:
        return None
    from scipy.linalg import expm

    w, z = 2.0 * np.pi * errors.flex_hz, errors.flex_damping
    M = np.zeros((3, 3))
    M[0, 1] = 1.0
    M[1, 0], M[1, 1], M[1, 2] = -w * w, -2.0 * z * w, -errors.flex_gain
    E = expm(M * dt)
    return E[:2, :2].copy(), E[:2, 2].copy()


def _concat_logs(logs: list[ArmLog]) -> ArmLog:
    return ArmLog(*(np.concatenate(parts, axis=0) for parts in zip(*logs)))


@dataclass(eq=False)
class LongReachArm:
    """A hydraulic long-reach manipulator: nominal model, true (erroneous) arm, joint servos.

    Parameters
    ----------
    model : KinematicChain, optional
        The nominal model the controller knows (a DH table or a URDF chain, e.g. from
        :func:`posekit.robots.load_urdf`); ``hiab033()`` by default.
    errors : NonKinematicErrors, optional
        The true arm's deviations; ``sample_nonkinematic_errors(seed)`` by default.
    dt_s : float
        Controller period, s (100 Hz by default).
    tau_s : float or array_like, shape (n,)
        PT-1 time constant of each hydraulic joint (eq. 25), s.
    kv : float or array_like, shape (n,)
        Joint P-servo gain ``K_v`` of eq. (6), 1/s.
    v_max_rad_s : float or array_like, shape (n,)
        Joint velocity limit, rad/s.
    encoder_noise_rad : float
        Standard deviation of the encoder noise, rad.
    rate_gains : (float, float)
        Resolved-rate feedback gains ``(K_p, K_θ)`` of eq. (4), 1/s.
    q0 : array_like, shape (n,), optional
        Start configuration (actuator angles), rad; :data:`DEFAULT_Q0` for the 6-joint crane.
    seed : int or numpy.random.Generator
        Seeds the errors (when not given), the initial backlash state and the encoder noise.

    Examples
    --------
    >>> arm = LongReachArm(seed=0)
    >>> T = arm.nominal_pose()
    >>> T[:3, 3] -= 300.0 * T[:3, 2]          # 0.3 m forward along the torsion axis
    >>> log = arm.move_to(T)                   # ~3.8 s + 1.5 s settling at 100 Hz
    >>> bool(np.linalg.norm(arm.nominal_pose()[:3, 3] - T[:3, 3]) < 1.0)  # the model: there
    True
    >>> bool(np.linalg.norm(arm.true_pose()[:3, 3] - T[:3, 3]) > 10.0)  # the real tool: cm off
    True
    """

    model: KinematicChain | None = None
    errors: NonKinematicErrors | None = None
    _: KW_ONLY
    dt_s: float = 0.01
    tau_s: float | np.ndarray = 0.1
    kv: float | np.ndarray = 4.0
    v_max_rad_s: float | np.ndarray = 0.3
    encoder_noise_rad: float = 2e-5
    rate_gains: tuple[float, float] = (10.0, 10.0)
    q0: np.ndarray | None = None
    seed: int | np.random.Generator = 0
    _state: dict = field(init=False, repr=False)

    def __post_init__(self):
        if self.model is None:
            self.model = hiab033()
        if not isinstance(self.model, KinematicChain):
            raise ConfigError(f"model: expected a KinematicChain (DH or URDF), got {type(self.model).__name__}")
        n = self.model.n_joints
        rng = np.random.default_rng(self.seed)
        err_rng, state_rng, self._rng = rng.spawn(3)
        if self.errors is None:
            self.errors = sample_nonkinematic_errors(err_rng, n_joints=n)
        if not isinstance(self.errors, NonKinematicErrors) or self.errors.n_joints != n:
            raise ConfigError(
                f"errors: expected NonKinematicErrors for {n} joints, got {self.errors!r}"
            )
        if not (np.ndim(self.dt_s) == 0 and np.isfinite(self.dt_s) and self.dt_s > 0):
            raise ConfigError(f"dt_s must be a finite number > 0, got {self.dt_s!r}")
        tau = _vector(self.tau_s, "tau_s", n)
        if np.any(tau <= 0):
            raise ConfigError(f"tau_s: expected values > 0 s, got {tau.tolist()}")
        kv = _vector(self.kv, "kv", n)
        vmax = _vector(self.v_max_rad_s, "v_max_rad_s", n)
        if np.any(kv <= 0) or np.any(vmax <= 0):
            raise ConfigError(
                f"kv and v_max_rad_s: expected values > 0, got {kv.tolist()} and {vmax.tolist()}"
            )
        if not (np.ndim(self.encoder_noise_rad) == 0 and np.isfinite(self.encoder_noise_rad)
                and self.encoder_noise_rad >= 0):
            raise ConfigError(
                f"encoder_noise_rad must be a finite number >= 0, got {self.encoder_noise_rad!r}"
            )
        gains = _vector(self.rate_gains, "rate_gains", 2)
        if np.any(gains <= 0) or np.any(gains * self.dt_s > 1.0):
            raise ConfigError(
                f"rate_gains: expected 0 < gain <= 1/dt_s = {1.0 / self.dt_s:g} 1/s, "
                f"got {gains.tolist()}"
            )
        if self.q0 is None:
            if n != DEFAULT_Q0.shape[0]:
                raise ConfigError(f"q0: required for a {n}-joint model")
            q0 = DEFAULT_Q0.copy()
        else:
            q0 = self.model.check_q(self.q0, "q0")
            if q0.ndim != 1:
                raise ConfigError(f"q0: expected shape ({n},), got shape {q0.shape}")
        half = 0.5 * self.errors.backlash_rad
        m = self.model
        self._kernel_model = (*m.kinematic_pack, m.q_min, m.q_max)
        self._params = {
            "gains": np.repeat(gains, 3),
            "kv": kv,
            "lag": np.exp(-self.dt_s / tau),
            "v_max": vmax,
            "half_play": half,
        }
        self._state = {
            "t": 0.0,
            "residual": 0.0,
            "q_cmd": q0.copy(),
            "q_act": q0.copy(),
            "v": np.zeros(n),
            # the link rests somewhere inside its dead band at the start
            "q_link": q0 + state_rng.uniform(-1.0, 1.0, n) * half,
            "q_meas": q0 + self._rng.normal(0.0, self.encoder_noise_rad, n),
            # boom vibration: (deflection rad, rate rad/s) per bending joint; the last two commands
            "flex": np.zeros((2, len(self.errors.bending_joints))),
            "q_cmd_hist": np.stack([q0, q0]),
        }
        self._flex_step = _flex_discretisation(self.errors, self.dt_s)

    # ------------------------------------------------------------------ state
    @property
    def n_joints(self) -> int:
        """Number of joints ``n``."""
        return self.model.n_joints

    @property
    def t_s(self) -> float:
        """Simulated time since the arm was created, s."""
        return self._state["t"]

    @property
    def command_residual_mm(self) -> float:
        """Distance of the commanded nominal TCP from the last move's reference, mm.

        ~0 when the reference was reachable; large when the resolved-rate control stopped at
        joint limits or a singularity (the move then ends short of the reference).
        """
        return self._state["residual"]

    def _residual(self, T_ref: np.ndarray) -> None:
        T = self.model.forward_kinematics(self._state["q_cmd"], check=False)
        self._state["residual"] = float(np.linalg.norm(T[:3, 3] - T_ref[:3, 3]))

    def q_measured(self) -> np.ndarray:
        """Encoder readings, shape (n,), rad."""
        return self._state["q_meas"].copy()

    def nominal_pose(self) -> np.ndarray:
        """``T_B_F`` by the nominal DH model at the encoder readings, (4, 4), mm."""
        return self.model.forward_kinematics(self._state["q_meas"], check=False)

    def true_pose(self) -> np.ndarray:
        """The true ``T_B_F`` (joint offsets, backlash state, bending, boom vibration), (4, 4), mm."""
        return self.true_kinematics(self._state["q_link"], self._state["flex"][0])

    def true_kinematics(self, q_link, flex_rad=None) -> np.ndarray:
        """True TCP poses for link-side joint angles (before offsets and droop).

        Parameters
        ----------
        q_link : array_like, shape (n,) or (N, n)
            Actuator angles after the backlash dead band, rad.
        flex_rad : array_like, shape (m,) or (N, m), optional
            Boom vibration deflection of each bending joint, rad (none by default).

        Returns
        -------
        T_B_F : ndarray, shape (4, 4) or (N, 4, 4)
            True TCP poses in the base frame, mm.
        """
        e = self.errors
        q = np.asarray(q_link, dtype=np.float64) + e.joint_offsets_rad
        if np.any(e.bending_rad_per_m):
            T = self.model.forward_kinematics(q, check=False)
            axes, points = self.model.joint_axes(q, check=False)
            p = T[..., None, :3, 3]
            idx = list(e.bending_joints)
            z, o = np.take(axes, idx, axis=-2), np.take(points, idx, axis=-2)  # joints idx
            torque_mm = np.einsum("...k,...k->...", z, np.cross(p - o, -_UP))
            q = q.copy()
            q[..., idx] += e.bending_rad_per_m * torque_mm / 1000.0
        if flex_rad is not None:
            q = q.copy()
            q[..., list(e.bending_joints)] += flex_rad
        return self.model.forward_kinematics(q, check=False)

    def _flex(self, q_cmd) -> np.ndarray:
        """Boom deflection after each step of a move, (K, m) rad, from the commanded joints (K, n)."""
        st = self._state
        idx = list(self.errors.bending_joints)
        hist = np.vstack([st["q_cmd_hist"], q_cmd])
        st["q_cmd_hist"] = hist[-2:].copy()
        if self._flex_step is None:
            return np.zeros((len(q_cmd), len(idx)))
        Phi, Gam = self._flex_step
        qc = hist[:, idx]
        alpha = (qc[2:] - 2.0 * qc[1:-1] + qc[:-2]) / self.dt_s ** 2
        x = st["flex"].copy()
        out = np.empty((len(q_cmd), len(idx)))
        for k in range(len(q_cmd)):
            x = Phi @ x + Gam[:, None] * alpha[k]
            out[k] = x[0]
        st["flex"] = x
        return out

    # ------------------------------------------------------------------ motion
    def _default_duration(self, T0: np.ndarray, T1: np.ndarray) -> float:
        dist = np.linalg.norm(T1[:3, 3] - T0[:3, 3])
        angle = np.linalg.norm(rotation_vector_from_matrix(T0[:3, :3].T @ T1[:3, :3], check=False))
        # peak speed of a quintic is 1.875 x the mean: ~150 mm/s and ~0.15 rad/s peaks
        return float(max(1.0, 1.875 * dist / 150.0, 1.875 * angle / 0.15))

    def _cartesian_path(self, T0, T1, duration_s, settle_s):
        """Quintic Cartesian reference sampled at the end of every step."""
        dt = self.dt_s
        k_move = int(np.ceil(duration_s / dt - 1e-9))
        k_settle = int(np.ceil(settle_s / dt - 1e-9))
        t_rel = dt * np.arange(1, k_move + k_settle + 1)
        rv = rotation_vector_from_matrix(T0[:3, :3].T @ T1[:3, :3], check=False)
        dp = T1[:3, 3] - T0[:3, 3]
        s = quintic_trajectory(np.zeros(6), np.concatenate([dp, rv]), k_move * dt, t_rel)
        p = T0[:3, 3] + s.q[:, :3]
        R = T0[:3, :3] @ matrix_from_rotation_vector(s.q[:, 3:])
        twist = np.concatenate([s.qd[:, :3], s.qd[:, 3:] @ T0[:3, :3].T], axis=1)
        # exact end pose (no round-off drift of the axis-angle interpolation)
        p[k_move - 1:] = T1[:3, 3]
        R[k_move - 1:] = T1[:3, :3]
        return t_rel, np.ascontiguousarray(p), np.ascontiguousarray(R), np.ascontiguousarray(twist)

    def _run(self, t_rel, p, R, twist) -> ArmLog:
        st, par = self._state, self._params
        K, n = len(t_rel), self.n_joints
        noise = self._rng.normal(0.0, self.encoder_noise_rad, (K, n))
        q_meas0, q_link0, t0 = st["q_meas"].copy(), st["q_link"].copy(), st["t"]
        flex0 = st["flex"][0].copy()
        q_meas, q_link, q_cmd = simulate_moves(
            *self._kernel_model, p, R, twist, par["gains"], 1e-3, self.dt_s,
            par["kv"], par["lag"], par["v_max"], par["half_play"], noise,
            st["q_cmd"], st["q_act"], st["v"], st["q_link"], st["q_meas"],
        )
        st["t"] = t0 + t_rel[-1]
        flex = np.vstack([flex0, self._flex(q_cmd)])
        q_meas = np.vstack([q_meas0, q_meas])
        q_link = np.vstack([q_link0, q_link])
        return ArmLog(
            np.concatenate([[t0], t0 + t_rel]),
            q_meas,
            self.model.forward_kinematics(q_meas, check=False),
            self.true_kinematics(q_link, flex),
        )

    def move_to(self, T_B_ref, *, duration_s: float | None = None, settle_s: float = 1.5) -> ArmLog:
        """Point-to-point move of the TCP to a reference pose (nominal model, eq. 4–6, 25).

        The path starts at the nominal pose of the current *commanded* joints (equal to the
        encoder pose once the arm has settled) and follows a quintic in position and in the
        rotation angle about a fixed axis; after ``duration_s`` the reference holds for
        ``settle_s`` while the hydraulic joints settle.

        Parameters
        ----------
        T_B_ref : array_like, shape (4, 4)
            Reference TCP pose ``T_B_F`` in the base frame, mm.
        duration_s : float, optional
            Motion time, s; by default from the distance and rotation angle (peak speeds
            ~150 mm/s and ~0.15 rad/s, at least 1 s).
        settle_s : float
            Time to hold the final reference, s (>= 0).

        Returns
        -------
        ArmLog
            The samples of this move (start state first).

        Raises
        ------
        GeometryError
            ``T_B_ref`` is not a rigid transform.
        ConfigError
            ``duration_s <= 0`` or ``settle_s < 0``.
        """
        T1 = check_transform(T_B_ref, name="T_B_ref")
        if T1.shape != (4, 4):
            raise GeometryError(f"T_B_ref: expected one (4, 4) transform, got shape {T1.shape}")
        T0 = self.model.forward_kinematics(self._state["q_cmd"], check=False)
        duration_s, settle_s = self._check_times(duration_s, settle_s, T0, T1)
        log = self._run(*self._cartesian_path(T0, T1, duration_s, settle_s))
        self._residual(T1)
        return log

    def _check_times(self, duration_s, settle_s, T0, T1):
        if duration_s is None:
            duration_s = self._default_duration(T0, T1)
        if not (np.ndim(duration_s) == 0 and np.isfinite(duration_s) and duration_s > 0):
            raise ConfigError(f"duration_s must be a finite number > 0 s, got {duration_s!r}")
        if not (np.ndim(settle_s) == 0 and np.isfinite(settle_s) and settle_s >= 0):
            raise ConfigError(f"settle_s must be a finite number >= 0 s, got {settle_s!r}")
        return float(duration_s), float(settle_s)

    def follow(self, T_B_path, *, segment_s: float | None = None, settle_s: float = 1.5) -> ArmLog:
        """Point-to-point motion through waypoints (each segment a quintic, eq. 4–6, 25).

        Parameters
        ----------
        T_B_path : array_like, shape (K, 4, 4)
            Waypoint TCP poses in the base frame, mm, visited in order.
        segment_s : float, optional
            Duration of every segment, s; by default each from its length (as in
            :meth:`move_to`).
        settle_s : float
            Hold time after the last waypoint, s (no hold between waypoints).

        Returns
        -------
        ArmLog
            All samples of the motion (start state first).

        Raises
        ------
        GeometryError
            A waypoint is not a rigid transform (the message names its index).
        ConfigError
            An empty path, ``segment_s <= 0`` or ``settle_s < 0``.
        """
        try:
            path = np.asarray(T_B_path, dtype=np.float64)
        except (TypeError, ValueError):
            raise GeometryError(
                f"T_B_path: expected an array of shape (K, 4, 4), got {type(T_B_path).__name__}"
            ) from None
        if path.ndim != 3 or path.shape[1:] != (4, 4) or path.shape[0] == 0:
            raise GeometryError(f"T_B_path: expected shape (K, 4, 4) with K >= 1, got shape {path.shape}")
        check_transform(path, name="T_B_path")      # names the first bad waypoint
        logs = []
        for k in range(path.shape[0]):
            T0 = self.model.forward_kinematics(self._state["q_cmd"], check=False)
            last = k == path.shape[0] - 1
            dur, hold = self._check_times(segment_s, settle_s if last else 0.0, T0, path[k])
            log = self._run(*self._cartesian_path(T0, path[k], dur, hold))
            self._residual(path[k])
            logs.append(log if k == 0 else ArmLog(*(a[1:] for a in log)))
        return _concat_logs(logs)
