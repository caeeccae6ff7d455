"""A welding cell posekit never simulated: an episode generator written here, independent of posekit's simulator.

Its own robot (a UR10-like standard-DH arm whose true lengths and angles differ from the URDF it writes for
posekit), its own kinematics, inverse kinematics and seam geometry (NumPy only), and the recorded-episode
format of DESIGN.md (``setup.yaml``, ``seam.csv``, ``log.csv``, ``truth.csv``):

- the seam runs 180 mm along the base y axis and waves 6 mm sideways (one sine period over the 180 mm), the tool
  points down and its heading follows the seam's tangent; 45 mm/s, sampled at 100 Hz;
- the motors follow a cubic spline through the program's joints 2 ms late; the encoders read them with
  0.003 deg noise (and, when asked, a constant offset on one joint);
- the process force (tool frame, about 3.5 kN, drifting 15 % and with 30 N of white variation) bends the joints
  (true compliance 8e-7 rad/(N m); the cell declares 7e-7) and the tool (an unmodelled Cartesian part), and the
  tool also drifts smoothly by a few tenths of a mm and a few hundredths of a degree that nothing models;
- the wrist force sensor reads with 15 N noise (and, when asked, a constant bias);
- two laser seam trackers 30 and 55 mm ahead (the second 1.5 mm aside and turned 4 deg) see the true seam at
  the time they sample it, ``latency_s`` before the row's ``time_s`` (10-20 ms), with 0.03 / 0.04 mm noise and
  2 % dropouts.

The cell (robot errors, compliance, mounts, latencies) is fixed by ``cell_seed``; an episode (``seed``) places
the seam a few mm differently, draws the wave's phase, the force, the drift and the noise.
"""

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from scipy.interpolate import CubicSpline

# ----------------------------------------------------------------------------------------- the robot

#: UR10-like standard DH table: (d mm, a mm, alpha rad) per joint.
DH = np.array([
    [127.3, 0.0, math.pi / 2],
    [0.0, -612.0, 0.0],
    [0.0, -572.3, 0.0],
    [163.941, 0.0, math.pi / 2],
    [115.7, 0.0, -math.pi / 2],
    [92.2, 0.0, 0.0],
])
#: Tool: 180 mm along the flange z axis.
T_FLANGE_TOOL = np.array([[1.0, 0, 0, 0], [0, 1.0, 0, 0], [0, 0, 1.0, 180.0], [0, 0, 0, 1.0]])
H = 0.01          # s, the sample period
SPEED = 45.0      # mm/s along the seam
LENGTH = 180.0    # mm of travel
WAVE_MM = 6.0     # sideways amplitude
WAVE_PERIOD = 180.0


def _rz(t):
    c, s = np.cos(t), np.sin(t)
    out = np.zeros(t.shape + (4, 4))
    out[..., 0, 0], out[..., 0, 1], out[..., 1, 0], out[..., 1, 1] = c, -s, s, c
    out[..., 2, 2] = out[..., 3, 3] = 1.0
    return out


def _link(d, a, alpha):
    """``Tz(d) Tx(a) Rx(alpha)`` (4, 4)."""
    c, s = math.cos(alpha), math.sin(alpha)
    return np.array([[1.0, 0, 0, a], [0, c, -s, 0], [0, s, c, d], [0, 0, 0, 1.0]])


def fk(q, dh=DH, tool=T_FLANGE_TOOL, offsets=None):
    """Standard-DH forward kinematics of joints ``q (..., 6)`` (rad): ``T_base_tool (..., 4, 4)``, mm.

    ``offsets`` (6, 4, 4): extra fixed transforms after each joint's link (the true robot's errors)."""
    q = np.asarray(q, dtype=np.float64)
    T = np.broadcast_to(np.eye(4), q.shape[:-1] + (4, 4)).copy()
    for j in range(6):
        L = _link(*dh[j])
        if offsets is not None:
            L = L @ offsets[j]
        T = T @ _rz(q[..., j]) @ L
    return T @ tool


def _log_so3(R):
    c = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    th = np.arccos(c)
    v = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], -1)
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.where(th[..., None] > 1e-9, th[..., None] / (2.0 * np.sin(th[..., None])), 0.5)
    return k * v


