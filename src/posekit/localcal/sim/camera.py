"""Eye-in-hand camera: ArUco markers rendered with OpenCV, detected with OpenCV's ArUco
detector and located with ``cv2.solvePnP`` (IPPE_SQUARE) by :class:`~posekit.localcal.sim.marker_detector.MarkerDetector`.

Frames: C is the camera in the OpenCV optical convention (x right, y down, z along the
optical axis); a marker frame M follows OpenCV ArUco's convention (origin at the marker
centre, x to the right and y up on the printed face, z out of the face), so a marker seen
head-on has ``R_C_M ≈ diag(1, -1, -1)``. Marker corners in M, in the order ArUco reports
them and IPPE_SQUARE expects (top-left, top-right, bottom-right, bottom-left):
``(-s/2, s/2, 0), (s/2, s/2, 0), (s/2, -s/2, 0), (-s/2, -s/2, 0)`` with ``s`` the side of
the black square in mm. mm and rad; pixels for image coordinates.

Noise: the rendered image has sub-pixel jitter of the marker corners (``noise_px``, standing
in for vibration and rolling shutter), a Gaussian blur (``blur_px``) and grey-level noise
(``noise_gray``). The pose noise of a marker then grows with its distance, as it does with
a real camera: a fixed corner noise in pixels is a lateral noise ∝ Z and a depth noise
∝ Z² / (f s).

Speed: a 1280×720 frame costs a few milliseconds. The wall texture, a unit Gaussian noise
field and a few noisy frames of the wall are computed once and cached; per frame only the
patches around the markers (quiet zone plus 12 px, enough for the detector's 13 px
threshold window) are warped, blurred and given noise in float, the rest is a copy of a
cached noisy wall frame (same noise level).
"""

import functools
from collections.abc import Sequence

import numpy as np

from posekit._extras import lazy
from posekit.errors import ConfigError, GeometryError, InputFileError
from posekit.geometry import check_transform
from posekit.localcal.model.camera import CameraIntrinsics

cv2 = lazy("cv2", "vision", "the localcal camera simulator")

__all__ = [
    "ARUCO_DICTIONARY",
    "marker_corners",
    "render_markers",
]

#: The ArUco dictionary of every marker (ids 0–49).
ARUCO_DICTIONARY = "DICT_4X4_50"
_N_IDS = 50
_CELLS = 6  # 4x4 data bits + 1-cell black border on each side
_NEAR_MM = 10.0


def _dictionary():
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, ARUCO_DICTIONARY))


@functools.lru_cache(maxsize=4)
def _ideal_pixel_map(intr: CameraIntrinsics) -> tuple[np.ndarray, float]:
    """Ideal (undistorted) pixel coordinates of every pixel of a distorted image, cached.

    Returns ``(map, r2_max)``: map (H, W, 2) float32 px, and the largest squared normalized
    radius the image covers (points beyond it are out of view).
    """
    from scipy.ndimage import map_coordinates

    H, W = intr.height, intr.width
    step_px = 4                      # exact on a 4 px grid, bilinear between (error < 1e-3 px: the map is smooth)
    uc = np.arange(0, W + step_px, step_px, dtype=np.float64)
    vc = np.arange(0, H + step_px, step_px, dtype=np.float64)
    u, v = np.meshgrid(uc, vc)
    xd = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy], axis=-1)
    xy = xd.copy()
    for _ in range(50):  # fixed point x <- x + (xd - distort(x)); converges for moderate distortion
        step = xd - intr.distort_normalized(xy)
        xy += step
        if np.max(np.abs(step)) < 1e-7:  # ~5e-5 px
            break
    rows, cols = np.meshgrid(np.arange(H) / step_px, np.arange(W) / step_px, indexing="ij")
    xy = np.stack([map_coordinates(xy[..., k], [rows, cols], order=1) for k in range(2)], axis=-1)
    r2_max = float(np.max(np.sum(xy * xy, axis=-1)))
    m = np.empty((H, W, 2), np.float32)
    m[..., 0] = intr.fx * xy[..., 0] + intr.cx
    m[..., 1] = intr.fy * xy[..., 1] + intr.cy
    m.setflags(write=False)
    return m, r2_max


