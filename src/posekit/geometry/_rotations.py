"""Rotations: matrices, Hamilton quaternions and rotation vectors, batched.

Vectorised NumPy (and compiled kernels for matrix to quaternion / rotation vector), checked
against :class:`scipy.spatial.transform.Rotation`, the reference implementation, in the tests
(importing it costs 0.2-0.4 s at every start of the command line). Every function takes leading batch axes (``(..., 3, 3)``,
``(..., 4)``, ``(..., 3)``); a single rotation is the zero-batch case. Quaternions are
Hamilton, scalar first (``q_wxyz``) unless the name says ``xyzw`` (scipy's order).
A rotation matrix ``R_a_b`` maps coordinates in frame b into frame a.
"""

import numpy as np

from posekit.errors import GeometryError

from ._rotation_kernels import (
    _flat,
    quaternion_from_matrix_kernel,
    rotvec_from_matrix_kernel,
)

__all__ = [
    "quaternion_from_matrix",
    "matrix_from_quaternion",
    "quaternion_product",
    "quaternion_xyzw_from_wxyz",
    "quaternion_wxyz_from_xyzw",
    "matrix_from_rotation_vector",
    "rotation_vector_from_matrix",
    "nearest_rotation",
    "is_rotation_matrix",
    "check_rotation_matrix",
    "rotation_angle_between",
]

#: Default tolerance of the ``check_*`` validators (max abs entry of ``R^T R - I``).
CHECK_TOL = 1e-6
#: Default tolerance of the ``is_*`` predicates.
IS_TOL = 1e-9


# --------------------------------------------------------------------------- validation
def _as_float_array(x, name: str, tail: tuple[int, ...]) -> np.ndarray:
    """Return ``x`` as float64 with trailing shape ``tail``, or raise GeometryError."""
    expected = "(..., " + ", ".join(map(str, tail)) + ")"
    try:
        a = np.asarray(x, dtype=np.float64)
    except (TypeError, ValueError):
        raise GeometryError(
            f"{name}: expected a numeric array of shape {expected}, got {type(x).__name__}"
        ) from None
    if a.ndim < len(tail) or a.shape[a.ndim - len(tail):] != tail:
        raise GeometryError(f"{name}: expected an array of shape {expected}, got shape {a.shape}")
    return a


def _where(bad: np.ndarray) -> str:
    """Say where the first True of a batch mask is: ``' at index (i, j)'``, or ``''``."""
    if bad.ndim == 0:
        return ""
    index = tuple(int(i) for i in np.argwhere(bad)[0])
    return f" at index {index} ({int(bad.sum())} of {bad.size} bad)"


def _require_finite(a: np.ndarray, name: str, ndim_tail: int) -> None:
    """Raise GeometryError if any element of ``a`` is NaN or infinite."""
    bad = ~np.isfinite(a).all(axis=tuple(range(-ndim_tail, 0)))
    if bad.any():
        raise GeometryError(f"{name}: expected finite values, found NaN or inf{_where(bad)}")


