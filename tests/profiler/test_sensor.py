"""Sensor simulator: measuring range, noise, seeds, self-occlusion."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posekit.errors import ConfigError
from posekit.geometry import transform_from
from posekit.profiler import (
    LJ_X8400,
    NoiseModel,
    Workspace,
    gauge_from_design,
    nominal_pose,
    render_profiles,
    sample_poses,
)
from posekit.profiler.sim.poses import visible_mask


def test_lj_x8400_trapezoid():
    m = LJ_X8400
    assert m.n_points == 3200
    assert 2 * m.half_width(285.0) == pytest.approx(163.0)
    assert 2 * m.half_width(600.0) == pytest.approx(320.0)
    assert m.half_width(m.z_apex) == pytest.approx(0.0, abs=1e-9)


def test_returns_lie_on_the_gauge_inside_the_range(gauge5):
    Ts = sample_poses(gauge5, 20, rng=1)
    profiles = render_profiles(gauge5, Ts, NoiseModel(0, 0), rng=1)
    for T, prof in zip(Ts, profiles):
        ok = np.isfinite(prof[:, 0])
        assert 0.2 < ok.mean() < 0.8
        z = prof[ok, 1]
        assert np.all((z >= 285) & (z <= 600))
        assert np.all(np.abs(prof[ok, 0]) <= LJ_X8400.half_width(z) + 1e-9)
        p_F = np.stack([prof[ok, 0], np.zeros(ok.sum()), prof[ok, 1]], 1)
        p_G = p_F @ T[:3, :3].T + T[:3, 3]
        np.testing.assert_allclose(gauge5.surface_z(p_G[:, 0], p_G[:, 1]), p_G[:, 2], atol=1e-9)


def test_noise_levels_and_seeds(gauge5):
    Ts = sample_poses(gauge5, 5, rng=0)
    clean = render_profiles(gauge5, Ts, NoiseModel(0, 0), rng=3)
    noisy = render_profiles(gauge5, Ts, NoiseModel(sigma_x_um=10, sigma_z_um=5), rng=3)
    d = (noisy - clean)[np.isfinite(clean[..., 0])]
    assert np.std(d[:, 0]) * 1e3 == pytest.approx(10, rel=0.05)
    assert np.std(d[:, 1]) * 1e3 == pytest.approx(5, rel=0.05)
    again = render_profiles(gauge5, Ts, NoiseModel(sigma_x_um=10, sigma_z_um=5), rng=3)
    np.testing.assert_array_equal(again, noisy)
    np.testing.assert_array_equal(sample_poses(gauge5, 5, rng=0), Ts)
    assert not np.array_equal(sample_poses(gauge5, 5, rng=1), Ts)


def test_steep_face_self_occludes():
    """Tilting the sensor beyond β turns the steepest face away from the laser (§III-D)."""
    g = gauge_from_design("steep", [-30, -10, 10, 30], [0.2, -0.2, 1.2, -0.2, 0.2], [0.1, -0.1, 0.1, -0.1],
                          extent=((-45, 45), (-20, 20)))
    beta = g.beta_deg                                      # face 2 rises at 50°: β = 40°
    assert beta == pytest.approx(90 - np.degrees(np.arctan(np.hypot(1.2, g.normals[2, 1] / g.normals[2, 2]))))
    T0 = nominal_pose(g)
    counts = {}
    for alpha in (0.0, beta + 8, -(beta + 8)):
        # tilt the laser plane about F's y axis, pivoting on the gauge centre
        R = T0[:3, :3] @ Rotation.from_euler("y", alpha, degrees=True).as_matrix()
        pivot = np.array([0, 0, LJ_X8400.z_mid])
        T = transform_from(R, T0[:3, :3] @ pivot + T0[:3, 3] - R @ pivot)
        prof = render_profiles(g, T, NoiseModel(0, 0), rng=0)
        ok = np.isfinite(prof[:, 0])
        p_F = np.stack([prof[ok, 0], np.zeros(ok.sum()), prof[ok, 1]], 1)
        p_G = p_F @ T[:3, :3].T + T[:3, 3]
        on_face2 = np.abs(p_G @ g.normals[2] - g.offsets[2]) < 1e-6
        counts[alpha] = (on_face2.sum(), visible_mask(g, T[None])[0])
    assert counts[0.0][0] > 50 and counts[0.0][1]
    # tilted past β one way, the steep face turns its back to the laser: no return, not visible
    occluded = [a for a in counts if a != 0.0 and counts[a][0] == 0]
    assert len(occluded) == 1 and not counts[occluded[0]][1]


def test_workspace_too_large_is_an_error(gauge5):
    with pytest.raises(ConfigError, match="workspace too large for gauge 'demo-5'"):
        sample_poses(gauge5, 100, rng=0, workspace=Workspace(translation_mm=(200, 200, 200)))
    with pytest.raises(ConfigError, match="'sigma_z_um' must be a finite number >= 0, got -1"):
        NoiseModel(sigma_z_um=-1)
