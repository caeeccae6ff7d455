"""Is the gauge what its file says? A test of the gauge file across a batch of profiles.

One profile cannot tell. A face machined off its drawing moves the corners of a profile
almost exactly as a shift of the pose along the ridges (G's y, seen only through the
ridges' skew) would: on demo-5 a face 20 µm off is a pose 0.1–0.9 mm off along y, and the
per-profile χ² test (:mod:`~posekit.profiler.estimate.consistency`) sees only what is left,
which for faces 1, 3 and 5 of demo-5 is within the noise. Such an estimate reads 'ok' while
its error is several times its std: the single-profile limit, which no per-profile test
removes. Across profiles at varied poses the same face error needs a different pose shift
in every profile, so the profiles disagree with one another; a bundle adjustment of every
face and every pose (:mod:`~posekit.profiler.gauge.bundle`, the solver of
``calibrate-gauge``) sees it.

Test. :func:`check_gauge_file` adjusts the ``n + 1`` face planes ``θ`` (tilts and offsets
from the file's planes) and every pose, the gauge frame held to the file's by the datum and
hinge conditions of :mod:`~posekit.profiler.gauge.calibration` (``C θ = 0``); the
corners are weighted by the assumed sensor noise. On the constrained subspace (an
orthonormal basis ``N`` of ``{θ : C θ = 0}``, ``θ = N φ``, ``m = 3(n + 1) - 8`` values) the
estimate ``φ̂`` has, if the file is right, covariance

    ``Σ = S_φ⁻¹ M S_φ⁻¹``,   ``M = S_φ + A Λ Aᵀ + σ_s² B Bᵀ``,   ``S_φ = Nᵀ S N``,   ``A = Nᵀ S``,

with ``S`` the faces' information (the poses eliminated, Schur complement), ``Λ`` the prior
covariance of the as-built faces about the file's that the declared ``tolerance_um`` allows
(each face's offset 1σ = ``tolerance_um``, as in the per-profile test; tilts none), and
``B = Nᵀ S_θs`` the faces' response to a scale error of the sensor in x and z, allowed with
1σ ``σ_s`` = the noise model's ``scale_sigma_ppm`` (default 100 ppm, an uncalibrated sensor;
:data:`SCALE_ALLOWANCE_PPM` without a noise model): a sensor scale error also changes the
corners' pattern and would otherwise be taken for a face off. The statistic is the Wald form
of the likelihood ratio of "faces as the file says, within its tolerance" against "faces free",

    ``χ² = φ̂ᵀ Σ⁻¹ φ̂ / s² = gᵀ M⁻¹ g / s²``  (``g = S_φ φ̂``)   against χ²(m),

with ``s² = max(1, χ²_fit / dof_fit)`` the bundle's own residual scale (so corners noisier
than the assumed noise do not pass for a face error). One face off spreads its signal over
the m dof, so each face also gets its own 1-dof score test, ``z_f² = (u_fᵀ M⁻¹ g)² / (u_fᵀ
M⁻¹ u_f) / s²`` against χ²(1) (``u_f`` the response of ``g`` to a unit offset of face f): the
machining defect the test is for. The significance α (default 1e-3) is split, α/2 to the
test of all faces and α/(2(n + 1)) to each face's own, so a right gauge file fails on at
most α of batches; when it fails, the face that best explains the misfit if it alone were off
is named with its offset in µm and the χ² then left (and any other face that explains at
least half as much). A pass says from which offset this batch would see one face off
(``face_detectable_um``, ``sqrt(χ²₁ limit) × its σ``): a face off by less passes, and the
poses carry its bias.

Measured limits (demo-5, 100 profiles per batch, one face 20 µm off, default allowance 100 ppm;
``python -m posekit.profiler.studies.gauge_check_rates``). posekit's realistic simulator at its
default poses, 30 batches per face: with no tolerance declared no batch passes, whichever face is off; with
``tolerance_um: 2`` faces 0, 2, 4 and 5 fail every batch, face 1 29 of 30 (its own 1-dof test;
without it and the scale allowance of 150 ppm, 42 of 50 passed) and face 3 none: face 3's offset is, across these
poses, almost a shift of the frame (its σ ~18 µm, detectable from ~70 µm, however much the
laser line is turned), so the poses it leaves 'ok' are off by 2.6σ (tx) / 2.3σ (tz) at the
95th percentile, 86-100 % of each component within 2σ. A calibrated sensor (``scale_sigma_ppm``
20, sensor off by 15 ppm) does not change face 3 (20 of 20 pass) and catches face 1 in 20 of
20. The tests' independent generator (20 batches per face): faces 0, 1, 2, 4, 5 caught in every
batch, face 3 never (poses 88-100 % within 2σ). Good batches (the true file, every defect of
the simulator): the file failed 0 of 100 batches on demo-5 (χ² mean 10.3 for 10 dof), 0 of 30
on each of demo-4, demo-7, demo-10 and 0 of 30 on the independent generator; 2 of 10,000
poses suspect, 95.7-97.2 % of each component within 2σ. Faces tilted by the realistic 0.01°
are outside the tolerance model (offsets only): a nominal file with ``tolerance_um`` 10 or 20
fails every such batch (10 of 10), rightly: the poses the per-profile test leaves 'ok' have
only 69-77 % of tx and ry within 2σ.

When the batch cannot check the file. Fewer than :data:`MIN_CHECK_PROFILES` profiles with an
estimate, or poses too alike to fix every face (the condition test of
:func:`~posekit.profiler.gauge.calibration.calibrate_gauge`, :data:`MAX_CONDITION`):
the result says so (``checked`` False) and nothing else changes. The power grows with the
pose variety: turning the laser line about its line of sight (yaw) between profiles
separates the faces best.
"""