def marker_corners(size_mm: float) -> np.ndarray:
    """Corners of a square marker of side ``size_mm`` in its own frame M, shape (4, 3), mm.

    Order top-left, top-right, bottom-right, bottom-left (ArUco / IPPE_SQUARE order).
    """
    h = 0.5 * float(size_mm)
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])


def _check_marker(marker_id, size_mm, name: str) -> tuple[int, float]:
    if isinstance(marker_id, bool) or not isinstance(marker_id, (int, np.integer)) or not 0 <= marker_id < _N_IDS:
        raise ConfigError(
            f"{name}: marker id {marker_id!r} is not in {ARUCO_DICTIONARY} (expected an integer 0-{_N_IDS - 1})"
        )
    try:
        size = float(size_mm)
    except (TypeError, ValueError):
        size = float("nan")
    if not (np.isfinite(size) and size > 0):
        raise ConfigError(
            f"{name}: marker {int(marker_id)} has size {size_mm!r}, expected a finite size > 0 mm"
        )
    return int(marker_id), size


def _check_image(image) -> np.ndarray:
    if not isinstance(image, np.ndarray) or image.dtype != np.uint8 or not (
        image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)
    ):
        what = (
            f"{image.dtype} of shape {image.shape}" if isinstance(image, np.ndarray) else type(image).__name__
        )
        raise InputFileError(
            f"image: expected a (H, W) uint8 grey image or (H, W, 3) uint8 BGR image, got {what}"
        )
    return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)


@functools.lru_cache(maxsize=4)
def _background(width: int, height: int) -> np.ndarray:
    """Smooth grey clutter (a textured wall), (H, W) float32 grey levels in ~[70, 180].

    Fixed (seeded once) and cached: rendering cost is then the markers only.
    """
    coarse = np.random.default_rng(20231230).uniform(70.0, 180.0, (9, 16)).astype(np.float32)
    bg = cv2.resize(coarse, (width, height), interpolation=cv2.INTER_CUBIC)
    bg.setflags(write=False)
    return bg


def _to_u8(img: np.ndarray) -> np.ndarray:
    """Round and saturate float grey levels to uint8 (same shape)."""
    return cv2.convertScaleAbs(np.maximum(img, 0.0))  # rounds and saturates


_NOISE_PAD = 64
_N_WALLS = 8


@functools.lru_cache(maxsize=4)
def _noise_bank(width: int, height: int) -> np.ndarray:
    """Unit Gaussian noise field, (H + pad, W + pad) float32, generated once and cached.

    Each frame uses a random crop (and sign) of it, so a frame costs one addition instead
    of drawing ~10^6 normal numbers; the noise at any pixel still differs between frames.
    """
    bank = np.random.default_rng(60).standard_normal(
        (height + _NOISE_PAD, width + _NOISE_PAD), dtype=np.float32
    )
    bank.setflags(write=False)
    return bank


@functools.lru_cache(maxsize=4)
def _noisy_walls(width: int, height: int, noise_gray: float) -> np.ndarray:
    """A few noisy uint8 frames of the default wall, (K, H, W), cached.

    Frame k is the wall plus ``noise_gray`` times a fixed crop of :func:`_noise_bank`,
    rounded; away from the markers a rendered frame is a copy of one of them.
    """
    if noise_gray == 0:
        walls = _to_u8(_background(width, height))[None]
    else:
        bank = _noise_bank(width, height)
        offsets = np.random.default_rng(61).integers(0, _NOISE_PAD, (_N_WALLS, 2))
        walls = np.stack(
            [
                _to_u8(_background(width, height) + np.float32(noise_gray) * bank[dy : dy + height, dx : dx + width])
                for dy, dx in offsets
            ]
        )
    walls.setflags(write=False)
    return walls


@functools.lru_cache(maxsize=64)
def _ones(n: int) -> np.ndarray:
    """(n, n) float32 ones (the alpha of a marker texture), cached, read-only."""
    ones = np.ones((n, n), np.float32)
    ones.setflags(write=False)
    return ones


@functools.lru_cache(maxsize=256)
def _marker_texture(marker_id: int, ppc: int) -> np.ndarray:
    """Grey texture of a marker with its one-cell white quiet zone, ``ppc`` px per cell.

    Returns an (n, n) float32 array, ``n = (_CELLS + 2) ppc``: black 25, white 230.
    """
    tex = cv2.aruco.generateImageMarker(_dictionary(), marker_id, _CELLS * ppc, borderBits=1)
    tex = cv2.copyMakeBorder(tex, ppc, ppc, ppc, ppc, cv2.BORDER_CONSTANT, value=255)
    tex = 25.0 + tex.astype(np.float32) * np.float32(205.0 / 255.0)
    tex.setflags(write=False)
    return tex


