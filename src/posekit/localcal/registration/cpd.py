"""Rigid Coherent Point Drift with a uniform outlier component and an optional orientation term.

Rigid CPD (Myronenko & Song, 2010, PAMI 32(12), Fig. 2): the moving set Y are the centroids of
an isotropic Gaussian mixture with variance ``sigma2`` plus a uniform component of weight ``w``
that absorbs outliers; EM alternates soft correspondences ``P`` (E-step) and a closed-form
rigid (or similarity) transform and ``sigma2`` (M-step).

Orientation term, in the spirit of the hybrid mixture model of Min et al. (ICRA 2018, ref. [31]
of the paper), which adds a von Mises-Fisher factor on normals: when both point sets carry
orientations, each pair's Gaussian is multiplied by a matrix-Fisher factor
``exp(-kappa (3 - tr(Rx_n^T R Ry_m X)))``, where ``X`` is an unknown constant rotation between the
two bodies (a camera and a tool flange need not share axes) estimated in the M-step, and
``kappa`` is re-estimated like ``sigma2``. The factor is at most 1 and leaves the uniform
component unchanged, so gross position outliers with good orientations are handled as in plain
CPD. When the orientations are constant along the path the factor is the same for every pair and
the result equals plain CPD's; when they vary it sharpens the correspondences. Trajectory
matching uses it with ``matcher='hybrid'`` (:mod:`.hybrid`); the default positional matcher lets
orientations break coarse-candidate ties only. Measured with
``python -m tests.localcal.test_localcal_hybrid 0 1 2 3 4`` (35 synthetic correspondence-free
cases): rotation error mean/max 0.045/0.173 deg (cpd) vs 0.040/0.129 deg (hybrid), the hybrid
~1.4x slower; it helps most on thin paths whose orientations vary (0.17 -> 0.02 deg). On the real
TUM pairs, against the timestamped Umeyama: fr1/xyz 0.65 deg / 20 mm (cpd) and 0.65 deg / 15 mm
(hybrid) — fr1/xyz is a 125 mm (std) path with 13 mm SLAM residuals, and the reported 1-sigma is
0.26-0.32 deg there; fr2/desk 0.04 deg / 0.4 mm and 0.05 deg / 0.8 mm.
"""

from typing import NamedTuple

import numpy as np

from posekit.geometry import nearest_rotation

__all__ = ["CPDResult", "box_volume", "initial_sigma2", "rigid_cpd"]

#: Floor of the mixture variance, mm^2 (exact data would otherwise drive it to 0).
SIGMA2_FLOOR = 1e-8
#: Cap of the orientation concentration (an angular spread of ~0.2 deg).
KAPPA_MAX = 1.0 / (2.0 * np.deg2rad(0.2) ** 2)


#: Gaussian terms below exp(_LOG_CUT) are set to 0 (they are negligible against the outlier term).
_LOG_CUT = -60.0


class CPDResult(NamedTuple):
    """Result of :func:`rigid_cpd`: ``x ≈ s R y + t`` (maps the Y frame into the X frame)."""

    R: np.ndarray           #: (3, 3) rotation, det +1
    t: np.ndarray           #: (3,) translation, mm
    s: float                #: scale (1 unless with_scale)
    sigma2: float           #: final mixture variance, mm^2
    kappa: float            #: final orientation concentration (0 without orientations)
    X_body: np.ndarray      #: (3, 3) rotation between the bodies (identity without orientations)
    P: np.ndarray           #: (M, N) final posterior of centroid m for point n
    iterations: int


def box_volume(X) -> float:
    """Volume of the bounding box of a point set, each side at least a tenth of the longest.

    The support of CPD's uniform outlier component: a planar path's outliers also leave its plane.

    Parameters
    ----------
    X : ndarray, shape (N, 3)
        Points, mm.

    Returns
    -------
    float
        Volume, mm^3 (each side at least 1 mm).
    """
    side = np.ptp(X, axis=0)
    return float(np.prod(np.maximum(side, max(1.0, 0.1 * side.max()))))


