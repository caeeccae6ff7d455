"""Compiled kernels of the ceiling renderer: the ceiling's albedo (tiles, T-bars, vents, fibre
texture) at world points, its supersampled image, and the per-frame composition with noise.

World points ``X, Y`` are in mm on the ceiling plane (frame W of :mod:`posekit.ceiling.sim.render`).
"""

import functools
import math

import numpy as np

from posekit._jit import njit

__all__ = ["WALL_ALBEDO", "RIM_MM", "NOISE_LUT_BITS", "albedo_params", "ceiling_albedo", "render_albedo",
           "noise_lut", "compose", "compose_shaded", "undistort_normalized",
           "undistort_many", "shade_board"]

WALL_ALBEDO = 0.45                 # outside the ceiling (walls) and above the horizon
OUTSIDE_LENS_ALBEDO = 0.02         # a pixel no ray reaches (beyond the distortion model's fold)
RIM_MM = 30.0                      # white metal frame around a vent opening
NOISE_LUT_BITS = 16


def albedo_params(config) -> tuple[np.ndarray, np.ndarray, np.uint32]:
    """Ceiling parameters of a :class:`~posekit.ceiling.sim.config.SceneConfig` as kernel arguments:
    sizes and albedos (8,), vent openings (n, 4) in mm, texture seed."""
    p = np.array([*config.ceiling_size_mm, *config.tile_size_mm, config.tbar_width_mm / 2.0,
                  config.tile_albedo, config.tile_albedo_spread, config.tbar_albedo], np.float64)
    holes = np.asarray(config.hole_rects_mm if config.holes else (), np.float64).reshape(-1, 4)
    return p, holes, np.uint32(config.ceiling_seed & 0xFFFFFFFF)


