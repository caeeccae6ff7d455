"""The sensor's unknown scale in every pose's std (``NoiseModel.scale_sigma_ppm``).

A sensor whose x and z readings are off by ~100 ppm (the realistic default of both generators)
moves every corner by ``(s_x x, s_z (z - z_c))``; the pose absorbs almost all of it, so the fit's
χ² does not see it, but the pose is biased: without the allowance the std of rz covered ~10 % of
the errors within 2σ on realistic profiles. The profiles here come from the tests' own generator
(tests/profiler/test_realistic_generator.py), not from posekit's simulator.
"""

import numpy as np
import pytest

from posekit.cli.main import main
from posekit.errors import ConfigError
from posekit.profiler import bundled_gauge, pose_errors
from posekit.profiler.estimate.covariance import SCALE_Z_CENTER_MM, scale_covariance
from posekit.profiler.estimate.pipeline import estimate_profiles
from posekit.profiler.sensor import DEFAULT_SCALE_SIGMA_PPM, LJ_X8400, NoiseModel
from tests.profiler.test_gauge_check import batch
from tests.profiler.test_realistic_generator import Z_CENTER_MM


def test_scale_covariance_against_corners_moved_by_random_scales():
    """``σ² (j_x j_xᵀ + j_z j_zᵀ)`` by hand, and the sample covariance of corners scaled by random
    ``(1 + s_x, 1 + s_z)`` (z about the middle of the LJ-X8400's range, as both generators)."""
    assert SCALE_Z_CENTER_MM == LJ_X8400.z_mid == Z_CENTER_MM
    pts = np.array([[-10.0, 440.0], [5.0, 445.5], [12.0, 441.0]])
    J = np.array([[-10.0, 0.0], [0.0, -2.5], [5.0, 0.0], [0.0, 3.0], [12.0, 0.0], [0.0, -1.5]])
    np.testing.assert_allclose(scale_covariance(pts, 100.0), 1e-8 * J @ J.T, rtol=1e-12, atol=0)
    rng = np.random.default_rng(3)
    s = rng.normal(0.0, 150e-6, (20000, 2))
    moved = np.stack([pts[None, :, 0] * (1 + s[:, :1]),
                      Z_CENTER_MM + (pts[None, :, 1] - Z_CENTER_MM) * (1 + s[:, 1:])], axis=2).reshape(-1, 6)
    np.testing.assert_allclose(np.cov(moved.T), scale_covariance(pts, 150.0), atol=0.03 * (150e-6 * 12) ** 2)
    assert np.all(scale_covariance(pts, 0.0) == 0)


def test_noise_model_scale_sigma_default_and_errors():
    assert NoiseModel().scale_sigma_ppm == DEFAULT_SCALE_SIGMA_PPM == 100.0
    with pytest.raises(ConfigError) as e:
        NoiseModel(scale_sigma_ppm=-1.0)
    assert str(e.value) == "noise: 'scale_sigma_ppm' must be a finite number >= 0, got -1.0"
    with pytest.raises(ConfigError) as e:
        NoiseModel(scale_sigma_ppm=2e4)
    assert str(e.value) == "noise: 'scale_sigma_ppm' must be <= 10000 ppm, got 20000"


def test_std_is_honest_under_a_sensor_scale_error():
    """demo-5, 120 profiles of the independent generator with every cell defect but machining
    (100 ppm scale error): with the default allowance >= 88 % of each component's errors lie
    within 2σ (measured 95-100 %); without it rz's std covers under half (measured ~14 %)."""
    d5 = bundled_gauge("demo-5")
    profiles, Ts = batch(d5, d5, 120, 800)
    honest = estimate_profiles(profiles, d5, check_gauge=False)
    blind = estimate_profiles(profiles, d5, noise=NoiseModel(scale_sigma_ppm=0.0), check_gauge=False)

    def within(res):
        z = np.array([np.abs(pose_errors(e.T_G_F, T)) / np.sqrt(np.diag(e.cov))
                      for e, T in zip(res.estimates, Ts) if e is not None])
        return np.mean(z <= 2.0, axis=0), len(z)

    w_honest, n = within(honest)
    w_blind, _ = within(blind)
    assert n >= 110
    assert np.all(w_honest >= 0.88), w_honest
    assert w_blind[5] < 0.5 and np.all(w_blind <= w_honest), w_blind
    # good data: the allowance makes fewer poses suspect (the scale error shows in χ² too), never more
    sus = [sum(r["status"] == "suspect" for r in res.records) for res in (honest, blind)]
    assert sus[0] <= 2 and sus[0] <= sus[1], sus
    # the GLS fit de-weights what a scale error moves: the pose moves by ~0.6 of its (wider) std (median)
    moved = np.array([np.abs(pose_errors(a.T_G_F, b.T_G_F)) / np.sqrt(np.diag(a.cov))
                      for a, b in zip(honest.estimates, blind.estimates) if a is not None and b is not None])
    assert np.all(np.median(moved, axis=0) < 1.0)


def test_cli_scale_sigma_flag(tmp_path, capsys):
    """``--scale-sigma-ppm`` reaches the std columns; a bad value is a one-line error."""
    d5 = bundled_gauge("demo-5")
    profiles, _ = batch(d5, d5, 3, 810)
    np.savez(tmp_path / "p.npz", profiles=profiles)
    stds = {}
    for ppm in ("0", "100"):
        out = tmp_path / f"poses{ppm}.csv"
        main(["profiler", "estimate", str(tmp_path / "p.npz"), "--gauge", "demo-5", "--scale-sigma-ppm", ppm,
              "--out", str(out)])
        lines = out.read_text().splitlines()
        head = lines[0].split(",")
        stds[ppm] = np.array([[float(v) for v in np.array(row.split(","))[[head.index("std_rz_deg")]]]
                              for row in lines[1:] if row.split(",")[head.index("status")] != "error"])
    default = tmp_path / "default.csv"
    main(["profiler", "estimate", str(tmp_path / "p.npz"), "--gauge", "demo-5", "--out", str(default)])
    assert default.read_text() == (tmp_path / "poses100.csv").read_text()
    assert len(stds["0"]) >= 2 and np.all(stds["100"] > 1.5 * stds["0"])
    capsys.readouterr()
    rc = main(["profiler", "estimate", str(tmp_path / "p.npz"), "--gauge", "demo-5", "--scale-sigma-ppm", "-5"])
    assert rc != 0
    assert capsys.readouterr().err.strip() == ("posekit: error: --scale-sigma-ppm: expected a number in 0..10000 ppm, "
                                               "got -5")