def _exp_so3(w):
    w = np.asarray(w, dtype=np.float64)
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2], K[..., 1, 0] = -w[..., 2], w[..., 1], w[..., 2]
    K[..., 1, 2], K[..., 2, 0], K[..., 2, 1] = -w[..., 0], -w[..., 1], w[..., 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        a = np.where(th > 1e-12, np.sin(th) / th, 1.0)
        b = np.where(th > 1e-12, (1.0 - np.cos(th)) / th ** 2, 0.5)
    return np.eye(3) + a * K + b * (K @ K)


def _pose(R, p):
    T = np.zeros(p.shape[:-1] + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = p
    T[..., 3, 3] = 1.0
    return T


def _jacobian(q, dh, tool, offsets=None, h=1e-6):
    """Numerical geometric Jacobians ``(..., 6, 6)`` at ``q (..., 6)``: rows [v (mm/rad); w (rad/rad)], base frame."""
    q = np.asarray(q, dtype=np.float64)
    T0 = fk(q, dh, tool, offsets)
    J = np.empty(q.shape[:-1] + (6, 6))
    for j in range(6):
        dq = np.zeros(6)
        dq[j] = h
        T1 = fk(q + dq, dh, tool, offsets)
        J[..., :3, j] = (T1[..., :3, 3] - T0[..., :3, 3]) / h
        J[..., 3:, j] = _log_so3(T1[..., :3, :3] @ np.swapaxes(T0[..., :3, :3], -1, -2)) / h
    return J


def _newton(q, targets, dh, tool, iterations):
    for _ in range(iterations):
        T = fk(q, dh, tool)
        e = np.concatenate([targets[..., :3, 3] - T[..., :3, 3],
                            _log_so3(targets[..., :3, :3] @ np.swapaxes(T[..., :3, :3], -1, -2))], -1)
        J = _jacobian(q, dh, tool)
        Jt = np.swapaxes(J, -1, -2)
        q = q + np.linalg.solve(Jt @ J + 1e-9 * np.eye(6), (Jt @ e[..., None]))[..., 0]
    return q


def ik(targets, q0, dh=DH, tool=T_FLANGE_TOOL):
    """Joint stream ``(T, 6)`` reaching each target pose ``(T, 4, 4)``: damped Gauss-Newton on every 40th target
    from the last solution, then on all at once from the joints interpolated between those."""
    coarse = np.unique(np.r_[np.arange(0, len(targets), 40), len(targets) - 1])
    qc = np.empty((coarse.size, 6))
    q = np.array(q0, dtype=np.float64)
    for i, k in enumerate(coarse):
        q = _newton(q, targets[k], dh, tool, 30 if i == 0 else 8)
        qc[i] = q
    idx = np.arange(len(targets))
    q_all = np.stack([np.interp(idx, coarse, qc[:, j]) for j in range(6)], -1)
    q_all = _newton(q_all, targets, dh, tool, 5)
    T = fk(q_all, dh, tool)
    err = np.abs(T[:, :3, 3] - targets[:, :3, 3]).max()
    if not err < 1e-7:
        raise RuntimeError(f"independent cell: inverse kinematics off by {err:.3g} mm")
    return q_all


def urdf_text() -> str:
    """The nominal robot as a URDF file (metres): what the cell's user hands posekit."""
    links = ["base"] + [f"link{j + 1}" for j in range(6)] + ["flange"]
    xml = ['<?xml version="1.0"?>', '<robot name="indep_ur10like">']
    xml += [f'  <link name="{n}"/>' for n in links]
    prev = (0.0, 0.0, 0.0)  # (d, a, alpha) of the link before the joint
    for j in range(6):
        d, a, al = prev
        xml.append(f'  <joint name="j{j + 1}" type="revolute"><parent link="{links[j]}"/>'
                   f'<child link="{links[j + 1]}"/><origin xyz="{a / 1e3:.17g} 0 {d / 1e3:.17g}" rpy="{al:.17g} 0 0"/>'
                   '<axis xyz="0 0 1"/><limit lower="-6.283" upper="6.283" effort="100" velocity="3"/></joint>')
        prev = tuple(DH[j])
    d, a, al = prev
    xml.append(f'  <joint name="flange_fixed" type="fixed"><parent link="link6"/><child link="flange"/>'
               f'<origin xyz="{a / 1e3:.17g} 0 {d / 1e3:.17g}" rpy="{al:.17g} 0 0"/></joint>')
    xml.append("</robot>")
    return "\n".join(xml) + "\n"


# ----------------------------------------------------------------------------------------- the cell


def _translate(x, y, z, yaw_deg=0.0):
    T = np.eye(4)
    T[:3, :3] = _exp_so3(np.array([0.0, 0.0, math.radians(yaw_deg)]))
    T[:3, 3] = (x, y, z)
    return T


@dataclass
class Cell:
    """What stays the same from one episode to the next: the robot, its errors, the tool, the sensors."""

    cell_seed: int = 0
    latency_s: tuple = (0.013, 0.017)
    laser_sigma_mm: tuple = (0.03, 0.04)
    mounts: tuple = field(default_factory=lambda: (_translate(0.0, 30.0, 0.0), _translate(1.5, 55.0, 0.0, -4.0)))
    compliance_true: float = 8e-7        # rad / (N m)
    compliance_declared: float = 7e-7
    joint_noise_deg: float = 0.003
    force_noise_n: float = 15.0
    servo_lag_s: float = 0.002

    def __post_init__(self):
        rng = np.random.default_rng([self.cell_seed, 77])
        # the true robot: each link's fixed transform off by ~0.25 mm and ~0.02 deg
        self.offsets = np.stack([_pose(_exp_so3(np.radians(0.02) * rng.standard_normal(3)),
                                       0.25 * rng.standard_normal(3)) for _ in range(6)])


# ----------------------------------------------------------------------------------------- an episode


@dataclass
class Episode:
    t: np.ndarray            # (T,) s
    qref: np.ndarray         # (T, 6) rad
    q_meas: np.ndarray       # (T, 6)
    force_tool: np.ndarray   # (T, 3) N, measured
    laser: np.ndarray        # (T, S, 2) mm, NaN = none
    truth: np.ndarray        # (T, 4, 4) T_base_tool
    nominal: np.ndarray      # (T, 4, 4) Fk_nominal(qref)
    seam: np.ndarray         # (K, 3)
    stamps: np.ndarray       # (T, S) s, the readings' own times


def _seam_point(u, p0, phase):
    """The true seam at parameter ``u`` (mm along base y): (K, 3) base frame, and its tangent."""
    u = np.asarray(u, dtype=np.float64)
    k = 2.0 * math.pi / WAVE_PERIOD
    p = np.stack([p0[0] + WAVE_MM * np.sin(k * u + phase), p0[1] + u, np.full_like(u, p0[2])], -1)
    d = np.stack([WAVE_MM * k * np.cos(k * u + phase), np.ones_like(u), np.zeros_like(u)], -1)
    return p, d / np.linalg.norm(d, axis=-1, keepdims=True)


def _crossing(o, n, p0, phase, u0):
    """The seam's crossing of the planes through ``o (T, 3)`` with normals ``n (T, 3)`` (Newton in u)."""
    u = np.asarray(u0, dtype=np.float64).copy()
    k = 2.0 * math.pi / WAVE_PERIOD
    for _ in range(30):
        p, _ = _seam_point(u, p0, phase)
        g = np.einsum("ij,ij->i", n, p - o)
        dp = np.stack([WAVE_MM * k * np.cos(k * u + phase), np.ones_like(u), np.zeros_like(u)], -1)
        u = u - g / np.einsum("ij,ij->i", n, dp)
    return _seam_point(u, p0, phase)[0]


def episode(cell: Cell, seed: int, *, encoder_offset_deg=(0.0,) * 6, force_bias_n=(0.0, 0.0, 0.0),
            steps: int | None = None) -> Episode:
    """Simulate one episode of ``cell`` (see the module docstring)."""
    rng = np.random.default_rng([cell.cell_seed, seed, 5])
    n = int(round(LENGTH / SPEED / H)) if steps is None else int(steps)
    t = np.arange(n) * H
    p0 = np.array([600.0, -100.0, 60.0]) + rng.uniform(-4.0, 4.0, 3)
    phase = rng.uniform(0.0, 2.0 * math.pi)
    # the program: the TCP on the seam, tool z down, tool y along the seam's tangent (dense in time, for the
    # spline the motors follow and for the readings taken between samples)
    t_fine = np.arange(-10, n + 10) * H
    p, tang = _seam_point(SPEED * t_fine, p0, phase)
    z = np.array([0.0, 0.0, -1.0])
    x = np.cross(tang, z)
    R = np.stack([x, tang, np.broadcast_to(z, x.shape)], axis=-1)
    q_fine = ik(_pose(R, p), np.radians([0.0, -100.0, -100.0, -70.0, 90.0, 0.0]))
    spline = CubicSpline(t_fine, q_fine, axis=0)
    qref = spline(t)

    # the process force in the tool frame: mean, slow drift, white variation
    f0 = np.array([80.0, -600.0, -3500.0]) * (1.0 + 0.1 * rng.standard_normal())
    drift_period, drift_phase = rng.uniform(3.0, 6.0), rng.uniform(0.0, 2.0 * math.pi)

    def force_tool(tt, white):
        return f0[None] * (1.0 + 0.15 * np.sin(2.0 * math.pi * tt / drift_period + drift_phase))[:, None] + white

    white_f = 30.0 * rng.standard_normal((n, 3))
    # the smooth drift nothing models (tool frame: mm, deg)
    amp = np.array([0.15, 0.15, 0.10, 0.02, 0.02, 0.01])
    per = rng.uniform(2.5, 7.0, 6)
    ph = rng.uniform(0.0, 2.0 * math.pi, 6)

    def truth_at(tt, white):
        q_mot = spline(tt - cell.servo_lag_s)
        f_tool = force_tool(tt, white)
        T_rigid = fk(q_mot, DH, T_FLANGE_TOOL, cell.offsets)
        f_base = np.einsum("tij,tj->ti", T_rigid[:, :3, :3], f_tool)
        J = _jacobian(q_mot, DH, T_FLANGE_TOOL, cell.offsets, h=1e-5)  # the true robot's, (T, 6, 6)
        dq = cell.compliance_true * 1e-3 * np.einsum("tij,ti->tj", J[:, :3], f_base)  # joint deflection
        T = fk(q_mot + dq, DH, T_FLANGE_TOOL, cell.offsets)
        xi = amp[None] * np.sin(2.0 * math.pi * tt[:, None] / per[None] + ph[None])
        xi[:, :3] += 6e-5 * f_tool
        xi[:, 3:] = np.radians(xi[:, 3:]) + math.radians(3e-4) * np.cross([0.0, 0.0, 1.0], f_tool)
        E = _pose(_exp_so3(xi[:, 3:]), xi[:, :3])
        return T @ E, q_mot

    truth, q_mot = truth_at(t, white_f)
    q_meas = q_mot + math.radians(cell.joint_noise_deg) * rng.standard_normal((n, 6))
    q_meas += np.radians(np.asarray(encoder_offset_deg, dtype=np.float64))[None]
    f_meas = force_tool(t, white_f) + cell.force_noise_n * rng.standard_normal((n, 3)) + np.asarray(force_bias_n)

    S = len(cell.mounts)
    laser = np.full((n, S, 2), np.nan)
    stamps = np.empty((n, S))
    for s, M in enumerate(cell.mounts):
        ts = t - cell.latency_s[s]
        stamps[:, s] = ts
        white_s = np.stack([np.interp(ts, t, white_f[:, j]) for j in range(3)], -1)
        Ts, _ = truth_at(ts, white_s)
        Sp = Ts @ M
        o, xs, ys, zs = Sp[:, :3, 3], Sp[:, :3, 0], Sp[:, :3, 1], Sp[:, :3, 2]
        hit = _crossing(o, ys, p0, phase, o[:, 1] - p0[1])
        e = hit - o
        m = np.stack([np.einsum("ij,ij->i", e, xs), np.einsum("ij,ij->i", e, zs)], -1)
        m += cell.laser_sigma_mm[s] * rng.standard_normal((n, 2))
        keep = rng.random(n) >= 0.02
        laser[keep, s] = m[keep]
    seam, _ = _seam_point(np.arange(-20.0, SPEED * n * H + 80.0, 0.5), p0, phase)
    nominal = fk(qref)
    return Episode(t, qref, q_meas, f_meas, laser, truth, nominal, seam, stamps)


# ----------------------------------------------------------------------------------------- the files


def _fmt(v) -> str:
    return "" if not np.isfinite(v) else repr(float(v))


def _rows(path: Path, header, table) -> None:
    lines = [",".join(header)] + [",".join(_fmt(v) for v in row) for row in table]
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")


def _quat_wxyz(R):
    """Unit quaternions (T, 4) of rotation matrices (T, 3, 3) (Shepperd's method, written here)."""
    out = np.empty(R.shape[:-2] + (4,))
    for i, m in enumerate(R.reshape(-1, 3, 3)):
        tr = np.trace(m)
        if tr > 0:
            s = 2.0 * math.sqrt(tr + 1.0)
            q = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
        else:
            j = int(np.argmax(np.diag(m)))
            k, m2 = (j + 1) % 3, (j + 2) % 3
            s = 2.0 * math.sqrt(1.0 + m[j, j] - m[k, k] - m[m2, m2])
            q = [0.0] * 4
            q[0] = (m[m2, k] - m[k, m2]) / s
            q[1 + j] = 0.25 * s
            q[1 + k] = (m[k, j] + m[j, k]) / s
            q[1 + m2] = (m[m2, j] + m[j, m2]) / s
        out.reshape(-1, 4)[i] = q
    return out


def write_episode(folder, cell: Cell, ep: Episode, *, declare_latency: bool = True, stamps: bool = False,
                  latency_declared=None, truth: bool = True, extra_setup: dict | None = None) -> Path:
    """Write ``ep`` as a recorded episode in ``folder`` (created): DESIGN.md's format.

    ``declare_latency``: each sensor as ``{T_tool_sensor, latency_s}`` (``latency_declared`` or the true
    latency), else a bare 4x4; ``stamps``: the ``m{k}_t_s`` columns; ``truth``: write ``truth.csv``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cell.urdf").write_text(urdf_text(), encoding="utf-8")
    lat = cell.latency_s if latency_declared is None else latency_declared
    sensors = []
    for s, M in enumerate(cell.mounts):
        m = [[float(v) for v in row] for row in M]
        sensors.append({"T_tool_sensor": m, "latency_s": float(lat[s])} if declare_latency else m)
    setup = {"robot": {"urdf": "cell.urdf", "base_link": "base", "tip_link": "flange"},
             "tool": [[float(v) for v in row] for row in T_FLANGE_TOOL], "sensors": sensors,
             "compliance_rad_per_nm": cell.compliance_declared, "seed": 0, **(extra_setup or {})}
    (folder / "setup.yaml").write_text(yaml.safe_dump(setup, sort_keys=False), encoding="utf-8")
    _rows(folder / "seam.csv", ("x_mm", "y_mm", "z_mm"), ep.seam)
    S = ep.laser.shape[1]
    cols = (["time_s"] + [f"qref_{j + 1}" for j in range(6)] + [f"q_{j + 1}" for j in range(6)]
            + ["fx_n", "fy_n", "fz_n"])
    parts = [ep.t[:, None], ep.qref, ep.q_meas, ep.force_tool]
    for s in range(S):
        cols += [f"m{s + 1}_x_mm", f"m{s + 1}_z_mm"] + ([f"m{s + 1}_t_s"] if stamps else [])
        parts.append(ep.laser[:, s])
        if stamps:
            parts.append(np.where(np.isfinite(ep.laser[:, s, 0]), ep.stamps[:, s], np.nan)[:, None])
    _rows(folder / "log.csv", cols, np.hstack(parts))
    if truth:
        Tn_inv = np.linalg.inv(ep.nominal)
        T_st = Tn_inv @ ep.truth
        _rows(folder / "truth.csv", ("time_s", "tx_mm", "ty_mm", "tz_mm", "qw", "qx", "qy", "qz"),
              np.hstack([ep.t[:, None], T_st[:, :3, 3], _quat_wxyz(T_st[:, :3, :3])]))
    return folder


def seam_frame_errors(T_est, ep: Episode) -> np.ndarray:
    """``(T, 6)``: ``R_nomᵀ (p_est - p_true)`` (mm) and the rotation vector of ``R_trueᵀ R_est`` (rad), written
    here (the seam frame of DESIGN.md: the nominal tool pose)."""
    dp = np.einsum("tji,tj->ti", ep.nominal[:, :3, :3], T_est[:, :3, 3] - ep.truth[:, :3, 3])
    dr = _log_so3(np.swapaxes(ep.truth[:, :3, :3], 1, 2) @ T_est[:, :3, :3])
    return np.hstack([dp, dr])


def scores(T_est, spread, status, ep: Episode) -> dict:
    """2-sigma coverage per axis (and per step: ``covered (T, 6)``), the share of ``tracking`` steps and of confident-wrong steps (tracking while
    beyond 3 sigma on some axis), computed here from the estimates, spreads (mm, rad) and statuses."""
    err = np.abs(seam_frame_errors(np.asarray(T_est), ep))
    spread = np.asarray(spread)
    status = np.asarray(status)
    return {"coverage": np.mean(err <= 2.0 * spread, axis=0), "covered": err <= 2.0 * spread,
            "tracking": float(np.mean(status == "tracking")),
            "confident_wrong": float(np.mean((status == "tracking") & np.any(err > 3.0 * spread, axis=1))),
            "rmse": np.sqrt(np.mean(err ** 2, axis=0))}


def write_training(root, seeds=(0, 1, 2)) -> list:
    """The training episodes of the checked-in profile tests/seam/data/independent_cell_profile.yaml: episodes
    ``seeds`` of the default cell, latency not declared, written to ``root/train{seed}``."""
    cell = Cell()
    return [write_episode(Path(root) / f"train{s}", cell, episode(cell, s), declare_latency=False) for s in seeds]


if __name__ == "__main__":
    # python -m tests.seam.independent_cell DIR [N]: write the training episodes 0 .. N - 1 (default 3) into DIR
    # (see write_training)
    import sys

    for folder in write_training(sys.argv[1], range(int(sys.argv[2]) if len(sys.argv) > 2 else 3)):
        print(folder)