def _rotation_errors(R: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Max abs entry of ``R^T R - I`` and the determinant, each of shape ``(...)``."""
    gram = np.swapaxes(R, -1, -2) @ R
    orth = np.abs(gram - np.eye(3)).max(axis=(-2, -1))
    return orth, np.linalg.det(R)


# --------------------------------------------------------------------------- validators
def is_rotation_matrix(R, tol: float = IS_TOL) -> bool:
    """Tell whether every matrix of a batch is a rotation matrix.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Candidate rotation matrices (dimensionless).
    tol : float
        Largest accepted absolute entry of ``R^T R - I``.

    Returns
    -------
    bool
        True if ``R`` has shape ``(..., 3, 3)``, is finite, and every matrix is orthonormal
        within ``tol`` with determinant > 0 (True for an empty batch). Never raises.

    See Also
    --------
    check_rotation_matrix : the validator that raises instead.

    Examples
    --------
    >>> is_rotation_matrix(np.eye(3)), is_rotation_matrix(np.diag([1.0, 1.0, -1.0]))
    (True, False)
    """
    try:
        R = _as_float_array(R, "R", (3, 3))
    except GeometryError:
        return False
    if not np.isfinite(R).all():
        return False
    orth, det = _rotation_errors(R)
    return bool(np.all((orth <= tol) & (det > 0.0)))


def check_rotation_matrix(R, tol: float = CHECK_TOL, *, name: str = "R") -> np.ndarray:
    """Validate rotation matrices and return them as float64.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices ``R_a_b`` (dimensionless).
    tol : float
        Largest accepted absolute entry of ``R^T R - I``.
    name : str
        Name of the input in error messages.

    Returns
    -------
    R : ndarray, shape (..., 3, 3)
        The input as float64 (not copied if it already was).

    Raises
    ------
    GeometryError
        If the shape is wrong, a value is not finite, or a matrix is not orthonormal within
        ``tol`` with determinant +1; the message names the first bad batch index.

    Examples
    --------
    >>> check_rotation_matrix(2 * np.eye(3))  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    posekit.errors.GeometryError: R: expected rotation matrices (...), found max |R^T R - I| = 3, det = 8
    """
    R = _as_float_array(R, name, (3, 3))
    _require_finite(R, name, 2)
    orth, det = _rotation_errors(R)
    bad = ~((orth <= tol) & (det > 0.0))
    if bad.any():
        i = tuple(np.argwhere(bad)[0])
        raise GeometryError(
            f"{name}: expected rotation matrices (R^T R = I within {tol:g}, det +1), "
            f"found max |R^T R - I| = {orth[i]:.3g}, det = {det[i]:.3g}{_where(bad)}"
        )
    return R


# --------------------------------------------------------------------------- quaternions
def quaternion_xyzw_from_wxyz(q_wxyz) -> np.ndarray:
    """Reorder quaternions from scalar-first ``[w, x, y, z]`` to scalar-last ``[x, y, z, w]``.

    Parameters
    ----------
    q_wxyz : array_like, shape (..., 4)
        Quaternions, scalar first.

    Returns
    -------
    q_xyzw : ndarray, shape (..., 4)
        The same quaternions, scalar last (scipy's and TUM's order); not normalised.

    Examples
    --------
    >>> quaternion_xyzw_from_wxyz([1.0, 2.0, 3.0, 4.0])
    array([2., 3., 4., 1.])
    """
    q = _as_float_array(q_wxyz, "q_wxyz", (4,))
    return np.roll(q, -1, axis=-1)


def quaternion_wxyz_from_xyzw(q_xyzw) -> np.ndarray:
    """Reorder quaternions from scalar-last ``[x, y, z, w]`` to scalar-first ``[w, x, y, z]``.

    Parameters
    ----------
    q_xyzw : array_like, shape (..., 4)
        Quaternions, scalar last (scipy's and TUM's order).

    Returns
    -------
    q_wxyz : ndarray, shape (..., 4)
        The same quaternions, scalar first; not normalised.

    Examples
    --------
    >>> quaternion_wxyz_from_xyzw([2.0, 3.0, 4.0, 1.0])
    array([1., 2., 3., 4.])
    """
    q = _as_float_array(q_xyzw, "q_xyzw", (4,))
    return np.roll(q, 1, axis=-1)


def matrix_from_quaternion(q_wxyz) -> np.ndarray:
    """Rotation matrices from Hamilton quaternions (normalised first).

    Parameters
    ----------
    q_wxyz : array_like, shape (..., 4)
        Quaternions ``q_a_b`` as ``[w, x, y, z]``, any non-zero norm.

    Returns
    -------
    R : ndarray, shape (..., 3, 3)
        Rotation matrices ``R_a_b``.

    Raises
    ------
    GeometryError
        If the shape is wrong, or a quaternion is zero or not finite.

    See Also
    --------
    quaternion_from_matrix : the inverse conversion.

    Examples
    --------
    >>> matrix_from_quaternion([0.0, 1.0, 0.0, 0.0])  # 180 degrees about x
    array([[ 1.,  0.,  0.],
           [ 0., -1.,  0.],
           [ 0.,  0., -1.]])
    """
    q = _as_float_array(q_wxyz, "q_wxyz", (4,))
    _require_finite(q, "q_wxyz", 1)
    scale = np.abs(q).max(axis=-1, keepdims=True)  # avoids overflow/underflow in the norm
    zero = scale[..., 0] == 0.0
    if zero.any():
        raise GeometryError(
            f"q_wxyz: expected non-zero quaternions [w, x, y, z], found norm 0{_where(zero)}"
        )
    q = q / scale
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], axis=-1),
        np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], axis=-1),
        np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], axis=-1),
    ], axis=-2)


def quaternion_product(q1_wxyz, q2_wxyz) -> np.ndarray:
    """Hamilton product ``q1 ⊗ q2`` (the rotation ``R(q1) R(q2)``), batched.

    Parameters
    ----------
    q1_wxyz, q2_wxyz : array_like, shape (..., 4)
        Quaternions ``[w, x, y, z]`` (broadcast against each other); not normalised.

    Returns
    -------
    q_wxyz : ndarray, shape (..., 4)
        The product, e.g. ``q_a_c = q_a_b ⊗ q_b_c``.

    Raises
    ------
    GeometryError
        If a shape is wrong.

    Examples
    --------
    >>> quaternion_product([0.0, 1.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0])  # i j = k
    array([0., 0., 0., 1.])
    """
    a = _as_float_array(q1_wxyz, "q1_wxyz", (4,))
    b = _as_float_array(q2_wxyz, "q2_wxyz", (4,))
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ], axis=-1)


def quaternion_from_matrix(R, *, check: bool = True) -> np.ndarray:
    """Hamilton quaternions from rotation matrices, with canonical sign ``w >= 0``.

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices ``R_a_b``.
    check : bool
        Validate ``R`` with :func:`check_rotation_matrix`; ``False`` is the unchecked hot path
        (a matrix that is not quite a rotation then gives the normalised quaternion of
        Shepperd's formulas: project it with :func:`nearest_rotation` first if it may be far
        from one).

    Returns
    -------
    q_wxyz : ndarray, shape (..., 4)
        Unit quaternions ``q_a_b`` as ``[w, x, y, z]`` with ``w >= 0``; if ``w == 0`` the first
        non-zero of ``x, y, z`` is positive.

    Raises
    ------
    GeometryError
        If ``check`` and ``R`` is not a batch of rotation matrices.

    Examples
    --------
    >>> quaternion_from_matrix(np.diag([1.0, -1.0, -1.0]))  # 180 degrees about x
    array([0., 1., 0., 0.])
    """
    R = check_rotation_matrix(R) if check else _as_float_array(R, "R", (3, 3))
    out = np.empty(R.shape[:-2] + (4,))
    quaternion_from_matrix_kernel(_flat(R), out.reshape(-1, 4))  # compiled Shepperd
    return out


# --------------------------------------------------------------------------- rotation vectors
def matrix_from_rotation_vector(rotvec) -> np.ndarray:
    """Rotation matrices from rotation vectors (axis times angle, Rodrigues).

    Parameters
    ----------
    rotvec : array_like, shape (..., 3)
        Rotation vectors: unit axis times angle in rad (any angle).

    Returns
    -------
    R : ndarray, shape (..., 3, 3)
        Rotation matrices.

    Raises
    ------
    GeometryError
        If the shape is wrong or a value is not finite.

    Examples
    --------
    >>> R = matrix_from_rotation_vector([0.0, 0.0, np.pi / 2])  # 90 degrees about z
    >>> np.round(R @ [1.0, 0.0, 0.0], 12) + 0.0  # x goes to y
    array([0., 1., 0.])
    """
    v = _as_float_array(rotvec, "rotvec", (3,))
    _require_finite(v, "rotvec", 1)
    theta2 = np.einsum("...i,...i->...", v, v)
    theta = np.sqrt(theta2)
    small = theta2 < 1e-8                  # Taylor series of sin(t)/t and (1 - cos t)/t^2, error < 1e-24
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta2 / 6.0 + theta2 * theta2 / 120.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta2 / 24.0 + theta2 * theta2 / 720.0, (1.0 - np.cos(safe)) / (safe * safe))
    x, y, z = np.moveaxis(v, -1, 0)
    zero = np.zeros_like(x)
    K = np.stack([np.stack([zero, -z, y], axis=-1), np.stack([z, zero, -x], axis=-1),
                  np.stack([-y, x, zero], axis=-1)], axis=-2)
    return np.eye(3) + a[..., None, None] * K + b[..., None, None] * (K @ K)   # Rodrigues


def rotation_vector_from_matrix(R, *, check: bool = True) -> np.ndarray:
    """Rotation vectors from rotation matrices (robust near 0 and pi, via quaternions).

    Parameters
    ----------
    R : array_like, shape (..., 3, 3)
        Rotation matrices.
    check : bool
        Validate ``R`` with :func:`check_rotation_matrix`; ``False`` is the unchecked hot path.

    Returns
    -------
    rotvec : ndarray, shape (..., 3)
        Axis times angle, angle in [0, pi] rad. At exactly pi the sign of the axis is
        arbitrary (both describe the same rotation).

    Raises
    ------
    GeometryError
        If ``check`` and ``R`` is not a batch of rotation matrices.

    Examples
    --------
    >>> rotation_vector_from_matrix(np.diag([1.0, -1.0, -1.0]))
    array([3.14159265, 0.        , 0.        ])
    """
    R = check_rotation_matrix(R) if check else _as_float_array(R, "R", (3, 3))
    out = np.empty(R.shape[:-2] + (3,))
    rotvec_from_matrix_kernel(_flat(R), out.reshape(-1, 3))  # compiled, via the quaternion
    return out


# --------------------------------------------------------------------------- projections, metrics
def nearest_rotation(M) -> np.ndarray:
    """Nearest rotation matrix (Frobenius norm) to each 3x3 matrix, by SVD.

    ``M = U S V^T`` gives ``R = U diag(1, 1, det(U V^T)) V^T``: the orthogonal polar factor
    when ``det M > 0``, and otherwise the best proper rotation (never a reflection).

    Parameters
    ----------
    M : array_like, shape (..., 3, 3)
        Any real matrices, e.g. a noisy or accumulated rotation estimate.

    Returns
    -------
    R : ndarray, shape (..., 3, 3)
        Rotation matrices with determinant +1.

    Raises
    ------
    GeometryError
        If the shape is wrong or a value is not finite.

    Examples
    --------
    >>> nearest_rotation(np.diag([3.0, 2.0, -1.0]))  # a reflection goes to the identity
    array([[1., 0., 0.],
           [0., 1., 0.],
           [0., 0., 1.]])
    """
    M = _as_float_array(M, "M", (3, 3))
    _require_finite(M, "M", 2)
    U, _, Vt = np.linalg.svd(M)
    d = np.sign(np.linalg.det(U @ Vt))
    U = U.copy()
    U[..., :, 2] *= d[..., None]
    return U @ Vt


def rotation_angle_between(R_a, R_b, *, check: bool = True) -> np.ndarray:
    """Angle of the relative rotation ``R_a^T R_b`` (geodesic distance on SO(3)).

    Computed as ``atan2(|vee(M - M^T)| / 2, (trace M - 1) / 2)``, which stays accurate near
    0 and near pi (unlike ``arccos`` of the trace).

    Parameters
    ----------
    R_a, R_b : array_like, shape (..., 3, 3)
        Rotation matrices; batch axes broadcast against each other.
    check : bool
        Validate both inputs with :func:`check_rotation_matrix`.

    Returns
    -------
    angle : ndarray, shape (...)
        Angle in rad, in [0, pi].

    Raises
    ------
    GeometryError
        If ``check`` and an input is not a batch of rotation matrices, or the batch shapes
        do not broadcast.

    Examples
    --------
    >>> float(rotation_angle_between(np.eye(3), np.diag([1.0, -1.0, -1.0])))
    3.141592653589793
    """
    if check:
        R_a = check_rotation_matrix(R_a, name="R_a")
        R_b = check_rotation_matrix(R_b, name="R_b")
    else:
        R_a = _as_float_array(R_a, "R_a", (3, 3))
        R_b = _as_float_array(R_b, "R_b", (3, 3))
    try:
        M = np.swapaxes(R_a, -1, -2) @ R_b
    except ValueError:
        raise GeometryError(
            f"R_a, R_b: expected broadcastable batch shapes, got {R_a.shape} and {R_b.shape}"
        ) from None
    skew = np.stack(
        [M[..., 2, 1] - M[..., 1, 2], M[..., 0, 2] - M[..., 2, 0], M[..., 1, 0] - M[..., 0, 1]],
        axis=-1,
    )
    sin = 0.5 * np.linalg.norm(skew, axis=-1)
    cos = 0.5 * (np.trace(M, axis1=-2, axis2=-1) - 1.0)
    return np.arctan2(sin, cos)
