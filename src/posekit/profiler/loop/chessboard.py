"""The simulated camera of the paper's Table III: chessboard images with a known pose.

An 8-bit 2590 x 1942 grayscale image (:data:`IMAGE_SIZE`) of a printed chessboard with 3 x 4
inner corners (4 x 5 squares of 20 mm) on a white sheet, rendered by a pinhole camera
(:func:`default_intrinsics`) at a pose ``(rvec, tvec)`` = ``T_C_B`` (:func:`render_chessboard`),
and poses that keep the whole board in view (:func:`random_board_poses`). The OpenCV pipeline
that reads them, and its timing, is :mod:`~posekit.profiler.loop.camera_peer`; frames, units and
the corner order are described there.
"""

from __future__ import annotations

import numpy as np

from posekit._extras import lazy

cv2 = lazy("cv2", "vision", "the simulated chessboard camera (Table III)")

__all__ = ["IMAGE_SIZE", "board_object_points", "default_intrinsics", "random_board_poses", "render_chessboard"]


#: Image size of the paper's camera (Basler acA2500-14gc), (width, height) px.
IMAGE_SIZE = (2590, 1942)

# Scene radiometry (8-bit digital numbers): a printed board on a white sheet, grey background.
_BACKGROUND_DN = 110.0
_PAPER_DN = 215.0
_INK_DN = 35.0
# Texture resolution: texels per image pixel at the nearest point of the sheet.
_SUPERSAMPLING = 2.0
# Fixed-point scale of the uint16 texture (keeps sub-DN precision through blur and warp).
_FIXED_POINT = 256.0
# Quiet zone required in view around the squares by `random_board_poses`, in squares.
_QUIET_ZONE_SQUARES = 0.5
_VIEW_MARGIN_PX = 10.0


def default_intrinsics(
    width: int = 2590, height: int = 1942, focal_mm: float = 16.0, pixel_um: float = 2.2
) -> np.ndarray:
    """Camera matrix of the Table III camera: 2590 x 1942 px, 16 mm lens, 2.2 um pixels.

    Parameters
    ----------
    width, height : int
        Image size in pixels.
    focal_mm : float
        Focal length of the lens, in mm.
    pixel_um : float
        Pixel pitch, in um (square pixels).

    Returns
    -------
    K : ndarray, shape (3, 3), float64
        ``[[f, 0, cx], [0, f, cy], [0, 0, 1]]`` with ``f = focal_mm / pixel pitch`` in px
        (7272.7 px by default) and the principal point at the image centre
        ``((width - 1) / 2, (height - 1) / 2)``; zero skew. Distortion is zero.
    """
    f_px = focal_mm / (pixel_um * 1e-3)
    return np.array(
        [
            [f_px, 0.0, (width - 1) / 2.0],
            [0.0, f_px, (height - 1) / 2.0],
            [0.0, 0.0, 1.0],
        ]
    )


def _check_inner(inner: tuple[int, int]) -> tuple[int, int]:
    nx, ny = (int(v) for v in inner)
    if nx < 2 or ny < 2 or (nx, ny) != tuple(inner):
        raise ValueError(
            f"inner: expected two integers >= 2 (corners per row, per column), got {inner!r}"
        )
    return nx, ny


def board_object_points(
    inner: tuple[int, int] = (3, 4), square_mm: float = 20.0
) -> np.ndarray:
    """Inner corners of the board in the order ``findChessboardCorners`` returns them.

    Parameters
    ----------
    inner : (int, int)
        Inner corners per row and per column (OpenCV's ``patternSize``); the counts must have
        different parity (e.g. ``(3, 4)``) so that the board has no 180-degree symmetry.
    square_mm : float
        Side of a square, in mm.

    Returns
    -------
    points_B : ndarray, shape (inner[0] * inner[1], 3), float32
        Corners in the board frame B, in mm, row by row: point ``i * inner[0] + j`` is
        ``(j * square_mm, i * square_mm, 0)``.

    Raises
    ------
    ValueError
        If the counts are not integers >= 2 or have equal parity (a symmetric board, whose
        detected corner order depends on the view).
    """
    nx, ny = _check_inner(inner)
    if nx % 2 == ny % 2:
        raise ValueError(
            f"inner={inner!r}: a board whose inner-corner counts have equal parity is symmetric "
            "and its detected corner order is ambiguous; expected counts of different parity, "
            "e.g. (3, 4)"
        )
    jj, ii = np.meshgrid(np.arange(nx), np.arange(ny))
    points = np.zeros((nx * ny, 3), np.float32)
    points[:, 0] = jj.ravel() * square_mm
    points[:, 1] = ii.ravel() * square_mm
    return points


