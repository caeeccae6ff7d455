"""Where things are in the simulated ceiling scene: the fixed camera (pose, intrinsics, lens), the
homography it sees the ceiling through, and the robot's path on the floor.

Frames: world W with the ceiling plane Z = 0, X and Y along the T-bars in mm, Z up; camera x right,
y down, z forward. Pixels ``(u, v)``, u right, v down, the centre of the top-left pixel at (0, 0).
"""

from __future__ import annotations

import math

import numpy as np

from ..camera.lens import CameraModel
from .config import SceneConfig

__all__ = ["lens_camera", "true_homography", "robot_path"]


def _camera(config: SceneConfig) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """K (3, 3) in px, R_cam_world (3, 3), t_cam_world (3,) in mm (camera: x right, y down, z forward)."""
    C = np.asarray(config.camera_position_mm, float)
    forward = np.array([*config.camera_target_mm, 0.0]) - C
    forward /= np.linalg.norm(forward)
    x = np.cross(forward, [0.0, 0.0, 1.0])
    if np.linalg.norm(x) < 1e-9:                       # looking straight up: image x along world X
        x = np.array([1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    y = np.cross(forward, x)
    R = np.stack([x, y, forward])
    r = math.radians(config.camera_roll_deg)
    R = np.array([[math.cos(r), -math.sin(r), 0.0], [math.sin(r), math.cos(r), 0.0], [0.0, 0.0, 1.0]]) @ R
    K = np.array([[config.focal_px, 0.0, (config.width_px - 1) / 2.0],
                  [0.0, config.focal_px, (config.height_px - 1) / 2.0],
                  [0.0, 0.0, 1.0]])
    return K, R, -R @ C


def lens_camera(config: SceneConfig) -> CameraModel:
    """The simulated camera's lens: ``K`` (focal_px, principal point at the image centre) and
    ``dist`` of ``config`` (written as ``camera.json`` beside each rendered video)."""
    K, _, _ = _camera(config)
    return CameraModel(K=K, dist=np.asarray(config.dist, float), image_size=(config.width_px, config.height_px),
                       rms_px=0.0)


def true_homography(config: SceneConfig) -> np.ndarray:
    """H_image_world, shape (3, 3): ceiling point ``(X, Y, 1)`` in mm → image ``(u, v, 1)`` in px
    (pixel-centre convention), normalised so that ``H[2, 2] == 1``. With lens distortion these
    are *undistorted* pixels (same K); :func:`lens_camera` maps them to the distorted image."""
    K, R, t = _camera(config)
    H = K @ np.column_stack([R[:, 0], R[:, 1], t])
    return H / H[2, 2]


def _apply_h(H: np.ndarray, p: np.ndarray) -> np.ndarray:
    p = np.asarray(p, float)
    q = p @ H[:, :2].T + H[:, 2]
    return q[..., :2] / q[..., 2:3]


def robot_path(config: SceneConfig, t_s) -> tuple[np.ndarray, np.ndarray]:
    """Pose of the robot at times ``t_s`` (shape (N,), s) on the rectangle, counter-clockwise.

    The robot drives each side at ``speed_mm_s`` and turns on the spot by +90° at each corner
    at ``turn_rate_deg_s``, starting at corner (x0, y0) heading +X (at ``path_phase_s``).

    Returns
    -------
    xy : ndarray, shape (N, 2)
        Position of the robot's reference point (the red laser) in W, mm.
    heading : ndarray, shape (N,)
        Heading in rad, counter-clockwise from +X seen from above, unwrapped (continuous).
    """
    t = np.asarray(t_s, float) + config.path_phase_s
    x0, y0, x1, y1 = config.path_rect_mm
    corners = np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)
    lengths = np.array([x1 - x0, y1 - y0, x1 - x0, y1 - y0])
    t_drive = lengths / config.speed_mm_s
    t_turn = (math.pi / 2) / math.radians(config.turn_rate_deg_s)
    durations = np.ravel(np.column_stack([t_drive, np.full(4, t_turn)]))    # drive, turn, ...
    starts = np.concatenate([[0.0], np.cumsum(durations)])
    lap = starts[-1]
    laps, tau = np.divmod(t, lap)
    phase = np.clip(np.searchsorted(starts, tau, side="right") - 1, 0, 7)
    side = phase // 2
    frac = np.clip((tau - starts[phase]) / durations[phase], 0.0, 1.0)
    driving = phase % 2 == 0
    a, b = corners[side], corners[(side + 1) % 4]
    xy = np.where(driving[:, None], a + (b - a) * frac[:, None], b)
    heading = (laps * 4 + side + np.where(driving, 0.0, frac)) * (math.pi / 2)
    return xy, heading
