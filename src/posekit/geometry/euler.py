"""Euler angles as robot controllers want them, and back.

Two conventions, the same matrix with the angles in the other order:

``zyx`` (intrinsic Z-Y'-X'')
    ``[A, B, C]`` with ``R = Rz(A) Ry(B) Rx(C)``: KUKA's A, B, C (yaw, pitch, roll about the
    moving axes). scipy: ``Rotation.from_euler("ZYX", [A, B, C])``.
``xyz`` (extrinsic, fixed axes X-Y-Z)
    ``[W, P, R]``: W about the fixed x, then P about the fixed y, then R about the fixed z,
    ``R = Rz(R) Ry(P) Rx(W)``: Fanuc's W, P, R and ABB's Euler angles. scipy:
    ``Rotation.from_euler("xyz", [W, P, R])``. ``[W, P, R] = [C, B, A]``.

Ranges: the first and last angle in (-π, π], the middle one in [-π/2, π/2]. At gimbal lock
(middle angle ±π/2, ``cos B`` below :data:`GIMBAL_COS`) only ``A ∓ C`` is defined: C (W of
``xyz``) is set to 0 and A (R of ``xyz``) carries the whole turn, as scipy does.
"""

import numpy as np

from ._rotations import check_rotation_matrix

__all__ = ["euler_zyx_from_matrix", "euler_xyz_from_matrix", "matrix_from_euler_zyx", "GIMBAL_COS"]

#: ``cos B`` below which the angles are at gimbal lock (``|B|`` within about 1e-7° of 90°).
GIMBAL_COS = 2e-9


def euler_zyx_from_matrix(R, *, check: bool = True) -> np.ndarray:
    """Intrinsic Z-Y'-X'' angles ``[A, B, C]`` with ``R = Rz(A) Ry(B) Rx(C)``.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotations ``R_a_b`` (any leading batch axes); with ``check`` (default) validated by
        :func:`~posekit.geometry.check_rotation_matrix`, else taken as they are.

    Returns
    -------
    ndarray, shape (..., 3)
        ``[A, B, C]`` in rad: A, C in (-π, π], B in [-π/2, π/2]; at gimbal lock C = 0.
        :func:`matrix_from_euler_zyx` of them gives ``R`` back to rounding, and at gimbal lock to
        ``2 cos B`` (≤ ``2 GIMBAL_COS``: the part of ``R`` that C = 0 cannot hold).

    Raises
    ------
    GeometryError
        If ``check`` and ``R`` is not a batch of rotation matrices.

    Examples
    --------
    >>> euler_zyx_from_matrix(matrix_from_euler_zyx([0.3, -0.2, 1.0])).round(12)
    array([ 0.3, -0.2,  1. ])
    """
    R = check_rotation_matrix(R) if check else np.asarray(R, dtype=np.float64)
    cb = np.hypot(R[..., 0, 0], R[..., 1, 0])
    b = np.arctan2(-R[..., 2, 0], cb)
    lock = cb <= GIMBAL_COS
    a = np.where(lock, np.arctan2(-R[..., 0, 1], R[..., 1, 1]), np.arctan2(R[..., 1, 0], R[..., 0, 0]))
    # C from A and the columns 1, 2 (sin C = sA R02 - cA R12, cos C = cA R11 - sA R01 for any B), not from R21, R22:
    # near gimbal lock those two are of size cos B and A, C each carry an error eps / cos B, while C taken this
    # way cancels A's and the angles give R back to rounding (M. Day, Extracting Euler angles from a rotation matrix, 2014)
    sa, ca = np.sin(a), np.cos(a)
    c = np.where(lock, 0.0, np.arctan2(sa * R[..., 0, 2] - ca * R[..., 1, 2], ca * R[..., 1, 1] - sa * R[..., 0, 1]))
    out = np.stack([a, b, c], axis=-1) + 0.0                       # + 0.0: no -0.0
    out[..., [0, 2]] = np.where(out[..., [0, 2]] <= -np.pi, np.pi, out[..., [0, 2]])   # (-π, π]
    return out


def euler_xyz_from_matrix(R, *, check: bool = True) -> np.ndarray:
    """Extrinsic (fixed-axis) X-Y-Z angles ``[W, P, R]`` with ``R = Rz(R) Ry(P) Rx(W)``.

    The angles of :func:`euler_zyx_from_matrix` in reverse order (same ranges; at gimbal lock
    W = 0).

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
    check : bool

    Returns
    -------
    ndarray, shape (..., 3)
        ``[W, P, R]`` in rad.
    """
    return euler_zyx_from_matrix(R, check=check)[..., ::-1].copy()


def matrix_from_euler_zyx(abc) -> np.ndarray:
    """``R = Rz(A) Ry(B) Rx(C)`` from intrinsic Z-Y'-X'' angles.

    Parameters
    ----------
    abc : array_like, shape (..., 3)
        ``[A, B, C]`` in rad.

    Returns
    -------
    ndarray, shape (..., 3, 3)
    """
    abc = np.asarray(abc, dtype=np.float64)
    ca, cb, cc = np.cos(abc[..., 0]), np.cos(abc[..., 1]), np.cos(abc[..., 2])
    sa, sb, sc = np.sin(abc[..., 0]), np.sin(abc[..., 1]), np.sin(abc[..., 2])
    R = np.empty(abc.shape[:-1] + (3, 3))
    R[..., 0, 0] = ca * cb
    R[..., 0, 1] = ca * sb * sc - sa * cc
    R[..., 0, 2] = ca * sb * cc + sa * sc
    R[..., 1, 0] = sa * cb
    R[..., 1, 1] = sa * sb * sc + ca * cc
    R[..., 1, 2] = sa * sb * cc - ca * sc
    R[..., 2, 0] = -sb
    R[..., 2, 1] = cb * sc
    R[..., 2, 2] = cb * cc
    return R