def _pose_matrix(rvec: np.ndarray, tvec: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    rvec = np.asarray(rvec, dtype=np.float64).reshape(3)
    tvec = np.asarray(tvec, dtype=np.float64).reshape(3)
    return cv2.Rodrigues(rvec)[0], tvec


def render_chessboard(
    rvec: np.ndarray,
    tvec: np.ndarray,
    *,
    width: int = 2590,
    height: int = 1942,
    inner: tuple[int, int] = (3, 4),
    square_mm: float = 20.0,
    K: np.ndarray | None = None,
    rng: np.random.Generator | int | None = None,
    noise_dn: float = 2.0,
    blur_sigma_px: float = 0.8,
) -> np.ndarray:
    """Render an 8-bit camera image of a printed chessboard seen at a known pose.

    The board has ``(inner[0] + 1) x (inner[1] + 1)`` squares (the outer square next to
    corner 0 black) printed on a white sheet with a one-square margin, in front of a
    mid-grey background. The image is formed as a camera would: the sheet texture (edges on
    texel boundaries, so area-exact) is blurred by the optics' Gaussian PSF plus the pixel
    aperture, mapped through the pinhole model with ``cv2.warpPerspective`` (about 2 texels
    per pixel, so sampling a band-limited texture), then Gaussian sensor noise is added and
    the result rounded to 8 bits.

    Parameters
    ----------
    rvec : array_like, shape (3,)
        Rotation vector of ``R_C_B`` (board frame B into camera frame C), in rad.
    tvec : array_like, shape (3,)
        ``t_C_B``, the board origin (corner 0) in the camera frame C, in mm.
    width, height : int
        Image size in pixels.
    inner : (int, int)
        Inner corners per row and per column (OpenCV's ``patternSize``).
    square_mm : float
        Side of a square, in mm.
    K : ndarray, shape (3, 3), optional
        Camera matrix in px; `default_intrinsics` of the image size if None. No distortion.
    rng : numpy.random.Generator or int or None
        Source (or seed) of the sensor noise.
    noise_dn : float
        Standard deviation of the additive Gaussian sensor noise, in digital numbers.
    blur_sigma_px : float
        Standard deviation of the optical Gaussian PSF, in px (the 1-px pixel aperture is
        added to it).

    Returns
    -------
    image : ndarray, shape (height, width), uint8
        The grayscale image.

    Raises
    ------
    ValueError
        If part of the sheet is not in front of the camera.
    """
    nx, ny = _check_inner(inner)
    if K is None:
        K = default_intrinsics(width, height)
    K = np.asarray(K, dtype=np.float64)
    R_C_B, t_C_B = _pose_matrix(rvec, tvec)
    rng = np.random.default_rng(rng)

    # Sheet: (nx + 3) x (ny + 3) cells of one square each (margin of one square all round).
    cells_x, cells_y = nx + 3, ny + 3
    x0 = y0 = -2.0 * square_mm
    corners_B = np.array(
        [
            [x0 + a * cells_x * square_mm, y0 + b * cells_y * square_mm, 0.0]
            for a in (0, 1)
            for b in (0, 1)
        ]
    )
    depth = (corners_B @ R_C_B.T + t_C_B)[:, 2]
    if depth.min() <= 1.0:
        raise ValueError(
            f"render_chessboard: the sheet must lie in front of the camera, nearest depth is {depth.min():.1f} mm"
        )
    f_px = max(K[0, 0], K[1, 1])
    magnification = f_px / depth.min()  # px per mm at the nearest point
    texels_per_mm = max(1, int(np.ceil(_SUPERSAMPLING * magnification)))
    cell = round(square_mm * texels_per_mm)
    texels_per_mm_exact = cell / square_mm

    levels = np.full((cells_y, cells_x), _PAPER_DN)
    a, b = np.meshgrid(np.arange(nx + 1), np.arange(ny + 1))
    levels[1:-1, 1:-1] = np.where((a + b) % 2 == 0, _INK_DN, _PAPER_DN)
    levels = np.round(levels * _FIXED_POINT).astype(np.uint16)
    texture = np.repeat(np.repeat(levels, cell, axis=0), cell, axis=1)

    texel_sigma = (
        np.hypot(blur_sigma_px, np.sqrt(1.0 / 12.0))
        * texels_per_mm_exact
        / magnification
    )
    pad = int(np.ceil(4.0 * texel_sigma)) + 2
    background = round(_BACKGROUND_DN * _FIXED_POINT)
    texture = cv2.copyMakeBorder(
        texture, pad, pad, pad, pad, cv2.BORDER_CONSTANT, value=background
    )
    texture = cv2.GaussianBlur(texture, (0, 0), texel_sigma)

    # Texel (u, v) has its centre at board point (x0 + (u - pad + 0.5) / tpm, y0 + ...).
    s = 1.0 / texels_per_mm_exact
    B_from_texel = np.array(
        [
            [s, 0.0, x0 + (0.5 - pad) * s],
            [0.0, s, y0 + (0.5 - pad) * s],
            [0.0, 0.0, 1.0],
        ]
    )
    H_image_texel = (
        K @ np.column_stack([R_C_B[:, 0], R_C_B[:, 1], t_C_B]) @ B_from_texel
    )
    image = cv2.warpPerspective(
        texture,
        H_image_texel,
        (width, height),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=background,
    ).astype(np.float32)
    if noise_dn > 0:
        noise = rng.standard_normal((height, width), dtype=np.float32)
        image = cv2.scaleAdd(noise, float(noise_dn * _FIXED_POINT), image)
    np.clip(image, 0.0, 255.0 * _FIXED_POINT, out=image)
    return cv2.convertScaleAbs(image, alpha=1.0 / _FIXED_POINT)


def _in_view(points_px: np.ndarray, width: int, height: int, margin: float) -> bool:
    return bool(
        np.all(points_px[:, 0] >= margin)
        and np.all(points_px[:, 0] <= width - 1 - margin)
        and np.all(points_px[:, 1] >= margin)
        and np.all(points_px[:, 1] <= height - 1 - margin)
    )


def random_board_poses(
    count: int,
    rng: np.random.Generator | int | None,
    *,
    inner: tuple[int, int] = (3, 4),
    square_mm: float = 20.0,
    K: np.ndarray | None = None,
    width: int = 2590,
    height: int = 1942,
    depth_mm: tuple[float, float] = (500.0, 900.0),
    max_tilt_deg: float = 25.0,
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Random views of the board, fully in the image.

    Each pose turns the board about its normal by a uniform angle in [-180, 180) degrees,
    tilts it about a uniformly oriented in-plane axis by a uniform angle in
    ``[0, max_tilt_deg]`` (the angle between the board normal and the optical axis), and puts
    the centre of the squares at a uniform depth in `depth_mm` and a uniform image position.
    Views are redrawn until the squares plus half a square of white quiet zone project at least
    10 px inside the image.

    Parameters
    ----------
    count : int
        Number of poses.
    rng : numpy.random.Generator or int or None
        Random source or seed; the same seed gives the same poses.
    inner, square_mm, K, width, height
        Board and camera as in `render_chessboard`.
    depth_mm : (float, float)
        Range of the depth of the board centre along the optical axis, in mm.
    max_tilt_deg : float
        Largest angle between the board normal and the optical axis, in degrees.

    Returns
    -------
    poses : list of (rvec, tvec)
        ``rvec`` ndarray, shape (3,): rotation vector of ``R_C_B`` in rad; ``tvec`` ndarray,
        shape (3,): ``t_C_B`` in mm (see the module docstring for the frames).

    Raises
    ------
    RuntimeError
        If no view fits the image after many draws (board too large for the depth range).
    """
    nx, ny = _check_inner(inner)
    if K is None:
        K = default_intrinsics(width, height)
    K = np.asarray(K, dtype=np.float64)
    rng = np.random.default_rng(rng)
    q = _QUIET_ZONE_SQUARES
    outline_B = square_mm * np.array(
        [
            [-1 - q, -1 - q, 0.0],
            [nx + q, -1 - q, 0.0],
            [nx + q, ny + q, 0.0],
            [-1 - q, ny + q, 0.0],
        ]
    )
    centre_B = square_mm * np.array([(nx - 1) / 2.0, (ny - 1) / 2.0, 0.0])
    poses: list[tuple[np.ndarray, np.ndarray]] = []
    attempts = 0
    while len(poses) < count:
        attempts += 1
        if attempts > 1000 * max(count, 1):
            raise RuntimeError(
                f"random_board_poses: no view of a {inner} board with {square_mm} mm squares fits "
                f"a {width}x{height} image at depths {depth_mm} mm"
            )
        spin = rng.uniform(-np.pi, np.pi)
        tilt = np.deg2rad(rng.uniform(0.0, max_tilt_deg))
        axis_angle = rng.uniform(-np.pi, np.pi)
        R_spin = cv2.Rodrigues(np.array([0.0, 0.0, spin]))[0]
        R_tilt = cv2.Rodrigues(
            tilt * np.array([np.cos(axis_angle), np.sin(axis_angle), 0.0])
        )[0]
        R_C_B = R_tilt @ R_spin
        depth = rng.uniform(*depth_mm)
        u = rng.uniform(0.0, width - 1.0)
        v = rng.uniform(0.0, height - 1.0)
        centre_C = depth * np.linalg.solve(K, np.array([u, v, 1.0]))
        t_C_B = centre_C - R_C_B @ centre_B
        outline_C = outline_B @ R_C_B.T + t_C_B
        if np.any(outline_C[:, 2] <= 0):
            continue
        outline_px = (outline_C / outline_C[:, 2:]) @ K.T
        if _in_view(outline_px[:, :2], width, height, _VIEW_MARGIN_PX):
            poses.append((cv2.Rodrigues(R_C_B)[0].ravel(), t_C_B))
    return poses
