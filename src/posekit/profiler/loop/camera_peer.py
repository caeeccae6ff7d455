"""Camera peer of the profiler benchmark: the chessboard pipeline of the paper's Table III.

The laser-profiler paper compares its speed with a camera system: an 8-bit 2590 x 1942
grayscale image of a chessboard with 3 x 4 inner corners (4 x 5 squares of 20 mm), processed by
OpenCV ``findChessboardCorners`` and ``cornerSubPix`` (corner detection, CD) and ``solvePnP``
(posture computation, PC). The images, with a known pose, come from :mod:`~posekit.profiler.loop.chessboard`;
this module times that pipeline on them, so ``posekit bench profiler`` can report both systems from one run.

Frames and conventions (OpenCV's):

- Board frame B: origin at the first inner corner that ``findChessboardCorners`` returns,
  x along the first row of corners (``inner[0]`` of them), y along the columns (``inner[1]``),
  z = x cross y, pointing out of the back of the board (away from a camera that sees its face).
  Lengths in mm.
- Camera frame C: x right, y down, z along the optical axis; pixel coordinates have integer
  values at pixel centres.
- A pose is ``(rvec, tvec)`` = ``T_C_B``: ``p_C = R(rvec) @ p_B + tvec``; ``rvec`` is a
  rotation vector in radians, ``tvec`` in mm, as ``cv2.solvePnP`` returns them.

Corner order. A board whose inner-corner counts have different parity (3 x 4 inner corners,
4 x 5 squares) has no 180-degree symmetry, and OpenCV orders its corners by the colour
pattern: the rendering paints the outer square next to corner 0 black (square ``(a, b)`` is
black when ``a + b`` is even), and ``findChessboardCorners`` then returns the corners in the
order of `board_object_points` for any in-plane rotation of the board (checked at 0, 90, 180
and 270 degrees and in between by ``tests/profiler/test_camera_peer.py``). Boards with counts of equal
parity are symmetric, so their detected order depends on the view; `board_object_points`
refuses them rather than resolve the ambiguity with a pose prior.

Only frames that contain the board are ever fed to the detector: with default flags and no
board in view, ``findChessboardCorners`` can run for minutes (a known OpenCV issue).
"""

from __future__ import annotations

import time

import numpy as np

from posekit._extras import lazy

from .chessboard import board_object_points, default_intrinsics, random_board_poses, render_chessboard

cv2 = lazy("cv2", "vision", "the OpenCV camera pipeline (Table III)")

__all__ = ["DETECTOR_FLAGS", "camera_pipeline", "time_camera_pipeline"]


#: ``findChessboardCorners`` flags of the comparison: OpenCV's defaults, never FAST_CHECK.
DETECTOR_FLAGS = cv2.CALIB_CB_ADAPTIVE_THRESH + cv2.CALIB_CB_NORMALIZE_IMAGE
#: ``cornerSubPix`` half window (px), dead zone and stop criteria (OpenCV tutorial values).
SUBPIX_WINDOW = (11, 11)
SUBPIX_ZERO_ZONE = (-1, -1)
SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.001)
#: solvePnP methods allowed for the comparison, by name.
PNP_METHODS = {"sqpnp": cv2.SOLVEPNP_SQPNP, "ippe": cv2.SOLVEPNP_IPPE}


