"""The error model and the verdict of a pose from one profile (DESIGN.md "Trust").

The corners' covariance under an assumed noise model (:func:`corner_covariance`) and under
the gauge's declared tolerance (:func:`face_tolerance_covariance`), the closed form's own
linearisation, and the tests that make an estimate of
:func:`~posekit.profiler.estimate.solve.solve_pose` 'ok' or 'suspect'.

Verdict (DESIGN.md "Trust"). Every estimate carries ``status`` 'ok' or 'suspect' with a
``reason``, from a χ² test at significance α (default :data:`DEFAULT_SIGNIFICANCE`, the
rate at which good data are called suspect; split equally over the tests made):

* **fit**: ``χ² = rᵀ C⁻¹ r`` of the corner residuals at the estimate, with ``C`` the
  corners' covariance under the assumed noise plus the gauge's ``tolerance_um`` (each
  face's position uncertain by that 1σ, mapped to the corners at the estimated pose)
  plus the sensor's unknown scale (:func:`scale_covariance`, 1σ ``noise.scale_sigma_ppm``,
  default 100 ppm, only with an assumed ``noise``), against χ²(2n - 6). The refinement
  itself is weighted by the line fits' own covariance (plus the tolerance and the scale),
  as the real-time server weights it, so the offline and streamed poses agree; on data
  that match the model the two weightings differ by sampling only. The scale term is what
  makes the std honest on a real sensor: a scale error of 100 ppm moves the corners mostly
  as a pose change would, so it biases the pose (demo-5, realistic profiles: without it
  only ~60 % of the errors lay within 2σ, rz ~10 %; with it 96 %) and, left out, also made
  ~5 % of good realistic profiles suspect (with it 2 in 10,000).
  For the closed form, r and its covariance come from the closed form's own linearisation
  (its pseudo-inverse, rank 2n - 6). It catches a wrong gauge
  file, a face machined off its drawing beyond the tolerance, a rounded or chamfered
  ridge that moves a corner, a wrong basin (a local minimum fits badly).
* **noise** (only with an assumed ``noise`` model): the scatter of the profile's points
  about the fitted faces, ``Σ RSS_j / σ_j²`` against χ²(Σ (N_j - 2)) with σ_j the assumed
  noise across face j. Noise above the sensor model's makes the covariance a lie.
* **ambiguity** (mounting 'auto'): the other corner order fits too (passes the fit test at
  a possible pose); **possibility**: the best fit would see a face from behind.

The assumed noise is explicit: ``noise=NoiseModel(...)`` (the estimator entry points in
:mod:`~posekit.profiler.estimate.pipeline` default to the LJ-X8400's 10/5 µm). With ``noise=None``
the corner covariance comes from the line fits' own residuals (the noise is estimated,
so the test sees the geometry but not the noise level) — the behaviour of the studies.

A batch adds one more test, of the gauge file against all its profiles together
(:mod:`~posekit.profiler.estimate.gauge_check`): what one profile cannot see.
"""

import functools
from dataclasses import dataclass

import numpy as np

from posekit._chi2 import chi2 as _chi2
from posekit._jit import njit

from ...errors import EstimationError
from ...geometry import matrix_from_rotation_vector, quaternion_from_matrix, rotation_vector_from_matrix
from .closed_form import cf_kernel
from .corners import Corners
from .gauge import SEEN_FROM_BEHIND_COS, _piercing_points
from .raycast import seen_from_behind

__all__ = ["PoseEstimate", "DEFAULT_SIGNIFICANCE", "corner_covariance", "face_tolerance_covariance", "scale_covariance",
           "chi2_critical", "check_noise"]

#: Default significance α of the consistency test: the rate at which data that match the
#: model are called suspect. Measured on simulated good data of the bundled gauges
#: (tests/profiler/test_verdict_rates.py): well under 1 % suspect.
DEFAULT_SIGNIFICANCE = 1e-3


