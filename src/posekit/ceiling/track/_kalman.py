"""Kalman kernels of the ceiling trackers: constant-velocity prediction, Joseph-form update,
closed-form inverses of 2×2 covariances, Mahalanobis distances, angle wrapping."""

import numpy as np

__all__ = ["cv_predict", "kf_update"]


def cv_predict(x: np.ndarray, P: np.ndarray, dt: float, q: float) -> tuple[np.ndarray, np.ndarray]:
    """Constant-velocity prediction of ``[p_1..p_n, v_1..v_n]`` over ``dt``.

    Parameters
    ----------
    x : ndarray, shape (2n,)
        Positions then velocities (any unit u; velocities in u/s).
    P : ndarray, shape (2n, 2n)
        Covariance of ``x``.
    dt : float
        Time step, s (>= 0).
    q : float
        Spectral density of the white acceleration of each axis, u²/s³.

    Returns
    -------
    x, P : ndarray
        Predicted state and covariance (new arrays).
    """
    n = x.shape[0] // 2
    x = x.copy()
    x[:n] += dt * x[n:]
    # F P Fᵀ with F = [[I, dt I], [0, I]], block-wise (cheaper than two matmuls)
    P = P.copy()
    P[:n, :] += dt * P[n:, :]
    P[:, :n] += dt * P[:, n:]
    a, b, c = dt ** 3 / 3.0 * q, dt ** 2 / 2.0 * q, dt * q      # continuous white-noise acceleration
    for i in range(n):
        P[i, i] += a
        P[i, i + n] += b
        P[i + n, i] += b
        P[i + n, i + n] += c
    return x, P


def kf_update(x: np.ndarray, P: np.ndarray, z: np.ndarray, R: np.ndarray,
              innovation: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Kalman update with a measurement of the first ``m`` state components (Joseph form).

    Parameters
    ----------
    x : ndarray, shape (k,)
        Prior state.
    P : ndarray, shape (k, k)
        Prior covariance.
    z : ndarray, shape (m,)
        Measurement of ``x[:m]``.
    R : ndarray, shape (m, m)
        Measurement covariance.
    innovation : ndarray, shape (m,), optional
        Use this instead of ``z - x[:m]`` (a wrapped angle difference).

    Returns
    -------
    x, P : ndarray
        Posterior state and covariance.
    """
    m = z.shape[0]
    nu = z - x[:m] if innovation is None else innovation
    S = P[:m, :m] + R
    K = (_inv_sym(S) @ P[:m, :]).T                # P Hᵀ S⁻¹ with H = [I 0]
    x = x + K @ nu
    IKH = np.eye(x.shape[0])
    IKH[:, :m] -= K
    P = IKH @ P @ IKH.T + K @ R @ K.T
    return x, 0.5 * (P + P.T)


def _inv_sym(S: np.ndarray) -> np.ndarray:
    """Inverse of symmetric positive-definite matrices (..., m, m); closed form for m <= 2
    (a general solver costs more than the whole filter step at this size)."""
    m = S.shape[-1]
    if m == 1:
        return 1.0 / S
    if m == 2:
        a, b, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 1]
        det = a * d - b * b
        inv = np.empty_like(S)
        inv[..., 0, 0] = d / det
        inv[..., 1, 1] = a / det
        inv[..., 0, 1] = inv[..., 1, 0] = -b / det
        return inv
    return np.linalg.inv(S)


def _mahalanobis2(nu: np.ndarray, S: np.ndarray) -> np.ndarray:
    """Squared Mahalanobis distances of innovations ``nu`` (K, m) under covariances ``S`` (K, m, m)."""
    return np.einsum("ki,kij,kj->k", nu, _inv_sym(S), nu)


def _wrap(a):
    """Angle(s) wrapped to (-π, π]."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=float), 2.0 * np.pi)
