"""The one compiled forward kinematics and geometric Jacobian of every serial chain (numba).

Every chain — a DH table or a URDF path — is the same internal representation, a
*kinematic pack*:

``M`` : float64 (n + 1, 4, 4)
    ``M[i]`` (i < n) is the fixed transform from the frame after joint i - 1's motion (the base
    for i = 0) to joint i's frame at q = 0 (a URDF joint's ``<origin>``, fixed joints folded
    in; for DH row i it is the row ``i - 1`` transform at zero joint value). ``M[n]`` maps the
    frame after the last joint to the tip (the flange, times ``T_flange_tool`` when the tool
    is included). Translations in mm.
``A`` : float64 (n, 4)
    ``A[i, :3]`` the unit joint axis in joint i's frame, ``A[i, 3]`` 1.0 for a prismatic and
    0.0 for a revolute joint.

``T_base_tip = M[0] J_0(q_0) M[1] J_1(q_1) ··· M[n-1] J_{n-1}(q_{n-1}) M[n]`` where ``J_i`` is
the rotation by ``q_i`` about the axis (rad), or the translation ``q_i`` along it (mm).

The geometric Jacobian (base frame) has column i = ``[w_i × (p_tip - o_i); w_i]`` for a
revolute joint and ``[w_i; 0]`` for a prismatic one, with ``w_i`` the joint axis and ``o_i`` a
point on it, both in the base frame: rows ``[v (mm/rad or mm/mm); ω (rad/rad or 0)]``.

:func:`fk_jacobian_into` is the kernel other numba code calls inside its own loops (the
long-reach arm simulator, the resolved-rate step); the others wrap it for single
configurations and batches from Python.
"""

import math

import numpy as np

from posekit._jit import njit

__all__ = [
    "fk_batch",
    "fk_into",
    "fk_jacobian_batch",
    "fk_jacobian_into",
    "fk_jacobian_single",
    "fk_single",
    "joint_axes_batch",
]


@njit(cache=True, nogil=True, boundscheck=False)
def _chain(q, M, A, T, W, want_axes):
    """Run the chain product into ``T (4, 4)``; with ``want_axes`` write ``W (n, 6)``:
    ``W[i] = [w_i (unit axis), o_i (point on it, mm)]`` in the base frame."""
    n = q.shape[0]
    # current frame C = [R | p] as 12 scalars
    c00, c01, c02, c03 = M[0, 0, 0], M[0, 0, 1], M[0, 0, 2], M[0, 0, 3]
    c10, c11, c12, c13 = M[0, 1, 0], M[0, 1, 1], M[0, 1, 2], M[0, 1, 3]
    c20, c21, c22, c23 = M[0, 2, 0], M[0, 2, 1], M[0, 2, 2], M[0, 2, 3]
    for i in range(n):
        if i > 0:  # C <- C @ M[i]
            m = M[i]
            a00 = c00 * m[0, 0] + c01 * m[1, 0] + c02 * m[2, 0]
            a01 = c00 * m[0, 1] + c01 * m[1, 1] + c02 * m[2, 1]
            a02 = c00 * m[0, 2] + c01 * m[1, 2] + c02 * m[2, 2]
            a03 = c00 * m[0, 3] + c01 * m[1, 3] + c02 * m[2, 3] + c03
            a10 = c10 * m[0, 0] + c11 * m[1, 0] + c12 * m[2, 0]
            a11 = c10 * m[0, 1] + c11 * m[1, 1] + c12 * m[2, 1]
            a12 = c10 * m[0, 2] + c11 * m[1, 2] + c12 * m[2, 2]
            a13 = c10 * m[0, 3] + c11 * m[1, 3] + c12 * m[2, 3] + c13
            a20 = c20 * m[0, 0] + c21 * m[1, 0] + c22 * m[2, 0]
            a21 = c20 * m[0, 1] + c21 * m[1, 1] + c22 * m[2, 1]
            a22 = c20 * m[0, 2] + c21 * m[1, 2] + c22 * m[2, 2]
            a23 = c20 * m[0, 3] + c21 * m[1, 3] + c22 * m[2, 3] + c23
            c00, c01, c02, c03 = a00, a01, a02, a03
            c10, c11, c12, c13 = a10, a11, a12, a13
            c20, c21, c22, c23 = a20, a21, a22, a23
        ax, ay, az = A[i, 0], A[i, 1], A[i, 2]
        # joint axis in the base frame
        wx = c00 * ax + c01 * ay + c02 * az
        wy = c10 * ax + c11 * ay + c12 * az
        wz = c20 * ax + c21 * ay + c22 * az
        if want_axes:
            W[i, 0], W[i, 1], W[i, 2] = wx, wy, wz
            W[i, 3], W[i, 4], W[i, 5] = c03, c13, c23
        if A[i, 3] != 0.0:  # prismatic: slide along the axis
            c03 += wx * q[i]
            c13 += wy * q[i]
            c23 += wz * q[i]
        else:  # revolute: C_R <- Rot(w, q) C_R, column by column (Rodrigues)
            ct, st = math.cos(q[i]), math.sin(q[i])
            vt = 1.0 - ct
            # column 0
            d = wx * c00 + wy * c10 + wz * c20
            x = c00 * ct + (wy * c20 - wz * c10) * st + wx * d * vt
            y = c10 * ct + (wz * c00 - wx * c20) * st + wy * d * vt
            z = c20 * ct + (wx * c10 - wy * c00) * st + wz * d * vt
            c00, c10, c20 = x, y, z
            # column 1
            d = wx * c01 + wy * c11 + wz * c21
            x = c01 * ct + (wy * c21 - wz * c11) * st + wx * d * vt
            y = c11 * ct + (wz * c01 - wx * c21) * st + wy * d * vt
            z = c21 * ct + (wx * c11 - wy * c01) * st + wz * d * vt
            c01, c11, c21 = x, y, z
            # column 2
            d = wx * c02 + wy * c12 + wz * c22
            x = c02 * ct + (wy * c22 - wz * c12) * st + wx * d * vt
            y = c12 * ct + (wz * c02 - wx * c22) * st + wy * d * vt
            z = c22 * ct + (wx * c12 - wy * c02) * st + wz * d * vt
            c02, c12, c22 = x, y, z
    m = M[n]  # T = C @ M[n]
    T[0, 0] = c00 * m[0, 0] + c01 * m[1, 0] + c02 * m[2, 0]
    T[0, 1] = c00 * m[0, 1] + c01 * m[1, 1] + c02 * m[2, 1]
    T[0, 2] = c00 * m[0, 2] + c01 * m[1, 2] + c02 * m[2, 2]
    T[0, 3] = c00 * m[0, 3] + c01 * m[1, 3] + c02 * m[2, 3] + c03
    T[1, 0] = c10 * m[0, 0] + c11 * m[1, 0] + c12 * m[2, 0]
    T[1, 1] = c10 * m[0, 1] + c11 * m[1, 1] + c12 * m[2, 1]
    T[1, 2] = c10 * m[0, 2] + c11 * m[1, 2] + c12 * m[2, 2]
    T[1, 3] = c10 * m[0, 3] + c11 * m[1, 3] + c12 * m[2, 3] + c13
    T[2, 0] = c20 * m[0, 0] + c21 * m[1, 0] + c22 * m[2, 0]
    T[2, 1] = c20 * m[0, 1] + c21 * m[1, 1] + c22 * m[2, 1]
    T[2, 2] = c20 * m[0, 2] + c21 * m[1, 2] + c22 * m[2, 2]
    T[2, 3] = c20 * m[0, 3] + c21 * m[1, 3] + c22 * m[2, 3] + c23
    T[3, 0] = 0.0
    T[3, 1] = 0.0
    T[3, 2] = 0.0
    T[3, 3] = 1.0


