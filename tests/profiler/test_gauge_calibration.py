"""The as-built gauge (``posekit profiler calibrate-gauge``): recovered faces, poses, messages.

The machined gauge of these tests is the drawing with every face moved 20–50 µm along its
normal and tilted by ~0.02° (written here, not taken from the simulator), then placed in the
drawing's frame by the best fit of its faces (:func:`datum_transform`): a rigid offset of a
whole gauge is a mounting error that no calibration from profiles can see.
"""

from dataclasses import replace

import numpy as np
import pytest
import scipy.sparse
import yaml
from scipy.optimize import least_squares

from posekit.cli.main import main
from posekit.errors import CalibrationError
from posekit.geometry import matrix_from_rotation_vector
from posekit.profiler import (
    NoiseModel,
    Workspace,
    bundled_gauge,
    detect_corners,
    load_gauge,
    pose_errors,
    render_profiles,
    sample_poses,
    solve_pose,
)
from posekit.profiler.gauge.bundle import bundle_residuals, plane_params
from posekit.profiler.gauge.calibration import (
    NEEDED,
    as_built_yaml,
    calibrate_gauge,
    datum_constraints,
    hinge_constraints,
)
from posekit.profiler.gauge.datum import datum_transform, face_deviation_um
from posekit.profiler.gauge.model import bundled_gauge_path

TOO_FEW = ("profiles: 30 of 30 profiles show all 5 corners of gauge 'demo-5'; take >= 50 profiles, the laser line "
           "turned ±10-15° about its line of sight and tilted a few degrees, at varied places along the ridges")
#: Where the calibration profiles are taken: the laser line turned by up to ±15° about the line of sight.
CALIBRATION_POSES = Workspace(rotation_deg=(4.0, 4.0, 15.0))


def _gauge_file(path, name, normals, offsets, nominal):
    doc = {"name": name, "planes": [{"normal": [float(v) for v in n], "offset": float(d)}
                                    for n, d in zip(normals, offsets)],
           "extent": {"x": list(nominal.x_range), "y": list(nominal.y_range)}}
    path.write_text(yaml.safe_dump(doc, sort_keys=False))
    return load_gauge(path)


def machined_gauge(nominal, rng, tmp_path, shift_um=(20.0, 50.0), tilt_deg=0.02):
    """The drawing with each face moved by ±20–50 µm and tilted by ~``tilt_deg``: as machined
    (``raw``) and placed in the drawing's frame (``true``)."""
    F = len(nominal.offsets)
    offsets = nominal.offsets + rng.choice([-1.0, 1.0], F) * rng.uniform(*shift_um, F) * 1e-3
    axis = np.cross(nominal.normals, rng.standard_normal((F, 3)))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    R = matrix_from_rotation_vector(axis * np.radians(tilt_deg) * rng.uniform(0.5, 1.5, (F, 1)))
    normals = np.einsum("fij,fj->fi", R, nominal.normals)
    raw = _gauge_file(tmp_path / "raw.yaml", "machined", normals, offsets, nominal)
    T = datum_transform(raw, nominal)
    n = raw.normals @ T[:3, :3].T
    return raw, _gauge_file(tmp_path / "machined.yaml", "machined", n, raw.offsets + n @ T[:3, 3], nominal)


def _estimate(gauge, Ts, profiles):
    """RMSE of the pose errors ``[mm, rad]`` (6,), mean reprojection error (µm) and the share of
    'ok' verdicts with ``gauge`` (the estimator's own noise model, the gauge's tolerance)."""
    err, reproj, ok = [], [], 0
    for T, profile in zip(Ts, profiles):
        est = solve_pose(detect_corners(profile, gauge.n_corners), gauge, mounting="normal", noise=NoiseModel())
        err.append(pose_errors(est.T_G_F, T))
        reproj.append(est.reprojection_um)
        ok += est.status == "ok"
    return np.sqrt(np.mean(np.square(err), axis=0)), float(np.mean(reproj)), ok / len(Ts)


