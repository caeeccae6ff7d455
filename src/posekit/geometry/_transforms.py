"""Rigid transforms as homogeneous 4x4 matrices, batched.

``T_a_b`` maps coordinates in frame b into frame a: ``p_a = R_a_b @ p_b + t_a_b``, with
``T_a_b[..., :3, :3] = R_a_b``, ``T_a_b[..., :3, 3] = t_a_b`` (mm) and last row
``[0, 0, 0, 1]``. Compose with ``T_a_c = T_a_b @ T_b_c``. Every function takes leading batch
axes; a single transform is the zero-batch case.
"""

import numpy as np

from posekit.errors import GeometryError

from ._rotations import (
    CHECK_TOL,
    _as_float_array,
    _require_finite,
    _where,
    check_rotation_matrix,
    matrix_from_quaternion,
)

__all__ = [
    "transform_from",
    "transform_from_quaternion",
    "rotation_translation",
    "invert_transform",
    "apply_transform",
    "check_transform",
]


def _batch_shape(name: str, *shapes: tuple[int, ...]) -> tuple[int, ...]:
    try:
        return np.broadcast_shapes(*shapes)
    except ValueError:
        raise GeometryError(
            f"{name}: expected broadcastable batch shapes, got {' and '.join(map(str, shapes))}"
        ) from None


def check_transform(T, tol: float = CHECK_TOL, *, name: str = "T") -> np.ndarray:
    """Validate rigid transforms and return them as float64.

    Parameters
    ----------
    T : array_like, shape (..., 4, 4)
        Homogeneous rigid transforms ``T_a_b``, translation in mm.
    tol : float
        Tolerance on the rotation block (max abs entry of ``R^T R - I``) and on the last row.
    name : str
        Name of the input in error messages.

    Returns
    -------
    T : ndarray, shape (..., 4, 4)
        The input as float64 (not copied if it already was).

    Raises
    ------
    GeometryError
        If the shape is wrong, a value is not finite, the last row is not ``[0, 0, 0, 1]``
        or the rotation block is not a rotation; the message names the first bad index.

    Examples
    --------
    >>> check_transform(np.zeros((4, 4)))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    posekit.errors.GeometryError: T: expected last row [0, 0, 0, 1] ..., found [0. 0. 0. 0.]
    """
    T = _as_float_array(T, name, (4, 4))
    _require_finite(T, name, 2)
    row_err = np.abs(T[..., 3, :] - [0.0, 0.0, 0.0, 1.0]).max(axis=-1)
    bad = row_err > tol
    if bad.any():
        i = tuple(np.argwhere(bad)[0])
        raise GeometryError(
            f"{name}: expected last row [0, 0, 0, 1] within {tol:g}, "
            f"found {T[i + (3,)]}{_where(bad)}"
        )
    check_rotation_matrix(T[..., :3, :3], tol, name=f"{name}[..., :3, :3]")
    return T


