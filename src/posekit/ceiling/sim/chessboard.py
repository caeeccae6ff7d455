"""Synthetic chessboard views through a distorting lens, to test the lens calibration
(:func:`posekit.ceiling.camera.calibrate_camera`) against a known :class:`~posekit.ceiling.camera.CameraModel`.

Each output pixel of the real (distorted) image is supersampled, every sample undistorted with
the camera (``cv2.undistortPoints``), its ray intersected with the board plane and coloured by
the square it hits: exact edges through the lens, anti-aliased, with seeded sensor noise.

Frames: the board frame B has its origin at the outer corner of the first square, x along the
columns, y along the rows, z towards the camera's back (the board is seen from the front);
``T_cam_board`` maps board points (mm) into the camera frame (x right, y down, z forward).
Inner corners: ``board = (cols, rows)``, the corner ``(i, j)`` at ``((i + 1) s, (j + 1) s)`` mm.
"""

from __future__ import annotations

import math

import numpy as np

from ..._extras import lazy
from ..camera.lens import CameraModel
from ._kernels import shade_board, undistort_many

cv2 = lazy("cv2", "vision", "the chessboard renderer")

__all__ = ["board_corners", "render_board_view", "chessboard_poses"]


def board_corners(board: tuple[int, int], square_mm: float) -> np.ndarray:
    """Inner corners of the board in B, shape (cols·rows, 3), mm, OpenCV's order (row by row)."""
    cols, rows = board
    j, i = np.mgrid[0:rows, 0:cols]
    return np.column_stack([(i.ravel() + 1) * square_mm, (j.ravel() + 1) * square_mm, np.zeros(cols * rows)])


def _rot(rx: float, ry: float, rz: float) -> np.ndarray:
    cx, sx, cy, sy, cz, sz = math.cos(rx), math.sin(rx), math.cos(ry), math.sin(ry), math.cos(rz), math.sin(rz)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def chessboard_poses(camera: CameraModel, board: tuple[int, int], square_mm: float, n_views: int,
                     rng=None, *, fill: float = 0.45) -> list[np.ndarray]:
    """``n_views`` poses ``T_cam_board`` (4, 4) that put the whole board in view, tilted by up to
    ~35°, spread over the image (the centre and towards each corner) so the distortion is seen.

    ``fill`` is the board's width as a fraction of the image width at the centre view.
    """
    rng = np.random.default_rng(rng)
    w, h = camera.image_size
    K = camera.K
    cols, rows = board
    bw, bh = (cols + 1) * square_mm, (rows + 1) * square_mm
    z = K[0, 0] * bw / (fill * w)                                 # distance for the wanted size
    targets = [(0.5, 0.5), (0.2, 0.22), (0.8, 0.22), (0.2, 0.78), (0.8, 0.78), (0.5, 0.22), (0.5, 0.78),
               (0.2, 0.5), (0.8, 0.5)]
    corners = board_corners(board, square_mm)
    poses = []
    k = 0
    while len(poses) < n_views and k < 50 * n_views:
        tu, tv = targets[len(poses) % len(targets)]
        k += 1
        R = _rot(rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-0.4, 0.4))
        zi = z * rng.uniform(0.9, 1.25)
        c = np.array([(tu * w - K[0, 2]) / K[0, 0] * zi, (tv * h - K[1, 2]) / K[1, 1] * zi, zi])
        t = c - R @ np.array([bw / 2, bh / 2, 0.0])
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, t
        # whole board (outer squares included) in view, 8 px inside the border
        outer = np.array([[0, 0, 0], [bw, 0, 0], [0, bh, 0], [bw, bh, 0]], float)
        pc = np.vstack([corners, outer]) @ R.T + t
        if np.any(pc[:, 2] <= 0):
            continue
        uv = camera.normalized_to_pixels(pc[:, :2] / pc[:, 2:3])
        if np.all((uv[:, 0] > 8) & (uv[:, 0] < w - 9) & (uv[:, 1] > 8) & (uv[:, 1] < h - 9)):
            poses.append(T)
    return poses


_RAYS: dict = {}


def _rays(camera: CameraModel, s: int) -> list[np.ndarray]:
    """Undistorted rays (h·w, 3) of the s×s sub-pixel samples, cached per lens (views share them)."""
    key = (camera.K.tobytes(), camera.dist.tobytes(), tuple(camera.image_size), s)
    if key not in _RAYS:
        w, h = camera.image_size
        off = (np.arange(s) + 0.5) / s - 0.5
        vv, uu = np.mgrid[0:h, 0:w].astype(np.float64)
        rays = []
        for dv in off:
            for du in off:
                uv = np.column_stack([(uu + du).ravel(), (vv + dv).ravel()])
                xy = camera.pixels_to_normalized(uv)                  # distorted, normalized
                if camera.is_distorted:
                    x, y = np.empty(len(xy)), np.empty(len(xy))
                    undistort_many(np.ascontiguousarray(xy[:, 0]), np.ascontiguousarray(xy[:, 1]),
                                   np.asarray(camera.dist, float), x, y)
                    xy = np.column_stack([x, y])
                rays.append(np.ascontiguousarray(np.column_stack([xy, np.ones(len(xy))])))
        _RAYS.clear()
        _RAYS[key] = rays
    return _RAYS[key]


def render_board_view(camera: CameraModel, T_cam_board: np.ndarray, board: tuple[int, int], square_mm: float,
                      *, supersample: int = 3, noise_std: float = 1.5, rng=None) -> np.ndarray:
    """A grey image (h, w) uint8 of the board seen by ``camera`` at pose ``T_cam_board``.

    The board (cols + 1) × (rows + 1) squares, dark/light 40/215, on a mid-grey wall (128), a
    white margin of one square around it (as printed boards have; the detector needs it).
    """
    rng = np.random.default_rng(rng)
    w, h = camera.image_size
    s = int(supersample)
    acc = np.zeros(h * w)
    R = np.ascontiguousarray(T_cam_board[:3, :3], dtype=float)
    t = np.ascontiguousarray(T_cam_board[:3, 3], dtype=float)
    cols, rows = board
    for ray in _rays(camera, s):
        shade_board(ray, R, t, float(square_mm), int(cols), int(rows), acc)
    acc = acc.reshape(h, w)
    img = acc / (s * s) + noise_std * rng.standard_normal((h, w))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)
