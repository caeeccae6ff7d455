"""The realistic simulator (posekit.profiler.sim.realism): each defect does what it says, and only that."""

from dataclasses import replace

import numpy as np
import pytest

from posekit.cli.main import main
from posekit.errors import ConfigError
from posekit.profiler import LJ_X8400, NoiseModel, nominal_pose, render_profiles, sample_poses
from posekit.profiler.sim.realism import RealismModel, build_as_built
from posekit.profiler.sim.realism_render import EDGE, FIXTURE, PLATE, cast_as_built, true_corners

NOISELESS = NoiseModel(0.0, 0.0)
REALISTIC = RealismModel.realistic()


def render_pair(gauge, Ts, realism, seed=0):
    """The same poses without and with ``realism`` (as-built drawn with the seed), noise-free."""
    scene = build_as_built(gauge, realism, seed)
    sharp = render_profiles(gauge, Ts, NOISELESS, 1)
    real = render_profiles(gauge, Ts, NOISELESS, 1, realism=scene)
    return scene, sharp, real


def test_every_option_off_is_the_ideal_render(gauge5):
    Ts = sample_poses(gauge5, 8, rng=0)
    _, sharp, real = render_pair(gauge5, Ts, RealismModel())
    np.testing.assert_array_equal(np.isnan(sharp), np.isnan(real))
    np.testing.assert_allclose(real, sharp, atol=1e-9)


def test_same_seed_same_numbers(gauge5):
    Ts = sample_poses(gauge5, 4, rng=0)
    a = render_profiles(gauge5, Ts, NoiseModel(), 7, realism=REALISTIC)
    b = render_profiles(gauge5, Ts, NoiseModel(), 7, realism=REALISTIC)
    c = render_profiles(gauge5, Ts, NoiseModel(), 8, realism=REALISTIC)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c, equal_nan=True)
    # an as-built gauge renders again the same way
    scene = build_as_built(gauge5, REALISTIC, 3)
    np.testing.assert_array_equal(render_profiles(gauge5, Ts, NoiseModel(), 4, realism=scene),
                                  render_profiles(gauge5, Ts, NoiseModel(), 4, realism=scene))


def test_rounded_ridges_cut_peaks_and_fill_valleys_near_the_ridge_only(gauge5):
    Ts = sample_poses(gauge5, 6, rng=2)
    r_max = 1.0
    scene, sharp, real = render_pair(gauge5, Ts, RealismModel(edge_radius_mm=(0.5, r_max)))
    assert np.all(scene.edge_kind == 1)
    xc = true_corners(scene.gauge, Ts)[..., 0]
    dz = real[..., 1] - sharp[..., 1]
    both = np.isfinite(dz)
    near = np.abs(sharp[..., 0][..., None] - xc[:, None, :]) < 2 * r_max         # (K, N, n)
    assert np.all(np.abs(dz[both & ~near.any(axis=-1)]) < 1e-9)                 # away from ridges: untouched
    for k in range(gauge5.n_corners):
        zone = both & near[..., k]
        sign = 1.0 if scene.convex[k] else -1.0                                   # z is depth
        assert np.all(sign * dz[zone] > -1e-9)                                    # peaks deeper, valleys filled
        assert (sign * dz[zone]).max() > 0.03                                     # and it shows
        assert np.abs(dz[zone]).max() < 0.5 * r_max


def test_chamfers_are_flat_bevels(gauge5):
    Ts = nominal_pose(gauge5)[None]
    scene, sharp, real = render_pair(gauge5, Ts, RealismModel(chamfer_fraction=1.0, chamfer_mm=(1.0, 1.0)))
    assert np.all(scene.edge_kind == 2)
    _, label, _ = cast_as_built(scene, Ts, LJ_X8400)
    for k in range(gauge5.n_corners):
        on = label[0] == EDGE + k
        pts = real[0, on]
        assert 8 <= on.sum() <= 20                     # ~1 mm of returns at ~0.1 mm spacing
        # the bevel is a straight segment about 1 mm long
        d = pts - pts.mean(axis=0)
        _, s, _ = np.linalg.svd(d, full_matrices=False)
        assert s[1] / np.sqrt(len(pts)) < 1e-9
        assert 0.8 < np.ptp(pts[:, 0]) < 1.3