from dataclasses import dataclass, field

import numpy as np

from posekit._chi2 import chi2 as _chi2

from ...errors import PosekitError
from ..estimate.covariance import corner_covariance
from ..sensor import DEFAULT_SCALE_SIGMA_PPM
from .bundle import adjust, normal_blocks, reduced_system
from .calibration import (
    MAX_CONDITION,
    NEEDED,
    _scaled_information,
    datum_constraints,
    hinge_constraints,
    outlying_profiles,
)
from .model import Gauge

__all__ = ["GaugeCheck", "check_gauge_file", "MIN_CHECK_PROFILES", "SCALE_ALLOWANCE_PPM"]

#: Fewest profiles with an estimate that :func:`check_gauge_file` tests a gauge file with.
MIN_CHECK_PROFILES = 50
#: 1σ of the sensor's x and z scale errors the test allows (ppm) without a noise model (``noise=None``):
#: a scale error within it is not taken for a gauge that differs from its file. With a noise model the
#: allowance is its ``scale_sigma_ppm`` (default :data:`~posekit.profiler.sensor.DEFAULT_SCALE_SIGMA_PPM`).
SCALE_ALLOWANCE_PPM = DEFAULT_SCALE_SIGMA_PPM


def scale_allowance_ppm(noise) -> float:
    """The sensor's scale 1σ (ppm) the test allows: ``noise.scale_sigma_ppm``, else :data:`SCALE_ALLOWANCE_PPM`."""
    return SCALE_ALLOWANCE_PPM if noise is None else float(getattr(noise, "scale_sigma_ppm", SCALE_ALLOWANCE_PPM))
#: Rounds of "adjust, drop the outlying profiles" before the test (the profiles kept are adjusted once more).
OUTLIER_ROUNDS = 3
#: When no one face explains the misfit, a face is named when it alone explains at least this share of
#: the best face's χ² drop.
NAME_SHARE = 0.5
#: Most faces a reason names.
MAX_NAMED = 3


