"""Compiled rotation conversions: the one fast path from a rotation matrix to a quaternion or
a rotation vector, for Python callers and for other numba kernels alike.

The public converters :func:`~posekit.geometry.quaternion_from_matrix` and
:func:`~posekit.geometry.rotation_vector_from_matrix` run these kernels over their batch; a
numba kernel elsewhere in posekit (the seam filter's densities, the resolved-rate step of
:mod:`posekit.robots`) calls :func:`quaternion_from_entries` / :func:`rotvec_from_entries`
inline on nine scalars, so no system keeps its own copy. scipy's
:class:`~scipy.spatial.transform.Rotation` is the reference in the tests.

Method: Shepperd's — the quaternion component of largest magnitude is computed from the
diagonal and the other three from the off-diagonal sums/differences, which is exact to
rounding for any rotation (no cancellation near 180°); the rotation vector is then
``2 atan2(‖v‖, w) v / ‖v‖`` with ``w >= 0``, accurate at 0 and at π alike.
"""

import math

import numpy as np

from posekit._jit import njit

__all__ = [
    "quaternion_from_entries",
    "quaternion_from_matrix_kernel",
    "rotvec_from_entries",
    "rotvec_from_matrix_kernel",
]


@njit(cache=True, inline="always", nogil=True)
def quaternion_from_entries(r00, r01, r02, r10, r11, r12, r20, r21, r22):
    """Unit quaternion ``(w, x, y, z)`` with ``w >= 0`` of the rotation matrix with these entries.

    A matrix that is not exactly orthogonal gives the normalised quaternion of Shepperd's
    formulas (the caller validates or projects first where that matters).
    """
    tr = r00 + r11 + r22
    if tr >= r00 and tr >= r11 and tr >= r22:
        s = 2.0 * math.sqrt(max(1.0 + tr, 0.0))
        w, x, y, z = 0.25 * s, (r21 - r12) / s, (r02 - r20) / s, (r10 - r01) / s
    elif r00 >= r11 and r00 >= r22:
        s = 2.0 * math.sqrt(max(1.0 + r00 - r11 - r22, 0.0))
        w, x, y, z = (r21 - r12) / s, 0.25 * s, (r01 + r10) / s, (r02 + r20) / s
    elif r11 >= r22:
        s = 2.0 * math.sqrt(max(1.0 - r00 + r11 - r22, 0.0))
        w, x, y, z = (r02 - r20) / s, (r01 + r10) / s, 0.25 * s, (r12 + r21) / s
    else:
        s = 2.0 * math.sqrt(max(1.0 - r00 - r11 + r22, 0.0))
        w, x, y, z = (r10 - r01) / s, (r02 + r20) / s, (r12 + r21) / s, 0.25 * s
    norm = math.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0 or (w == 0.0 and (x < 0.0 or (x == 0.0 and (y < 0.0 or (y == 0.0 and z < 0.0))))):
        norm = -norm  # canonical sign: w >= 0; at w == 0 the first non-zero of x, y, z > 0
    return w / norm, x / norm, y / norm, z / norm


@njit(cache=True, inline="always", nogil=True)
def rotvec_from_entries(r00, r01, r02, r10, r11, r12, r20, r21, r22):
    """Rotation vector ``(x, y, z)`` (axis × angle, angle in [0, π] rad) of the rotation
    matrix with these entries."""
    w, x, y, z = quaternion_from_entries(r00, r01, r02, r10, r11, r12, r20, r21, r22)
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-8:  # atan2(s, w) / s = (1 - s²/(3w²) + ...) / w: the series term is < 1e-16
        k = 2.0 / w
    else:
        k = 2.0 * math.atan2(s, w) / s
    return k * x, k * y, k * z


@njit(cache=True, nogil=True)
def quaternion_from_matrix_kernel(R, out):
    """``out[i] = [w, x, y, z]`` (``w >= 0``) of ``R[i]``; R (m, 3, 3), out (m, 4)."""
    for i in range(R.shape[0]):
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = quaternion_from_entries(
            R[i, 0, 0], R[i, 0, 1], R[i, 0, 2],
            R[i, 1, 0], R[i, 1, 1], R[i, 1, 2],
            R[i, 2, 0], R[i, 2, 1], R[i, 2, 2])


@njit(cache=True, nogil=True)
def rotvec_from_matrix_kernel(R, out):
    """``out[i]`` = rotation vector (rad) of ``R[i]``; R (m, 3, 3), out (m, 3)."""
    for i in range(R.shape[0]):
        out[i, 0], out[i, 1], out[i, 2] = rotvec_from_entries(
            R[i, 0, 0], R[i, 0, 1], R[i, 0, 2],
            R[i, 1, 0], R[i, 1, 1], R[i, 1, 2],
            R[i, 2, 0], R[i, 2, 1], R[i, 2, 2])


def _flat(R: np.ndarray) -> np.ndarray:
    """``R (..., 3, 3)`` as a C-contiguous float64 ``(m, 3, 3)`` (a view when possible)."""
    return np.ascontiguousarray(R, dtype=np.float64).reshape(-1, 3, 3)
