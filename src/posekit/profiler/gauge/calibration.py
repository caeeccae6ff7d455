"""The as-built gauge: every face plane from profiles taken at unknown, varied poses.

A machined gauge differs from its drawing by tens of µm; estimated with the drawing, every
pose is biased by that much (y, seen only through the ridges' skew, by several times more)
and the estimator's consistency test calls it suspect. :func:`calibrate_gauge` measures the
gauge with the profiler itself (``posekit profiler calibrate-gauge``): corners by
:func:`~posekit.profiler.estimate.corners.detect_corners`, start poses with the drawing, then a
bundle adjustment of the ``n + 1`` face planes and the ``K >= 50`` poses ``T_G_F``
together (:mod:`~posekit.profiler.gauge_bundle`: ML residuals in the laser plane, analytic
Jacobian, Levenberg–Marquardt with the poses eliminated by Schur complement); profiles
whose corners are not found, or whose fit is an outlier (χ² tail below 1e-6), are left out.

Gauge constraint. Profiles alone cannot tell where the gauge's frame is: moving all faces
and all poses by one rigid motion changes no corner, so the normal matrix has a
6-dimensional null space. The as-built frame is fixed to the drawing by six linear
conditions on the faces' deviations θ from the drawing, :func:`datum_constraints` — no face
is held at its nominal place; instead the deviations ``e_f(p) = n_f · p - d_f`` at points p
spread over each face (weighted by area) have no net rigid motion in the least-squares
sense, ``Σ_f Σ_p w_p e_f(p) [n0_f; p × n0_f] = 0``: the normal equations of the rigid motion
that would best fit the as-built faces onto the drawing, a CMM's best-fit alignment. The
as-built gauge is thereby in the nominal gauge's frame, as close to its drawing as any rigid
placement would make it (:func:`~posekit.profiler.gauge.datum.datum_transform` puts any other measurement of the gauge in
the same frame). A rigid offset of the whole gauge is a mounting error, not a machining one:
no calibration from profiles can see it.

Outer faces. Face 0 meets only ridge 0, face n only ridge n - 1: turning an outer face about
its one ridge moves no corner. Two more conditions (:func:`hinge_constraints`) keep that
tilt at the drawing's, and the outer faces enter the datum and the statistics along their
ridge only (:func:`~posekit.profiler.gauge.datum.observed_samples`), the part of them that profiles see. (Their full
planes would need the outer face lines of each profile as observations, with their
correlation to the corners.)

Tolerance. The covariance of θ under the 8 constraints is the upper-left block of the
inverse of the bordered matrix ``[[S, Cᵀ], [C, 0]]`` (S: the reduced normal matrix of the
faces), scaled by ``χ²/dof`` when the fit is worse than its noise model. Each face's 1σ
position uncertainty is the RMS over its observed points of the standard deviation of
``e_f(p)``; ``tolerance_um`` is the largest of them. The faces' errors are correlated — on
demo-5 mostly one mode: its odd faces are nearly parallel to each other, as are its even
ones, so shifting all odd faces along their normal is nearly a translation of every pose;
turning the laser line about its line of sight (yaw) between profiles separates them
(100 profiles: ±8° → 5.3 µm, ±15° → 1.8 µm).

Pose variety. Too few profiles (< :data:`MIN_PROFILES`) or poses too alike to fix every face
— the constrained normal matrix, scaled to µm of face displacement, has a condition number
above :data:`MAX_CONDITION` (profiles that only translate leave a face combination free;
tilts about the laser line alone fix it barely) — are a
:class:`~posekit.errors.CalibrationError` that says, in one line, what was measured and
what is needed (:data:`NEEDED`).

Importing a CMM report instead. A coordinate measuring machine that probes each face
reports a plane per face (a unit normal and a point, or a normal and a distance). Align the
CMM to the gauge's frame G (x across the faces in the laser's scan order, y along the
ridges, z towards the sensor), or transform each plane into G (``n_G = R n``,
``d_G = d + n_G · t`` for ``p_G = R p + t``). Write the faces, in crossing order, into the
same gauge YAML: ``normal`` pointing out of the material (towards +z), ``offset = normal ·
point`` in mm, and ``tolerance_um`` the CMM's stated 1σ uncertainty of a plane's position
(e.g. its MPE / 2); then pass that file as ``--gauge``. To use the best-fit frame of this
module instead of the CMM's datums, move the measured gauge by :func:`~posekit.profiler.gauge.datum.datum_transform`.
"""