@dataclass(frozen=True)
class GaugeCheck:
    """Result of :func:`check_gauge_file`.

    Attributes
    ----------
    checked : bool
        Whether the batch could test the gauge file (enough profiles, varied enough).
    passed : bool or None
        The file agrees with the profiles within its tolerance (None when not checked).
    message : str
        One line: the outcome, or why the batch could not check the file.
    chi2 : float
        The test statistic (NaN when not checked).
    dof : int
        Its degrees of freedom, ``3(n + 1) - 8``.
    critical : float
        ``chi2.isf(significance / 2, dof)``: the limit of the test of all faces together.
    significance : float
        α: half to the test of all faces, half split over the tests of one face each.
    n_profiles : int
        Profiles the adjustment used (after dropping outliers).
    face_offset_um : ndarray, shape (n + 1,)
        For each face f, the offset along its normal (µm, positive out of the material) that
        best explains the batch if face f alone were off its file: ``δ_f = u_fᵀ M⁻¹ g /
        u_fᵀ M⁻¹ u_f`` with ``u_f`` the response of ``g`` to a unit offset of face f.
    face_sigma_um : ndarray, shape (n + 1,)
        1σ of ``face_offset_um`` (the fit and the tolerance), µm.
    faces : tuple of int
        The faces the reason names, best first (empty when passed or not checked): those
        whose offset alone brings χ² below the critical value, else (several faces differ)
        those whose offset alone lowers χ² by at least :data:`NAME_SHARE` of the best one's
        drop; at most :data:`MAX_NAMED`.
    condition : float
        Condition number of the constrained, unit-scaled normal matrix of the faces.
    scale : float
        ``s²``: the bundle's χ²/dof when above 1, else 1.
    sensor_scale_ppm : ndarray, shape (2,)
        The sensor's x and z scale errors the batch shows (nuisance parameters of the test), ppm.
    face_critical : float
        ``chi2.isf(significance / (2 (n + 1)), 1)``: the limit of each face's own test,
        ``(face_offset_um / face_sigma_um)² <= face_critical``.
    face_detectable_um : ndarray, shape (n + 1,)
        ``sqrt(face_critical) face_sigma_um``: one face off its file (beyond the tolerance) by
        this much fails the batch half the time; a face off by less mostly passes, and the
        poses then carry its bias (the batch's detection limit, per face, µm).
    """

    checked: bool
    passed: bool | None
    message: str
    chi2: float = float("nan")
    dof: int = 0
    critical: float = float("nan")
    significance: float = float("nan")
    n_profiles: int = 0
    face_offset_um: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    face_sigma_um: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)
    faces: tuple = ()
    condition: float = float("nan")
    scale: float = 1.0
    sensor_scale_ppm: np.ndarray = field(default_factory=lambda: np.zeros(2), repr=False)
    face_critical: float = float("nan")
    face_detectable_um: np.ndarray = field(default_factory=lambda: np.zeros(0), repr=False)


def _not_checked(why: str, n_profiles: int) -> GaugeCheck:
    return GaugeCheck(False, None, f"the gauge file could not be checked by this batch: {why}",
                      n_profiles=n_profiles)


def _ridge_order(corners, est, noise):
    """Corners (n, 2) and their whitening (2n, 2n) in ridge order."""
    C = corner_covariance(corners, noise)
    pts = np.asarray(corners.points, dtype=np.float64)
    if est.reversed:
        n = pts.shape[0]
        order = np.arange(2 * n).reshape(n, 2)[::-1].ravel()
        pts, C = pts[::-1], C[np.ix_(order, order)]
    return pts, np.linalg.inv(np.linalg.cholesky(C))


def _prior(gauge: Gauge, tol_mm: float) -> np.ndarray:
    """``Λ`` (3(n + 1),): the prior variances of θ the declared tolerance allows: each face's
    offset ``tol²``, its tilts 0 (the tolerance model of the per-profile test)."""
    lam = np.zeros((gauge.n_corners + 1, 3))
    lam[:, 2] = tol_mm**2
    return lam.ravel()


def _scale_jacobian(pts, r, Linv):
    """d r / d(scale x, scale z) (K, 2n, 2), whitened: a corner measured at ``(1 + sx) x``,
    ``(1 + sz) z`` (a constant in z is a pose translation)."""
    K, n = pts.shape[:2]
    P = pts.reshape(K, 2 * n) - np.linalg.solve(Linv, r[..., None])[..., 0]   # predicted corners
    J = np.zeros((K, 2 * n, 2))
    J[:, 0::2, 0] = -P[:, 0::2]
    J[:, 1::2, 1] = -(P[:, 1::2] - P[:, 1::2].mean())
    return Linv @ J