#: Margin around each marker's quiet zone rendered with full noise and blur, px: covers
#: the blur kernel, the detector's adaptive-threshold window (13 px) and its corner
#: refinement window (9 px), so what the detector sees of a marker is as if the whole
#: frame had been rendered.
_PATCH_MARGIN_PX = 12


def _overlapping(a, b) -> bool:
    return a[0] < b[2] and b[0] < a[2] and a[1] < b[3] and b[1] < a[3]


def _merge_boxes(boxes: list) -> list[tuple[list[int], list[int]]]:
    """Group overlapping boxes ``[x0, y0, x1, y1]``: list of (union box, sorted member indices)."""
    groups: list[tuple[list[int], list[int]]] = []
    for i, box in enumerate(boxes):
        box, members = list(box), [i]
        overlapping = [g for g in groups if _overlapping(g[0], box)]
        while overlapping:  # absorb them; the grown box may now overlap others
            for g in overlapping:
                groups.remove(g)
                box = [min(box[0], g[0][0]), min(box[1], g[0][1]), max(box[2], g[0][2]), max(box[3], g[0][3])]
                members += g[1]
            overlapping = [g for g in groups if _overlapping(g[0], box)]
        groups.append((box, sorted(members)))
    return groups


def _one_transform(T, name: str) -> np.ndarray:
    """One (4, 4) rigid transform (:func:`posekit.geometry.check_transform`, no batch)."""
    T = check_transform(T, name=name)
    if T.shape != (4, 4):
        raise GeometryError(f"{name}: expected one (4, 4) transform, got shape {T.shape}")
    return T


def _checked_markers(markers) -> tuple[list[int], np.ndarray, np.ndarray]:
    """Validate ``(marker_id, size_mm, T_C_M)`` items: ids (N,), sizes (N,) mm, T_C_M (N, 4, 4)."""
    ids, sizes, Ts = [], [], []
    for k, item in enumerate(markers):
        try:
            marker_id, size_mm, T_C_M = item
        except (TypeError, ValueError):
            raise ConfigError(
                f"markers[{k}]: expected (marker_id, size_mm, T_C_M), got {item!r}"
            ) from None
        marker_id, size = _check_marker(marker_id, size_mm, f"markers[{k}]")
        ids.append(marker_id)
        sizes.append(size)
        Ts.append(T_C_M)
    if not Ts:
        return ids, np.zeros(0), np.zeros((0, 4, 4))
    try:  # all at once; if one is bad, the per-item check names it
        T = np.array(Ts, dtype=np.float64)
        R = T[:, :3, :3]
        ok = (
            T.shape == (len(Ts), 4, 4)
            and np.all(np.isfinite(T))
            and np.max(np.abs(np.swapaxes(R, 1, 2) @ R - np.eye(3))) <= 1e-6
            and np.all(np.linalg.det(R) > 0)
            and np.max(np.abs(T[:, 3] - [0.0, 0.0, 0.0, 1.0])) <= 1e-9
        )
    except (TypeError, ValueError, IndexError):
        ok = False
    if not ok:
        T = np.stack([_one_transform(T_C_M, f"markers[{k}] T_C_M") for k, T_C_M in enumerate(Ts)])
    return ids, np.asarray(sizes), T


