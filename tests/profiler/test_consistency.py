"""The verdict of an estimate (DESIGN.md "Trust"): χ² of the fit against the assumed noise and the
gauge's tolerance, the noise test, and the records that carry them.

The defect generators here are the tests' own (not the simulator's realism): a gauge file
with one face moved along its normal, another gauge's file, noise above the assumed one,
a start in a wrong basin.
"""

from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy import stats

from posekit.errors import EstimationError
from posekit.profiler import (
    NoiseModel,
    bundled_gauge,
    detect_corners,
    load_gauge,
    render_profiles,
    sample_poses,
    solve_pose,
)
from posekit.profiler.estimate.consistency import DEFAULT_SIGNIFICANCE
from posekit.profiler.estimate.covariance import corner_covariance, face_tolerance_covariance
from posekit.profiler.estimate.pipeline import DEFAULT_NOISE, estimate_batch, estimate_pose
from posekit.profiler.gauge.design import random_gauge
from posekit.profiler.gauge.model import gauge_to_yaml
from posekit.profiler.studies.evaluate import evaluate, pose_errors

GAUGES = ["demo-4", "demo-5", "demo-7", "demo-10"]


def gauge_variant(gauge, path: Path, *, offsets=None, tolerance_um=None):
    """``gauge`` written to ``path`` with other face offsets (mm) and/or a tolerance, and loaded."""
    doc = yaml.safe_load(gauge_to_yaml(gauge))
    if offsets is not None:
        for plane, d in zip(doc["planes"], offsets):
            plane["offset"] = float(d)
    if tolerance_um is not None:
        doc["tolerance_um"] = float(tolerance_um)
    path.write_text(yaml.safe_dump(doc))
    return load_gauge(path)


#: The noise the ideal simulator makes, told to the estimator: its sensor has no scale error (the
#: default allowance of 100 ppm would widen every std for an error these profiles do not have).
EXACT_SCALE = NoiseModel(scale_sigma_ppm=0.0)


def simulate(gauge, count, seed, noise=NoiseModel()):
    rng = np.random.default_rng(seed)
    Ts = sample_poses(gauge, count, rng)
    return Ts, render_profiles(gauge, Ts, noise, rng)


def chi2_within(values, dof, n_sigma=4.0):
    """Mean and variance of χ²(dof) samples within n_sigma of their sampling spread."""
    values = np.asarray(values)
    n = len(values)
    assert abs(values.mean() - dof) < n_sigma * np.sqrt(2 * dof / n), (values.mean(), dof)
    # var of the sample variance of χ²(k): (μ4 - σ⁴)/n with μ4 = 12k(k + 4), σ² = 2k
    sd_var = np.sqrt((12 * dof * (dof + 4) - 4 * dof**2) / n)
    # the variance gets 1.5x the room: the model detector's trimmed face fits give slightly heavier
    # tails than chi2 (1,000 demo-5 profiles: mean 3.97, variance 7.74 for dof 4; demo-7 8.15 / 18.9)
    assert abs(values.var() - 2 * dof) < 1.5 * n_sigma * sd_var, (values.var(), 2 * dof)
    assert stats.kstest(values, "chi2", args=(dof,)).pvalue > 1e-3


# --- good data: χ² ~ dof, calibrated standard deviations ----------------------------------

@pytest.mark.parametrize("name", GAUGES)
def test_chi2_on_good_data_follows_its_distribution(name):
    """250 profiles at the LJ-X8400's 10/5 µm, estimated with the same assumed noise."""
    g = bundled_gauge(name)
    ev = evaluate(g, 250, NoiseModel(), seed=31, assumed_noise=EXACT_SCALE)
    assert not ev.failures
    assert ev.dof == 2 * g.n_corners - 6
    chi2_within(ev.chi2, ev.dof)
    assert ev.suspect.mean() <= 0.01
    # the standard deviations are honest: about 95 % of the errors within 2 sigma (±4 sd of 250 draws)
    cover = np.mean(np.abs(ev.errors) <= 2 * ev.predicted_std, axis=0)
    assert np.all(np.abs(cover - 0.954) < 4 * np.sqrt(0.954 * 0.046 / 250)), cover