def test_plate_and_fixture_beside_the_gauge(gauge5):
    Ts = sample_poses(gauge5, 5, rng=3)
    scene = build_as_built(gauge5, RealismModel(plate_depth_mm=8.0, fixture_height_mm=(5.0, 5.0)), 0)
    pts, label, _ = cast_as_built(scene, Ts, LJ_X8400)
    for k, T in enumerate(Ts):
        p_G = np.stack([pts[k, :, 0], np.zeros(len(pts[k])), pts[k, :, 1]], 1) @ T[:3, :3].T + T[:3, 3]
        plate = label[k] == PLATE
        fix = label[k] == FIXTURE
        assert plate.sum() > 500 and fix.sum() > 50
        np.testing.assert_allclose(p_G[plate, 2], scene.plate_z, atol=1e-9)
        outside = (p_G[plate, 0] < gauge5.x_range[0]) | (p_G[plate, 0] > gauge5.x_range[1])
        assert np.all(outside)                                          # never under the gauge
        top = np.abs(p_G[fix, 2] - scene.fixture[2]) < 1e-9
        wall = np.abs(p_G[fix, 0] - scene.fixture[0 if scene.fixture[3] > 0 else 1]) < 1e-9
        assert np.all(top | wall) and top.sum() > 50
    assert scene.fixture[2] == pytest.approx(scene.plate_z + 5.0)


def test_multipath_only_beside_valleys_and_deeper(gauge5):
    Ts = sample_poses(gauge5, 20, rng=4)
    rm = RealismModel(multipath_rate=1.0, multipath_length_mm=(1.0, 2.0), multipath_depth_mm=(0.2, 0.4))
    scene, sharp, real = render_pair(gauge5, Ts, rm)
    xc = true_corners(scene.gauge, Ts)[..., 0]
    dz = real[..., 1] - sharp[..., 1]
    moved = np.isfinite(dz) & (np.abs(dz) > 1e-9)
    assert np.all(dz[moved] > 0.09) and np.all(dz[moved] < 0.41)
    dist = np.abs(sharp[..., 0][..., None] - xc[:, None, :])                 # (K, N, n)
    valley = dist[..., ~scene.convex].min(axis=-1)
    assert np.all(valley[moved] < 2.35)                                        # 0.3 + 2 mm, with slack
    assert moved.sum(axis=1).min() > 10                                        # every profile has ghosts


def test_machining_error_moves_the_faces_by_their_tolerance(gauge5):
    diffs, shifts = [], []
    Ts = sample_poses(gauge5, 5, rng=5)
    for seed in range(40):
        scene = build_as_built(gauge5, RealismModel(face_offset_um=10.0), seed)
        diffs.append(scene.gauge.offsets - gauge5.offsets)
        np.testing.assert_allclose(scene.gauge.normals, gauge5.normals, atol=1e-12)
        shifts.append(true_corners(scene.gauge, Ts) - true_corners(gauge5, Ts))
    # 40 × 6 offsets of σ 10 µm: the sample std is within 15 % of σ unless 4.7 of its standard
    # errors (σ / sqrt(2 · 240) = 4.6 %) away
    assert np.std(diffs) * 1e3 == pytest.approx(10.0, rel=0.15)
    # each corner is where its two faces cross the laser plane, so offsets δ of faces k, k + 1
    # move corner k by exactly N_k⁻¹ [δ_k, δ_k+1], N_k the faces' normals in F (x, z): by hand
    for d, shift in zip(diffs, shifts):
        for T, s in zip(Ts, shift):
            m = (gauge5.normals @ T[:3, :3])[:, [0, 2]]
            expected = [np.linalg.solve(m[k:k + 2], d[k:k + 2]) for k in range(gauge5.n_corners)]
            np.testing.assert_allclose(s, expected, atol=1e-9)
    tilted = build_as_built(gauge5, RealismModel(face_tilt_deg=0.05), 0).gauge
    angles = np.degrees(np.arccos(np.clip(np.sum(tilted.normals * gauge5.normals, axis=1), -1, 1)))
    assert np.all(angles < 0.3) and angles.max() > 0.01
    # the rendered returns lie on the as-built faces, not on the drawing
    scene = build_as_built(gauge5, RealismModel(face_offset_um=10.0), 1)
    prof = render_profiles(gauge5, Ts[0], NOISELESS, 0, realism=scene)
    ok = np.isfinite(prof[:, 0])
    p_G = np.stack([prof[ok, 0], np.zeros(ok.sum()), prof[ok, 1]], 1) @ Ts[0][:3, :3].T + Ts[0][:3, 3]
    np.testing.assert_allclose(scene.gauge.surface_z(p_G[:, 0], p_G[:, 1]), p_G[:, 2], atol=1e-9)


