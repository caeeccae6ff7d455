"""The error model of a pose from one profile: the corners' covariance and what it maps to.

The corners' covariance under an assumed noise model (:func:`corner_covariance`), under the
gauge's declared tolerance (:func:`face_tolerance_covariance`) and under the sensor's unknown
scale (:func:`scale_covariance`), and the closed form's own linearisation
(:func:`cf_linearisation`: its pose covariance and χ²). The tests that read them are in
:mod:`~posekit.profiler.estimate.consistency`.
"""

import numpy as np

from posekit._jit import njit

from ...geometry import matrix_from_rotation_vector, rotation_vector_from_matrix
from ..gauge.ambiguity import piercing_points
from .closed_form import cf_kernel
from .corners import Corners

__all__ = ["corner_covariance", "face_tolerance_covariance", "scale_covariance", "plus_scale_covariance",
           "cf_linearisation", "face_sigma_mm", "noise_statistic", "SCALE_Z_CENTER_MM"]


def corner_covariance(corners: Corners, noise=None) -> np.ndarray:
    """Joint covariance of the corners under an assumed noise model, mm², (2n, 2n).

    The line fits of :func:`~posekit.profiler.estimate.corners.detect_corners` give each corner's
    covariance from the residual RMS σ̂_j of its two faces. Under a known noise model the
    scatter of face j across its line is ``σ_j² = nx² σx² + nz² σz²`` ((nx, nz) its unit
    normal in F); each face's share of the covariance is rescaled by ``(σ_j / σ̂_j)²``.
    The shares separate exactly: with ``N_k`` the 2×2 matrix of the normals of faces k,
    k+1, ``N_k δp_k`` holds the two faces' offsets at corner k, one face per entry, so the
    rescaled covariance is ``T C Tᵀ`` with ``T_k = N_k⁻¹ diag(σ_k/σ̂_k, σ_k+1/σ̂_k+1) N_k``.

    Parameters
    ----------
    corners : Corners
        Corners in scan order with their fits (``lines``, ``sigma``, ``cov``).
    noise : NoiseModel or None
        Assumed noise (``sigma_x_um``, ``sigma_z_um``: 1σ per point along x and z of F,
        µm). None: the fits' own residuals (``corners.cov`` unchanged).

    Returns
    -------
    ndarray, shape (2n, 2n)
    """
    if noise is None:
        return np.ascontiguousarray(corners.cov, dtype=np.float64)
    return _model_corner_cov(np.ascontiguousarray(corners.lines, dtype=np.float64),
                             np.ascontiguousarray(corners.sigma, dtype=np.float64),
                             np.ascontiguousarray(corners.cov, dtype=np.float64),
                             noise.sigma_x_um * 1e-3, noise.sigma_z_um * 1e-3)


@njit(cache=True, nogil=True)
def _face_sigma_kernel(lines, sx, sz):
    """Assumed scatter of each face's points across its fitted line, mm, (n + 1,)."""
    out = np.empty(lines.shape[0])
    for j in range(lines.shape[0]):
        out[j] = max(np.hypot(lines[j, 0] * sx, lines[j, 1] * sz), 1e-9)
    return out