@pytest.mark.parametrize("name", ["demo-5", "demo-10"])
def test_closed_form_has_its_own_error_model(name):
    """The closed form's std and χ² from its own linearisation: calibrated too (its errors are larger)."""
    g = bundled_gauge(name)
    cf = evaluate(g, 200, NoiseModel(), seed=32, method="cf", assumed_noise=EXACT_SCALE)
    mle = evaluate(g, 200, NoiseModel(), seed=32, method="mle", assumed_noise=EXACT_SCALE)
    assert np.all(np.isfinite(cf.predicted_std))
    chi2_within(cf.chi2, cf.dof)
    cover = np.mean(np.abs(cf.errors) <= 2 * cf.predicted_std, axis=0)
    assert np.all(np.abs(cover - 0.954) < 4 * np.sqrt(0.954 * 0.046 / 200)), cover
    # the closed form is the less precise estimator, and says so
    assert np.all(np.median(cf.predicted_std / mle.predicted_std, axis=0) >= 1.0)


def test_corner_covariance_under_the_model_matches_monte_carlo(gauge5):
    """At one pose, 400 noisy profiles: the corners scatter as the model's covariance says."""
    T = sample_poses(gauge5, 1, rng=40)[0]
    profiles = render_profiles(gauge5, np.repeat(T[None], 400, axis=0), NoiseModel(), rng=41)
    corners = [detect_corners(p, 5) for p in profiles]
    pts = np.array([c.points.ravel() for c in corners])
    empirical = np.cov(pts.T)
    model = corner_covariance(corners[0], NoiseModel())
    ratio = np.diag(model) / np.diag(empirical)
    assert np.all(np.abs(ratio - 1) < 4 * np.sqrt(2 / 400) + 0.05), ratio
    # noise=None keeps the line fits' own covariance; a model twice as noisy gives 4x the covariance
    np.testing.assert_array_equal(corner_covariance(corners[0], None), corners[0].cov)
    np.testing.assert_allclose(corner_covariance(corners[0], NoiseModel(20, 10)), 4 * model, rtol=1e-10)


def _plane_corners(gauge, T_G_F, offsets):
    """Corners (x, z) in F of the laser plane of T_G_F and faces with these offsets (exact, 3×3 solves)."""
    y_axis = T_G_F[:3, 1]
    out = []
    for k in range(gauge.n_corners):
        A = np.stack([gauge.normals[k], gauge.normals[k + 1], y_axis])
        p_G = np.linalg.solve(A, [offsets[k], offsets[k + 1], y_axis @ T_G_F[:3, 3]])
        p_F = T_G_F[:3, :3].T @ (p_G - T_G_F[:3, 3])
        out.append(p_F[[0, 2]])
    return np.array(out).ravel()


def test_face_tolerance_covariance_matches_finite_differences(tmp_path):
    g = gauge_variant(bundled_gauge("demo-5"), tmp_path / "g.yaml", tolerance_um=7.0)
    T = sample_poses(g, 1, rng=42)[0]
    J = np.empty((10, 6))
    h = 1e-3                                 # the corners are linear in the offsets
    for k in range(6):
        d = np.zeros(6)
        d[k] = h
        J[:, k] = (_plane_corners(g, T, g.offsets + d) - _plane_corners(g, T, g.offsets - d)) / (2 * h)
    expected = (7e-3) ** 2 * J @ J.T
    np.testing.assert_allclose(face_tolerance_covariance(g, T), expected, rtol=1e-6, atol=1e-12)
    # reversed scan order: the same covariance with the corners' 2x2 blocks in reverse order
    idx = (2 * (4 - np.arange(5))[:, None] + np.arange(2)).ravel()
    np.testing.assert_allclose(face_tolerance_covariance(g, T, True), expected[np.ix_(idx, idx)], rtol=1e-6,
                               atol=1e-12)
    assert not face_tolerance_covariance(bundled_gauge("demo-5"), T).any()      # no tolerance, nothing added