@pytest.fixture(scope="module")
def machined(tmp_path_factory):
    nominal = bundled_gauge("demo-5")
    rng = np.random.default_rng(7)
    raw, true = machined_gauge(nominal, rng, tmp_path_factory.mktemp("gauge"))
    Ts = sample_poses(true, 100, rng, CALIBRATION_POSES)
    profiles = render_profiles(true, Ts, NoiseModel(), rng)
    return nominal, raw, true, Ts, profiles, calibrate_gauge(profiles, nominal)


def test_machined_gauge_is_off_its_drawing(machined):
    nominal, raw, true, *_ = machined
    assert np.all(face_deviation_um(raw, nominal) > 10.0)           # 20-50 µm shifts, 0.02° tilts
    # in the drawing's frame the rigid part is gone (no profile can see it); the rest stays
    aligned = face_deviation_um(true, nominal, observed=True)
    assert np.max(aligned) > 10.0
    assert np.sqrt(np.mean(aligned**2)) < np.sqrt(np.mean(face_deviation_um(raw, nominal, observed=True) ** 2))


def test_recovered_faces_within_their_tolerance(machined):
    nominal, _, true, Ts, profiles, cal = machined
    assert len(cal.used) == 100 and cal.skipped == []
    # residuals at the corners' own noise: 100 profiles × 10 corner coordinates - 600 pose - 10 face
    # parameters ≈ 390 dof, so χ² / dof has sd sqrt(2 / 390) ≈ 0.07: ±0.3 is over 4 sd
    assert 0.7 < cal.chi2 / cal.dof < 1.3
    assert cal.tolerance_um == pytest.approx(cal.face_sigma_um.max()) and cal.tolerance_um > 0
    # every face where the profiles see it (an outer face along its ridge), vs the truth
    err = face_deviation_um(cal.gauge, true, observed=True)
    assert np.all(err <= 3.0 * cal.face_sigma_um), (err, cal.face_sigma_um)
    drawing = face_deviation_um(nominal, true, observed=True)
    assert np.sqrt(np.mean(err**2)) < 0.35 * np.sqrt(np.mean(drawing**2)), (err, drawing)
    # the adjusted poses of the calibration profiles: close to estimates with the true gauge (the
    # faces' remaining error biases the weakly seen y and rx, as it does any later estimate)
    rmse = np.sqrt(np.mean(pose_errors(cal.Ts_G_F, Ts[cal.used]) ** 2, axis=0))
    assert np.all(rmse < 2.0 * _estimate(true, Ts, profiles)[0]), rmse
    # the constraints hold: the frame is the drawing's, the outer faces keep their tilt about the ridge
    C = np.concatenate([datum_constraints(nominal), hinge_constraints(nominal)])
    assert np.max(np.abs(C @ cal.theta.ravel())) < 1e-9


def test_as_built_gauge_brings_pose_errors_back_to_the_true_gauge(machined):
    nominal, _, true, _, _, cal = machined
    rng = np.random.default_rng(99)
    Ts = sample_poses(true, 200, rng)
    profiles = render_profiles(true, Ts, NoiseModel(), rng)
    assert cal.gauge.tolerance_um == pytest.approx(cal.tolerance_um)
    (r_nom, rep_nom, ok_nom), (r_ab, rep_ab, ok_ab), (r_ab0, rep_ab0, _), (r_true, rep_true, ok_true) = (
        _estimate(g, Ts, profiles) for g in (nominal, cal.gauge, replace(cal.gauge, tolerance_um=0.0), true))
    # the drawing: reprojection several µm, pose errors biased far above the noise, every verdict 'suspect'
    assert rep_nom > 5.0 * rep_true and ok_nom == 0.0
    assert np.all(r_nom[:4] > 2.5 * r_true[:4]), (r_nom, r_true)
    # the as-built gauge: back to the true gauge's level, 'ok'
    assert ok_ab >= 0.98 and ok_true >= 0.98
    assert rep_ab < 1.1 * rep_true and rep_ab0 < 1.05 * rep_true
    assert np.all(r_ab[:5] < 1.5 * r_true[:5]), (r_ab, r_true)
    assert np.all(r_ab0[:5] < 1.35 * r_true[:5]), (r_ab0, r_true)
    assert r_ab[5] < 2.0 * r_true[5]                        # rz: where the faces' weakest mode shows