def ceiling_albedo(config, X, Y, *, texture: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Albedo of the ceiling at world points ``X, Y`` (same shape, mm).

    Returns the albedo, a mask of the points that reflect a laser (on the ceiling, outside the
    vent openings) and a mask of the points on a tile face (where the fibre texture shows);
    ``texture=False`` leaves the fibre texture out.
    """
    X, Y = np.broadcast_arrays(np.asarray(X, np.float64), np.asarray(Y, np.float64))
    p, holes, seed = albedo_params(config)
    albedo = np.empty(X.size)
    flags = np.empty(X.size, np.uint8)
    _albedo_many(np.ascontiguousarray(X).ravel(), np.ascontiguousarray(Y).ravel(), p, holes, seed, texture,
                 albedo, flags)
    return albedo.reshape(X.shape), (flags & 1).astype(bool).reshape(X.shape), (flags & 2).astype(bool).reshape(X.shape)


@njit(cache=True)
def _hash01(i, j, seed):
    """A deterministic pseudo-random value in [0, 1) per integer lattice point (i, j)."""
    m = np.uint64(0xFFFFFFFF)
    h = ((np.uint64(np.int64(i) & 0xFFFFFFFF) * np.uint64(73856093))
         ^ (np.uint64(np.int64(j) & 0xFFFFFFFF) * np.uint64(19349663))
         ^ (np.uint64(seed) * np.uint64(83492791)) ^ np.uint64(0x9E3779B9)) & m
    h ^= h >> np.uint64(13)
    h = (h * np.uint64(0x5BD1E995)) & m
    h ^= h >> np.uint64(15)
    return np.float64(h) / 4294967296.0


@njit(cache=True)
def _value_noise(x, y, seed):
    """Bilinearly interpolated lattice noise in [0, 1) (the fibre texture of a mineral tile)."""
    i, j = math.floor(x), math.floor(y)
    fx, fy = x - i, y - j
    fx, fy = fx * fx * (3 - 2 * fx), fy * fy * (3 - 2 * fy)
    a, b = _hash01(i, j, seed), _hash01(i + 1, j, seed)
    c, d = _hash01(i, j + 1, seed), _hash01(i + 1, j + 1, seed)
    return (a * (1 - fx) + b * fx) * (1 - fy) + (c * (1 - fx) + d * fx) * fy


@njit(cache=True)
def _texture(X, Y, seed):
    """Fibre texture: albedo offsets at two scales (25 mm and 7 mm)."""
    return (0.025 * (2.0 * _value_noise(X / 25.0, Y / 25.0, seed + np.uint32(1)) - 1.0)
            + 0.012 * (2.0 * _value_noise(X / 7.0, Y / 7.0, seed + np.uint32(2)) - 1.0))


@njit(cache=True)
def _albedo_at(X, Y, p, holes, seed, texture):
    """(albedo, flags) of the ceiling at (X, Y) mm; flags: 1 reflects a laser, 2 tile face."""
    sx, sy, tx, ty, half, tile, spread, tbar = p[0], p[1], p[2], p[3], p[4], p[5], p[6], p[7]
    if not (0.0 <= X <= sx and 0.0 <= Y <= sy):
        return WALL_ALBEDO, np.uint8(0)
    ix, iy = math.floor(X / tx), math.floor(Y / ty)
    dx = min(X - ix * tx, (ix + 1) * tx - X)
    dy = min(Y - iy * ty, (iy + 1) * ty - Y)
    edge = min(min(X, sx - X), min(Y, sy - Y))
    for k in range(holes.shape[0]):
        x0, y0, x1, y1 = holes[k, 0], holes[k, 1], holes[k, 2], holes[k, 3]
        if x0 < X < x1 and y0 < Y < y1:                               # the vent opening
            return 0.05 + 0.07 * (math.floor((Y - y0) / 40.0) % 2), np.uint8(0)
        if x0 - RIM_MM <= X <= x1 + RIM_MM and y0 - RIM_MM <= Y <= y1 + RIM_MM:
            return 0.85, np.uint8(1)                                  # its white metal frame
    if dx < half or dy < half or edge < half:
        return tbar, np.uint8(1)
    albedo = tile + spread * (2.0 * _hash01(ix, iy, seed) - 1.0)
    if texture:
        albedo += _texture(X, Y, seed)
    return albedo, np.uint8(3)


@njit(cache=True)
def _albedo_many(X, Y, p, holes, seed, texture, albedo, flags):
    for k in range(X.size):
        albedo[k], flags[k] = _albedo_at(X[k], Y[k], p, holes, seed, texture)


@njit(cache=True)
def undistort_normalized(xd, yd, dist):
    """Undistorted normalized coordinates of distorted ones (OpenCV's fixed-point iteration,
    run to 1e-12); ``dist = [k1, k2, p1, p2, k3]``."""
    k1, k2, p1, p2, k3 = dist[0], dist[1], dist[2], dist[3], dist[4]
    x, y = xd, yd
    for _ in range(100):
        r2 = x * x + y * y
        icdist = 1.0 / (1.0 + r2 * (k1 + r2 * (k2 + r2 * k3)))
        if icdist <= 0.0:                 # beyond the lens model's fold: give up on this point
            return np.nan, np.nan
        dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
        dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
        xn, yn = (xd - dx) * icdist, (yd - dy) * icdist
        if abs(xn - x) + abs(yn - y) < 1e-12:
            x, y = xn, yn
            break
        x, y = xn, yn
    r2 = x * x + y * y
    if 1.0 + r2 * (3.0 * k1 + r2 * (5.0 * k2 + r2 * 7.0 * k3)) <= 0.0:     # beyond the fold: no ray
        return np.nan, np.nan
    rd2 = xd * xd + yd * yd
    rad = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    if abs(math.sqrt(r2) * rad - math.sqrt(rd2)) > 1e-6 * (1.0 + math.sqrt(rd2)) and p1 == 0.0 and p2 == 0.0:
        return np.nan, np.nan                                                 # not converged
    return x, y


@njit(cache=True)
def undistort_many(xd, yd, dist, x, y):
    """:func:`undistort_normalized` of every (xd[k], yd[k]) into x[k], y[k] (NaN: no ray)."""
    for k in range(xd.shape[0]):
        x[k], y[k] = undistort_normalized(xd[k], yd[k], dist)


@njit(cache=True)
def shade_board(rays, R, t, square, cols, rows, acc):
    """Add to ``acc`` (N,) the grey level of a chessboard (cols+1)×(rows+1) squares of ``square``
    mm at pose (R, t) seen along each camera ray (N, 3): squares 40/215, a one-square white
    margin (215), a grey wall (128) elsewhere."""
    n0, n1, n2 = R[0, 2], R[1, 2], R[2, 2]
    nt = n0 * t[0] + n1 * t[1] + n2 * t[2]
    for k in range(rays.shape[0]):
        den = rays[k, 0] * n0 + rays[k, 1] * n1 + rays[k, 2] * n2
        val = 128.0
        if den != 0.0 and rays[k, 0] == rays[k, 0]:
            lam = nt / den
            if lam > 0.0:
                px, py, pz = lam * rays[k, 0] - t[0], lam * rays[k, 1] - t[1], lam * rays[k, 2] - t[2]
                x = (px * R[0, 0] + py * R[1, 0] + pz * R[2, 0]) / square
                y = (px * R[0, 1] + py * R[1, 1] + pz * R[2, 1]) / square
                if 0.0 <= x < cols + 1 and 0.0 <= y < rows + 1:
                    val = 40.0 if (math.floor(x) + math.floor(y)) % 2 == 0 else 215.0
                elif -1.0 <= x < cols + 2 and -1.0 <= y < rows + 2:
                    val = 215.0
        acc[k] += val


@njit(cache=True)
def _undistort_pixel(u, v, K, dist, lens):
    """Undistorted pixel (same K) of the distorted pixel (u, v); identity without a lens."""
    if not lens:
        return u, v
    y = (v - K[1, 2]) / K[1, 1]
    x = (u - K[0, 2] - K[0, 1] * y) / K[0, 0]
    xu, yu = undistort_normalized(x, y, dist)
    return K[0, 0] * xu + K[0, 1] * yu + K[0, 2], K[1, 1] * yu + K[1, 2]


@njit(cache=True)
def render_albedo(H_world_image, h, w, s, p, holes, seed, K, dist):
    """Mean albedo over s×s samples per pixel, plus the fibre texture at the pixel centre
    weighted by the pixel's tile-face coverage; shape (h, w).

    Pixels are those of the real (distorted) camera: each sample is undistorted with ``K`` and
    ``dist = [k1, k2, p1, p2, k3]`` (all zero: a pinhole) before ``H_world_image`` maps it to the
    ceiling."""
    lens = False
    for k in range(dist.shape[0]):
        if dist[k] != 0.0:
            lens = True
    out = np.empty((h, w))
    for i in range(h):
        for j in range(w):
            acc = 0.0
            face = 0.0
            for a in range(s):
                vd = i + (a + 0.5) / s - 0.5
                for b in range(s):
                    ud = j + (b + 0.5) / s - 0.5
                    u, v = _undistort_pixel(ud, vd, K, dist, lens)
                    if u != u:                                        # outside the lens's image circle
                        acc += OUTSIDE_LENS_ALBEDO
                        continue
                    q0 = H_world_image[0, 0] * u + H_world_image[0, 1] * v + H_world_image[0, 2]
                    q1 = H_world_image[1, 0] * u + H_world_image[1, 1] * v + H_world_image[1, 2]
                    q2 = H_world_image[2, 0] * u + H_world_image[2, 1] * v + H_world_image[2, 2]
                    if not (q2 > 0.0):                                # above the horizon: a wall
                        acc += WALL_ALBEDO
                        continue
                    alb, fl = _albedo_at(q0 / q2, q1 / q2, p, holes, seed, False)
                    acc += alb
                    face += fl >> 1
            acc /= s * s
            if face > 0:
                u, v = _undistort_pixel(float(j), float(i), K, dist, lens)
                q0 = H_world_image[0, 0] * u + H_world_image[0, 1] * v + H_world_image[0, 2]
                q1 = H_world_image[1, 0] * u + H_world_image[1, 1] * v + H_world_image[1, 2]
                q2 = H_world_image[2, 0] * u + H_world_image[2, 1] * v + H_world_image[2, 2]
                if q2 > 0.0:
                    acc += face / (s * s) * _texture(q0 / q2, q1 / q2, seed)
            out[i, j] = acc
    return out


@functools.lru_cache(maxsize=1)
def noise_lut() -> np.ndarray:
    """Standard normal quantiles of 2**16 equiprobable bins (noise from 16 random bits)."""
    from scipy.special import ndtri  # here: scipy.special costs 0.15-1.5 s at every start of `ceiling track`

    n = 1 << NOISE_LUT_BITS
    return ndtri((np.arange(n) + 0.5) / n).astype(np.float32)


@njit(cache=True, fastmath=True, boundscheck=False)
def compose(bg, gain_rows, gain_cols, offset, noise_bits, lut, sigma, out):
    """out = clip(round(bg * (gain_rows[i] + gain_cols[j]) + offset + sigma * lut[bits]))."""
    h, w, _ = bg.shape
    k = 0
    for i in range(h):
        gi = gain_rows[i]
        for j in range(w):
            g = gi + gain_cols[j]
            for c in range(3):
                val = bg[i, j, c] * g + offset + sigma * lut[noise_bits[k]] + np.float32(0.5)
                k += 1
                out[i, j, c] = np.uint8(min(max(val, np.float32(0.0)), np.float32(255.0)))
    return out


@njit(cache=True, fastmath=True, boundscheck=False)
def compose_shaded(bg, shade, gain_rows, gain_cols, offset, noise_bits, lut, sigma, out):
    """As :func:`compose` with a per-pixel illumination factor ``shade`` (h, w) on the ceiling
    (shadows): out = clip(round(bg * shade[i, j] * (gain_rows[i] + gain_cols[j]) + offset + noise))."""
    h, w, _ = bg.shape
    k = 0
    for i in range(h):
        gi = gain_rows[i]
        for j in range(w):
            g = (gi + gain_cols[j]) * shade[i, j]
            for c in range(3):
                val = bg[i, j, c] * g + offset + sigma * lut[noise_bits[k]] + np.float32(0.5)
                k += 1
                out[i, j, c] = np.uint8(min(max(val, np.float32(0.0)), np.float32(255.0)))
    return out


# --- truth ------------------------------------------------------------------------------------