import time
from dataclasses import dataclass, field, fields, replace

import numpy as np
import yaml

from posekit._chi2 import chi2 as _chi2

from ...errors import CalibrationError, PosekitError
from ..estimate.corner_params import CornerParams
from ..estimate.corners import detect_corners
from ..estimate.solve import solve_pose
from .bundle import adjust, normal_blocks, plane_params, reduced_system, tangent_bases
from .datum import GRID, face_deviation_um, observed_samples
from .model import Gauge, _build

__all__ = ["GaugeCalibration", "calibrate_gauge", "as_built_yaml", "datum_constraints", "hinge_constraints",
           "pose_variety", "outlying_profiles", "MIN_PROFILES", "MAX_CONDITION", "NEEDED"]

#: Fewest usable profiles :func:`calibrate_gauge` accepts.
MIN_PROFILES = 50
#: Largest condition number of the constrained, unit-scaled normal matrix of the faces.
MAX_CONDITION = 1e5
#: A profile whose χ² has a smaller upper-tail probability than this is dropped as an outlier.
OUTLIER_P = 1e-6


# --------------------------------------------------------------------------- faces


def datum_constraints(nominal: Gauge, grid: int = GRID) -> np.ndarray:
    """The six linear conditions ``C θ = 0`` that fix the as-built frame to the drawing, (6, 3(n + 1)).

    Row block ``[n0; p × n0]`` weighted by the face deviation's gradient ``[Bᵀ p; -1]``,
    summed over the points of :func:`observed_samples` (module docstring, "Gauge
    constraint").
    """
    pts, w = observed_samples(nominal, grid)
    B = tangent_bases(nominal.normals)
    n0 = np.broadcast_to(nominal.normals[:, None, :], pts.shape)
    v = np.concatenate([n0, np.cross(pts, n0)], axis=-1)            # (F, M, 6)
    g = np.concatenate([np.einsum("fmi,fij->fmj", pts, B), -np.ones(pts.shape[:2] + (1,))], axis=-1)
    C = np.einsum("fm,fma,fmb->afb", w, v, g)                       # (6, F, 3)
    return C.reshape(6, -1)


def hinge_constraints(nominal: Gauge) -> np.ndarray:
    """Two conditions ``H θ = 0``, (2, 3(n + 1)): the outer faces keep their drawing's tilt about their ridge.

    Face 0 meets only ridge 0, and face n only ridge n - 1: turning an outer face about its
    ridge moves no corner, so no profile can see it. Its normal may tilt only across the
    ridge: ``(a × n0) · B α = 0`` for the ridge direction a.
    """
    F = nominal.normals.shape[0]
    B = tangent_bases(nominal.normals)
    a = nominal.ridge_s / np.linalg.norm(nominal.ridge_s, axis=1, keepdims=True)
    H = np.zeros((2, F, 3))
    for row, (face, ridge) in enumerate(((0, 0), (F - 1, F - 2))):
        H[row, face, :2] = np.cross(a[ridge], nominal.normals[face]) @ B[face]
    return H.reshape(2, -1)


# --------------------------------------------------------------------------- API