def test_scale_error_scales_x_about_zero_and_z_about_mid_range(gauge5):
    Ts = sample_poses(gauge5, 3, rng=6)
    _, sharp, real = render_pair(gauge5, Ts, RealismModel(scale_x_ppm=200.0, scale_z_ppm=-300.0))
    ok = np.isfinite(sharp[..., 0])
    np.testing.assert_allclose(real[ok][:, 0], sharp[ok][:, 0] * (1 + 200e-6), atol=1e-10)
    np.testing.assert_allclose(real[ok][:, 1] - LJ_X8400.z_mid, (sharp[ok][:, 1] - LJ_X8400.z_mid) * (1 - 300e-6),
                               atol=1e-10)


def test_dropouts_follow_the_incidence_angle(gauge5):
    Ts = sample_poses(gauge5, 30, rng=7)
    rm = RealismModel(plate_depth_mm=8.0, fixture_height_mm=(10.0, 10.0), steep_dropout_max=0.6)
    scene, _, real = render_pair(gauge5, Ts, rm)
    pts, _, cosinc = cast_as_built(scene, Ts, LJ_X8400)
    theta = np.degrees(np.arccos(np.clip(cosinc, 0, 1)))
    seen = np.isfinite(pts[..., 0])
    lost = seen & np.isnan(real[..., 0])
    mild = seen & (theta < 15.0)
    steep = seen & (theta > 50.0)
    assert steep.sum() > 50 and mild.sum() > 1000
    # a run starts only on a steep return (it may run 2 returns on): mild ones far from steep are all kept
    assert lost[mild].mean() < 0.01
    assert lost[steep].mean() > 0.2


@pytest.mark.parametrize("kwargs, message", [
    ({"edge_radius_mm": (1.0, 0.5)}, "'edge_radius_mm' must be a range"),
    ({"chamfer_fraction": 2.0}, "'chamfer_fraction' must lie in \\[0, 1\\]"),
    ({"fixture_height_mm": (3.0, 4.0)}, "'fixture_height_mm' needs a plate"),
    ({"face_offset_um": -1.0}, "'face_offset_um' must be a finite number >= 0"),
    ({"steep_dropout_deg": (40.0, 30.0)}, "'steep_dropout_deg' must be a range"),
])
def test_bad_options_are_config_errors(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        RealismModel(**kwargs)
    with pytest.raises(ConfigError, match="unknown defect"):
        REALISTIC.only("rust")


def test_only_keeps_one_defect():
    m = REALISTIC.only("multipath")
    assert m.multipath_rate == REALISTIC.multipath_rate and m.plate_depth_mm is None
    assert m.edge_radius_mm == (0.0, 0.0) and m.scale_x_ppm == 0.0
    assert replace(REALISTIC.only(), dropout_run_points=4) == RealismModel()


def test_cli_simulate_realistic(tmp_path, capsys):
    argv = ["profiler", "simulate", "--gauge", "demo-5", "--count", "3", "--seed", "2"]
    assert main(argv + ["--realistic", "--out", str(tmp_path / "a")]) == 0
    assert "realistic profiles" in capsys.readouterr().out
    assert main(argv + ["--realistic", "--out", str(tmp_path / "b")]) == 0
    assert main(argv + ["--out", str(tmp_path / "c")]) == 0
    a, b, c = (np.load(tmp_path / d / "profiles.npz")["profiles"] for d in "abc")
    np.testing.assert_array_equal(a, b)                         # same seed, same numbers
    assert np.isfinite(a[..., 0]).mean() > 0.85                 # the plate fills the view
    assert np.isfinite(c[..., 0]).mean() < 0.7                  # the ideal gauge alone does not