def test_machining_within_the_declared_tolerance_is_ok_and_covered(tmp_path):
    """20 as-built gauges, each face off by N(0, 20 µm), estimated with tolerance_um: 20."""
    d5 = bundled_gauge("demo-5")
    nominal = gauge_variant(d5, tmp_path / "nominal.yaml", tolerance_um=20.0)
    rng = np.random.default_rng(43)
    z, status = [], []
    for i in range(20):
        built = gauge_variant(d5, tmp_path / f"built{i}.yaml", offsets=d5.offsets + rng.normal(0, 0.020, 6))
        Ts, profiles = simulate(built, 15, 100 + i)
        for T, prof in zip(Ts, profiles):
            _, est = estimate_pose(prof, nominal)
            z.append(pose_errors(est.T_G_F, T) / np.sqrt(np.diag(est.cov)))
            status.append(est.status)
    assert status.count("suspect") <= 3                        # <= 1 % of 300
    cover = np.mean(np.abs(np.array(z)) <= 2, axis=0)
    assert np.all(cover > 0.92), cover


# --- bad data: suspect, with the reason -------------------------------------------------

def test_wrong_gauge_file_is_suspect(gauge5):
    """demo-5 profiles against another 5-ridge gauge: every record suspect; against demo-7: errors."""
    Ts, profiles = simulate(gauge5, 30, 50)
    other = random_gauge(5, 3)
    records = [rec for rec, _ in estimate_batch(profiles, other)]
    # never ok: the model-based corner detector refuses most (the section does not match the
    # file), the chi2 test marks the rest suspect
    assert "ok" not in {r["status"] for r in records}
    assert {r["status"] for r in records} <= {"suspect", "error"}
    for r in (r for r in records if r["status"] == "suspect"):
        assert r["chi2"] > 1e3 and r["dof"] == 4
        fit = r["reason"].split("; ")[0]                 # the fit test's reason comes first
        assert fit.startswith("chi2 = ")
        assert (" > 20.0 (4 dof, significance 0.0005): the corners do not fit gauge 'random-5' within the assumed "
                "noise (x 10 µm, z 5 µm) and its tolerance (0 µm), largest miss at corner ") in fit
        assert fit.endswith(" µm): wrong gauge file, a face off its drawing, a rounded or chamfered ridge, or a "
                            "wrong basin")
    records = [rec for rec, _ in estimate_batch(profiles, bundled_gauge("demo-7"))]
    assert {r["status"] for r in records} == {"error"}
    assert records[0]["error"].startswith("expected 7 corners for gauge 'demo-7', found 5")


@pytest.mark.parametrize("face", [0, 2, 4])
def test_face_off_its_drawing(tmp_path, gauge5, face):
    """One face machined 20 µm off: suspect against a 2 µm tolerance, ok against 30 µm."""
    offsets = gauge5.offsets.copy()
    offsets[face] += 0.020
    built = gauge_variant(gauge5, tmp_path / "built.yaml", offsets=offsets)
    tight = gauge_variant(gauge5, tmp_path / "tight.yaml", tolerance_um=2.0)
    loose = gauge_variant(gauge5, tmp_path / "loose.yaml", tolerance_um=30.0)
    Ts, profiles = simulate(built, 40, 60 + face)
    assert [r["status"] for r, _ in estimate_batch(profiles, tight)] == ["suspect"] * 40
    records = list(estimate_batch(profiles, loose))
    assert [r["status"] for r, _ in records] == ["ok"] * 40
    z = np.array([pose_errors(est.T_G_F, T) / np.sqrt(np.diag(est.cov)) for (_, est), T in zip(records, Ts)])
    assert np.all(np.abs(z) < 5)