@dataclass(frozen=True)
class PoseEstimate:
    """Result of :func:`~posekit.profiler.estimate.solve.solve_pose`.

    Attributes
    ----------
    T_G_F : ndarray, shape (4, 4)
        Pose of the profiler frame F in the gauge frame G, mm.
    cov : ndarray, shape (6, 6)
        Covariance of the pose error ``[δt (mm), δθ (rad)]`` with both parts in G
        (``t_true = t + δt``, ``R_true = Exp(δθ) R``), propagated from the corners (and
        the gauge's tolerance): for 'mle' the inverse Fisher information, for 'cf' the
        closed form's own linearisation ``J C Jᵀ`` (its error is far larger).
    reprojection_um : float
        Mean distance of the estimated 3D corners from their ridges, µm.
    cost : float
        The refinement's objective at the estimate: ``rᵀ C⁻¹ r`` with ``C`` the line fits'
        corner covariance (plus the gauge's tolerance).
    reversed : bool
        True when the corners matched the ridges in reverse order (sensor mounted the
        other way round).
    method : str
    chi2 : float
        Consistency statistic of the fit, ``rᵀ C⁻¹ r`` with ``C`` under the assumed noise
        (equal to ``cost`` for 'mle' without one; the closed form's own linearisation for
        'cf'): χ²(dof) on data that match the model.
    dof : int
        ``2n - 6``.
    status : {'ok', 'suspect'}
    reason : str or None
        Why the estimate is suspect (None when 'ok').
    """

    T_G_F: np.ndarray
    cov: np.ndarray
    reprojection_um: float
    cost: float
    reversed: bool
    method: str
    chi2: float = float("nan")
    dof: int = 0
    status: str = "ok"
    reason: str | None = None

    @property
    def t_mm(self) -> np.ndarray:
        """Translation of F in G, mm, shape (3,)."""
        return self.T_G_F[:3, 3]

    @property
    def q_wxyz(self) -> np.ndarray:
        """Rotation of F in G as a unit quaternion [w, x, y, z], shape (4,)."""
        return quaternion_from_matrix(self.T_G_F[:3, :3])

    @property
    def std_t_um(self) -> np.ndarray:
        """Predicted standard deviation of the translation along x, y, z of G, µm."""
        return np.sqrt(np.diag(self.cov)[:3]) * 1e3

    @property
    def std_rot_deg(self) -> np.ndarray:
        """Predicted standard deviation of the rotation about x, y, z of G, degrees."""
        return np.degrees(np.sqrt(np.diag(self.cov)[3:]))


# --------------------------------------------------------------------------- covariances


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


def _face_sigma_mm(corners: Corners, noise) -> np.ndarray:
    """Assumed scatter of each face's points across its fitted line, mm, (n + 1,)."""
    return _face_sigma_kernel(np.ascontiguousarray(corners.lines, dtype=np.float64), noise.sigma_x_um * 1e-3,
                              noise.sigma_z_um * 1e-3)


@njit(cache=True, nogil=True)
def _noise_statistic(lines, sigma, n_points, sx, sz):
    """``Σ (N_j - 2) σ̂_j² / σ_j²`` and its dof ``Σ (N_j - 2)`` (the noise test of :func:`_verdict`)."""
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
#: range (:attr:`ProfilerModel.z_mid <posekit.profiler.estimate.sensor.ProfilerModel.z_mid>`), as in the
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


# --------------------------------------------------------------------------- verdict


class _Candidate:
    """One corner order's solution; what only the verdict may need is computed on demand."""

    __slots__ = ("rev", "T", "cov", "reprojection_mm", "cost", "chi2", "_c", "_gauge", "_resid", "_possible")

    def __init__(self, rev, T, cov, reprojection_mm, cost, chi2, c, gauge):
        self.rev, self.T, self.cov, self.reprojection_mm, self.cost, self.chi2 = rev, T, cov, reprojection_mm, cost, chi2
        self._c = c                   # corners in ridge order
        self._gauge = gauge
        self._resid = None
        self._possible = None

    @property
    def resid_mm(self) -> np.ndarray:
        """|corner - predicted| per ridge, mm."""
        if self._resid is None:
            P = _piercing_points(self._gauge, self.T[:3, :3], self.T[:3, 3])
            self._resid = (np.full(len(self._c), np.nan) if P is None
                           else np.sqrt(np.sum((self._c - P) ** 2, axis=1)))
        return self._resid

    @property
    def possible(self) -> bool:
        """Whether the pose could have produced the corners (no face seen from behind)."""
        if self._possible is None:
            self._possible = not seen_from_behind(self._gauge.normals, self.T, self._c, SEEN_FROM_BEHIND_COS)
        return self._possible