@dataclass(frozen=True)
class GaugeCalibration:
    """Result of :func:`calibrate_gauge`.

    Attributes
    ----------
    gauge : Gauge
        The as-built gauge, in the nominal gauge's frame (module docstring).
    nominal : Gauge
    theta : ndarray, shape (n + 1, 3)
        Face deviations from the drawing ``[α1, α2 (rad), δ (mm)]`` (:func:`plane_params`).
    cov_theta : ndarray, shape (3(n + 1), 3(n + 1))
        Their covariance under the gauge constraint, scaled by ``max(1, χ²/dof)``.
    face_sigma_um : ndarray, shape (n + 1,)
        1σ uncertainty of each face's position (RMS over its footprint; an outer face's
        along its ridge, :func:`observed_samples`), µm.
    tolerance_um : float
        ``max(face_sigma_um)``: what the YAML's ``tolerance_um`` says.
    face_shift_um : ndarray, shape (n + 1,)
        RMS distance of each as-built face from its drawing over the footprint, µm.
    face_tilt_deg : ndarray, shape (n + 1,)
        Angle between each as-built face and its drawing, degrees.
    Ts_G_F : ndarray, shape (K_used, 4, 4)
        Adjusted poses of the profiles used, mm.
    used : ndarray of int, shape (K_used,)
        Indices of the profiles used.
    skipped : list of (int, str)
        Index and reason of every profile left out (corners not found, outlier).
    rms_um : float
        RMS of the corner residuals ``c - P`` (x and z), µm.
    chi2, dof : float, int
        Whitened cost and its degrees of freedom ``2 n K - 6 K - 3(n + 1) + 8`` (8 constraints).
    condition : float
        Condition number of the constrained, unit-scaled normal matrix of the faces.
    iterations : int
    seconds : float
        Wall time of detection, start poses and adjustment.
    """

    gauge: Gauge
    nominal: Gauge
    theta: np.ndarray
    cov_theta: np.ndarray = field(repr=False)
    face_sigma_um: np.ndarray
    tolerance_um: float
    face_shift_um: np.ndarray
    face_tilt_deg: np.ndarray
    Ts_G_F: np.ndarray = field(repr=False)
    used: np.ndarray = field(repr=False)
    skipped: list
    rms_um: float
    chi2: float
    dof: int
    condition: float
    iterations: int
    seconds: float


def _corner_data(profiles, nominal, mounting, params):
    """Corners in ridge order, their whitening and the start poses of the usable profiles."""
    n = nominal.n_corners
    corners, Linv, Ts, used, skipped = [], [], [], [], []
    for k in range(profiles.shape[0]):
        try:
            c = detect_corners(profiles[k], nominal, params)
            est = solve_pose(c, nominal, method="mle", mounting=mounting)
        except PosekitError as exc:
            skipped.append((k, str(exc)))
            continue
        pts, cov = c.points, c.cov
        if est.reversed:                       # ridge order: reverse the corners and their 2×2 blocks
            order = np.arange(2 * n).reshape(n, 2)[::-1].ravel()
            pts, cov = pts[::-1], cov[np.ix_(order, order)]
        try:
            L = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            skipped.append((k, "corner covariance is not positive definite"))
            continue
        corners.append(pts)
        Linv.append(np.linalg.inv(L))
        Ts.append(est.T_G_F)
        used.append(k)
    return (np.asarray(corners).reshape(-1, n, 2), np.asarray(Linv).reshape(-1, 2 * n, 2 * n),
            np.asarray(Ts).reshape(-1, 4, 4), np.asarray(used, dtype=int), skipped)


def pose_variety(Ts_G_F, corners_F):
    """How varied the profiles' laser lines are on the gauge.

    Parameters
    ----------
    Ts_G_F : ndarray, shape (K, 4, 4)
    corners_F : ndarray, shape (K, n, 2)

    Returns
    -------
    yaw_deg, tilt_deg : float
        RMS turn of the laser plane's normal (F's y) about G's z (yaw: the line turned about
        the line of sight) and about G's x (tilt), from its mean direction, degrees.
    spread_mm : float
        Standard deviation of where the line crosses the gauge along the ridges (G's y), mm.
    """
    y_F = Ts_G_F[:, :3, 1]
    m = y_F.mean(axis=0)
    m /= np.linalg.norm(m)
    side = np.cross([0.0, 0.0, 1.0], m)
    side /= np.linalg.norm(side)
    up = np.cross(m, side)
    yaw = np.degrees(np.arcsin(np.clip(y_F @ side, -1.0, 1.0)))
    tilt = np.degrees(np.arcsin(np.clip(y_F @ up, -1.0, 1.0)))
    p = np.einsum("kij,kcj->kci", Ts_G_F[:, :3, [0, 2]], corners_F) + Ts_G_F[:, None, :3, 3]
    return float(np.sqrt(np.mean(yaw**2))), float(np.sqrt(np.mean(tilt**2))), float(np.std(p[..., 1].mean(axis=1)))


