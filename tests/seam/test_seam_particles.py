"""Particle-set primitives: log-weight normalisation and recovery, ESS, resamplers (cross-checked
against filterpy.monte_carlo), the fast rotation log against posekit.geometry, weighted mean on SE(3)."""

import numpy as np
import pytest
from filterpy import monte_carlo

from posekit.errors import ConfigError
from posekit.geometry import (
    matrix_from_rotation_vector,
    rotation_vector_from_matrix,
    se3_exp,
)
from posekit.seam.engine.particles import (
    RESAMPLERS,
    effective_sample_size,
    normalize_log_weights,
    resample,
    residual_resample,
    stratified_resample,
    systematic_resample,
    weighted_mean_se3,
)


def test_normalize_log_weights_values():
    r = normalize_log_weights(np.log([1.0, 3.0]) + 1000.0)  # no overflow
    np.testing.assert_allclose(r.w, [0.25, 0.75])
    np.testing.assert_allclose(np.exp(r.logw).sum(), 1.0)
    assert not r.recovered
    r = normalize_log_weights([0.0, np.nan, -np.inf, np.log(3.0)])  # NaN counts as weight 0
    np.testing.assert_allclose(r.w, [0.25, 0.0, 0.0, 0.75])
    assert not r.recovered
    r = normalize_log_weights([np.inf, 0.0, 0.0, 0.0])  # an overflowed likelihood is not trusted
    np.testing.assert_allclose(r.w, [0.0, 1 / 3, 1 / 3, 1 / 3])


@pytest.mark.parametrize("bad", [[-np.inf] * 4, [np.nan] * 4, [np.nan, -np.inf, np.nan, -np.inf]])
def test_vanishing_weights_are_reset_to_uniform(bad):
    r = normalize_log_weights(np.array(bad))
    assert r.recovered
    np.testing.assert_allclose(r.w, 0.25)
    np.testing.assert_allclose(r.logw, -np.log(4.0))


def test_effective_sample_size():
    assert effective_sample_size(np.full(10, 0.1)) == pytest.approx(10.0)
    assert effective_sample_size(np.r_[1.0, np.zeros(9)]) == pytest.approx(1.0)
    assert effective_sample_size([0.5, 0.5, 0.0]) == pytest.approx(2.0)


def _weights(n, seed):
    w = np.random.default_rng(seed).random(n) ** 4
    return w / w.sum()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_systematic_and_stratified_match_filterpy(seed):
    w = _weights(257, seed)
    np.random.seed(seed)
    ref = monte_carlo.systematic_resample(w)
    np.random.seed(seed)
    ours = systematic_resample(w, offset=np.random.random())
    np.testing.assert_array_equal(ours, ref)
    np.random.seed(seed + 10)
    ref = monte_carlo.stratified_resample(w)
    np.random.seed(seed + 10)
    ours = stratified_resample(w, uniforms=np.random.random(257))
    np.testing.assert_array_equal(ours, ref)


def test_residual_keeps_floor_copies_and_fills_from_residuals():
    w = np.array([0.5, 0.3, 0.15, 0.05])
    counts = np.zeros(4)
    rng = np.random.default_rng(0)
    for _ in range(2000):
        idx = residual_resample(w, rng)
        c = np.bincount(idx, minlength=4)
        # floor(N w) = [2, 1, 0, 0] deterministic copies
        assert c[0] >= 2 and c[1] >= 1 and c.sum() == 4
        counts += c
    # the one remaining draw follows the residuals N w - floor(N w) = [0, .2, .6, .2]
    np.testing.assert_allclose(counts / 2000 - [2, 1, 0, 0], [0.0, 0.2, 0.6, 0.2], atol=0.04)
    # filterpy's residual_resample uses w - floor(N w) as residual (a known bug): ours does not
    assert np.bincount(residual_resample(np.full(4, 0.25), 0), minlength=4).tolist() == [1, 1, 1, 1]


@pytest.mark.parametrize("name", sorted(RESAMPLERS))
def test_resamplers_unbiased_and_in_range(name):
    w = _weights(50, 3)
    rng = np.random.default_rng(1)
    counts = np.zeros(50)
    for _ in range(400):
        idx = resample(name, w, rng)
        assert idx.shape == (50,) and idx.min() >= 0 and idx.max() < 50
        counts += np.bincount(idx, minlength=50)
    np.testing.assert_allclose(counts / (400 * 50), w, atol=0.01)
    # one dominant particle: every index is it
    assert set(resample(name, np.r_[0.0, 1.0, 0.0], rng).tolist()) == {1}


def test_unknown_resampler():
    with pytest.raises(ConfigError, match=r"unknown resampler 'best', expected one of \['residual', 'stratified', 'systematic'\]"):
        resample("best", np.ones(3) / 3)


def test_weighted_mean_se3():
    rng = np.random.default_rng(1)
    T0 = se3_exp([10.0, -20.0, 30.0, 0.3, -0.2, 0.1])
    # symmetric pairs around T0 (in its frame): the mean is T0
    xi = rng.normal(size=(500, 6)) * [0.5, 1.0, 2.0, 0.01, 0.02, 0.03]
    xi = np.concatenate([xi, -xi])
    D = np.repeat(np.eye(4)[None], 1000, axis=0)
    D[:, :3, :3] = matrix_from_rotation_vector(xi[:, 3:])
    D[:, :3, 3] = xi[:, :3]
    Ts = T0 @ D
    w = np.full(1000, 1e-3)
    T_mean, spread = weighted_mean_se3(Ts, w)
    np.testing.assert_allclose(T_mean[:3, 3], T0[:3, 3], atol=1e-9)
    np.testing.assert_allclose(rotation_vector_from_matrix(T0[:3, :3].T @ T_mean[:3, :3]), 0.0, atol=1e-9)
    np.testing.assert_allclose(spread, [0.5, 1.0, 2.0, 0.01, 0.02, 0.03], rtol=0.1)
    # weights select: all weight on one particle -> that particle, zero spread
    w = np.zeros(1000)
    w[7] = 1.0
    T_mean, spread = weighted_mean_se3(Ts, w)
    np.testing.assert_allclose(T_mean, Ts[7], atol=1e-12)
    np.testing.assert_allclose(spread, 0.0, atol=1e-7)
    # identical rotations: the mean rotation is that rotation exactly
    R = matrix_from_rotation_vector([0.0, 0.0, 2.5])
    Ts = np.repeat(np.eye(4)[None], 3, axis=0)
    Ts[:, :3, :3] = R
    Ts[:, :3, 3] = [[0, 0, 0], [3, 0, 0], [0, 6, 0]]
    T_mean, _ = weighted_mean_se3(Ts, np.array([0.5, 0.25, 0.25]))
    np.testing.assert_allclose(T_mean[:3, :3], R, atol=1e-12)
    np.testing.assert_allclose(T_mean[:3, 3], [0.75, 1.5, 0.0])