def camera_pipeline(
    image: np.ndarray,
    K: np.ndarray,
    dist: np.ndarray | None,
    object_points: np.ndarray,
    inner: tuple[int, int],
    *,
    method: str = "sqpnp",
) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Board pose from one image, timing corner detection (CD) and posture computation (PC).

    CD is ``findChessboardCorners`` with OpenCV's default flags (`DETECTOR_FLAGS`) followed
    by ``cornerSubPix``; PC is one ``solvePnP`` call. Each stage is timed with
    ``time.perf_counter_ns``.

    Parameters
    ----------
    image : ndarray, shape (H, W), uint8
        Grayscale image that contains the board.
    K : ndarray, shape (3, 3)
        Camera matrix, in px.
    dist : ndarray, shape (k,), or None
        OpenCV distortion coefficients (None: no distortion).
    object_points : ndarray, shape (inner[0] * inner[1], 3)
        Corners in the board frame B, in mm, in detection order (`board_object_points`).
    inner : (int, int)
        Inner corners per row and per column (``patternSize``).
    method : {"sqpnp", "ippe"}
        ``solvePnP`` method (``SOLVEPNP_SQPNP`` or ``SOLVEPNP_IPPE``).

    Returns
    -------
    rvec : ndarray, shape (3,)
        Rotation vector of ``R_C_B``, in rad.
    tvec : ndarray, shape (3,)
        ``t_C_B``, the board origin in the camera frame C, in mm.
    cd_ms : float
        Corner-detection time, in ms.
    pc_ms : float
        Posture-computation time, in ms.

    Raises
    ------
    ValueError
        If the image is not a 2-D uint8 array or the method is unknown.
    RuntimeError
        If the board is not found or ``solvePnP`` fails.
    """
    if image.ndim != 2 or image.dtype != np.uint8:
        raise ValueError(
            f"image: expected a 2-D uint8 grayscale array, got {image.dtype} of shape {image.shape}"
        )
    if method not in PNP_METHODS:
        raise ValueError(
            f"method: expected one of {sorted(PNP_METHODS)}, got {method!r}"
        )
    flag = PNP_METHODS[method]
    pattern = (int(inner[0]), int(inner[1]))

    t0 = time.perf_counter_ns()
    found, corners = cv2.findChessboardCorners(image, pattern, flags=DETECTOR_FLAGS)
    if found:
        corners = cv2.cornerSubPix(
            image, corners, SUBPIX_WINDOW, SUBPIX_ZERO_ZONE, SUBPIX_CRITERIA
        )
    t1 = time.perf_counter_ns()
    if not found:
        raise RuntimeError(
            f"camera_pipeline: no {pattern[0]}x{pattern[1]} chessboard found in the image"
        )

    ok, rvec, tvec = cv2.solvePnP(object_points, corners, K, dist, flags=flag)
    t2 = time.perf_counter_ns()
    if not ok:
        raise RuntimeError(f"camera_pipeline: solvePnP ({method}) failed")
    return rvec.ravel(), tvec.ravel(), (t1 - t0) * 1e-6, (t2 - t1) * 1e-6


def _rotation_error_deg(rvec_a: np.ndarray, rvec_b: np.ndarray) -> float:
    R_a = cv2.Rodrigues(np.asarray(rvec_a, np.float64).reshape(3))[0]
    R_b = cv2.Rodrigues(np.asarray(rvec_b, np.float64).reshape(3))[0]
    cos = np.clip((np.trace(R_a @ R_b.T) - 1.0) / 2.0, -1.0, 1.0)
    return float(np.degrees(np.arccos(cos)))


def time_camera_pipeline(
    n_images: int = 10, repeats: int = 3, seed: int = 0, *, method: str = "sqpnp"
) -> dict[str, np.ndarray]:
    """Time the Table III camera pipeline on rendered images of known pose.

    Renders `n_images` views (`random_board_poses`, `render_chessboard` with default camera
    and noise), runs one untimed warm-up, then runs `camera_pipeline` on every image
    `repeats` times (image order within each repeat).

    Parameters
    ----------
    n_images : int
        Number of distinct rendered images.
    repeats : int
        Passes over the images.
    seed : int
        Seed of the poses and the sensor noise.
    method : {"sqpnp", "ippe"}
        ``solvePnP`` method.

    Returns
    -------
    result : dict of str to ndarray
        Arrays of shape (n_images * repeats,), one value per run:
        ``cd_ms``, ``pc_ms``, ``total_ms`` (= CD + PC) in ms; ``t_err_mm``, the distance
        between recovered and true ``t_C_B`` in mm; ``rot_err_deg``, the angle of
        ``R_est @ R_true.T`` in degrees; ``image_index``, the image of each run.
    """
    rng = np.random.default_rng(seed)
    K = default_intrinsics()
    inner = (3, 4)
    object_points = board_object_points(inner, 20.0)
    poses = random_board_poses(n_images, rng, inner=inner, K=K)
    images = [render_chessboard(rv, tv, K=K, rng=rng) for rv, tv in poses]
    camera_pipeline(images[0], K, None, object_points, inner, method=method)  # warm-up

    n_runs = n_images * repeats
    out = {
        key: np.empty(n_runs)
        for key in ("cd_ms", "pc_ms", "total_ms", "t_err_mm", "rot_err_deg")
    }
    out["image_index"] = np.empty(n_runs, dtype=np.int64)
    run = 0
    for _ in range(repeats):
        for index, (image, (rvec_true, tvec_true)) in enumerate(zip(images, poses)):
            rvec, tvec, cd_ms, pc_ms = camera_pipeline(
                image, K, None, object_points, inner, method=method
            )
            out["cd_ms"][run] = cd_ms
            out["pc_ms"][run] = pc_ms
            out["total_ms"][run] = cd_ms + pc_ms
            out["t_err_mm"][run] = np.linalg.norm(tvec - tvec_true)
            out["rot_err_deg"][run] = _rotation_error_deg(rvec, rvec_true)
            out["image_index"][run] = index
            run += 1
    return out


if (
    __name__ == "__main__"
):  # pragma: no cover - manual run: python benchmarks/_camera.py
    for name in PNP_METHODS:
        res = time_camera_pipeline(n_images=10, repeats=3, seed=0, method=name)
        print(
            f"{name}: CD median {np.median(res['cd_ms']):.3f} ms, PC median {np.median(res['pc_ms']):.4f} ms, "
            f"|t| err median {np.median(res['t_err_mm']):.4f} mm (max {res['t_err_mm'].max():.4f}), "
            f"rot err median {np.median(res['rot_err_deg']):.4f} deg (max {res['rot_err_deg'].max():.4f})"
        )