def check_gauge_file(corners, estimates, gauge: Gauge, *, noise=None, significance: float = 1e-3,
                     min_profiles: int = MIN_CHECK_PROFILES, max_iter: int = 30) -> GaugeCheck:
    """Test the gauge file against a batch of profiles (module docstring).

    Parameters
    ----------
    corners : sequence of Corners or None
        Each profile's corners (scan order), None where there is no estimate.
    estimates : sequence of PoseEstimate or None
        Each profile's estimate with ``gauge`` (``T_G_F`` starts the adjustment, ``reversed``
        gives the corner order), None where there is none.
    gauge : Gauge
        The gauge file under test (its ``tolerance_um`` is the allowance).
    noise : NoiseModel, optional
        The assumed sensor noise (the corners' covariance); None: the line fits' own.
    significance : float
        α of the test: the rate at which a right gauge file fails.
    min_profiles : int
        Fewest profiles with an estimate the test is made with.
    max_iter : int
        Levenberg–Marquardt iterations per round of the adjustment.

    Returns
    -------
    GaugeCheck
        ``checked`` False (and the reason in ``message``) when the batch is too small or too
        alike; never raises on degenerate data.
    """
    pairs = [(c, e) for c, e in zip(corners, estimates) if c is not None and e is not None]
    try:
        return _check(pairs, gauge, noise, significance, min_profiles, max_iter)
    except (PosekitError, np.linalg.LinAlgError, FloatingPointError, ValueError) as exc:
        return _not_checked(f"the adjustment failed ({type(exc).__name__}: {exc})", len(pairs))