def render_markers(
    intr: CameraIntrinsics,
    markers: Sequence[tuple[int, float, np.ndarray]],
    rng=None,
    *,
    noise_px: float = 0.15,
    noise_gray: float = 3.0,
    blur_px: float = 0.6,
    background: np.ndarray | None = None,
) -> np.ndarray:
    """Render ArUco markers into a grey camera image.

    Each marker (black square of side ``size_mm`` plus a white quiet zone of one cell) is
    drawn with ``cv2.aruco.generateImageMarker`` and warped with ``cv2.warpPerspective``
    onto the background, far markers first (nearer ones occlude them). A marker behind the
    camera, seen from its back, or entirely out of view is not drawn; a partly visible one
    is clipped.

    Only patches around the markers (quiet zone plus a 12 px margin, overlapping patches
    merged) are rendered in float: warp, blur, grey-level noise, rounding. The rest of the
    frame is the background with the same grey-level noise (for the default wall, one of a
    few cached noisy frames); blurring the smooth background there would change nothing.
    The grey-level noise is a cached unit Gaussian field, shifted by a random offset and
    sign per frame, so every pixel's noise is normal with std ``noise_gray``, independent between
    neighbouring pixels.

    Parameters
    ----------
    intr : CameraIntrinsics
        The camera.
    markers : sequence of (marker_id, size_mm, T_C_M)
        ``marker_id`` an integer of :data:`ARUCO_DICTIONARY`; ``size_mm`` the side of the
        black square, mm; ``T_C_M`` array_like (4, 4), the marker frame in the camera
        frame, mm.
    rng : numpy.random.Generator or int or None
        Random source for the corner jitter and the image noise.
    noise_px : float
        Standard deviation of the jitter of each projected corner, px.
    noise_gray : float
        Standard deviation of the additive grey-level noise (0–255 scale).
    blur_px : float
        Gaussian blur sigma (optics), px; 0 for none.
    background : ndarray, shape (H, W), optional
        Background grey levels; by default a fixed smooth clutter (a textured wall).

    Returns
    -------
    image : ndarray, shape (H, W), uint8
        The grey image.

    Raises
    ------
    ConfigError
        An unknown marker id, a non-positive marker size or negative noise settings.
    GeometryError
        A ``T_C_M`` that is not a (4, 4) rigid transform.
    """
    for name, value in (("noise_px", noise_px), ("noise_gray", noise_gray), ("blur_px", blur_px)):
        if not (np.ndim(value) == 0 and np.isfinite(value) and value >= 0):
            raise ConfigError(f"{name} must be a finite number >= 0, got {value!r}")
    rng = np.random.default_rng(rng)
    ids, sizes, T = _checked_markers(markers)
    H, W = intr.height, intr.width
    if background is not None:
        background = np.asarray(background, dtype=np.float32)
        if background.shape != (H, W):
            raise ConfigError(f"background: expected shape ({H}, {W}), got {background.shape}")
    # all markers at once: black-square corners (jittered) and quiet-zone corners in pixels
    order = np.argsort(-T[:, 2, 3], kind="stable")  # far markers first: nearer ones drawn over them
    ids, sizes, T = [ids[i] for i in order], sizes[order], T[order]
    R, t = T[:, :3, :3], T[:, :3, 3]
    half = 0.5 * sizes[:, None, None] * np.array([[-1.0, 1.0, 0.0], [1.0, 1.0, 0.0], [1.0, -1.0, 0.0], [-1.0, -1.0, 0.0]])
    corners_M = np.concatenate([half, half * ((_CELLS + 2.0) / _CELLS)], axis=1)  # (N, 8, 3)
    p_C = corners_M @ np.swapaxes(R, 1, 2) + t[:, None, :]
    front = np.einsum("ni,ni->n", R[:, :, 2], t) < 0.0  # seen from the front
    front &= np.all(p_C[:, 4:, 2] >= _NEAR_MM, axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv_all = intr.project(p_C, distort=False)  # ideal pinhole pixels
    uv = uv_all[:, :4].copy()
    uv[front] += rng.normal(0.0, noise_px, (np.count_nonzero(front), 4, 2))  # far first
    # box of each quiet zone in the image (clipped), texture px per cell
    uv_quiet = np.clip(np.nan_to_num(uv_all[:, 4:]), -1e6, 1e6)  # finite for markers behind too
    lo, hi = uv_quiet.min(axis=1), uv_quiet.max(axis=1)
    if intr.distorted:
        # the distorted quiet-zone outline (edges bow): 5 points per edge; a marker reaching
        # beyond the field of view the image covers is not drawn (the distortion polynomial
        # folds back there)
        _, r2_max = _ideal_pixel_map(intr)
        s_ = np.linspace(0.0, 1.0, 5)[:, None]
        q = corners_M[:, 4:]
        outline = np.concatenate([q[:, j][:, None] * (1 - s_) + q[:, (j + 1) % 4][:, None] * s_ for j in range(4)],
                                 axis=1)
        o_C = outline @ np.swapaxes(R, 1, 2) + t[:, None, :]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = o_C[..., :2] / o_C[..., 2:3]
            inside = np.all(np.sum(xy * xy, axis=-1) < 1.05 * r2_max, axis=1)
            uv_d = np.clip(np.nan_to_num(intr.project(o_C)), -1e6, 1e6)
        front &= inside
        lo, hi = uv_d.min(axis=1), uv_d.max(axis=1)
    boxes = np.concatenate(
        [np.maximum(np.floor(lo) - 1, 0), np.minimum(np.ceil(hi) + 2, [W, H])], axis=1
    ).astype(np.int64)
    front &= np.all(boxes[:, :2] < boxes[:, 2:], axis=1)  # else entirely out of view
    ppcs = np.clip(np.ceil(np.max(hi - lo, axis=1) / (_CELLS + 2)), 2, 40).astype(np.int64)
    # where each visible marker lands: texture, homography texture -> image, box in the image
    drawn = []
    for k in np.flatnonzero(front):
        ppc = int(ppcs[k])
        tex = _marker_texture(ids[k], ppc)
        # texture pixel centres: the black square spans [ppc - 0.5, n - ppc - 0.5]
        a, b = ppc - 0.5, tex.shape[0] - ppc - 0.5
        src = np.array([[a, a], [b, a], [b, b], [a, b]], dtype=np.float32)
        drawn.append((tex, cv2.getPerspectiveTransform(src, uv[k].astype(np.float32)), boxes[k].tolist()))
    # one unit noise field for the frame: a random crop of the cached bank, random sign
    dy, dx, gain = 0, 0, np.float32(0.0)
    if noise_gray > 0:
        dy, dx = rng.integers(0, _NOISE_PAD, 2)
        gain = np.float32(noise_gray if rng.random() < 0.5 else -noise_gray)
    bank = _noise_bank(W, H)
    # away from the markers: the noisy background (for the default wall, a cached frame)
    if background is None:
        bg = _background(W, H)
        walls = _noisy_walls(W, H, float(noise_gray))
        img = walls[(dy * _NOISE_PAD + dx) % len(walls)].copy()  # picked by the crop: no extra draw
    else:
        bg = background
        img = _to_u8(bg + gain * bank[dy : dy + H, dx : dx + W])
    # around the markers: warp, blur and noise, patch by patch
    m = _PATCH_MARGIN_PX
    patches = [[max(x0 - m, 0), max(y0 - m, 0), min(x1 + m, W), min(y1 + m, H)] for _, _, (x0, y0, x1, y1) in drawn]
    for (px0, py0, px1, py1), members in _merge_boxes(patches):
        patch = bg[py0:py1, px0:px1].copy()
        for tex, Hm, (x0, y0, x1, y1) in (drawn[i] for i in members):  # far markers first
            if intr.distorted:  # each distorted pixel samples the texture at its ideal position
                ideal = _ideal_pixel_map(intr)[0][y0:y1, x0:x1]
                Hi = np.linalg.inv(Hm)
                den = Hi[2, 0] * ideal[..., 0] + Hi[2, 1] * ideal[..., 1] + Hi[2, 2]
                mx = ((Hi[0, 0] * ideal[..., 0] + Hi[0, 1] * ideal[..., 1] + Hi[0, 2]) / den).astype(np.float32)
                my = ((Hi[1, 0] * ideal[..., 0] + Hi[1, 1] * ideal[..., 1] + Hi[1, 2]) / den).astype(np.float32)
                warped = cv2.remap(tex, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT, borderValue=0)
                mask = cv2.remap(_ones(tex.shape[0]), mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                                 borderValue=0)
            else:
                Hm = np.array([[1.0, 0.0, -x0], [0.0, 1.0, -y0], [0.0, 0.0, 1.0]]) @ Hm
                warped = cv2.warpPerspective(tex, Hm, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR)
                mask = cv2.warpPerspective(_ones(tex.shape[0]), Hm, (x1 - x0, y1 - y0), flags=cv2.INTER_LINEAR)
            roi = patch[y0 - py0 : y1 - py0, x0 - px0 : x1 - px0]
            roi += mask * (warped - roi)
        if blur_px > 0:  # optics
            patch = cv2.GaussianBlur(patch, (0, 0), blur_px)
        if noise_gray > 0:
            patch += gain * bank[py0 + dy : py1 + dy, px0 + dx : px1 + dx]
        img[py0:py1, px0:px1] = _to_u8(patch)
    return img