#: What :func:`calibrate_gauge` asks for when the profiles are too few or too alike.
NEEDED = (f"take >= {MIN_PROFILES} profiles, the laser line turned ±10-15° about its line of sight and tilted a "
          "few degrees, at varied places along the ridges")


def _scaled_information(S, C, nominal):
    """Eigenvalues of the reduced normal matrix on the constrained subspace, in mm⁻² of face
    displacement (tilts scaled by each face's radius, offsets taken at its centroid)."""
    F = nominal.normals.shape[0]
    pts, w = observed_samples(nominal)
    B = tangent_bases(nominal.normals)
    centroid = np.einsum("fm,fmi->fi", w, pts) / w.sum(axis=1)[:, None]
    spread = np.einsum("fm,fm->f", w, np.sum((pts - centroid[:, None]) ** 2, axis=2)) / w.sum(axis=1)
    radius = np.sqrt(np.maximum(spread, 1.0))
    D = np.zeros((3 * F, 3 * F))                      # θ' = D θ, all in mm
    for f in range(F):
        D[3 * f:3 * f + 2, 3 * f:3 * f + 2] = radius[f] * np.eye(2)
        D[3 * f + 2, 3 * f:3 * f + 2] = centroid[f] @ B[f]
        D[3 * f + 2, 3 * f + 2] = -1.0
    Dinv = np.linalg.inv(D)
    _, _, Vt = np.linalg.svd(C @ Dinv)
    N = Vt[len(C):].T                                 # orthonormal basis of {θ' : C D⁻¹ θ' = 0}
    return np.linalg.eigvalsh(N.T @ (Dinv.T @ S @ Dinv) @ N)


def outlying_profiles(r):
    """The profiles whose fit is an outlier of the bundle adjustment.

    Parameters
    ----------
    r : ndarray, shape (K, 2n)
        Whitened corner residuals of each profile at the adjustment's solution.

    Returns
    -------
    bad : ndarray of bool, shape (K,)
        χ² of the profile (scaled down by the batch's median χ² over its expected median when
        above 1) has an upper-tail probability below :data:`OUTLIER_P`.
    chi2 : ndarray, shape (K,)
    dof : int
        Values per profile, ``2n``.
    """
    chi2_k = np.sum(r**2, axis=1)
    dof_k = r.shape[1]
    scale = max(1.0, float(np.median(chi2_k)) / _chi2.median(dof_k))
    return _chi2.sf(chi2_k / scale, dof_k) < OUTLIER_P, chi2_k, dof_k