def transform_from(R, t, *, check: bool = True) -> np.ndarray:
    """Rigid transforms from rotation matrices and translations.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotations ``R_a_b``.
    t : array_like, shape (..., 3)
        Translations ``t_a_b``: origin of frame b in frame a, in mm. Batch axes broadcast
        against those of ``R``.
    check : bool
        Validate ``R`` with :func:`check_rotation_matrix` and ``t`` for finite values.

    Returns
    -------
    T : ndarray, shape (..., 4, 4)
        Transforms ``T_a_b`` (translation in mm), batch shape broadcast from ``R`` and ``t``.

    Raises
    ------
    GeometryError
        If a shape is wrong or the batch shapes do not broadcast; if ``check``, also if
        ``R`` is not a rotation or ``t`` is not finite.

    Examples
    --------
    >>> transform_from(np.eye(3), [1.0, 2.0, 3.0])
    array([[1., 0., 0., 1.],
           [0., 1., 0., 2.],
           [0., 0., 1., 3.],
           [0., 0., 0., 1.]])
    """
    R = check_rotation_matrix(R) if check else _as_float_array(R, "R", (3, 3))
    t = _as_float_array(t, "t", (3,))
    if check:
        _require_finite(t, "t", 1)
    batch = _batch_shape("R, t", R.shape[:-2], t.shape[:-1])
    T = np.zeros(batch + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def transform_from_quaternion(q_wxyz, t) -> np.ndarray:
    """Rigid transforms from Hamilton quaternions and translations.

    Parameters
    ----------
    q_wxyz : array_like, shape (..., 4)
        Rotations ``q_a_b`` as ``[w, x, y, z]`` (normalised here; must be non-zero, finite).
    t : array_like, shape (..., 3)
        Translations ``t_a_b`` in mm; batch axes broadcast against those of ``q_wxyz``.

    Returns
    -------
    T : ndarray, shape (..., 4, 4)
        Transforms ``T_a_b``.

    Raises
    ------
    GeometryError
        If a shape is wrong, the batch shapes do not broadcast, a quaternion is zero or a
        value is not finite.

    Examples
    --------
    >>> T = transform_from_quaternion([0.0, 1.0, 0.0, 0.0], [10.0, 0.0, 0.0])
    >>> T[:3, :3].diagonal(), T[:3, 3]
    (array([ 1., -1., -1.]), array([10.,  0.,  0.]))
    """
    t = _as_float_array(t, "t", (3,))
    _require_finite(t, "t", 1)
    R = matrix_from_quaternion(q_wxyz)
    _batch_shape("q_wxyz, t", R.shape[:-2], t.shape[:-1])
    return transform_from(R, t, check=False)


def rotation_translation(T, *, check: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Split rigid transforms into rotation matrices and translations.

    Parameters
    ----------
    T : array_like, shape (..., 4, 4)
        Transforms ``T_a_b``, translation in mm.
    check : bool
        Validate ``T`` with :func:`check_transform`.

    Returns
    -------
    R : ndarray, shape (..., 3, 3)
        Rotations ``R_a_b`` (a copy).
    t : ndarray, shape (..., 3)
        Translations ``t_a_b`` in mm (a copy).

    Raises
    ------
    GeometryError
        If ``check`` and ``T`` is not a batch of rigid transforms.
    """
    T = check_transform(T) if check else _as_float_array(T, "T", (4, 4))
    return T[..., :3, :3].copy(), T[..., :3, 3].copy()


def invert_transform(T, *, check: bool = True) -> np.ndarray:
    """Invert rigid transforms in closed form: ``T_b_a = [R^T, -R^T t; 0, 1]``.

    Parameters
    ----------
    T : array_like, shape (..., 4, 4)
        Transforms ``T_a_b``, translation in mm.
    check : bool
        Validate ``T`` with :func:`check_transform`.

    Returns
    -------
    T_inv : ndarray, shape (..., 4, 4)
        The inverse transforms ``T_b_a``.

    Raises
    ------
    GeometryError
        If ``check`` and ``T`` is not a batch of rigid transforms.

    Examples
    --------
    >>> invert_transform(transform_from(np.eye(3), [1.0, 2.0, 3.0]))[:3, 3]
    array([-1., -2., -3.])
    """
    T = check_transform(T) if check else _as_float_array(T, "T", (4, 4))
    Rt = np.swapaxes(T[..., :3, :3], -1, -2)
    T_inv = np.zeros(T.shape)
    T_inv[..., :3, :3] = Rt
    T_inv[..., :3, 3] = -(Rt @ T[..., :3, 3, None])[..., 0]
    T_inv[..., 3, 3] = 1.0
    return T_inv


def apply_transform(T, p, *, check: bool = True) -> np.ndarray:
    """Map points from frame b into frame a: ``p_a = R_a_b @ p_b + t_a_b``.

    Parameters
    ----------
    T : array_like, shape (..., 4, 4)
        Transforms ``T_a_b``, translation in mm.
    p : array_like, shape (..., 3)
        Points ``p_b`` in frame b, in mm. Batch axes broadcast against those of ``T``, so
        one transform ``(4, 4)`` applies to points ``(N, 3)`` and transforms ``(N, 4, 4)``
        apply one-to-one to points ``(N, 3)``.
    check : bool
        Validate ``T`` with :func:`check_transform` and ``p`` for finite values.

    Returns
    -------
    p_a : ndarray, shape (..., 3)
        The points in frame a, in mm; batch shape broadcast from ``T`` and ``p``.

    Raises
    ------
    GeometryError
        If a shape is wrong or the batch shapes do not broadcast; if ``check``, also if
        ``T`` is not a rigid transform or ``p`` is not finite.

    Examples
    --------
    >>> R_a_b = [[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]]  # 90 degrees about z
    >>> T_a_b = transform_from(R_a_b, [0.0, 0.0, 5.0])
    >>> apply_transform(T_a_b, [[1.0, 0.0, 0.0], [0.0, 2.0, 0.0]])
    array([[ 0.,  1.,  5.],
           [-2.,  0.,  5.]])
    """
    T = check_transform(T) if check else _as_float_array(T, "T", (4, 4))
    p = _as_float_array(p, "p", (3,))
    if check:
        _require_finite(p, "p", 1)
    _batch_shape("T, p", T.shape[:-2], p.shape[:-1])
    if T.ndim == 2:  # one transform for many points: a single (n, 3) x (3, 3) product
        return p @ T[:3, :3].T + T[:3, 3]
    return (T[..., :3, :3] @ p[..., None])[..., 0] + T[..., :3, 3]
