"""Batched exponential and logarithm maps of SO(3) and SE(3) in closed form.

Twists are ``xi = [rho, phi]`` (translation part first, in mm, then the rotation vector
in rad), the order of Barfoot's *State Estimation for Robotics* and of Sophus. With
``theta = |phi|`` and ``K = hat(phi)``::

    exp(xi) = [R, V rho; 0, 1],   R = I + A K + B K^2,   V = I + B K + C K^2,
    A = sin(theta) / theta,  B = (1 - cos(theta)) / theta^2,  C = (theta - sin(theta)) / theta^3.

``A`` and ``B`` are evaluated through ``sinc`` (accurate for every theta, including 0);
``C`` and the coefficient of ``V^-1`` switch to their Taylor series below
``theta = 0.1``, where the closed forms lose digits to cancellation. The rotation vector
of the logarithm comes from :func:`rotation_vector_from_matrix` (quaternion based, accurate
near 0 and pi).
"""

import numpy as np

from ._rotations import _as_float_array, _require_finite, rotation_vector_from_matrix
from ._transforms import check_transform

__all__ = ["so3_hat", "so3_vee", "se3_exp", "se3_log"]

#: Below this angle (rad) the series are used; the truncation error there is < 1e-19.
_SERIES_BELOW = 0.1


def so3_hat(v) -> np.ndarray:
    """Skew-symmetric (cross-product) matrices: ``hat(v) @ w == cross(v, w)``.

    Parameters
    ----------
    v : array_like, shape (..., 3)
        Vectors, e.g. rotation vectors in rad or angular velocities in rad/s.

    Returns
    -------
    K : ndarray, shape (..., 3, 3)
        ``[[0, -vz, vy], [vz, 0, -vx], [-vy, vx, 0]]`` per vector, same unit as ``v``.

    Raises
    ------
    GeometryError
        If the shape is not ``(..., 3)``.

    Examples
    --------
    >>> so3_hat([1.0, 2.0, 3.0])
    array([[ 0., -3.,  2.],
           [ 3.,  0., -1.],
           [-2.,  1.,  0.]])
    """
    v = _as_float_array(v, "v", (3,))
    K = np.zeros(v.shape[:-1] + (3, 3))
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    K[..., 0, 1], K[..., 0, 2] = -z, y
    K[..., 1, 0], K[..., 1, 2] = z, -x
    K[..., 2, 0], K[..., 2, 1] = -y, x
    return K


def so3_vee(K) -> np.ndarray:
    """Vectors of skew-symmetric matrices, the inverse of :func:`so3_hat`.

    Parameters
    ----------
    K : array_like, shape (..., 3, 3)
        Skew-symmetric matrices. Only the skew-symmetric part ``(K - K^T) / 2`` is used.

    Returns
    -------
    v : ndarray, shape (..., 3)
        ``[K[2, 1], K[0, 2], K[1, 0]]`` of that part, same unit as ``K``.

    Raises
    ------
    GeometryError
        If the shape is not ``(..., 3, 3)``.

    Examples
    --------
    >>> so3_vee(so3_hat([1.0, 2.0, 3.0]))
    array([1., 2., 3.])
    """
    K = _as_float_array(K, "K", (3, 3))
    return 0.5 * np.stack(
        [K[..., 2, 1] - K[..., 1, 2], K[..., 0, 2] - K[..., 2, 0], K[..., 1, 0] - K[..., 0, 1]],
        axis=-1,
    )


def _series(theta2: np.ndarray, coefficients: tuple[float, ...]) -> np.ndarray:
    """Evaluate ``sum_k c_k theta^(2k)`` by Horner's rule."""
    out = np.full_like(theta2, coefficients[-1])
    for c in coefficients[-2::-1]:
        out = out * theta2 + c
    return out


def _c_coefficient(theta: np.ndarray) -> np.ndarray:
    """``(theta - sin theta) / theta^3`` = sum_k (-1)^k theta^(2k) / (2k + 3)!."""
    small = theta < _SERIES_BELOW
    safe = np.where(small, 1.0, theta)
    direct = (safe - np.sin(safe)) / safe**3
    series = _series(theta**2, (1 / 6, -1 / 120, 1 / 5040, -1 / 362880, 1 / 39916800))
    return np.where(small, series, direct)