def calibrate_gauge(profiles, nominal: Gauge, *, mounting: str = "auto", params: CornerParams = CornerParams(),
                    min_profiles: int = MIN_PROFILES, max_iter: int = 50, source: str = "profiles") -> GaugeCalibration:
    """The as-built gauge from profiles at unknown, varied poses (bundle adjustment).

    Parameters
    ----------
    profiles : array_like, shape (K, N, 2)
        Profiles (x, z) in F, mm, scan order, NaN = no return.
    nominal : Gauge
        The drawing: its faces start the adjustment and fix the frame.
    mounting : {'auto', 'normal', 'reversed'}
        Scan order of the corners vs the ridges (as :func:`~posekit.profiler.estimate.solve.solve_pose`).
    params : CornerParams
    min_profiles : int
        Fewest usable profiles accepted (default :data:`MIN_PROFILES`).
    max_iter : int
        Levenberg–Marquardt iterations per round (a round drops outlying profiles).
    source : str
        Name of the input in messages (the file).

    Returns
    -------
    GaugeCalibration

    Raises
    ------
    CalibrationError
        Fewer than ``min_profiles`` profiles with every corner, poses too alike to fix
        every face (condition above :data:`MAX_CONDITION`; the message says what variety is
        needed), or adjusted faces that no longer make a valid gauge.

    Examples
    --------
    >>> from posekit.profiler import bundled_gauge, render_profiles, sample_poses
    >>> gauge = bundled_gauge("demo-7")
    >>> profiles = render_profiles(gauge, sample_poses(gauge, 60, rng=1), rng=2)
    >>> cal = calibrate_gauge(profiles, gauge)
    >>> bool(cal.tolerance_um < 5.0), len(cal.used)
    (True, 60)
    >>> calibrate_gauge(profiles[:10], gauge)
    Traceback (most recent call last):
    ...
    posekit.errors.CalibrationError: profiles: 10 of 10 profiles show all 7 corners of gauge 'demo-7'; take >= 50 ...
    """
    t0 = time.perf_counter()
    if mounting == "auto" and getattr(nominal, "ambiguity", None):
        raise CalibrationError(f"gauge '{nominal.name}' is ambiguous ({nominal.ambiguity}); give the mounting "
                               "(normal or reversed) to calibrate it")
    profiles = np.asarray(profiles, dtype=np.float64)
    K_all = profiles.shape[0]
    n = nominal.n_corners
    corners, Linv, Ts, used, skipped = _corner_data(profiles, nominal, mounting, params)
    if len(used) < min_profiles:
        raise CalibrationError(f"{source}: {len(used)} of {K_all} profiles show all {n} corners of gauge "
                               f"'{nominal.name}'; {NEEDED}")
    C = np.concatenate([datum_constraints(nominal), hinge_constraints(nominal)])
    F = n + 1
    theta = np.zeros((F, 3))
    iters = 0
    for _ in range(3):                      # adjust, drop outlying profiles, adjust again
        theta, Ts, r, Jx, Jp, cost, it = adjust(theta, Ts, corners, Linv, nominal, C, max_iter)
        iters += it
        bad, chi2_k, dof_k = outlying_profiles(r)
        if not bad.any():
            break
        for k in np.flatnonzero(bad):
            skipped.append((int(used[k]), f"outlier: corner residuals χ² = {chi2_k[k]:.3g} for {dof_k} values"))
        keep = ~bad
        corners, Linv, Ts, used = corners[keep], Linv[keep], Ts[keep], used[keep]
        if len(used) < min_profiles:
            raise CalibrationError(f"{source}: {len(used)} of {K_all} profiles are left after dropping "
                                   f"{int(bad.sum())} outliers; {NEEDED}")
    K = len(used)
    dof = int(r.size - 6 * K - 3 * F + len(C))
    U, V, W, gp, gx = normal_blocks(Jx, Jp, r)
    S, _, _ = reduced_system(U, V, W, gp, gx, 0.0)
    ev = _scaled_information(S, C, nominal)
    condition = float(ev[-1] / ev[0]) if ev[0] > 0 else np.inf
    if not condition <= MAX_CONDITION:
        rank = int(np.sum(ev > ev[-1] / MAX_CONDITION))
        yaw, tilt, spread = pose_variety(Ts, corners)
        raise CalibrationError(
            f"{source}: the {K} profiles are too alike to fix the faces of '{nominal.name}' (rank {rank} of "
            f"{len(ev)}, condition {'singular' if not condition < 1e12 else f'{condition:.1e}'} > "
            f"{MAX_CONDITION:.0e}; yaw {yaw:.1f}°, tilt {tilt:.1f}° rms, {spread:.1f} mm along the ridges); "
            + NEEDED)
    Z = np.zeros((3 * F + len(C), 3 * F + len(C)))
    Z[:3 * F, :3 * F] = S
    Z[:3 * F, 3 * F:] = C.T
    Z[3 * F:, :3 * F] = C
    cov = np.linalg.inv(Z)[:3 * F, :3 * F]
    cov = 0.5 * (cov + cov.T) * (max(1.0, cost / dof) if dof > 0 else 1.0)
    pts, w = observed_samples(nominal)
    B = tangent_bases(nominal.normals)
    g = np.concatenate([np.einsum("fmi,fij->fmj", pts, B), -np.ones(pts.shape[:2] + (1,))], axis=-1)
    blocks = cov.reshape(F, 3, F, 3)[np.arange(F), :, np.arange(F), :]
    var = np.einsum("fma,fab,fmb->fm", g, blocks, g)
    face_sigma = np.sqrt(np.einsum("fm,fm->f", w, var) / w.sum(axis=1)) * 1e3
    normals, offsets = plane_params(nominal, theta)
    try:
        asbuilt = _build(f"{nominal.name}-as-built", normals, offsets, (nominal.x_range, nominal.y_range), source)
    except PosekitError as exc:
        raise CalibrationError(f"{source}: the adjusted faces do not make a valid gauge: {exc}") from None
    if "tolerance_um" in {f.name for f in fields(Gauge)}:         # a loader that knows tolerance_um
        asbuilt = replace(asbuilt, tolerance_um=float(face_sigma.max()))
    res_um = np.einsum("kab,kb->ka", np.linalg.inv(Linv), r) * 1e3
    return GaugeCalibration(
        gauge=asbuilt, nominal=nominal, theta=theta, cov_theta=cov, face_sigma_um=face_sigma,
        tolerance_um=float(face_sigma.max()), face_shift_um=face_deviation_um(asbuilt, nominal),
        face_tilt_deg=np.degrees(np.arccos(np.clip(np.sum(normals * nominal.normals, axis=1), -1.0, 1.0))),
        Ts_G_F=Ts, used=used, skipped=sorted(skipped), rms_um=float(np.sqrt(np.mean(res_um**2))),
        chi2=float(cost), dof=dof, condition=condition, iterations=iters, seconds=time.perf_counter() - t0)