@njit(cache=True, nogil=True, boundscheck=False)
def fk_into(q, M, A, T):
    """Forward kinematics ``T_base_tip`` of one configuration into ``T (4, 4)``.

    q (n,) rad / mm; M (n + 1, 4, 4), A (n, 4) the kinematic pack (module docs).
    """
    _chain(q, M, A, T, T, False)


@njit(cache=True, nogil=True, boundscheck=False)
def fk_jacobian_into(q, M, A, T, J, W):
    """Forward kinematics into ``T (4, 4)`` and the geometric Jacobian into ``J (6, n)``.

    q (n,) rad / mm; M (n + 1, 4, 4), A (n, 4) the kinematic pack; W (n, 6) work space (on
    return: the joint axes and points in the base frame). The kernel other numba code calls.
    """
    _chain(q, M, A, T, W, True)
    px, py, pz = T[0, 3], T[1, 3], T[2, 3]
    for i in range(q.shape[0]):
        wx, wy, wz = W[i, 0], W[i, 1], W[i, 2]
        if A[i, 3] != 0.0:
            J[0, i], J[1, i], J[2, i] = wx, wy, wz
            J[3, i], J[4, i], J[5, i] = 0.0, 0.0, 0.0
        else:
            ux, uy, uz = px - W[i, 3], py - W[i, 4], pz - W[i, 5]
            J[0, i] = wy * uz - wz * uy
            J[1, i] = wz * ux - wx * uz
            J[2, i] = wx * uy - wy * ux
            J[3, i], J[4, i], J[5, i] = wx, wy, wz


@njit(cache=True, nogil=True)
def fk_single(q, M, A):
    """``T_base_tip (4, 4)`` of one configuration ``q (n,)``."""
    T = np.empty((4, 4))
    _chain(q, M, A, T, T, False)
    return T


@njit(cache=True, nogil=True)
def fk_jacobian_single(q, M, A):
    """``(T_base_tip (4, 4), J (6, n))`` of one configuration ``q (n,)``."""
    n = q.shape[0]
    T = np.empty((4, 4))
    J = np.empty((6, n))
    W = np.empty((n, 6))
    fk_jacobian_into(q, M, A, T, J, W)
    return T, J


@njit(cache=True, nogil=True)
def fk_batch(Q, M, A):
    """``T (m, 4, 4)`` for configurations ``Q (m, n)``."""
    m = Q.shape[0]
    T = np.empty((m, 4, 4))
    for k in range(m):
        _chain(Q[k], M, A, T[k], T[k], False)
    return T


@njit(cache=True, nogil=True)
def fk_jacobian_batch(Q, M, A):
    """``(T (m, 4, 4), J (m, 6, n))`` for configurations ``Q (m, n)``."""
    m, n = Q.shape
    T = np.empty((m, 4, 4))
    J = np.empty((m, 6, n))
    W = np.empty((n, 6))
    for k in range(m):
        fk_jacobian_into(Q[k], M, A, T[k], J[k], W)
    return T, J


@njit(cache=True, nogil=True)
def joint_axes_batch(Q, M, A):
    """``(T (m, 4, 4), W (m, n, 6))``: tip poses and the joint axes/points in the base frame."""
    m, n = Q.shape
    T = np.empty((m, 4, 4))
    W = np.empty((m, n, 6))
    for k in range(m):
        _chain(Q[k], M, A, T[k], W[k], True)
    return T, W