def initial_sigma2(X, Y) -> float:
    """CPD's initial variance: mean squared distance of all pairs / 3.

    Parameters
    ----------
    X : ndarray, shape (N, 3)
        Data points, mm.
    Y : ndarray, shape (M, 3)
        Centroids, in the same frame as ``X``, mm.

    Returns
    -------
    float
        ``sum |x_n - y_m|^2 / (3 M N)``, mm^2.
    """
    n, m = len(X), len(Y)
    return float((m * (X ** 2).sum() + n * (Y ** 2).sum() - 2.0 * X.sum(0) @ Y.sum(0)) / (3 * m * n))


def _mm(A, B) -> np.ndarray:
    """``A @ B`` for a short inner or outer dimension of 9, as three products of width 3.

    Same result as ``A @ B``; multithreaded BLAS is erratic for these thin shapes on a loaded
    machine (35 ms instead of 1 ms for 400 x 9 x 400), the width-3 products are not.
    """
    if A.shape[1] == 9:
        return A[:, :3] @ B[:3] + A[:, 3:6] @ B[3:6] + A[:, 6:] @ B[6:]
    return np.hstack([A @ B[:, :3], A @ B[:, 3:6], A @ B[:, 6:]])


def rigid_cpd(X, Y, *, R0=None, t0=None, s0: float = 1.0, w: float = 0.05, with_scale: bool = False,
              Rx=None, Ry=None, sigma2=None, max_iter: int = 150, tol: float = 1e-6,
              uniform_density: float | None = None) -> CPDResult:
    """Register centroids ``Y`` to data ``X`` by rigid (or similarity) CPD.

    Parameters
    ----------
    X : ndarray, shape (N, 3)
        Data points (the fixed set), mm.
    Y : ndarray, shape (M, 3)
        Centroids (the moving set), mm.
    R0 : ndarray, shape (3, 3), optional
        Initial rotation ``R_X_Y`` (default identity).
    t0 : ndarray, shape (3,), optional
        Initial translation, mm (default 0): ``x ≈ s0 R0 y + t0``.
    s0 : float
        Initial scale.
    w : float
        Weight of the uniform outlier component, in [0, 1).
    with_scale : bool
        Estimate a scale as well.
    Rx : ndarray, shape (N, 3, 3), optional
        Orientations of the data points (their world frame); with ``Ry`` enables the orientation term.
    Ry : ndarray, shape (M, 3, 3), optional
        Orientations of the centroids.
    sigma2 : float, optional
        Initial variance, mm^2 (default :func:`initial_sigma2` after the initial transform).
    max_iter : int
        EM iterations at most.
    tol : float
        Stop when the relative change of ``sigma2`` and the change of R and t (rad, mm) fall below it.
    uniform_density : float, optional
        Density of the outlier component, 1/mm^3. Default: uniform over the bounding box of X,
        each side at least a tenth of the longest (a planar path's outliers also leave its
        plane). The original CPD uses ``1/N`` (pass ``1/len(X)`` to reproduce it, e.g. to
        compare with pycpd); with mm coordinates that makes the outlier term dominate while
        ``sigma2`` is large.

    Returns
    -------
    CPDResult
        ``x ≈ s R y + t`` (maps the Y frame into the X frame), the final variance and posteriors.
    """
    X = np.asarray(X, dtype=np.float64)
    Y = np.asarray(Y, dtype=np.float64)
    N, M = len(X), len(Y)
    R = np.eye(3) if R0 is None else np.asarray(R0, dtype=np.float64)
    t = np.zeros(3) if t0 is None else np.asarray(t0, dtype=np.float64)
    s = float(s0)
    use_rot = Rx is not None and Ry is not None
    TY = s * Y @ R.T + t
    if sigma2 is None:
        sigma2 = initial_sigma2(X, TY)
    sigma2 = max(float(sigma2), SIGMA2_FLOOR)
    Xb = np.eye(3)
    kappa = 0.0
    if use_rot:
        Rx_flat = np.asarray(Rx, dtype=np.float64).reshape(N, 9)
        Rx = Rx_flat.reshape(N, 3, 3)
        Ry = np.asarray(Ry, dtype=np.float64)
    if uniform_density is None:
        uniform_density = 1.0 / box_volume(X)
    xx = (X ** 2).sum(1)
    P = np.zeros((M, N))
    it = 0
    for it in range(1, max_iter + 1):
        # ---- E-step
        d2 = (TY ** 2).sum(1)[:, None] + xx[None, :] - 2.0 * TY @ X.T
        np.maximum(d2, 0.0, out=d2)
        logp = -d2 / (2.0 * sigma2)
        if use_rot:
            if kappa == 0.0:                 # first pass: X and kappa from positional posteriors
                P0 = np.exp(logp - logp.max(0))
                P0 /= P0.sum(0)
                G = _mm(P0.T, Ry.reshape(M, 9)).reshape(N, 3, 3)
                Xb = nearest_rotation(np.einsum("nji,kj,nkl->il", G, R, Rx))
                tr = _mm((R @ Ry @ Xb).reshape(M, 9), Rx_flat.T)
                mean_gap = max(float((P0 * (3.0 - tr)).sum() / N), 1e-12)
                kappa = min(1.5 / mean_gap, KAPPA_MAX)
            tr = _mm((R @ Ry @ Xb).reshape(M, 9), Rx_flat.T)     # tr(Rx_n^T R Ry_m X), (M, N)
            logp = logp - kappa * (3.0 - tr)
        c = (2.0 * np.pi * sigma2) ** 1.5 * w / (1.0 - w) * M * uniform_density
        logp[logp < _LOG_CUT] = -np.inf         # exact zeros: no slow subnormal arithmetic
        P = np.exp(logp)
        den = P.sum(0) + c
        den = np.where(den > 0, den, np.finfo(float).tiny)
        P /= den
        # ---- M-step
        Np = P.sum()
        if Np < 1e-12:
            break
        Pt1, P1 = P.sum(0), P.sum(1)
        mu_x = Pt1 @ X / Np
        mu_y = P1 @ Y / Np
        Xh, Yh = X - mu_x, Y - mu_y
        A = Xh.T @ P.T @ Yh                                      # sum P x^ y^T
        yPy = P1 @ (Yh ** 2).sum(1)
        xPx = Pt1 @ (Xh ** 2).sum(1)
        B = s * A / sigma2
        if use_rot:
            G = _mm(P.T, Ry.reshape(M, 9)).reshape(N, 3, 3)      # sum_m P_mn Ry_m
            B = B + kappa * np.einsum("nij,kj,nlk->il", Rx, Xb, G)
        R_new = nearest_rotation(B)                              # argmax tr(R^T B), det +1
        if with_scale:
            s = float(np.trace(A.T @ R_new) / yPy)
        t_new = mu_x - s * R_new @ mu_y
        sigma2_new = max((xPx - 2.0 * s * np.trace(R_new.T @ A) + s * s * yPy) / (3.0 * Np), SIGMA2_FLOOR)
        if use_rot:
            C = np.einsum("nji,kj,nkl->il", G, R_new, Rx)   # sum G_n^T R^T Rx_n
            Xb = nearest_rotation(C)
            Z = (R_new @ Ry @ Xb).reshape(M, 9)
            gap = max(float((P * (3.0 - _mm(Z, Rx_flat.T))).sum() / Np), 1e-12)
            kappa = min(1.5 / gap, KAPPA_MAX)
        dR = np.linalg.norm(R_new - R)
        dt = np.linalg.norm(t_new - t)
        dsig = abs(sigma2_new - sigma2) / sigma2
        R, t, sigma2 = R_new, t_new, sigma2_new
        TY = s * Y @ R.T + t
        if dR < tol and dt < tol * 1e3 and dsig < tol * 1e3:
            break
    return CPDResult(R, t, s, float(sigma2), float(kappa), Xb, P, it)
