"""Orientation adjustment (Sec. 3.1, eq. 7–8): turn the tool marker parallel to the OOI.

The camera measures the OOI pose ``T_C_O`` and the tool-marker pose ``T_C_M`` (the paper's
``^C T_T``). Eq. (7) takes the rotation difference of the two as a quaternion product,

``r_Δ = r_O ⊗ r_T⁻¹``        (a rotation expressed in the camera frame C),

and eq. (8) applies it to the current TCP pose, ``T_ref = ^B T_T · [R_Δ 0; 0 1]``. Eq. (8)
applies a camera-frame rotation in the TCP frame: the paper relies on the *uniformity* of
the camera frame and the TCP frame. Here that assumption is made explicit by the nominal
(designed) mount rotation ``R_F_C``: ``R_Δ`` is carried into the TCP frame F as
``R_F_C R_Δ R_F_Cᵀ``; with ``R_F_C = I`` (the paper's case) it is eq. (8) verbatim. With the
true mount rotation and exact measurements the tool marker ends exactly parallel to the OOI;
a mount that differs from the nominal one leaves a residual of about the misalignment.
"""

import numpy as np
from scipy.spatial.transform import Rotation

from posekit.geometry import (
    check_rotation_matrix,
    check_transform,
    matrix_from_quaternion,
    quaternion_from_matrix,
    quaternion_product,
)

__all__ = ["orientation_reference", "rotation_difference", "rotation_errors_deg"]


def rotation_difference(T_C_O, T_C_M) -> np.ndarray:
    """Rotation difference of eq. (7), ``r_Δ = r_O ⊗ r_T⁻¹``, as a matrix.

    Parameters
    ----------
    T_C_O : array_like, shape (..., 4, 4)
        OOI pose in the camera frame C (mm).
    T_C_M : array_like, shape (..., 4, 4)
        Tool-marker pose in the camera frame C (mm).

    Returns
    -------
    R_delta_C : ndarray, shape (..., 3, 3)
        ``R_C_O R_C_Mᵀ``: the rotation, expressed in C, that turns the tool marker's
        orientation into the OOI's.

    Raises
    ------
    GeometryError
        An input is not a (batch of) rigid transform(s).
    """
    T_C_O = check_transform(T_C_O, name="T_C_O")
    T_C_M = check_transform(T_C_M, name="T_C_M")
    r_O = quaternion_from_matrix(T_C_O[..., :3, :3], check=False)
    r_T = quaternion_from_matrix(T_C_M[..., :3, :3], check=False)
    r_T_inv = r_T * np.array([1.0, -1.0, -1.0, -1.0])         # unit quaternion: inverse = conjugate
    return matrix_from_quaternion(quaternion_product(r_O, r_T_inv))


def orientation_reference(T_B_F, T_C_O, T_C_M, *, R_F_C=None) -> np.ndarray:
    """Reference TCP pose of the orientation adjustment, eq. (8).

    Parameters
    ----------
    T_B_F : array_like, shape (4, 4)
        Current TCP pose in the robot base frame B (from the kinematic model), mm.
    T_C_O : array_like, shape (4, 4)
        Measured OOI pose in the camera frame C, mm.
    T_C_M : array_like, shape (4, 4)
        Measured tool-marker pose in the camera frame C, mm.
    R_F_C : array_like, shape (3, 3), optional
        Nominal rotation of the camera frame in the TCP frame (the 'uniformity' of the
        two frames); identity by default, which is eq. (8) as printed.

    Returns
    -------
    T_B_ref : ndarray, shape (4, 4)
        ``T_B_F · [R_F_C R_Δ R_F_Cᵀ, 0; 0, 1]``: same TCP position, rotated so that the
        tool marker becomes parallel to the OOI, mm.

    Raises
    ------
    GeometryError
        An input is not a rigid transform or ``R_F_C`` is not a rotation.

    Examples
    --------
    >>> T_C_M = np.eye(4)
    >>> T_C_O = np.eye(4); T_C_O[:3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90° about z
    >>> np.round(orientation_reference(np.eye(4), T_C_O, T_C_M)[:3, :3], 12) + 0.0
    array([[ 0., -1.,  0.],
           [ 1.,  0.,  0.],
           [ 0.,  0.,  1.]])
    """
    T_B_F = check_transform(T_B_F, name="T_B_F")
    R_delta = rotation_difference(T_C_O, T_C_M)
    if R_F_C is not None:
        R_F_C = check_rotation_matrix(R_F_C, name="R_F_C")
        R_delta = R_F_C @ R_delta @ R_F_C.T
    T_ref = T_B_F.copy()
    T_ref[:3, :3] = T_B_F[:3, :3] @ R_delta
    return T_ref


def rotation_errors_deg(T_C_O, T_C_M, *, signed: bool = False) -> np.ndarray:
    """Image-based absolute rotation errors between the tool marker and the OOI (Table 2).

    Parameters
    ----------
    T_C_O, T_C_M : array_like, shape (..., 4, 4)
        OOI and tool-marker poses in the camera frame, mm.
    signed : bool
        Return the signed angles (Fig. 5) instead of their absolute values.

    Returns
    -------
    errors_deg : ndarray, shape (..., 3)
        ``|e_θx|, |e_θy|, |e_θz|``: the rotation of the OOI relative to the tool marker,
        ``R_M_O = R_C_Mᵀ R_C_O``, as extrinsic XYZ Euler angles, in degrees.
    """
    T_C_O = check_transform(T_C_O, name="T_C_O")
    T_C_M = check_transform(T_C_M, name="T_C_M")
    R_M_O = np.swapaxes(T_C_M[..., :3, :3], -1, -2) @ T_C_O[..., :3, :3]
    shape = R_M_O.shape[:-2]
    euler = Rotation.from_matrix(R_M_O.reshape(-1, 3, 3)).as_euler("xyz", degrees=True)
    euler = euler.reshape(shape + (3,))
    return euler if signed else np.abs(euler)