@njit(cache=True, nogil=True)
def _model_corner_cov(lines, sigma, cov, sx, sz):
    """``T C Tᵀ`` (symmetrised) with block-diagonal ``T_k = N_k⁻¹ diag(f_k, f_k+1) N_k``,
    ``f_j = σ_j / σ̂_j`` (:func:`corner_covariance`)."""
    f = _face_sigma_kernel(lines, sx, sz) / sigma
    m = cov.shape[0]
    n = m // 2
    T = np.zeros((m, m))
    for k in range(n):
        a, b = lines[k, 0], lines[k, 1]
        c, d = lines[k + 1, 0], lines[k + 1, 1]
        det = a * d - b * c
        fa, fc = f[k], f[k + 1]
        # N⁻¹ = [[d, -b], [-c, a]] / det;  M = diag(fa, fc) N = [[fa a, fa b], [fc c, fc d]]
        T[2 * k, 2 * k] = (d * fa * a - b * fc * c) / det
        T[2 * k, 2 * k + 1] = (d * fa * b - b * fc * d) / det
        T[2 * k + 1, 2 * k] = (-c * fa * a + a * fc * c) / det
        T[2 * k + 1, 2 * k + 1] = (-c * fa * b + a * fc * d) / det
    out = np.zeros((m, m))
    for i in range(m):
        for j in range(m):
            acc = 0.0
            for p in range(2 * (i // 2), 2 * (i // 2) + 2):
                for q in range(2 * (j // 2), 2 * (j // 2) + 2):
                    acc += T[i, p] * cov[p, q] * T[j, q]
            out[i, j] = acc
    for i in range(m):
        for j in range(i + 1, m):
            v = 0.5 * (out[i, j] + out[j, i])
            out[i, j] = v
            out[j, i] = v
    return out


def face_sigma_mm(corners: Corners, noise) -> np.ndarray:
    """Assumed scatter of each face's points across its fitted line, mm, (n + 1,)."""
    return _face_sigma_kernel(np.ascontiguousarray(corners.lines, dtype=np.float64), noise.sigma_x_um * 1e-3,
                              noise.sigma_z_um * 1e-3)


@njit(cache=True, nogil=True)
def noise_statistic(lines, sigma, n_points, sx, sz):
    """``Σ (N_j - 2) σ̂_j² / σ_j²`` and its dof ``Σ (N_j - 2)`` (the noise test of :mod:`~posekit.profiler.estimate.consistency`)."""
    sig = _face_sigma_kernel(lines, sx, sz)
    stat = 0.0
    dof = 0
    for j in range(sig.shape[0]):
        stat += (n_points[j] - 2.0) * sigma[j] ** 2 / sig[j] ** 2
        dof += n_points[j] - 2
    return stat, dof


def face_tolerance_covariance(gauge, T_G_F, reversed_order: bool = False) -> np.ndarray:
    """Covariance of the corners from the gauge's face tolerance, mm², (2n, 2n).

    Face k lies at ``normal_k · p = offset_k + δ_k`` with independent ``δ_k ~ N(0, tol²)``
    (``tol = gauge.tolerance_um``). In the laser plane of a pose ``T_G_F`` face k is the
    line ``m_k · (x, z) = offset_k - normal_k · t`` with ``m_k`` the x, z part of
    ``R_G_Fᵀ normal_k``; corner k (faces k, k+1) moves by ``N_k⁻¹ [δ_k, δ_k+1]``.

    Parameters
    ----------
    gauge : Gauge
    T_G_F : ndarray, shape (4, 4)
        Pose of the profiler in G, mm.
    reversed_order : bool
        Corners in reverse scan order (the covariance is returned in scan order).

    Returns
    -------
    ndarray, shape (2n, 2n)
    """
    n = gauge.n_corners
    tol = gauge.tolerance_um * 1e-3
    if tol == 0:
        return np.zeros((2 * n, 2 * n))
    m = (gauge.normals @ np.asarray(T_G_F)[:3, :3])[:, [0, 2]]       # rows: (R^T normal_k)_x, _z
    J = np.zeros((2 * n, n + 1))
    for k in range(n):
        J[2 * k:2 * k + 2, k:k + 2] = np.linalg.inv(m[k:k + 2])
    cov = tol**2 * (J @ J.T)
    if reversed_order:
        idx = _reverse_index(n)
        cov = cov[np.ix_(idx, idx)]
    return cov


#: Depth about which the sensor's z scale error acts, mm: the middle of the LJ-X8400's measuring
#: range (:attr:`ProfilerModel.z_mid <posekit.profiler.sensor.ProfilerModel.z_mid>`), as in the
#: realistic simulator.
SCALE_Z_CENTER_MM = 442.5


def scale_covariance(points, scale_sigma_ppm: float, z_center_mm: float = SCALE_Z_CENTER_MM) -> np.ndarray:
    """Covariance of the corners from the sensor's unknown scale errors, mm², (2n, 2n).

    A sensor whose x and z readings are off by the factors ``1 + s_x``, ``1 + s_z`` (x about
    0, z about ``z_center_mm``) moves corner ``(x_i, z_i)`` by ``(s_x x_i, s_z (z_i - z_c))``:
    with independent ``s_x, s_z ~ N(0, σ_s²)`` the corners' covariance is
    ``σ_s² (j_x j_xᵀ + j_z j_zᵀ)``. It is a property of the sensor, not of the pose, so it is
    taken at the measured corners (their error changes it by far less than 1 %). Rank 2: it
    makes a pose's std honest under an uncalibrated scale (the fit is weighted by it too) and
    costs the consistency test little power.

    Parameters
    ----------
    points : array_like, shape (n, 2)
        Corners (x, z) in F, mm, in the order of the covariance they are added to.
    scale_sigma_ppm : float
        1σ of each scale error, ppm.
    z_center_mm : float
        Depth about which the z scale acts, mm.

    Returns
    -------
    ndarray, shape (2n, 2n)
    """
    p = np.ascontiguousarray(points, dtype=np.float64)
    return plus_scale_covariance(np.zeros((2 * p.shape[0], 2 * p.shape[0])), p, (scale_sigma_ppm * 1e-6) ** 2,
                                 z_center_mm)


@njit(cache=True, nogil=True)
def plus_scale_covariance(C, points, var, z_center_mm=SCALE_Z_CENTER_MM):
    """``C + scale_covariance(points, σ)`` (a new array) with ``var = σ²`` (σ as a fraction, not ppm):
    the per-profile path's form (a few hundred ns)."""
    n = points.shape[0]
    out = C.copy()
    for i in range(n):
        xi = points[i, 0]
        zi = points[i, 1] - z_center_mm
        for j in range(n):
            out[2 * i, 2 * j] += var * xi * points[j, 0]
            out[2 * i + 1, 2 * j + 1] += var * zi * (points[j, 1] - z_center_mm)
    return out


def _reverse_index(n: int) -> np.ndarray:
    """Index of the stacked ``[x0, z0, x1, z1, ...]`` with the corners in reverse order."""
    return (2 * (n - 1 - np.arange(n))[:, None] + np.arange(2)).ravel()

def cf_linearisation(c, C, gauge, T_cf):
    """The closed form's own error model (ridge order): pose covariance (6, 6) and χ².

    ``J = ∂pose/∂corners`` by central differences of eq. (9)-(14) (pose error as in
    :attr:`~posekit.profiler.estimate.result.PoseEstimate.cov`); the residual ``r = c - P(pose(c))`` then has covariance
    ``M C Mᵀ`` with ``M = I - J_P J`` (a projection of rank 2n - 6), and
    ``χ² = rᵀ (M C Mᵀ)⁺ r``.
    """
    n = c.shape[0]
    m = 2 * n
    dof = m - 6
    h = 1e-5
    flat = c.ravel()
    J = np.empty((6, m))
    for i in range(m):
        poses = []
        for sign in (1.0, -1.0):
            cp = flat.copy()
            cp[i] += sign * h
            ok, R, t = cf_kernel(cp.reshape(n, 2), gauge.ridge_q, gauge.ridge_s)
            if not ok:
                return np.full((6, 6), np.nan), np.nan
            poses.append((R, t))
        (Rp, tp), (Rm, tm) = poses
        J[:3, i] = (tp - tm) / (2 * h)
        J[3:, i] = rotation_vector_from_matrix(Rp @ Rm.T, check=False) / (2 * h)
    cov = J @ C @ J.T
    P0 = piercing_points(gauge, T_cf[:3, :3], T_cf[:3, 3])
    JP = np.empty((m, 6))
    for k in range(6):
        pts = []
        for sign in (1.0, -1.0):
            d = np.zeros(6)
            d[k] = sign * h
            R = matrix_from_rotation_vector(d[3:]) @ T_cf[:3, :3]
            P = piercing_points(gauge, R, T_cf[:3, 3] + d[:3])
            if P is None or P0 is None:
                return 0.5 * (cov + cov.T), np.nan
            pts.append(P.ravel())
        JP[:, k] = (pts[0] - pts[1]) / (2 * h)
    r = flat - P0.ravel()
    M = np.eye(m) - JP @ J
    try:
        L = np.linalg.cholesky(C)
    except np.linalg.LinAlgError:
        return 0.5 * (cov + cov.T), np.nan
    Mw = np.linalg.solve(L, M @ L)
    rw = np.linalg.solve(L, r)
    lam, U = np.linalg.eigh(Mw @ Mw.T)
    lam, U = lam[-dof:], U[:, -dof:]
    chi2 = float(np.sum((U.T @ rw) ** 2 / lam)) if dof > 0 else 0.0
    return 0.5 * (cov + cov.T), chi2