def _d_coefficient(theta: np.ndarray) -> np.ndarray:
    """``(1 - (theta / 2) cot(theta / 2)) / theta^2``, the K^2 coefficient of ``V^-1``."""
    small = theta < _SERIES_BELOW
    half = np.where(small, 1.0, theta) / 2.0
    direct = (1.0 - half * np.cos(half) / np.sin(half)) / (2.0 * half) ** 2
    series = _series(theta**2, (1 / 12, 1 / 720, 1 / 30240, 1 / 1209600, 1 / 47900160))
    return np.where(small, series, direct)


def se3_exp(xi) -> np.ndarray:
    """Exponential map of se(3): twists to rigid transforms.

    Parameters
    ----------
    xi : array_like, shape (..., 6)
        Twists ``[rho, phi]``: ``rho`` (mm) first, then the rotation vector ``phi`` (rad).
        Any angle; ``|phi| = 0`` exactly is fine.

    Returns
    -------
    T : ndarray, shape (..., 4, 4)
        Rigid transforms ``exp(hat(xi))``, translation ``V(phi) rho`` in mm.

    Raises
    ------
    GeometryError
        If the shape is not ``(..., 6)`` or a value is not finite.

    See Also
    --------
    se3_log : the inverse map (for ``|phi| < pi``).

    Examples
    --------
    >>> T = se3_exp([1.0, 0.0, 0.0, 0.0, 0.0, np.pi / 2])  # quarter turn about z
    >>> np.round(T[:3, 3], 6) + 0.0  # the translation follows the arc: V rho
    array([0.63662, 0.63662, 0.     ])
    """
    xi = _as_float_array(xi, "xi", (6,))
    _require_finite(xi, "xi", 1)
    rho, phi = xi[..., :3], xi[..., 3:]
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    K = so3_hat(phi)
    K2 = K @ K
    a = np.sinc(theta / np.pi)
    b = 0.5 * np.sinc(theta / (2.0 * np.pi)) ** 2
    c = _c_coefficient(theta)
    eye = np.eye(3)
    T = np.zeros(xi.shape[:-1] + (4, 4))
    T[..., :3, :3] = eye + a * K + b * K2
    T[..., :3, 3] = ((eye + b * K + c * K2) @ rho[..., None])[..., 0]
    T[..., 3, 3] = 1.0
    return T


def se3_log(T, *, check: bool = True) -> np.ndarray:
    """Logarithm map of SE(3): rigid transforms to twists.

    Parameters
    ----------
    T : array_like, shape (..., 4, 4)
        Rigid transforms, translation in mm.
    check : bool
        Validate ``T`` with :func:`check_transform`.

    Returns
    -------
    xi : ndarray, shape (..., 6)
        Twists ``[rho, phi]``: ``rho = V(phi)^-1 t`` in mm, then the rotation vector ``phi``
        in rad with ``|phi|`` in [0, pi]. At exactly pi the sign of ``phi`` is arbitrary;
        ``se3_exp(se3_log(T)) == T`` holds either way.

    Raises
    ------
    GeometryError
        If ``check`` and ``T`` is not a batch of rigid transforms.

    See Also
    --------
    se3_exp : the inverse map.

    Examples
    --------
    >>> np.round(se3_log(se3_exp([1.0, 2.0, 3.0, 0.1, -0.2, 0.3])), 12) + 0.0
    array([ 1. ,  2. ,  3. ,  0.1, -0.2,  0.3])
    """
    T = check_transform(T) if check else _as_float_array(T, "T", (4, 4))
    phi = rotation_vector_from_matrix(T[..., :3, :3], check=False)
    theta = np.linalg.norm(phi, axis=-1)[..., None, None]
    K = so3_hat(phi)
    V_inv = np.eye(3) - 0.5 * K + _d_coefficient(theta) * (K @ K)
    rho = (V_inv @ T[..., :3, 3, None])[..., 0]
    return np.concatenate([rho, phi], axis=-1)