def _cf_linearisation(c, C, gauge, T_cf):
    """The closed form's own error model (ridge order): pose covariance (6, 6) and χ².

    ``J = ∂pose/∂corners`` by central differences of eq. (9)-(14) (pose error as in
    :attr:`PoseEstimate.cov`); the residual ``r = c - P(pose(c))`` then has covariance
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
    P0 = _piercing_points(gauge, T_cf[:3, :3], T_cf[:3, 3])
    JP = np.empty((m, 6))
    for k in range(6):
        pts = []
        for sign in (1.0, -1.0):
            d = np.zeros(6)
            d[k] = sign * h
            R = matrix_from_rotation_vector(d[3:]) @ T_cf[:3, :3]
            P = _piercing_points(gauge, R, T_cf[:3, 3] + d[:3])
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


@functools.lru_cache(maxsize=4096)
def chi2_critical(alpha: float, dof: int) -> float:
    """Critical value of the χ² test: ``chi2.isf(alpha, dof)`` (0 for ``dof <= 0``), cached.

    The real-time path evaluates it per frame; SciPy's ``isf`` costs ~30 µs a call.
    """
    return float(_chi2.isf(alpha, dof)) if dof > 0 else 0.0


def _noise_verdict(corners: Corners, noise, alpha: float) -> str | None:
    """The reason why the profile is noisier than ``noise`` allows, or None."""
    stat, dof = _noise_statistic(np.ascontiguousarray(corners.lines, dtype=np.float64),
                                 np.ascontiguousarray(corners.sigma, dtype=np.float64),
                                 np.ascontiguousarray(corners.n_points, dtype=np.int64),
                                 noise.sigma_x_um * 1e-3, noise.sigma_z_um * 1e-3)
    crit = chi2_critical(alpha, int(dof))
    if not stat > crit:
        return None
    stat, dof = float(stat), int(dof)
    sig = _face_sigma_mm(corners, noise)
    ratio = corners.sigma / sig
    j = int(np.argmax(ratio))
    return (f"the profile scatters {np.sqrt(stat / dof):.2f}x the assumed noise about its faces (chi2 = {stat:.0f} "
            f"> {crit:.0f}, {dof} dof, worst face {j}: {corners.sigma[j] * 1e3:.1f} µm RMS, expected "
            f"{sig[j] * 1e3:.1f} µm): noisier than the sensor model (x {noise.sigma_x_um:g} µm, "
            f"z {noise.sigma_z_um:g} µm) or a face that is not flat")


def check_noise(noise) -> None:
    """Raise an :class:`~posekit.errors.EstimationError` unless ``noise`` is None or a usable noise model."""
    if noise is None:
        return
    sx = getattr(noise, "sigma_x_um", None)
    sz = getattr(noise, "sigma_z_um", None)
    if sx is None or sz is None:
        raise EstimationError(f"noise: expected a NoiseModel (sigma_x_um, sigma_z_um), got {type(noise).__name__}")
    if not (np.isfinite(sx) and np.isfinite(sz) and sx >= 0 and sz >= 0 and sx + sz > 0):
        raise EstimationError(f"noise: the assumed noise must be finite, >= 0 and not zero in both x and z, "
                              f"got x {sx:g} µm, z {sz:g} µm")


def _verdict(cands, corners: Corners, gauge, method: str, noise, significance: float) -> PoseEstimate:
    """The best candidate (a possible pose first, then the lower χ²) with its verdict (module docstring)."""
    n = corners.points.shape[0]
    # A possible pose first, then the lower χ²: the other candidate's possibility is only
    # looked at when it matters (the lower χ² is impossible, or the other one fits too).
    cands.sort(key=lambda c: c.chi2 if np.isfinite(c.chi2) else np.inf)
    if len(cands) == 2 and not cands[0].possible and cands[1].possible:
        cands.reverse()
    best = cands[0]

    dof = 2 * n - 6
    alpha = significance / (2 if noise is not None else 1)
    crit = chi2_critical(alpha, dof)
    reasons = []
    if not best.chi2 <= crit:
        k = int(np.nanargmax(best.resid_mm)) if np.any(np.isfinite(best.resid_mm)) else 0
        what = (f"the assumed noise (x {noise.sigma_x_um:g} µm, z {noise.sigma_z_um:g} µm)" if noise is not None
                else "the line fits' noise")
        reasons.append(f"chi2 = {best.chi2:.1f} > {crit:.1f} ({dof} dof, significance {alpha:g}): the corners do "
                       f"not fit gauge '{gauge.name}' within {what} and its tolerance ({gauge.tolerance_um:g} µm), "
                       f"largest miss at corner {k} ({best.resid_mm[k] * 1e3:.1f} µm): wrong gauge file, a face off "
                       "its drawing, a rounded or chamfered ridge, or a wrong basin")
    if noise is not None:
        why = _noise_verdict(corners, noise, alpha)
        if why is not None:
            reasons.append(why)
    if not best.possible:
        reasons.append("at the fitted pose the sensor would see a face from behind (through the gauge): no real "
                       "pose gives these corners")
    if len(cands) == 2 and cands[1].chi2 <= crit and cands[1].possible:
        reasons.append(f"the {'normal' if best.rev else 'reversed'} corner order fits too (chi2 = "
                       f"{cands[1].chi2:.1f} <= {crit:.1f}): the mounting cannot be told from this profile, "
                       "give it (--mounting normal|reversed)")
    # reasons hold no "; " of their own: the record joins them with it
    return PoseEstimate(T_G_F=best.T, cov=best.cov, reprojection_um=best.reprojection_mm * 1e3, cost=best.cost,
                        reversed=best.rev, method=method, chi2=float(best.chi2), dof=dof,
                        status="suspect" if reasons else "ok", reason="; ".join(reasons) or None)