def test_noise_three_times_the_model_is_suspect(gauge5):
    Ts, profiles = simulate(gauge5, 30, 70, noise=NoiseModel(30, 15))
    records = [rec for rec, _ in estimate_batch(profiles, gauge5)]
    assert [r["status"] for r in records] == ["suspect"] * 30
    for r in records:
        noise = [part for part in r["reason"].split("; ") if part.startswith("the profile scatters ")]
        assert len(noise) == 1
        assert 2.5 < float(noise[0].split()[3].rstrip("x")) < 3.5          # "the profile scatters 2.97x ..."
        assert noise[0].endswith("noisier than the sensor model (x 10 µm, z 5 µm) or a face that is not flat")
    # told the real noise, the same profiles are fine
    records = [rec for rec, _ in estimate_batch(profiles, gauge5, noise=NoiseModel(30, 15))]
    assert sum(r["status"] == "suspect" for r in records) <= 1


@pytest.mark.parametrize("name", ["demo-4", "demo-5"])
def test_wrong_basin_is_never_ok(name):
    """Refined from a start 30-60° off: wherever it lands far from the truth, the record is suspect."""
    from scipy.spatial.transform import Rotation

    g = bundled_gauge(name)
    Ts, profiles = simulate(g, 40, 80)
    far = 0
    for T, prof in zip(Ts, profiles):
        for rv in ([0, 0, 60], [10, 10, 30]):
            start = T.copy()
            start[:3, :3] = T[:3, :3] @ Rotation.from_rotvec(np.radians(rv)).as_matrix()
            start[:3, 3] += [3.0, 5.0, 2.0]
            _, est = estimate_pose(prof, g, T_init=start, noise=EXACT_SCALE)
            z = np.abs(pose_errors(est.T_G_F, T)) / np.sqrt(np.diag(est.cov))
            if z.max() > 6:
                far += 1
                assert est.status == "suspect"
                assert est.reason.startswith("chi2 = ")
    assert far >= 20                       # the starts do reach wrong basins


# --- API ------------------------------------------------------------------------------

def test_defaults_are_explicit():
    assert DEFAULT_SIGNIFICANCE == 1e-3
    assert (DEFAULT_NOISE.sigma_x_um, DEFAULT_NOISE.sigma_z_um) == (10.0, 5.0)


def test_noise_none_tests_the_geometry_only(gauge5):
    """Without an assumed noise the line fits' noise is used: 3x noise passes, the wrong gauge does not."""
    _, profiles = simulate(gauge5, 10, 90, noise=NoiseModel(30, 15))
    for prof in profiles:
        corners = detect_corners(prof, 5)
        est = solve_pose(corners, gauge5)
        assert est.dof == 4 and np.isfinite(est.chi2)
        if est.status == "suspect":
            assert "scatters" not in est.reason
        wrong = solve_pose(corners, random_gauge(5, 3))
        assert wrong.status == "suspect"
        assert "within the line fits' noise and its tolerance (0 µm)" in wrong.reason


def test_bad_verdict_arguments(gauge5):
    _, profiles = simulate(gauge5, 1, 91)
    corners = detect_corners(profiles[0], 5)
    for bad in (0, 1, -0.1, 1.5, float("nan"), "0.01"):
        with pytest.raises(EstimationError, match=r"^significance must be a number in \(0, 1\), got "):
            solve_pose(corners, gauge5, significance=bad)
    with pytest.raises(EstimationError, match=r"^noise: the assumed noise must be finite, >= 0 and not zero in both "
                                              r"x and z, got x 0 µm, z 0 µm$"):
        solve_pose(corners, gauge5, noise=NoiseModel(0, 0))
    with pytest.raises(EstimationError, match=r"^noise: expected a NoiseModel \(sigma_x_um, sigma_z_um\), got float$"):
        solve_pose(corners, gauge5, noise=5.0)