def test_jacobians_match_finite_differences(machined):
    nominal, _, _, Ts, profiles, _ = machined
    corners = np.stack([detect_corners(p, 5).points for p in profiles[:3]])
    theta = np.random.default_rng(3).normal(0, [1e-3, 1e-3, 0.03], (6, 3))
    r, J_pose, J_face = bundle_residuals(theta, Ts[:3], corners, nominal)
    h = 1e-6
    for j in range(18):
        d = np.zeros(18)
        d[j] = h
        num = (bundle_residuals(theta + d.reshape(6, 3), Ts[:3], corners, nominal)[0]
               - bundle_residuals(theta - d.reshape(6, 3), Ts[:3], corners, nominal)[0]) / (2 * h)
        np.testing.assert_allclose(J_face[..., j], num, atol=1e-7 * max(1.0, np.abs(num).max()))
    for j in range(6):
        step = np.zeros((3, 6))
        step[:, j] = h
        plus, minus = (Ts[:3].copy() for _ in range(2))
        for T, s in ((plus, step), (minus, -step)):
            T[:, :3, :3] = matrix_from_rotation_vector(s[:, 3:]) @ Ts[:3, :3, :3]
            T[:, :3, 3] += s[:, :3]
        num = (bundle_residuals(theta, plus, corners, nominal)[0] - bundle_residuals(theta, minus, corners, nominal)[0])
        np.testing.assert_allclose(J_pose[..., j], num / (2 * h), atol=1e-6)


def test_same_planes_as_scipy_least_squares(machined):
    """The block (Schur) Levenberg–Marquardt against ``least_squares`` on the constrained subspace
    (θ = N z with C N = 0, the poses as increments), from the same start."""
    nominal, _, _, _, profiles, _ = machined
    profiles = profiles[:60]
    cal = calibrate_gauge(profiles, nominal)
    corners, Linv, T0 = [], [], []
    for p in profiles:
        c = detect_corners(p, nominal)          # the model-based detector, as calibrate_gauge uses
        corners.append(c.points)
        Linv.append(np.linalg.inv(np.linalg.cholesky(c.cov)))
        T0.append(solve_pose(c, nominal, mounting="normal").T_G_F)
    corners, Linv, T0 = np.array(corners), np.array(Linv), np.array(T0)
    C = np.concatenate([datum_constraints(nominal), hinge_constraints(nominal)])
    N = np.linalg.svd(C)[2][len(C):].T                    # θ = N z satisfies C θ = 0
    K, nz = len(profiles), N.shape[1]

    def poses(x):
        xi = x[nz:].reshape(K, 6)
        T = T0.copy()
        T[:, :3, :3] = matrix_from_rotation_vector(xi[:, 3:]) @ T0[:, :3, :3]
        T[:, :3, 3] += xi[:, :3]
        return T

    def fun(x):
        return bundle_residuals((N @ x[:nz]).reshape(6, 3), poses(x), corners, nominal, Linv)[0].ravel()

    def jac(x):                                           # block-sparse: profile k sees z and its own pose
        _, J_pose, J_face = bundle_residuals((N @ x[:nz]).reshape(6, 3), poses(x), corners, nominal, Linv)
        J = scipy.sparse.hstack([scipy.sparse.csr_matrix((J_face @ N).reshape(K * 10, nz)),
                                 scipy.sparse.block_diag(list(J_pose))], format="csr")
        return J.toarray()        # MINPACK's LM wants it dense; trf + LSMR on the sparse one stalls on y

    sol = least_squares(fun, np.zeros(nz + 6 * K), jac=jac, method="lm", ftol=1e-14, xtol=1e-14, gtol=1e-14)
    assert sol.success
    normals, offsets = plane_params(nominal, (N @ sol.x[:nz]).reshape(6, 3))
    ours_n, ours_d = plane_params(nominal, cal.theta)
    assert 2 * sol.cost == pytest.approx(cal.chi2, rel=1e-6)
    np.testing.assert_allclose(offsets, ours_d, atol=2e-6)             # mm: 2 nm
    np.testing.assert_allclose(normals, ours_n, atol=1e-7)