def as_built_yaml(cal: GaugeCalibration, source: str = "profiles") -> str:
    """The as-built gauge as gauge YAML (unit normals, offsets in mm, frame G of the nominal),
    with ``tolerance_um`` at top level and the fit's summary as comments."""
    g = cal.gauge
    planes = [{"normal": [round(float(v), 12) + 0.0 for v in n], "offset": round(float(d), 12) + 0.0}
              for n, d in zip(g.normals, g.offsets)]
    digits = 2 - int(np.floor(np.log10(max(cal.tolerance_um, 1e-9))))
    tol = float(np.ceil(cal.tolerance_um * 10.0**digits) / 10.0**digits)   # 3 significant digits, rounded up
    doc = {"name": g.name, "planes": planes, "extent": {"x": list(g.x_range), "y": list(g.y_range)},
           "tolerance_um": tol}
    head = (f"# as-built gauge '{cal.nominal.name}' from {len(cal.used)} profiles of {source} "
            f"(posekit profiler calibrate-gauge), in the nominal gauge's frame (best fit of the faces to the "
            f"drawing).\n"
            f"# corner residual RMS {cal.rms_um:.2f} um, chi2/dof {cal.chi2 / max(cal.dof, 1):.2f}; "
            f"tolerance_um = largest 1-sigma face position.\n"
            "# face  shift from drawing (um rms)  tilt (deg)  1-sigma position (um)\n"
            + "".join(f"#  {f:>3}  {s:>12.1f}  {a:>18.4f}  {u:>12.2f}\n"
                      for f, (s, a, u) in enumerate(zip(cal.face_shift_um, cal.face_tilt_deg, cal.face_sigma_um))))
    return head + yaml.safe_dump(doc, sort_keys=False, default_flow_style=None)
