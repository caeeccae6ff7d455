"""Synthetic camera/kinematic trajectory pairs for the trajectory-matching tests (H1).

The kinematic trajectory is in the base frame B; the camera trajectory is the same body's motion
seen in a world frame W with ``T_B_W`` unknown to the matcher, sampled at another rate on a clock
shifted by an offset, with mm-level noise and gross position outliers.
"""

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from posekit.localcal.model.trajectory import Trajectory

#: The real TUM RGB-D trajectory pairs (SLAM estimate and ground truth) of ``tests/data/tum``.
TUM_DATA = Path(__file__).resolve().parents[1] / "data" / "tum"


def stack_poses(p_mm, R):
    """(N, 4, 4) poses from positions ``p_mm`` (N, 3) and rotations ``R`` ((N, 3, 3) or one (3, 3))."""
    T = np.zeros((len(p_mm), 4, 4))
    T[:, :3, :3], T[:, :3, 3], T[:, 3, 3] = R, p_mm, 1.0
    return T


def random_transform(rng, origin_mm=(0.0, 0.0, 0.0), *, t_scale_mm=200.0):
    """A random rigid transform T_B_W: uniform rotation, W's origin within t_scale_mm of origin_mm
    (a VO world frame is the first camera pose, so it lies near the path)."""
    T = np.eye(4)
    T[:3, :3] = Rotation.random(random_state=rng).as_matrix()
    T[:3, 3] = np.asarray(origin_mm) + rng.uniform(-t_scale_mm, t_scale_mm, 3)
    return T


def smooth_path(rng, duration_s=20.0, extent_mm=400.0, rotate=True):
    """A random smooth 3D motion: functions of time t -> (positions (K,3), rotations (K,3,3))."""
    freq = rng.uniform(0.02, 0.1, (3, 3))
    phase = rng.uniform(0, 2 * np.pi, (3, 3))
    amp = extent_mm * rng.uniform(0.3, 1.0, (3, 3))
    rfreq = rng.uniform(0.05, 0.2, 3)
    rphase = rng.uniform(0, 2 * np.pi, 3)
    R0 = Rotation.random(random_state=rng)

    def pose(t):
        p = (amp[None] * np.sin(2 * np.pi * freq[None] * t[:, None, None] + phase[None])).sum(-1)
        rv = 0.4 * np.sin(2 * np.pi * rfreq[None] * t[:, None] + rphase[None]) if rotate else np.zeros((len(t), 3))
        R = (R0 * Rotation.from_rotvec(rv)).as_matrix()
        return p, R
    return pose


def asymmetric_planar_path(rng, lengths_mm=(400.0, 300.0, 250.0, 350.0, 200.0, 300.0), segment_s=3.0):
    """The paper's asymmetric planar path (eq. 17-19): segments of length L_i along
    cos(xi) n + sin(xi) s with xi alternating 0 and pi/4, quintic point-to-point timing,
    constant orientation. Returns a function t -> (positions, rotations) and the duration."""
    R0 = Rotation.random(random_state=rng).as_matrix()
    n, s = R0[:, 0], R0[:, 1]
    p0 = rng.uniform(-1000, 1000, 3)
    xi = np.where(np.arange(len(lengths_mm)) % 2 == 0, 0.0, np.pi / 4)
    steps = np.asarray(lengths_mm)[:, None] * (np.cos(xi)[:, None] * n + np.sin(xi)[:, None] * s)
    way = np.vstack([p0, p0 + np.cumsum(steps, axis=0)])
    duration = segment_s * len(lengths_mm)

    def pose(t):
        u = np.clip(t / segment_s, 0, len(lengths_mm) - 1e-9)
        k = np.floor(u).astype(int)
        f = u - k
        blend = 10 * f ** 3 - 15 * f ** 4 + 6 * f ** 5
        p = way[k] + blend[:, None] * (way[k + 1] - way[k])
        return p, np.broadcast_to(R0, (len(t), 3, 3)).copy()
    return pose, duration


def make_pair(rng, pose, duration_s, *, T_B_W, rate_src_hz=30.0, rate_dst_hz=100.0, offset_s=0.137,
              noise_mm=1.0, noise_rad=0.002, outlier_fraction=0.05, outlier_mm=(150.0, 600.0)):
    """(camera src in W, kinematic dst in B) with t_dst = t_src + offset_s on overlapping spans.

    Body time runs over [0, duration_s]; the camera clock reads body time - offset_s.
    """
    t_body_dst = np.arange(0.0, duration_s, 1.0 / rate_dst_hz)
    t_body_src = np.arange(0.05, duration_s - 0.05, 1.0 / rate_src_hz) + rng.uniform(0, 1.0 / rate_src_hz)
    t_body_src = t_body_src[t_body_src < duration_s]

    def poses(t, noisy):
        p, R = pose(t)
        if noisy:
            p = p + rng.normal(0, noise_mm, p.shape)
            R = R @ Rotation.from_rotvec(rng.normal(0, noise_rad, (len(t), 3))).as_matrix()
        return stack_poses(p, R)

    T_B = poses(t_body_dst, True)
    T_Bsrc = poses(t_body_src, True)
    T_W = np.linalg.inv(T_B_W) @ T_Bsrc
    n_out = round(outlier_fraction * len(t_body_src))
    if n_out:
        k = rng.choice(len(t_body_src), n_out, replace=False)
        d = rng.normal(size=(n_out, 3))
        d *= (rng.uniform(*outlier_mm, n_out) / np.linalg.norm(d, axis=1))[:, None]
        T_W[k, :3, 3] += d
    return Trajectory(t_body_src - offset_s, T_W), Trajectory(t_body_dst, T_B)


def rotation_error_deg(R_a, R_b):
    c = (np.trace(R_a.T @ R_b) - 1) / 2
    return float(np.rad2deg(np.arccos(np.clip(c, -1, 1))))