def test_datum_transform_undoes_a_rigid_offset(tmp_path):
    nominal = bundled_gauge("demo-7")
    R = matrix_from_rotation_vector(np.radians([0.03, -0.05, 0.02]))
    t = np.array([0.04, -0.08, 0.03])
    n = nominal.normals @ R.T
    moved = _gauge_file(tmp_path / "moved.yaml", "moved", n, nominal.offsets + n @ t, nominal)
    T = datum_transform(moved, nominal)
    np.testing.assert_allclose(T[:3, :3], R.T, atol=1e-10)
    np.testing.assert_allclose(T[:3, 3], -R.T @ t, atol=1e-10)


def test_too_few_profiles(machined):
    nominal, _, _, _, profiles, _ = machined
    with pytest.raises(CalibrationError) as exc:
        calibrate_gauge(profiles[:30], nominal)
    assert str(exc.value) == TOO_FEW
    assert str(exc.value).endswith(NEEDED)


def test_profiles_too_alike(machined):
    """Poses that only translate: the laser plane never turns, a face combination stays free."""
    nominal, _, true, *_ = machined
    Ts = sample_poses(true, 60, 5, Workspace(rotation_deg=(0.0, 0.0, 0.0)))
    profiles = render_profiles(true, Ts, NoiseModel(), 6)
    with pytest.raises(CalibrationError) as exc:
        calibrate_gauge(profiles, nominal)
    assert str(exc.value) == (
        "profiles: the 60 profiles are too alike to fix the faces of 'demo-5' (rank 7 of 10, condition "
        "singular > 1e+05; yaw 0.0°, tilt 0.0° rms, 6.2 mm along the ridges); " + NEEDED)
    # tilted only about the laser line, by up to 1°: a full rank that says little
    Ts = sample_poses(true, 60, 5, Workspace(rotation_deg=(1.0, 0.0, 0.0)))
    with pytest.raises(CalibrationError, match=r"too alike .* condition \d\.\de\+\d\d > 1e\+05; yaw 0\.0°"):
        calibrate_gauge(render_profiles(true, Ts, NoiseModel(), 6), nominal)


def test_profiles_without_the_gauge_are_left_out(machined):
    nominal, _, _, _, profiles, _ = machined
    bad = profiles[:70].copy()
    bad[::7] = np.nan                                         # 10 profiles with no return
    cal = calibrate_gauge(bad, nominal)
    assert len(cal.used) == 60 and [k for k, _ in cal.skipped] == list(range(0, 70, 7))
    assert "no valid points" in cal.skipped[0][1]
    bad[1::7] = np.nan                                        # 20: 50 left, enough
    assert len(calibrate_gauge(bad, nominal).used) == 50
    bad[2::7] = np.nan
    with pytest.raises(CalibrationError, match=r"^profiles: 40 of 70 profiles show all 5 corners of gauge 'demo-5'; "):
        calibrate_gauge(bad, nominal)


