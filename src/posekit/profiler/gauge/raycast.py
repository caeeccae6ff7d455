"""First-hit ray casting at a gauge's faces: the one kernel of the ideal simulator
(:mod:`~posekit.profiler.sim.render`) and the as-built renderer
(:mod:`~posekit.profiler.sim.realism_render`).

A ray of the fan leaves the emitter at ``(0, 0, z_apex)`` in F along ``(dx_F, 0, dz_F)``;
:func:`ray_in_gauge` puts it in G for a pose ``T_G_F``, :func:`first_face_hit` finds the
nearest face it meets from outside (a face turned away from the ray self-occludes) within
the block's footprint: x between the face's ridges (or the block's ends), y within the
block. :func:`seen_from_behind` tells whether the line of sight to a corner meets one of its
faces from behind (through the material).
"""

import numpy as np

from posekit._jit import njit

__all__ = ["ray_in_gauge", "first_face_hit", "seen_from_behind"]


@njit(cache=True, nogil=True, inline="always")
def ray_in_gauge(R, t, z_apex, dxF, dzF):
    """Origin ``(ox, oy, oz)`` and direction ``(dx, dy, dz)`` in G (mm) of the ray ``(dxF, 0, dzF)``
    from the emitter, for the pose ``R_G_F`` (3, 3), ``t_G_F`` (3,)."""
    ox = R[0, 2] * z_apex + t[0]
    oy = R[1, 2] * z_apex + t[1]
    oz = R[2, 2] * z_apex + t[2]
    dx = R[0, 0] * dxF + R[0, 2] * dzF
    dy = R[1, 0] * dxF + R[1, 2] * dzF
    dz = R[2, 0] * dxF + R[2, 2] * dzF
    return ox, oy, oz, dx, dy, dz


@njit(cache=True, nogil=True, inline="always")
def first_face_hit(normals, offsets, ridge_q, ridge_s, x_lo, x_hi, y_lo, y_hi, ox, oy, oz, dx, dy, dz):
    """Ray parameter ``λ`` of the first face hit (``inf`` if none) and the face's index (-1).

    ``normals`` (F, 3), ``offsets`` (F,): the faces ``n · p = d`` in G, mm; ``ridge_q``,
    ``ridge_s`` (F - 1, 3): ridge k is ``q_k + y s_k`` (``s_k`` with unit y); the hit point is
    ``o + λ d``.
    """
    n_faces = normals.shape[0]
    n_ridges = ridge_q.shape[0]
    best = np.inf
    face = -1
    for f in range(n_faces):
        denom = normals[f, 0] * dx + normals[f, 1] * dy + normals[f, 2] * dz
        if denom >= 0.0:          # the ray meets the face from inside: occluded
            continue
        lam = (offsets[f] - (normals[f, 0] * ox + normals[f, 1] * oy + normals[f, 2] * oz)) / denom
        if lam <= 0.0 or lam >= best:
            continue
        px = ox + lam * dx
        py = oy + lam * dy
        if py < y_lo or py > y_hi:
            continue
        lo = x_lo
        hi = x_hi
        if f > 0:
            lo = max(lo, ridge_q[f - 1, 0] + ridge_s[f - 1, 0] * py)
        if f < n_ridges:
            hi = min(hi, ridge_q[f, 0] + ridge_s[f, 0] * py)
        if px >= lo and px <= hi:
            best = lam
            face = f
    return best, face


@njit(cache=True, nogil=True)
def seen_from_behind(normals, T_G_F, corners_F, cos_max) -> bool:
    """Whether a face meeting at a corner is seen from behind at the pose (:func:`~posekit.profiler.gauge.ambiguity.pose_is_possible`).

    ``normals`` (n + 1, 3) in G; ``T_G_F`` (4, 4); ``corners_F`` (n, 2) (x, z) in F, ridge
    order, mm: the line of sight to corner i (``R_G_F (x, 0, z)``, unit) makes
    ``normal · direction > cos_max`` with face i or face i + 1.
    """
    for i in range(corners_F.shape[0]):
        x = corners_F[i, 0]
        z = corners_F[i, 1]
        dx = T_G_F[0, 0] * x + T_G_F[0, 2] * z
        dy = T_G_F[1, 0] * x + T_G_F[1, 2] * z
        dz = T_G_F[2, 0] * x + T_G_F[2, 2] * z
        norm = np.sqrt(dx * dx + dy * dy + dz * dz)
        for f in range(i, i + 2):
            if (normals[f, 0] * dx + normals[f, 1] * dy + normals[f, 2] * dz) / norm > cos_max:
                return True
    return False