def _check(pairs, gauge: Gauge, noise, significance: float, min_profiles: int, max_iter: int) -> GaugeCheck:
    """:func:`check_gauge_file` on the profiles with an estimate, ``pairs`` of (Corners, PoseEstimate)."""
    K_all = len(pairs)
    need = (f"it needs >= {min_profiles} profiles with an estimate at varied poses (the laser line turned about "
            "its line of sight by up to ±10-15° and tilted by a few degrees)")
    if K_all < min_profiles:
        return _not_checked(f"{K_all} profiles with an estimate; {need}", K_all)
    pts, Linv = [], []
    try:
        for c, e in pairs:
            p, L = _ridge_order(c, e, noise)
            pts.append(p)
            Linv.append(L)
    except np.linalg.LinAlgError:
        return _not_checked("a corner covariance is not positive definite", K_all)
    pts, Linv = np.asarray(pts), np.asarray(Linv)
    Ts = np.asarray([e.T_G_F for _, e in pairs], dtype=np.float64)
    C = np.concatenate([datum_constraints(gauge), hinge_constraints(gauge)])
    F = gauge.n_corners + 1
    theta = np.zeros((F, 3))
    for _ in range(OUTLIER_ROUNDS):          # adjust, drop outlying profiles, adjust again
        theta, Ts, r, Jx, Jp, cost, _ = adjust(theta, Ts, pts, Linv, gauge, C, max_iter)
        bad = outlying_profiles(r)[0]
        if not bad.any():
            break
        keep = ~bad
        pts, Linv, Ts = pts[keep], Linv[keep], Ts[keep]
        if len(Ts) < min_profiles:
            return _not_checked(f"{len(Ts)} of {K_all} profiles are left after dropping outliers; {need}",
                                len(Ts))
    else:   # the last round dropped profiles: the residuals and Jacobians must be those of the kept ones
        theta, Ts, r, Jx, Jp, cost, _ = adjust(theta, Ts, pts, Linv, gauge, C, max_iter)
    K = len(Ts)
    P = 3 * F
    # the faces' information with the poses eliminated, and their cross-information with the sensor's scales
    J_s = _scale_jacobian(pts, r, Linv)
    U, V, W, gp, gx = normal_blocks(Jx, np.concatenate([Jp, J_s], axis=2), r)
    S_all, rhs, _ = reduced_system(U, V, W, gp, gx, 0.0)
    S = S_all[:P, :P]
    ev = _scaled_information(S, C, gauge)
    condition = float(ev[-1] / ev[0]) if ev[0] > 0 else np.inf
    if not condition <= MAX_CONDITION:
        return _not_checked(f"the {K} profiles are too alike to fix every face (condition "
                            f"{'singular' if not condition < 1e12 else f'{condition:.1e}'} > {MAX_CONDITION:.0e}); "
                            + NEEDED, K)
    dof_fit = int(r.size - 6 * K - 3 * F + len(C))
    scale = max(1.0, float(cost) / dof_fit) if dof_fit > 0 else 1.0
    _, _, Vt = np.linalg.svd(C)
    N = Vt[len(C):].T                                    # (3F, m), orthonormal basis of {C θ = 0}
    m = N.shape[1]
    phi = N.T @ theta.ravel()
    S_phi = N.T @ S @ N
    A = N.T @ S
    B = N.T @ S_all[:P, P:]                              # the faces' response to the sensor's scale
    lam = _prior(gauge, gauge.tolerance_um * 1e-3)
    sig_s = scale_allowance_ppm(noise) * 1e-6
    M = S_phi + (A * lam) @ A.T + sig_s**2 * (B @ B.T)  # Σ = S_φ⁻¹ M S_φ⁻¹
    g = S_phi @ phi
    chi2 = float(g @ np.linalg.solve(M, g)) / scale
    crit = float(_chi2.isf(significance / 2, m))                # α/2 to the test of all faces,
    face_crit = float(_chi2.isf(significance / (2 * F), 1))      # α/2 to the F tests of one face each
    # the single face that best explains the misfit: face f off by δ_f moves g by δ_f u_f (u_f = A e_f)
    w = np.linalg.solve(M, g)
    U = A[:, 2::3]                                       # (m, F): the offsets' columns
    Mi_U = np.linalg.solve(M, U)
    info = np.einsum("mf,mf->f", U, Mi_U)
    delta = (U.T @ w) / info
    gain = (U.T @ w) ** 2 / info / scale
    offset_um = delta * 1e3
    sigma_um = np.sqrt(scale / info) * 1e3
    detect_um = np.sqrt(face_crit) * sigma_um            # the offset one face's own test sees half the time
    common = dict(chi2=chi2, dof=m, critical=crit, significance=significance, n_profiles=K,
                  face_offset_um=offset_um, face_sigma_um=sigma_um, condition=condition, scale=scale,
                  face_critical=face_crit, face_detectable_um=detect_um)
    worst = int(np.argmax(gain))
    if chi2 <= crit and gain[worst] <= face_crit:
        weak = int(np.argmax(sigma_um))
        return GaugeCheck(True, True, f"gauge file '{gauge.name}' checked against {K} profiles: its faces agree "
                          f"within their tolerance ({gauge.tolerance_um:g} µm, chi2 = {chi2:.1f} <= {crit:.1f}, "
                          f"{m} dof; each face within {np.sqrt(face_crit):.1f} sigma); this batch sees a single face "
                          "off from "
                          f"{np.max(np.delete(detect_um, weak)):.0f} µm, face {weak} (the least pinned) from "
                          f"{detect_um[weak]:.0f} µm", **common)
    if chi2 > crit:
        test = f"chi2 = {chi2:.1f} > {crit:.1f}, {m} dof"
    else:
        test = (f"face {worst} alone {np.sqrt(gain[worst]):.1f} sigma > {np.sqrt(face_crit):.1f}; all faces "
                f"chi2 = {chi2:.1f} <= {crit:.1f}, {m} dof")
    order = np.argsort(-gain)
    left = chi2 - gain
    alone = [int(f) for f in order if left[f] <= crit]            # faces that alone explain the misfit
    if alone:
        faces = tuple(alone[:MAX_NAMED])
        what = "one face off along its normal explains it: " + " or ".join(
            f"face {f} {offset_um[f]:+.1f} ± {sigma_um[f]:.1f} µm (then chi2 = {left[f]:.1f})" for f in faces)
    else:
        faces = tuple(int(f) for f in order[:MAX_NAMED] if gain[f] >= NAME_SHARE * gain[order[0]])
        what = ("no one face's offset explains it (faces tilted, several off, or the sensor's scale beyond "
                f"{scale_allowance_ppm(noise):g} ppm); alone, it would take " + " or ".join(
            f"face {f} {offset_um[f]:+.1f} µm (then chi2 = {left[f]:.1f})" for f in faces))
    return GaugeCheck(True, False, (
        f"gauge '{gauge.name}' is not what its file says: across {K} profiles its faces are off the file by more "
        f"than the declared tolerance ({gauge.tolerance_um:g} µm, {test}, significance {significance:g}); {what}, "
        "so every pose of this batch is biased: measure the as-built "
        "gauge with 'posekit profiler calibrate-gauge'"),
        faces=faces, **common)