def test_cli_writes_the_as_built_gauge(machined, tmp_path, capsys):
    nominal, _, true, _, profiles, cal = machined
    np.savez_compressed(tmp_path / "profiles.npz", profiles=profiles)
    out = tmp_path / "asbuilt.yaml"
    assert main(["profiler", "calibrate-gauge", str(tmp_path / "profiles.npz"), "--gauge", "demo-5",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "as-built gauge 'demo-5-as-built' from 100 of 100 profiles" in printed and f"wrote {out}" in printed
    doc = yaml.safe_load(out.read_text())                     # read back without the gauge loader
    assert set(doc) == {"name", "planes", "extent", "tolerance_um"}
    assert cal.tolerance_um <= doc["tolerance_um"] <= cal.tolerance_um + 0.01  # rounded up to 0.01 µm
    normals = np.array([p["normal"] for p in doc["planes"]])
    offsets = np.array([p["offset"] for p in doc["planes"]])
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    pts = np.stack([true.ridge_q, true.ridge_q + 10.0 * true.ridge_s])      # points on the true ridges
    for k in range(5):                                        # ... lie on the written faces k and k + 1
        for f in (k, k + 1):
            dist_um = np.abs(pts[:, k] @ normals[f] - offsets[f]) * 1e3
            assert np.all(dist_um < 3.0 * doc["tolerance_um"]), (k, f, dist_um)
    # the rest of the file is a gauge file as it was before tolerance_um
    del doc["tolerance_um"]
    (tmp_path / "plain.yaml").write_text(yaml.safe_dump(doc))
    g = load_gauge(tmp_path / "plain.yaml")
    np.testing.assert_allclose(g.offsets, cal.gauge.offsets, atol=1e-9)
    assert as_built_yaml(cal, "profiles.npz") == out.read_text()


def test_as_built_file_is_a_gauge_file(machined, tmp_path):
    """The gauge loader (DESIGN.md: the optional ``tolerance_um``) reads what calibrate-gauge writes."""
    *_, cal = machined
    path = tmp_path / "asbuilt.yaml"
    path.write_text(as_built_yaml(cal))
    g = load_gauge(path)
    assert g.name == "demo-5-as-built" and g.tolerance_um == yaml.safe_load(path.read_text())["tolerance_um"]
    np.testing.assert_allclose(g.normals, cal.gauge.normals, atol=1e-12)
    np.testing.assert_allclose(g.ridge_q, cal.gauge.ridge_q, atol=1e-9)


def test_cli_refuses_bad_output_and_too_few(machined, tmp_path, capsys):
    nominal, _, _, _, profiles, _ = machined
    np.savez_compressed(tmp_path / "few.npz", profiles=profiles[:30])
    assert main(["profiler", "calibrate-gauge", str(tmp_path / "few.npz"), "--gauge", "demo-5",
                 "--out", str(tmp_path / "a.yaml")]) == 1
    err = capsys.readouterr().err
    from posekit.errors import one_line

    assert err == "posekit: error: " + one_line(f"{tmp_path / 'few.npz'}" + TOO_FEW.removeprefix("profiles"), 284) \
        + "\n"
    assert not (tmp_path / "a.yaml").exists()
    assert main(["profiler", "calibrate-gauge", str(tmp_path / "few.npz"), "--gauge", "demo-5",
                 "--out", str(tmp_path / "a.csv")]) == 1
    assert capsys.readouterr().err == f"posekit: error: --out {tmp_path / 'a.csv'}: expected a gauge file ASBUILT.yaml\n"
    drawing = tmp_path / "drawing.yaml"                       # never over the drawing
    drawing.write_bytes(bundled_gauge_path("demo-5").read_bytes())
    assert main(["profiler", "calibrate-gauge", str(tmp_path / "few.npz"), "--gauge", str(drawing),
                 "--out", str(drawing)]) == 1
    assert "is the nominal gauge file" in capsys.readouterr().err
    assert drawing.read_bytes() == bundled_gauge_path("demo-5").read_bytes()


def test_calibrates_from_realistic_profiles():
    """On what a real cell gives (rounded ridges, a fixture in view, multipath, as-built faces,
    scale error, dropouts) the model-based corners feed the bundle adjustment: every profile is
    used and the fit agrees with the noise (chi2/dof near 1)."""
    from posekit.profiler import RealismModel

    nominal = bundled_gauge("demo-5")
    Ts = sample_poses(nominal, 80, np.random.default_rng(11), CALIBRATION_POSES)
    profiles = render_profiles(nominal, Ts, NoiseModel(), np.random.default_rng(12), realism=RealismModel.realistic())
    cal = calibrate_gauge(profiles, nominal)
    assert len(cal.used) == 80
    assert 0.7 < cal.chi2 / cal.dof < 1.5
    assert 0.0 < cal.tolerance_um < 5.0
